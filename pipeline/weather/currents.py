"""Currents at forecast valid times: the latest OSCAR analysis at or before each valid time,
persisted forward, with its age in hours recorded (OSCAR is 5-daily or daily, not a forecast)."""

from __future__ import annotations

import numpy as np
import xarray as xr


def currents_at(oscar: xr.Dataset, valid_times) -> xr.Dataset:
    """`uo`, `vo` (valid_time, lat, lon) and `current_age_h` (valid_time; NaN where no analysis ≤ time)."""
    vt = np.asarray(valid_times, dtype="datetime64[ns]")
    times = oscar["time"].values.astype("datetime64[ns]")
    order = np.argsort(times)
    times = times[order]
    idx = np.searchsorted(times, vt, side="right") - 1
    have = idx >= 0
    pick = order[np.clip(idx, 0, None)]
    uo = oscar["uo"].values[pick].astype(np.float32)
    vo = oscar["vo"].values[pick].astype(np.float32)
    uo[~have] = np.nan
    vo[~have] = np.nan
    age = np.where(have, (vt - times[np.clip(idx, 0, None)]) / np.timedelta64(1, "h"), np.nan).astype(np.float32)
    return xr.Dataset(
        {
            "uo": (("valid_time", "lat", "lon"), uo, oscar["uo"].attrs),
            "vo": (("valid_time", "lat", "lon"), vo, oscar["vo"].attrs),
            "current_age_h": (("valid_time",), age, {"units": "hours", "long_name": "age of the OSCAR analysis used"}),
        },
        coords={"valid_time": vt, "lat": oscar["lat"], "lon": oscar["lon"]},
    )
