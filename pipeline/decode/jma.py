"""JMA GSM (10 m wind) and GWM (waves) GRIB2 → canonical xarray Datasets.

Canonical form: lat ascending, lon 0..360 east ascending, `cycle` (model init, UTC) and `step`
(lead time, whole hours). Wind in m/s; waves: `swh` m, `mwd` degrees coming-from, `mwp` s.
Land and ice (bitmap or fill value) are NaN.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import xarray as xr

from pipeline.decode.errors import DecodeError
from pipeline.decode.grib import GridInfo, read_fields
from schemas import cube_variables

# name → (discipline, category, number, level type, level)
GSM_WIND = {"u10": (0, 2, 2, 103, 10.0), "v10": (0, 2, 3, 103, 10.0)}
GWM_WAVES = {
    "swh": (10, 0, 3, None, None),
    "mwd": (10, 0, 14, None, None),
    "mwp": (10, 0, 15, None, None),
}
GWM_DIRECTION_ALTERNATIVES = ((10, 0, 4), (10, 0, 10))  # wind-wave direction, primary wave direction
GWM_PERIOD_ALTERNATIVES = ((10, 0, 5), (10, 0, 11), (10, 0, 34))
GWM_FILL_VALUE = 9999.0


def _order(axis: np.ndarray) -> np.ndarray | slice:
    """Index that sorts `axis` ascending; a slice (a view, no copy) when it is already sorted or reversed."""
    order = np.argsort(axis)
    if np.array_equal(order, np.arange(axis.size)):
        return slice(None)
    if np.array_equal(order, np.arange(axis.size)[::-1]):
        return slice(None, None, -1)
    return order


def _canonical(values: dict[str, dict[int, np.ndarray]], grid: GridInfo, cycle: np.datetime64, steps: list[int]) -> xr.Dataset:
    lat_order = _order(grid.lat)
    lon_order = _order(grid.lon)
    data = {}
    for name, by_step in values.items():
        cube = np.stack([by_step[s] for s in steps])[:, lat_order][:, :, lon_order]
        data[name] = (("step", "lat", "lon"), cube, cube_variables.attrs(name))
    ds = xr.Dataset(
        data,
        coords={
            "step": ("step", np.asarray(steps, dtype=np.int32), {"units": "hours", "long_name": "lead time"}),
            "lat": ("lat", grid.lat[lat_order], cube_variables.attrs("lat")),
            "lon": ("lon", grid.lon[lon_order], cube_variables.attrs("lon")),
            "cycle": np.datetime64(cycle, "ns"),
        },
    )
    return ds


def _require_global(grid: GridInfo, path: Path) -> None:
    """GSM and GWM are global products (`Rgl`): a grid that does not go round the globe in longitude
    (a regional or mislabelled file) would leave most of the routing grid empty, so it is refused."""
    lon = np.sort(grid.lon)
    step = float(np.median(np.diff(lon))) if lon.size > 1 else 0.0
    if step <= 0 or abs(lon.size * step - 360.0) > step / 2:
        raise DecodeError(path, f"wrong grid: longitudes {lon[0]:g}..{lon[-1]:g}E in {lon.size} points do not cover the globe; "
                                "expected a global GSM/GWM grid")


def _require_values(ds: xr.Dataset, path: Path) -> None:
    """Every field (at every lead) has at least one valid value: an all-missing field would otherwise pass as
    data and leave the cycle "complete" with nothing in it."""
    for name, da in ds.data_vars.items():
        valid = np.isfinite(da.values).reshape(-1, da.sizes["lat"] * da.sizes["lon"]).any(axis=1)
        if not valid.all():
            steps = np.atleast_1d(ds["step"].values)[~valid] if "step" in da.dims else np.atleast_1d(ds["step"].values)
            raise DecodeError(path, f"no valid values in {name} at lead {', '.join(f'{int(s)} h' for s in steps)} "
                                    "(every grid point is missing)")


def decode_gsm(path: Path) -> xr.Dataset:
    """One GSM file (one lead time) → u10, v10 (lat, lon) with scalar cycle, step, valid_time."""
    values, grid, cycle = read_fields(path, GSM_WIND)
    missing = [k for k, v in values.items() if not v]
    if missing:
        raise DecodeError(path, f"no {', '.join(missing)} (10 m wind) in this GSM file")
    _require_global(grid, path)
    steps = sorted(set(values["u10"]) & set(values["v10"]))
    if len(steps) != 1:
        raise DecodeError(path, f"expected one lead time in a GSM file, found {steps}")
    ds = _canonical(values, grid, cycle, steps).isel(step=0)
    _require_values(ds, path)
    return ds.assign_coords(valid_time=ds.cycle + np.timedelta64(int(ds.step), "h"))


def decode_gwm(path: Path) -> xr.Dataset:
    """One GWM file (several lead times) → swh, mwd, mwp (step, lat, lon); land/ice → NaN."""
    wanted = dict(GWM_WAVES)
    for alt in GWM_DIRECTION_ALTERNATIVES:
        wanted[f"mwd_{alt[2]}"] = (*alt, None, None)
    for alt in GWM_PERIOD_ALTERNATIVES:
        wanted[f"mwp_{alt[2]}"] = (*alt, None, None)
    values, grid, cycle = read_fields(path, wanted, fill_value=GWM_FILL_VALUE)
    for base in ("mwd", "mwp"):  # take the first direction/period product present
        if not values[base]:
            for key in [k for k in values if k.startswith(base + "_")]:
                if values[key]:
                    values[base] = values[key]
                    break
    values = {k: v for k, v in values.items() if k in GWM_WAVES}
    if not values["swh"]:
        raise DecodeError(path, "no significant wave height (GRIB2 10/0/3) in this GWM file")
    for k in ("mwd", "mwp"):
        if not values[k]:
            raise DecodeError(path, f"no {cube_variables.attrs(k)['long_name']} in this GWM file")
    _require_global(grid, path)
    steps = sorted(set(values["swh"]) & set(values["mwd"]) & set(values["mwp"]))
    if not steps:
        raise DecodeError(path, "wave fields do not share any lead time")
    ds = _canonical(values, grid, cycle, steps)
    _require_values(ds, path)
    return ds
