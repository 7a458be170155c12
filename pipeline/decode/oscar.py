"""OSCAR v1 and v2 NetCDF → canonical `(time, lat, lon)` dataset of `uo`, `vo` (m/s, going-to).

Fixes applied: v1 longitude 20→420 folded to 0..360 with the repeated band dropped, descending
latitude made ascending, depth squeezed; v2 dims `longitude/latitude` with coordinate variables
`lon/lat` renamed, -999 fill → NaN; both time units decoded to datetime64 UTC.
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


def decode_oscar(path: Path) -> xr.Dataset:
    path = Path(path)
    with _open(path) as raw:
        if "u" not in raw or "v" not in raw:
            raise DecodeError(path, f"no u/v current variables (has {sorted(raw.data_vars)})")
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
        raise DecodeError(path, "time axis has no decodable units")
    for k in ("uo", "vo"):
        v = ds[k].values.astype(np.float32)
        v[(v <= -999.0) | (np.abs(v) > 20.0)] = np.nan  # fill values and garbage
        ds[k] = (("time", "lat", "lon"), v, cube_variables.attrs(k))
        if not np.isfinite(v).any():  # an all-fill file would give a "complete" cycle without currents
            raise DecodeError(path, f"no valid values in {k[0]} (every value is fill or out of range)")
    ds["lat"].attrs = cube_variables.attrs("lat")
    ds["lon"].attrs = cube_variables.attrs("lon")
    return ds
