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
from pipeline.decode.grib import GridInfo, axis_order, read_fields
from pipeline.sources.rish import parse_name
from schemas import cube_variables

# name → (discipline, category, number, level type, level)
GSM_WIND = {"u10": (0, 2, 2, 103, 10.0), "v10": (0, 2, 3, 103, 10.0)}
GWM_WAVES = {
    "swh": (10, 0, 3, None, None),
    "mwd": (10, 0, 14, None, None),
    "mwp": (10, 0, 15, None, None),
}
GWM_DIRECTION_ALTERNATIVES = ((10, 0, 4), (10, 0, 10))  # wind-wave direction, primary wave direction
# mean period of wind waves, primary wave mean period, peak period (10/0/5 is the height of wind waves, not a period)
GWM_PERIOD_ALTERNATIVES = ((10, 0, 6), (10, 0, 11), (10, 0, 34))
GWM_FILL_VALUE = 9999.0
# the units eccodes reports for each field (GRIB2 parameter units), checked on every message
GSM_UNITS = {"u10": "m s**-1", "v10": "m s**-1"}
GWM_UNITS = {"swh": "m", "mwd": "Degree true", "mwp": "s"}
GWM_MIN_LAT_SPAN = (-60.0, 60.0)  # a global wave grid reaches at least these latitudes (ice-free ocean)

_order = axis_order


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


def _require_product_grid(grid: GridInfo, path: Path, res_deg: float, lat_span: tuple[float, float]) -> None:
    """The product's global grid: `res_deg` spacing both ways (the file name's resolution), longitudes round the
    globe from 0E and latitudes reaching `lat_span` — a regional or mislabelled file would leave most of the
    routing grid empty or put values in the wrong place."""
    _require_global(grid, path)
    dlat = np.diff(grid.lat)
    dlon = np.diff(grid.lon)
    if not (np.allclose(dlat, res_deg, atol=1e-4) and np.allclose(dlon, res_deg, atol=1e-4)):
        raise DecodeError(path, f"wrong grid: spacing {float(np.median(dlat)):g}°×{float(np.median(dlon)):g}°, "
                                f"expected {res_deg:g}° as the file name says")
    if abs(float(grid.lon[0])) > 1e-4:
        raise DecodeError(path, f"wrong grid: longitudes start at {float(grid.lon[0]):g}E, expected 0E")
    if grid.lat[0] > lat_span[0] + 1e-4 or grid.lat[-1] < lat_span[1] - 1e-4:
        raise DecodeError(path, f"wrong grid: latitudes {grid.lat[0]:g}..{grid.lat[-1]:g}, expected a global grid "
                                f"covering {lat_span[0]:g}..{lat_span[1]:g}")


def _require_name_matches(path: Path, cycle: np.datetime64, steps: list[int]) -> None:
    """Reference time and leads as the file name promises (when the name is a GSM/GWM name): a file of another
    date or lead served under this name would otherwise be stored as this cycle."""
    promised = parse_name(path.name)
    if promised is None:
        return
    if np.datetime64(cycle, "ns") != promised.cycle:
        raise DecodeError(path, f"reference time {np.datetime_as_string(np.datetime64(cycle, 'm'))} in the file, "
                                f"{np.datetime_as_string(np.datetime64(promised.cycle, 'm'))} in its name")
    outside = [s for s in steps if not promised.first_lead_h <= s <= promised.last_lead_h]
    if outside:
        raise DecodeError(path, f"lead {', '.join(f'{s} h' for s in outside)} in the file, "
                                f"{promised.first_lead_h}..{promised.last_lead_h} h in its name")


def _require_plausible(ds: xr.Dataset, path: Path) -> None:
    for name in ds.data_vars:
        problem = cube_variables.implausible(name, ds[name].values)
        if problem:
            raise DecodeError(path, problem)


def _require_no_holes(ds: xr.Dataset, path: Path) -> None:
    """GSM wind covers the whole globe (land too): a missing or non-finite point is damage, and a hole in the
    wind must never be read as calm."""
    for name, da in ds.data_vars.items():
        holes = ~np.isfinite(da.values)
        if holes.any():
            lat = np.broadcast_to(ds["lat"].values[:, None], holes.shape[-2:])[holes.reshape(-1, *holes.shape[-2:]).any(axis=0)]
            lon = np.broadcast_to(ds["lon"].values[None, :], holes.shape[-2:])[holes.reshape(-1, *holes.shape[-2:]).any(axis=0)]
            raise DecodeError(path, f"{int(holes.sum())} missing or non-finite value(s) of {name} "
                                    f"(lat {lat.min():g}..{lat.max():g}, lon {lon.min():g}..{lon.max():g}); "
                                    "wind has no land mask, so this is damage")


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
    path = Path(path)
    values, grid, cycle = read_fields(path, GSM_WIND, units=GSM_UNITS)
    missing = [k for k, v in values.items() if not v]
    if missing:
        raise DecodeError(path, f"no {', '.join(missing)} (10 m wind) in this GSM file")
    _require_product_grid(grid, path, 0.5, (-90.0, 90.0))
    steps = sorted(set(values["u10"]) | set(values["v10"]))
    if len(steps) != 1 or set(values["u10"]) != set(values["v10"]):
        raise DecodeError(path, f"expected one lead time in a GSM file, found u10 at {sorted(values['u10'])} h, "
                                f"v10 at {sorted(values['v10'])} h")
    _require_name_matches(path, cycle, steps)
    ds = _canonical(values, grid, cycle, steps).isel(step=0)
    _require_values(ds, path)
    _require_no_holes(ds, path)
    _require_plausible(ds, path)
    return ds.assign_coords(valid_time=ds.cycle + np.timedelta64(int(ds.step), "h"))


def decode_gwm(path: Path) -> xr.Dataset:
    """One GWM file (several lead times) → swh, mwd, mwp (step, lat, lon); land/ice → NaN."""
    wanted = dict(GWM_WAVES)
    for alt in GWM_DIRECTION_ALTERNATIVES:
        wanted[f"mwd_{alt[2]}"] = (*alt, None, None)
    for alt in GWM_PERIOD_ALTERNATIVES:
        wanted[f"mwp_{alt[2]}"] = (*alt, None, None)
    path = Path(path)
    units = dict(GWM_UNITS) | {k: GWM_UNITS[k[:3]] for k in wanted if k[:4] in ("mwd_", "mwp_")}
    values, grid, cycle = read_fields(path, wanted, fill_value=GWM_FILL_VALUE, units=units)
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
    promised = parse_name(path.name)
    _require_product_grid(grid, path, promised.res_deg if promised else float(np.median(np.diff(grid.lon))),
                          GWM_MIN_LAT_SPAN)
    steps = sorted(set(values["swh"]) & set(values["mwd"]) & set(values["mwp"]))
    if not steps:
        raise DecodeError(path, "wave fields do not share any lead time")
    _require_name_matches(path, cycle, steps)
    ds = _canonical(values, grid, cycle, steps)
    _require_values(ds, path)
    _require_plausible(ds, path)
    return ds
