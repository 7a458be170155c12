"""What the isochrone peer (52North WeatherRoutingTool, "WRT") reads and writes, and how jitroute prices its route.

The peer runs in its own interpreter (bench/peer_wrt_run.py); this side never imports it. It hands WRT:
- the voyage's weather (`weather_dataset`) in the netCDF layout WRT's `WeatherCondFromFile` and its ships read (the
  layout of its own `FakeWeather`): dims (latitude, longitude, time[, height_above_ground | depth]); wind
  `u-/v-component_of_wind_height_above_ground` (m/s, towards), `VHM0` (Hs, m), `VMDR` (wave direction, degrees,
  coming from), `utotal`/`vtotal` (current, m/s, going to). jitroute's field has no wave period, pressure, air or
  water temperature or salinity: those are written as constants (`FILLERS`), which WRT's direct-power ship does not
  use;
- deep water everywhere (`depth_dataset`: ETOPO's `z`, negative below sea level), so depth never constrains it;
- a config (`wrt_config`): isofuel, the direct-power ship, land from global_land_mask, stay on the map.

WRT takes longitudes in −180..180 and a map box lon_min..lon_max, so a box across the dateline cannot be given. Such a
voyage is handed over in a frame turned `shift_deg` east about the pole (every longitude minus the shift): great
circles, distances, courses and wind/current directions are the same in that frame, and the runner turns
global_land_mask's lookups back by the shift, so WRT meets the same land. `read_route` turns its waypoints back.

jitroute prices WRT's route (`route_instance` + `pipeline.routing.engine_limits.best_engine_plan`, the best engine
setting per leg on a fixed route): the waypoints become a graph of one node per line, sailed with the suite's
settings, weather, vessel model and objective, so its cost compares with the suite's DP and BFOA costs (also over
the settings, continuous=False).
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import xarray as xr

from pipeline.routing.geodesy import KN_PER_MS
from pipeline.routing.land import land_grid
from pipeline.routing.clearance import lat_band, line_edges_clear
from pipeline.routing.weather_field import SWH, U10, UO, V10, VO, WAVE_X, WAVE_Y, WeatherField

WIND_HEIGHT_M = 10.0
CURRENT_DEPTH_M = 0.494  # WRT's FakeWeather's surface layer (CMEMS's first depth)
DEEP_WATER_M = 5000.0
# what jitroute's field does not have, as constants (unused by WRT's direct-power ship)
FILLERS = {"VTPK": (0.0, "s"), "Pressure_reduced_to_MSL_msl": (101325.0, "Pa"), "Temperature_surface": (288.15, "K"),
           "thetao": (15.0, "degrees_C"), "so": (35.0, "1e-3")}
# the direct-power ship (WRT's config template's geometry) at the suite model's design point: 14 kn, and a calm-water
# fuel rate of 1.5 t/h there (pipeline.synthetic.routing_suite.MODEL); WRT scales power with speed³ as the model does
SHIP_LENGTH_M, SHIP_BREADTH_M, SHIP_HBR_M = 180.0, 32.0, 30.0
SFOC_G_PER_KWH = 170.0


def grid_axes(field: WeatherField) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(latitudes °, longitudes ° as the field numbers them, valid times UTC) of a weather field."""
    g = field.grid
    lat = g.lat0 + g.dlat * np.arange(g.nlat)
    lon = g.lon0 + g.dlon * np.arange(g.nlon)
    times = field.t_ref + np.round(field.times_h * 3600.0).astype("timedelta64[s]")
    return lat, lon, times


def shift_deg(lon: np.ndarray) -> float:
    """0 when the field's longitudes lie in −180..180 as WRT needs them; else the whole degrees to turn them by
    (their centre), so they do."""
    lo, hi = float(np.min(lon)), float(np.max(lon))
    if -180.0 <= lo and hi <= 180.0:
        return 0.0
    return float(np.round(0.5 * (lo + hi)))


def to_frame(lon, shift: float):
    """Longitude(s) in the frame turned `shift` degrees east, in −180..180."""
    return (np.asarray(lon, np.float64) - shift + 180.0) % 360.0 - 180.0


def weather_dataset(field: WeatherField, shift: float = 0.0) -> xr.Dataset:
    """The field in WRT's netCDF layout, longitudes in the frame turned by `shift`."""
    lat, lon, times = grid_axes(field)
    lon_f = lon - shift
    if lon_f.min() < -180.0 or lon_f.max() > 180.0:
        raise ValueError(f"longitudes {lon.min():g}..{lon.max():g} minus {shift:g} leave −180..180: use shift_deg()")
    cells = field.cells.astype(np.float64)  # (lat, lon, time, var)
    wave_from_deg = np.degrees(np.arctan2(cells[..., WAVE_X], cells[..., WAVE_Y])) % 360.0
    surface = (["latitude", "longitude", "time"])
    data = {
        "u-component_of_wind_height_above_ground": (surface + ["height_above_ground"], cells[..., U10][..., None],
                                                    {"units": "m s-1"}),
        "v-component_of_wind_height_above_ground": (surface + ["height_above_ground"], cells[..., V10][..., None],
                                                    {"units": "m s-1"}),
        "VHM0": (surface, cells[..., SWH], {"units": "m"}),
        "VMDR": (surface, wave_from_deg, {"units": "degree", "comment": "direction the waves come from"}),
        "utotal": (surface + ["depth"], cells[..., UO][..., None], {"units": "m s-1"}),
        "vtotal": (surface + ["depth"], cells[..., VO][..., None], {"units": "m s-1"}),
    }
    shape = cells.shape[:3]
    for name, (value, units) in FILLERS.items():
        dims = surface + (["depth"] if name in ("thetao", "so") else [])
        arr = np.full(shape + ((1,) if len(dims) == 4 else ()), value)
        data[name] = (dims, arr, {"units": units, "comment": "constant: not in jitroute's weather"})
    coords = {"latitude": ("latitude", lat, {"units": "degrees_north"}),
              "longitude": ("longitude", lon_f, {"units": "degrees_east"}),
              "time": ("time", times.astype("datetime64[ns]")),
              "height_above_ground": ("height_above_ground", [WIND_HEIGHT_M], {"units": "m"}),
              "depth": ("depth", [CURRENT_DEPTH_M], {"units": "m"})}
    attrs = {"source": "jitroute routing suite weather", "longitude_shift_deg": shift}
    return xr.Dataset({k: xr.Variable(d, v, a) for k, (d, v, a) in data.items()}, coords=coords, attrs=attrs)


def depth_dataset(field: WeatherField, shift: float = 0.0) -> xr.Dataset:
    """Deep water (`z` = −DEEP_WATER_M) over the field's grid, in the frame turned by `shift`."""
    lat, lon, _ = grid_axes(field)
    z = np.full((lat.size, lon.size), -DEEP_WATER_M)
    return xr.Dataset({"z": (("latitude", "longitude"), z, {"units": "m"})},
                      coords={"latitude": lat, "longitude": lon - shift})


def wrt_config(problem, field: WeatherField, shift: float, speed_kn: float, step_nm: float, out_dir: Path,
               route_steps: int, **overrides) -> dict:
    """WRT's config (its Config and ShipConfig read the same file): isofuel on the direct-power ship at `speed_kn`,
    one routing step burning the calm-water fuel of `step_nm` at that speed, inside the weather's box."""
    lat, lon, times = grid_axes(field)
    lon_f = lon - shift
    dep_t = np.datetime64(problem.depart_utc, "s")
    hours = float((times[-1] - dep_t) / np.timedelta64(1, "h"))
    fuel_tph = calm_fuel_tph(speed_kn)
    out_dir = Path(out_dir)
    cfg = {
        "ALGORITHM_TYPE": "isofuel",
        "BOAT_TYPE": "direct_power_method",
        "DEFAULT_ROUTE": [problem.dep[0], float(to_frame(problem.dep[1], shift)), problem.arr[0],
                          float(to_frame(problem.arr[1], shift))],
        "DEFAULT_MAP": [float(lat.min()), float(lon_f.min()), float(lat.max()), float(lon_f.max())],
        "DEPARTURE_TIME": str(dep_t.astype("datetime64[m]")) + "Z",
        "TIME_FORECAST": math.floor(hours) - 1,
        "DELTA_TIME_FORECAST": 3,  # WRT refuses a finer step; its ship samples the hourly file at the nearest hour
        "DELTA_FUEL": fuel_tph * 1000.0 * step_nm / speed_kn,  # kg per routing step
        "CONSTRAINTS_LIST": ["land_crossing_global_land_mask", "water_depth", "on_map"],
        "ISOCHRONE_MAX_ROUTING_STEPS": int(route_steps),
        "WEATHER_DATA": str(out_dir / "weather.nc"),
        "DEPTH_DATA": str(out_dir / "depth.nc"),
        "ROUTE_PATH": str(out_dir / "route"),
        "BOAT_SPEED": speed_kn / KN_PER_MS,
        "BOAT_SMCR_SPEED": 14.0 / KN_PER_MS,
        "BOAT_SMCR_POWER": 1.5e6 / SFOC_G_PER_KWH / 0.75,  # kW: 75 % of it at 14 kn burns 1.5 t/h
        "BOAT_FUEL_RATE": SFOC_G_PER_KWH,
        "BOAT_LENGTH": SHIP_LENGTH_M,
        "BOAT_BREADTH": SHIP_BREADTH_M,
        "BOAT_HBR": SHIP_HBR_M,
    }
    cfg.update(overrides)
    return cfg


def calm_fuel_tph(speed_kn: float) -> float:
    """WRT's direct-power ship's calm-water fuel rate (t/h) at `speed_kn`, as wrt_config sets it up."""
    return 1.5 * (speed_kn / 14.0) ** 3


def read_route(path: Path, shift: float = 0.0) -> tuple[np.ndarray, np.ndarray, float]:
    """(latitudes, longitudes −180..180, WRT's own fuel in t) of the route WRT wrote (a GeoJSON FeatureCollection of
    Points [lon, lat], one per routing step, with each step's fuel rate in t/h and start time)."""
    feats = json.loads(Path(path).read_text())["features"]
    lat = np.array([f["geometry"]["coordinates"][1] for f in feats], np.float64)
    lon = to_frame(np.array([f["geometry"]["coordinates"][0] for f in feats], np.float64), -shift)
    times = np.array([np.datetime64(f["properties"]["time"].replace("Z", ""), "s") for f in feats])
    hours = np.diff(times) / np.timedelta64(1, "h")
    rate = np.array([f["properties"]["fuel_consumption"]["value"] for f in feats[:-1]], np.float64)
    return lat, lon, float(np.sum(rate * hours))


def route_instance(inst, lat: np.ndarray, lon: np.ndarray):
    """The instance restricted to the route through (lat, lon): a graph of one node per line, every leg open (land is
    reported apart, `legs_off_clearance`), the instance's settings, weather, vessel and objective."""
    sp = inst.space
    lat = np.ascontiguousarray(lat, np.float64)[:, None]
    lon = np.ascontiguousarray(lon, np.float64)[:, None]
    n = lat.shape[0]
    route = replace(sp, lat=lat, lon=lon, node_ok=np.ones((n, 1), bool), edge_ok=np.ones((n - 1, 1, 1), bool),
                    max_shift=0, gate=None, line_d_point_nm=None)
    return replace(inst, space=route, graph=route.graph)


def legs_off_clearance(inst, lat: np.ndarray, lon: np.ndarray) -> int:
    """How many legs of the route break the land clearance and latitude limits jitroute's own graph keeps (0 when
    land was not checked)."""
    rule = inst.space.clearance
    if rule is None:
        return 0
    lat = np.ascontiguousarray(lat, np.float64)[:, None]
    lon = np.ascontiguousarray(lon, np.float64)[:, None]
    n = lat.shape[0]
    ok = np.zeros((n - 1, 1, 1), bool)
    band = lat_band(inst.problem.lat_limits)
    grid = land_grid()
    for i in range(n - 1):
        line_edges_clear(grid, rule, lat, lon, np.ones((n, 1), bool), i, 0, band, ok)
    return int(np.sum(~ok))
