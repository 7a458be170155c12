"""Assemble one forecast cycle on the routing grid from decoded GSM, GWM and OSCAR datasets.

Every lead time of the cube's fixed step axis gets a slot; a step whose wind or waves are
missing stays NaN and is listed in `missing_steps` so the cycle is marked incomplete.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import xarray as xr

from schemas.cube_variables import provided_by
from pipeline.weather.currents import analysis_for, persist_into
from pipeline.weather.regrid import regrid

WIND_VARS = provided_by("GSM")
WAVE_VARS = provided_by("GWM")
CURRENT_VARS = provided_by("OSCAR")


def assemble_cycle(cycle: np.datetime64, steps_h: Sequence[int], lat: np.ndarray, lon: np.ndarray,
                   gsm: Sequence[xr.Dataset], gwm: Sequence[xr.Dataset], oscar: xr.Dataset | None,
                   optional_after_h: int | None = None) -> tuple[xr.Dataset, list[int]]:
    """(cycle dataset with dims (step, lat, lon), steps with missing wind or waves).

    Steps past `optional_after_h` are leads a cycle may add (the 00/12 UTC cycles' to 264 h): never reported missing,
    used up to the first of them without wind or waves, and from there on left all NaN (currents too), so the cycle
    ends at its last step with both: readers take the trailing NaN steps for the cycle's end, never for a hole."""
    steps = np.asarray(steps_h, dtype=np.int32)
    shape = (steps.size, lat.size, lon.size)
    # uninitialised: every slot is written once below, by a field or by NaN (no full-size NaN prefill to overwrite)
    out = {v: np.empty(shape, np.float32) for v in (*WIND_VARS, *WAVE_VARS, *CURRENT_VARS)}
    have_wind = np.zeros(steps.size, bool)
    have_waves = np.zeros(steps.size, bool)
    pos = {int(s): i for i, s in enumerate(steps)}
    for ds in gsm:
        i = pos.get(int(ds["step"]))
        if i is None:
            continue
        r = regrid(ds, lat, lon)
        for v in WIND_VARS:
            out[v][i] = r[v].values
        have_wind[i] = True
    for ds in gwm:
        keep = [(k, pos[int(s)]) for k, s in enumerate(ds["step"].values) if int(s) in pos]
        if not keep:
            continue
        r = regrid(ds, lat, lon)  # all its steps at once (no copy when the decoder already regridded it)
        for k, i in keep:
            for v in WAVE_VARS:
                out[v][i] = r[v].values[k]
            have_waves[i] = True
    for v in WIND_VARS:
        out[v][~have_wind] = np.nan
    for v in WAVE_VARS:
        out[v][~have_waves] = np.nan
    valid = np.datetime64(cycle, "ns") + steps.astype("timedelta64[h]").astype("timedelta64[ns]")
    if oscar is not None:
        # regrid each analysis once, then persist it to the valid times (same values, far fewer fields)
        cur = regrid(oscar, lat, lon)
        idx, age = analysis_for(cur["time"].values, valid)
        for v in CURRENT_VARS:
            persist_into(cur[v].values, idx, out[v])
    else:
        age = np.full(steps.size, np.nan, np.float32)
        for v in CURRENT_VARS:
            out[v].fill(np.nan)
    if optional_after_h is not None:
        gap = np.flatnonzero((steps > optional_after_h) & ~(have_wind & have_waves))
        if gap.size:
            for v in out.values():
                v[gap[0]:] = np.nan
            age = np.array(age, np.float32)
            age[gap[0]:] = np.nan
    missing = [int(s) for s, w, a in zip(steps, have_wind, have_waves)
               if not (w and a) and (optional_after_h is None or s <= optional_after_h)]
    ds = xr.Dataset(
        {k: (("step", "lat", "lon"), v) for k, v in out.items()} | {"current_age_h": (("step",), age.astype(np.float32))},
        coords={"step": steps, "lat": lat, "lon": lon, "cycle": np.datetime64(cycle, "ns")},
    )
    return ds, missing
