"""Weather for routing as plain numpy arrays, and its numba sampler.

A `WeatherField` holds the variables a ship meets, on a regular lat/lon grid, at a few valid
times counted in hours from `t_ref` (UTC):

  0 u10, 1 v10   wind (m/s, u east / v north: the wind blows TOWARDS that vector)
  2 swh          significant wave height (m)
  3 wave_x, 4 wave_y   sin/cos of the direction the waves come FROM (unit components)
  5 uo, 6 vo     current (m/s, going to)

Sampling is bilinear in space (NaN-aware: NaN corners such as land are ignored and the others
re-weighted) and linear in time between the two bracketing valid times, with the weight taken
over that interval. Directions are never averaged as angles: wave direction is interpolated
through its components and turned back into an angle by the caller. Past the last valid time the sampler
persists the last step and flags the sample `beyond`; the leg kernel does not sail in that frozen weather but in the
field's neutral weather (`beyond_wind_ms`, `beyond_hs_m`, see `neutral_beyond`), the same for every route.

The field is stored in the sampling layout `cells` (nlat, nlon, nt, 7): a sample reads 4 corners × 2
valid times, and in this layout each corner's two times and seven variables are 56 contiguous bytes, and
the next step along a leg (same cell, a little later) reads the same lines again. In the variable-first
layout (7, nt, nlat, nlon), still offered as the view `values`, the same sample touches 28 cache lines
spread over the whole field: in the hourly 5,000 NM bench weather a sample took 3.3× as long when steps jump
about the field, and a whole BFOA solve about 9 % longer.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import NamedTuple

import numba
import numpy as np

from pipeline.routing.geodesy import KN_PER_MS
from schemas.cube_variables import step_hours

N_VARS = 7
U10, V10, SWH, WAVE_X, WAVE_Y, UO, VO = range(N_VARS)
CUBE_VARIABLES = ("u10", "v10", "swh", "mwd", "uo", "vo")  # what from_cycle takes of a cube cycle


class Grid(NamedTuple):
    """A regular lat/lon grid (degrees): latitudes lat0 + k·dlat increasing, longitudes lon0 + k·dlon; `wraps` when
    the longitudes go round the globe (lon0 then in 0..360)."""

    lat0: float
    dlat: float
    nlat: int
    lon0: float
    dlon: float
    nlon: int
    wraps: bool


class Weather(NamedTuple):
    """What the compiled kernels see of a `WeatherField`: its cells, valid times and grid, and the neutral weather a
    ship meets past the last valid time (`neutral_beyond`: this wind speed and Hs, no current)."""

    cells: np.ndarray  # (nlat, nlon, nt, 7) float32, C-contiguous (the sampling layout)
    times_h: np.ndarray  # (nt,) float64, hours after t_ref, increasing
    grid: Grid
    beyond_wind_ms: float = 0.0
    beyond_hs_m: float = 0.0


@dataclass(frozen=True)
class WeatherField:
    cells: np.ndarray  # (nlat, nlon, nt, 7) float32, C-contiguous: per grid point its variables at every valid time
    times_h: np.ndarray  # (nt,) float64, hours after t_ref, increasing
    grid: Grid
    t_ref: np.datetime64  # UTC
    cycle: np.datetime64 | None = None

    @property
    def kernel(self) -> Weather:
        wind_ms, hs_m = self.neutral_beyond
        return Weather(self.cells, self.times_h, self.grid, wind_ms, hs_m)

    @cached_property
    def neutral_beyond(self) -> tuple[float, float]:
        """(wind speed m/s, Hs m) a ship meets past the last valid time: the means over the field's whole area and
        every valid time (missing values left out), met at engine.leg.BEYOND_REL_DEG off the bow on any course (where
        the physical form's added resistance is its mean over all headings) and without current.

        Nobody forecast the weather there, and persisting the last step (a storm frozen in place) lets a plan route
        round weather that will not be there. This assumption is the same at every position and on every course, so
        no route can profit from it, while the time and fuel it costs stay of the region's order (not calm)."""
        c = self.cells
        wind = np.hypot(c[..., U10].astype(np.float64), c[..., V10].astype(np.float64))
        hs = c[..., SWH].astype(np.float64)
        wind_ms = float(np.nanmean(wind)) if np.isfinite(wind).any() else 0.0
        hs_m = float(np.nanmean(hs)) if np.isfinite(hs).any() else 0.0
        return wind_ms, hs_m

    @cached_property
    def max_over_time(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(wind speed in kn, Hs in m, current speed in kn) per grid point (nlat, nlon): the largest at any valid
        time or past the last one (`neutral_beyond`), missing values as 0. Computed once per field (the exact
        solvers' bounds ask for it per route), in one compiled pass over the cells."""
        wind_ms, hs, cur_ms = (np.empty(self.cells.shape[:2]) for _ in range(3))
        _max_over_time_nb(self.cells, wind_ms, hs, cur_ms)
        beyond_wind_ms, beyond_hs_m = self.neutral_beyond
        np.maximum(wind_ms, beyond_wind_ms, out=wind_ms)
        np.maximum(hs, beyond_hs_m, out=hs)
        return wind_ms * KN_PER_MS, hs, cur_ms * KN_PER_MS

    @property
    def values(self) -> np.ndarray:
        """(7, nt, nlat, nlon): the variables one by one (a view of `cells`, for maps and bounds)."""
        return self.cells.transpose(3, 2, 0, 1)

    @property
    def horizon_utc(self) -> np.datetime64:
        return self.t_ref + np.timedelta64(int(round(self.times_h[-1] * 3600)), "s")

    def hours_after_ref(self, when) -> float:
        return float((np.datetime64(when, "s") - np.datetime64(self.t_ref, "s")) / np.timedelta64(1, "h"))

    @property
    def lat_range_deg(self) -> tuple[float, float]:
        g = self.grid
        return float(g.lat0), float(g.lat0 + g.dlat * (g.nlat - 1))


def _grid(lat: np.ndarray, lon: np.ndarray) -> Grid:
    lat = np.asarray(lat, dtype=np.float64)
    lon = np.asarray(lon, dtype=np.float64)
    if lat.size < 2 or lon.size < 2:
        raise ValueError("a weather field needs at least 2 latitudes and 2 longitudes")
    dlat, dlon = lat[1] - lat[0], lon[1] - lon[0]
    if not (np.allclose(np.diff(lat), dlat) and np.allclose(np.diff(lon), dlon)) or dlat <= 0 or dlon <= 0:
        raise ValueError("weather grid must be regular with increasing latitude and longitude")
    wraps = bool(abs(lon.size * dlon - 360.0) < 1e-6)
    return Grid(float(lat[0]), float(dlat), int(lat.size), float(lon[0] % 360.0 if wraps else lon[0]), float(dlon),
                int(lon.size), wraps)


def from_arrays(lat, lon, times_utc, *, u10, v10, swh, mwd_deg, uo, vo, cycle=None, t_ref=None) -> WeatherField:
    """Build a field from (nt, nlat, nlon) arrays (mwd in degrees, coming from); times count from `t_ref`
    (default the first valid time)."""
    times = np.asarray(times_utc, dtype="datetime64[s]")
    t_ref = times[0] if t_ref is None else np.datetime64(t_ref, "s")
    times_h = ((times - t_ref) / np.timedelta64(1, "s")).astype(np.float64) / 3600.0
    if np.any(np.diff(times_h) <= 0):
        raise ValueError("weather valid times must increase")
    mwd = np.radians(np.asarray(mwd_deg, dtype=np.float64))
    lat = np.asarray(lat, dtype=np.float64)
    flip = lat[0] > lat[-1]
    grid = _grid(lat[::-1] if flip else lat, lon)
    cells = np.empty((grid.nlat, grid.nlon, times_h.size, N_VARS), np.float32)
    for k, var in enumerate((u10, v10, swh, np.sin(mwd), np.cos(mwd), uo, vo)):
        a = np.asarray(var).transpose(1, 2, 0)  # (nlat, nlon, nt)
        cells[..., k] = a[::-1] if flip else a
    return WeatherField(cells=cells, times_h=times_h, grid=grid, t_ref=t_ref,
                        cycle=None if cycle is None else np.datetime64(cycle, "s"))


def from_cycle(ds, cycle=None) -> WeatherField:
    """From one cube cycle, whole or a window of it (xarray dims step, lat, lon; variables CUBE_VARIABLES). Times
    count from the cycle, whichever steps the window holds, so a voyage meets the same numbers in both."""
    cyc = np.datetime64(cycle if cycle is not None else ds["cycle"].values, "s")
    return _from_cube(cyc, step_hours(ds["step"].values), ds["lat"].values, ds["lon"].values,
                      {v: ds[v].values for v in CUBE_VARIABLES})


def from_window(window) -> WeatherField:
    """From a storage.cube_window.Window (a cycle's variables in a box, as plain arrays); times count from the
    cycle as in `from_cycle`."""
    return _from_cube(np.datetime64(window.cycle, "s"), window.step_h, window.lat, window.lon, window.data)


def _from_cube(cyc: np.datetime64, step_h, lat, lon, data: dict) -> WeatherField:
    """The cycle's steps up to its last one with wind: the cube's step axis is the longest any cycle has (the 00/12
    UTC cycles' 264 h), and a cycle with shorter leads leaves the rest all NaN (pipeline/weather/assemble.py), which
    is its end, not a hole to sail as calm."""
    wind = np.asarray(data["u10"])
    have = np.flatnonzero(np.isfinite(wind).reshape(wind.shape[0], -1).any(axis=1)) if wind.size else np.array([], int)
    n = int(have[-1]) + 1 if have.size else len(step_h)
    times = cyc + (np.asarray(step_h, np.int64)[:n] * 3600).astype("timedelta64[s]")
    return from_arrays(lat, lon, times, **{k: np.asarray(data[v])[:n] for k, v in (
        ("u10", "u10"), ("v10", "v10"), ("swh", "swh"), ("mwd_deg", "mwd"), ("uo", "uo"), ("vo", "vo"))},
        cycle=cyc, t_ref=cyc)


def uniform(t_start_utc, hours: float = 240.0, *, wind_ms=(0.0, 0.0), swh_m=0.0, wave_from_deg=0.0,
            current_ms=(0.0, 0.0), lat=(-80.0, 80.0), lon=(0.0, 359.5)) -> WeatherField:
    """The same weather everywhere and always (calm by default): for tests and for routing without a cube."""
    la = np.array([lat[0], lat[1]])
    lo = np.arange(0.0, 360.0, 0.5) if lon == (0.0, 359.5) else np.array(lon)
    t0 = np.datetime64(t_start_utc, "s")
    times = np.array([t0, t0 + np.timedelta64(int(hours * 3600), "s")])
    shape = (2, la.size, lo.size)
    return from_arrays(la, lo, times, u10=np.full(shape, wind_ms[0]), v10=np.full(shape, wind_ms[1]),
                       swh=np.full(shape, swh_m), mwd_deg=np.full(shape, wave_from_deg),
                       uo=np.full(shape, current_ms[0]), vo=np.full(shape, current_ms[1]))


@numba.njit(cache=True, inline="always")
def _finite(x):
    """numpy.nan_to_num of one value: NaN 0, ±inf the largest finite float64 of that sign."""
    if math.isnan(x):
        return 0.0
    if math.isinf(x):
        return 1.7976931348623157e308 if x > 0.0 else -1.7976931348623157e308
    return x


@numba.njit(cache=True)
def _max_over_time_nb(cells, wind_ms, hs_m, cur_ms):
    """Per grid point of `cells` (nlat, nlon, nt, 7): the largest wind speed (m/s), Hs (m) and current speed (m/s)
    at any valid time, missing values taken as 0 (`WeatherField.max_over_time`)."""
    nlat, nlon, nt = cells.shape[0], cells.shape[1], cells.shape[2]
    for i in range(nlat):
        for j in range(nlon):
            w_hi, h_hi, c_hi = -np.inf, -np.inf, -np.inf
            for k in range(nt):
                c = cells[i, j, k]
                w_hi = max(w_hi, math.hypot(_finite(np.float64(c[U10])), _finite(np.float64(c[V10]))))
                h_hi = max(h_hi, _finite(np.float64(c[SWH])))
                c_hi = max(c_hi, math.hypot(_finite(np.float64(c[UO])), _finite(np.float64(c[VO]))))
            wind_ms[i, j], hs_m[i, j], cur_ms[i, j] = w_hi, h_hi, c_hi


@numba.njit(cache=True, inline="always")
def _bilinear(cells, iy, ix0, ix1, it, v, wy, wx):
    """Variable v at valid time index it, bilinear between the 4 corners, NaN corners left out."""
    v00, v01 = cells[iy, ix0, it, v], cells[iy, ix1, it, v]
    v10, v11 = cells[iy + 1, ix0, it, v], cells[iy + 1, ix1, it, v]
    s, w = 0.0, 0.0
    for val, wt in ((v00, (1 - wy) * (1 - wx)), (v01, (1 - wy) * wx), (v10, wy * (1 - wx)), (v11, wy * wx)):
        if not math.isnan(val) and wt > 0.0:
            s += val * wt
            w += wt
    if w <= 1e-12:
        return np.nan
    return s / w


@numba.njit(cache=True, inline="always")
def _time_index_nb(times_h, t_h):
    """The index of the last valid time ≤ t_h, for times_h[0] < t_h < times_h[-1]: where the steps would put it
    were they even (a field's steps mostly are), else by bisection (hundreds of steps over a voyage)."""
    nt = times_h.shape[0]
    k = min(max(int((t_h - times_h[0]) / (times_h[nt - 1] - times_h[0]) * (nt - 1)), 0), nt - 2)
    if times_h[k] <= t_h < times_h[k + 1]:
        return k
    return np.searchsorted(times_h, t_h, side="right") - 1


@numba.njit(cache=True)
def sample_nb(w, t_h, lat, lon, out):
    """Fill out[0:7] with the weather `w` (a `Weather`) at (t_h, lat, lon); return True when t_h is past the last
    valid time (out then holds the last step's weather: the leg kernel sails in `w`'s neutral weather there)."""
    times_h = w.times_h
    nt = times_h.shape[0]
    beyond = t_h > times_h[nt - 1] + 1e-9
    if nt == 1 or t_h <= times_h[0]:
        i0, i1, wt = 0, 0, 0.0
    elif t_h >= times_h[nt - 1]:
        i0, i1, wt = nt - 1, nt - 1, 0.0
    else:
        i0 = _time_index_nb(times_h, t_h)
        i1 = i0 + 1
        wt = (t_h - times_h[i0]) / (times_h[i1] - times_h[i0])
    g = w.grid
    lat0, dlat, nlat, lon0, dlon, nlon = g.lat0, g.dlat, g.nlat, g.lon0, g.dlon, g.nlon
    cells = w.cells
    fy = (lat - lat0) / dlat
    fy = min(max(fy, 0.0), nlat - 1.0)
    iy = min(int(fy), nlat - 2)
    wy = fy - iy
    if g.wraps:
        fx = ((lon - lon0) % 360.0) / dlon
        ix0 = int(fx) % nlon
        ix1 = (ix0 + 1) % nlon
        wx = fx - int(fx)
    else:
        x = lon0 + ((lon - lon0) % 360.0)
        if x > lon0 + dlon * (nlon - 1) + 0.5 * (360.0 - dlon * (nlon - 1)):
            x -= 360.0  # nearer the western edge
        fx = min(max((x - lon0) / dlon, 0.0), nlon - 1.0)
        ix0 = min(int(fx), nlon - 2)
        ix1 = ix0 + 1
        wx = fx - ix0
    for v in range(N_VARS):
        a = _bilinear(cells, iy, ix0, ix1, i0, v, wy, wx)
        if i1 != i0:
            b = _bilinear(cells, iy, ix0, ix1, i1, v, wy, wx)
            if math.isnan(a):
                a = b
            elif not math.isnan(b):
                a = a + wt * (b - a)
        out[v] = a
    return beyond


def snapshot(field: WeatherField, when, lat_range: tuple[float, float], lon_range: tuple[float, float]) -> dict:
    """Hs and wind on the field's own grid inside a box at the valid time nearest `when` (for maps); `valid_utc` is
    that valid time (numpy datetime64, UTC)."""
    g = field.grid
    lat = g.lat0 + g.dlat * np.arange(g.nlat)
    lon = g.lon0 + g.dlon * np.arange(g.nlon)
    it = int(np.argmin(np.abs(field.times_h - field.hours_after_ref(when))))
    valid = np.datetime64(field.t_ref, "s") + np.timedelta64(round(float(field.times_h[it]) * 3600.0), "s")
    iy = np.flatnonzero((lat >= lat_range[0] - 2) & (lat <= lat_range[1] + 2))
    lon_e = ((lon + 180.0) % 360.0) - 180.0
    lo, hi = lon_range
    if hi - lo > 180 or lo > hi:  # box across the dateline, given in -180..180
        ix = np.flatnonzero((lon_e >= max(lo, hi) - 2) | (lon_e <= min(lo, hi) + 2))
    else:
        ix = np.flatnonzero((lon_e >= lo - 2) & (lon_e <= hi + 2))
    if iy.size < 2 or ix.size < 2:
        return {"lat": lat[:0], "lon": lon[:0], "hs_m": None, "u_ms": None, "v_ms": None, "valid_utc": valid}
    sub = field.values[:, it][:, iy][:, :, ix]
    return {"lat": lat[iy], "lon": lon[ix], "hs_m": sub[SWH], "u_ms": sub[U10], "v_ms": sub[V10], "valid_utc": valid}
