"""Currents at forecast valid times: the latest OSCAR analysis at or before each valid time,
persisted forward, with its age in hours recorded (OSCAR is 5-daily or daily, not a forecast)."""

from __future__ import annotations

import numpy as np
import xarray as xr


def analysis_for(analysis_times, valid_times) -> tuple[np.ndarray, np.ndarray]:
    """(index into `analysis_times` of the latest analysis at or before each valid time, −1 where there is
    none; that analysis' age in hours, NaN where there is none)."""
    vt = np.asarray(valid_times, dtype="datetime64[ns]")
    times = np.asarray(analysis_times).astype("datetime64[ns]")
    order = np.argsort(times)
    k = np.searchsorted(times[order], vt, side="right") - 1
    have = k >= 0
    idx = np.where(have, order[np.clip(k, 0, None)], -1)
    age_h = np.where(have, (vt - times[np.clip(idx, 0, None)]) / np.timedelta64(1, "h"), np.nan).astype(np.float32)
    return idx, age_h


def persist_into(field: np.ndarray, idx: np.ndarray, out: np.ndarray) -> np.ndarray:
    """`out[t] = field[idx[t]]` (NaN where idx is −1), written in place: one pass, no temporaries."""
    np.take(field, np.clip(idx, 0, None), axis=0, out=out)
    out[idx < 0] = np.nan
    return out


def currents_at(oscar: xr.Dataset, valid_times) -> xr.Dataset:
    """`uo`, `vo` (valid_time, lat, lon) and `current_age_h` (valid_time; NaN where no analysis ≤ time)."""
    vt = np.asarray(valid_times, dtype="datetime64[ns]")
    idx, age = analysis_for(oscar["time"].values, vt)
    shape = (vt.size, oscar.sizes["lat"], oscar.sizes["lon"])
    uo = persist_into(oscar["uo"].values.astype(np.float32, copy=False), idx, np.empty(shape, np.float32))
    vo = persist_into(oscar["vo"].values.astype(np.float32, copy=False), idx, np.empty(shape, np.float32))
    return xr.Dataset(
        {
            "uo": (("valid_time", "lat", "lon"), uo, oscar["uo"].attrs),
            "vo": (("valid_time", "lat", "lon"), vo, oscar["vo"].attrs),
            "current_age_h": (("valid_time",), age, {"units": "hours", "long_name": "age of the OSCAR analysis used"}),
        },
        coords={"valid_time": vt, "lat": oscar["lat"], "lon": oscar["lon"]},
    )
