"""The weather cube's variables, defined once: name, dims, dtype, units, CF attributes and providing source.

Dims `(cycle, step, lat, lon)` made CF by their attributes: `cycle` is the `forecast_reference_time` (model
init, UTC), `step` the `forecast_period` (a duration, stored as whole hours), `valid_time(cycle, step)` =
cycle + step the `time`; `lat`/`lon` are the Y/X axes. Directions: wind and waves coming-from, currents going-to.
Decoders, the cycle assembly and the cube store all take their names and attributes from here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

DIMS = ("cycle", "step", "lat", "lon")
STATE_HIDDEN, STATE_COMPLETE, STATE_INCOMPLETE = 0, 1, 2


@dataclass(frozen=True)
class CubeVariable:
    name: str
    dims: tuple[str, ...]
    dtype: str
    units: str | None  # None: no units (a flag variable)
    standard_name: str | None
    long_name: str
    source: str | None  # the source that provides it (GSM, GWM, OSCAR); None: the cube's own bookkeeping
    # physically plausible values in `units` (a decoded file with a finite value outside is refused): wind beyond
    # 75 m/s is a unit mistake (km/h, knots) or damage, not weather; no surface current reaches 10 m/s (the
    # strongest are ~3 m/s), while cm/s read as m/s gives tens
    valid_range: tuple[float, float] | None = None

    @property
    def attrs(self) -> dict:
        out = {"long_name": self.long_name}
        if self.units is not None:
            out["units"] = self.units
        if self.standard_name is not None:
            out["standard_name"] = self.standard_name
        return out


FIELDS = (
    CubeVariable("u10", DIMS, "float32", "m s-1", "eastward_wind", "10 m eastward wind", "GSM", (-75.0, 75.0)),
    CubeVariable("v10", DIMS, "float32", "m s-1", "northward_wind", "10 m northward wind", "GSM", (-75.0, 75.0)),
    CubeVariable("swh", DIMS, "float32", "m", "sea_surface_wave_significant_height", "significant wave height", "GWM",
                 (0.0, 30.0)),
    CubeVariable("mwd", DIMS, "float32", "degree", "sea_surface_wave_from_direction", "mean wave direction (coming from)",
                 "GWM", (0.0, 360.0)),
    CubeVariable("mwp", DIMS, "float32", "s", "sea_surface_wave_mean_period", "mean wave period", "GWM", (0.0, 40.0)),
    CubeVariable("uo", DIMS, "float32", "m s-1", "eastward_sea_water_velocity", "surface current east (going to)", "OSCAR",
                 (-10.0, 10.0)),
    CubeVariable("vo", DIMS, "float32", "m s-1", "northward_sea_water_velocity", "surface current north (going to)",
                 "OSCAR", (-10.0, 10.0)),
)
CURRENT_AGE = CubeVariable("current_age_h", ("cycle", "step"), "float32", "h", None,
                           "age of the OSCAR analysis used", "OSCAR")
CYCLE_STATE = CubeVariable("cycle_state", ("cycle",), "int8", None, None, "state of the cycle's write", None)
CYCLE_STATE_FLAGS = {"flag_values": np.array([STATE_HIDDEN, STATE_COMPLETE, STATE_INCOMPLETE], np.int8),
                     "flag_meanings": "hidden complete incomplete"}

DATA_VARS = tuple(v.name for v in FIELDS)
BY_NAME = {v.name: v for v in (*FIELDS, CURRENT_AGE, CYCLE_STATE)}

COORD_ATTRS = {
    "cycle": {"standard_name": "forecast_reference_time", "long_name": "forecast cycle (model init time, UTC)"},
    "step": {"standard_name": "forecast_period", "long_name": "lead time"},
    "valid_time": {"standard_name": "time", "long_name": "valid time (cycle + step, UTC)"},
    "lat": {"standard_name": "latitude", "long_name": "latitude", "units": "degrees_north", "axis": "Y"},
    "lon": {"standard_name": "longitude", "long_name": "longitude", "units": "degrees_east", "axis": "X"},
}


def attrs(name: str) -> dict:
    """CF attributes of a cube variable or coordinate."""
    if name in COORD_ATTRS:
        return dict(COORD_ATTRS[name])
    out = BY_NAME[name].attrs
    return out | CYCLE_STATE_FLAGS if name == CYCLE_STATE.name else out


def implausible(name: str, values: np.ndarray) -> str | None:
    """None when every finite value of variable `name` lies in its `valid_range`, else what is wrong (one line)."""
    valid_range = BY_NAME[name].valid_range
    if valid_range is None:  # nothing to hold the values against
        return None
    lo, hi = valid_range
    v = np.asarray(values)
    bad = np.isfinite(v) & ((v < lo) | (v > hi))
    n = int(np.count_nonzero(bad))
    if not n:
        return None
    worst = v[bad][np.argmax(np.abs(v[bad]))]
    return (f"{n} value(s) of {name} outside the plausible {lo:g}..{hi:g} {BY_NAME[name].units} (e.g. {float(worst):.4g}): "
            "wrong units or a damaged file")


def provided_by(source: str) -> tuple[str, ...]:
    """Names of the cube's data variables that `source` provides."""
    return tuple(v.name for v in FIELDS if v.source == source)


def step_hours(step) -> np.ndarray:
    """Lead times as whole hours (int64) from a `step` axis stored as a duration or, in older cubes, as hours."""
    step = np.asarray(step)
    if np.issubdtype(step.dtype, np.timedelta64):
        return (step // np.timedelta64(1, "h")).astype(np.int64)
    return step.astype(np.int64)


def step_duration(step_h) -> np.ndarray:
    """Lead times in hours → timedelta64[ns] (the `step` coordinate of the cube)."""
    return np.asarray(step_hours(step_h)).astype("timedelta64[h]").astype("timedelta64[ns]")
