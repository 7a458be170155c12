"""OSCAR v1 and v2 NetCDF → canonical `(time, lat, lon)` dataset of `uo`, `vo` (m/s, going-to).

Fixes applied: v1 longitude 20→420 folded to 0..360 with the repeated band dropped, descending
latitude made ascending, depth squeezed; v2 dims `longitude/latitude` with coordinate variables
`lon/lat` renamed, -999 fill → NaN; both time units decoded to datetime64 UTC. Speeds are converted to m/s from
the variables' `units` (cm/s too; other units refused) and a value beyond the plausible range refuses the file.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import xarray as xr

from pipeline.decode.errors import DecodeError
from schemas import cube_variables


def _open(path: Path) -> xr.Dataset:
    try:
        return xr.open_dataset(path, engine="netcdf4", decode_times=True, mask_and_scale=True)
    except (OSError, ValueError, RuntimeError) as exc:
        raise DecodeError(path, f"not a readable NetCDF file ({exc})") from exc


# `units` spellings of current speed → factor to m/s (a file without `units` is in OSCAR's documented m/s)
SPEED_UNITS_TO_MS = {
    **dict.fromkeys(("m/s", "m s-1", "m s**-1", "m.s-1", "meter/sec", "meters/sec", "meter/second", "meters/second",
                     "meter second-1", "m sec-1"), 1.0),
    **dict.fromkeys(("cm/s", "cm s-1", "cm s**-1", "cm.s-1", "centimeter/sec", "centimeters/sec", "centimeter/second",
                     "centimeters/second", "cm sec-1"), 0.01),
}


def _to_ms_factor(var: xr.DataArray, path: Path) -> float:
    units = var.attrs.get("units", var.encoding.get("units"))
    if units is None:
        return 1.0
    factor = SPEED_UNITS_TO_MS.get(str(units).strip().lower())
    if factor is None:
        raise DecodeError(path, f"{var.name} is in {units!r}, expected a speed such as 'm/s' or 'cm/s'")
    return factor


def decode_oscar(path: Path) -> xr.Dataset:
    path = Path(path)
    with _open(path) as raw:
        if "u" not in raw or "v" not in raw:
            raise DecodeError(path, f"no u/v current variables (has {sorted(raw.data_vars)})")
        factors = {"uo": _to_ms_factor(raw["u"], path), "vo": _to_ms_factor(raw["v"], path)}
        calendar = str(raw["time"].encoding.get("calendar") or raw["time"].attrs.get("calendar") or "standard") \
            if "time" in raw.variables else "standard"
        ds = raw[["u", "v"]].load()
        lat_name = next((n for n in ("latitude", "lat") if n in ds.dims), None)
        lon_name = next((n for n in ("longitude", "lon") if n in ds.dims), None)
        if lat_name is None or lon_name is None or "time" not in ds.dims:
            raise DecodeError(path, f"unexpected dimensions {dict(ds.sizes)}; expected time and latitude/longitude")
        # v2: dimension names differ from the coordinate variables `lat`/`lon`
        for dim, var in ((lat_name, "lat"), (lon_name, "lon")):
            if dim != var and var in raw.variables and raw[var].dims == (dim,):
                ds = ds.assign_coords({dim: raw[var].values})
    if "depth" in ds.dims:
        ds = ds.isel(depth=0, drop=True)
    ds = ds.drop_vars([c for c in ds.coords if c not in ds.dims and c != "time"], errors="ignore")
    ds = ds.rename({lat_name: "lat", lon_name: "lon", "u": "uo", "v": "vo"}).transpose("time", "lat", "lon")
    lon = np.mod(ds["lon"].values.astype(np.float64), 360.0)
    lon = np.round(lon, 6) % 360.0
    _, first = np.unique(lon, return_index=True)  # drop the repeated band (first occurrence kept)
    ds = ds.assign_coords(lon=lon).isel(lon=np.sort(first)).sortby("lon").sortby("lat")
    if not np.issubdtype(ds["time"].dtype, np.datetime64):
        if calendar.lower() not in ("standard", "gregorian", "proleptic_gregorian"):
            raise DecodeError(path, f"time axis in the {calendar!r} calendar, not the standard calendar OSCAR uses: "
                                    "its dates are not real UTC dates")
        raise DecodeError(path, "time axis has no decodable units")
    for k in ("uo", "vo"):
        v = ds[k].values.astype(np.float32)
        v[(v <= -999.0) | ~np.isfinite(v)] = np.nan  # fill values (v2: -999 without a _FillValue honoured) and inf
        if factors[k] != 1.0:
            v *= np.float32(factors[k])
        ds[k] = (("time", "lat", "lon"), v, cube_variables.attrs(k))
        if not np.isfinite(v).any():  # an all-fill file would give a "complete" cycle without currents
            raise DecodeError(path, f"no valid values in {k[0]} (every value is fill or missing)")
        problem = cube_variables.implausible(k, v)
        if problem:
            raise DecodeError(path, problem)
    ds["lat"].attrs = cube_variables.attrs("lat")
    ds["lon"].attrs = cube_variables.attrs("lon")
    return ds
