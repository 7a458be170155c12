"""GRIB2 field discovery and selection through eccodes.

JMA packs several fields into one GRIB message (multi-field messages); multi-field support is
switched on so every field is seen, not only the first of each message. Fields are selected by
(discipline, category, number, level type, level value), never by their position in the file.
Nothing is written beside the input (no `.idx` files).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import eccodes
import numpy as np

from pipeline.decode.errors import DecodeError


@dataclass(frozen=True)
class FieldInfo:
    index: int
    discipline: int
    category: int
    number: int
    level_type: int
    level: float
    step_h: int
    cycle: np.datetime64
    centre: int
    short_name: str
    ni: int
    nj: int


@dataclass(frozen=True)
class GridInfo:
    lat: np.ndarray  # as stored (scan order), float64; ascending in what `read_fields` returns
    lon: np.ndarray  # 0..360 east; ascending in what `read_fields` returns


# The largest grid a field may declare (the 0.25° global grid of the newer GWM files), checked before its values
# are decoded: a message of 1 MB can declare a 0.05° grid (26 M points, 100 MB a field once decoded).
MAX_GRID_POINTS = 1440 * 721


def axis_order(axis: np.ndarray) -> np.ndarray | slice:
    """Index that sorts `axis` ascending; a slice (a view, no copy) when it is already sorted or reversed."""
    order = np.argsort(axis, kind="stable")
    if np.array_equal(order, np.arange(axis.size)):
        return slice(None)
    if np.array_equal(order, np.arange(axis.size)[::-1]):
        return slice(None, None, -1)
    return order


def _get(h, key, default=None):
    try:
        return eccodes.codes_get(h, key)
    except eccodes.KeyValueNotFoundError:
        return default


def _iter_handles(path: Path) -> Iterator[int]:
    eccodes.codes_grib_multi_support_on()
    try:
        with open(path, "rb") as f:
            while True:
                try:
                    h = eccodes.codes_grib_new_from_file(f)
                except eccodes.GribInternalError as exc:
                    raise DecodeError(path, f"corrupt GRIB2 message ({exc})") from exc
                if h is None:
                    return
                try:
                    yield h
                finally:
                    eccodes.codes_release(h)
    except OSError as exc:
        raise DecodeError(path, f"cannot read ({exc})") from exc


def _code(h: int) -> tuple[int, int, int]:
    """(discipline, category, number): read first, so fields nobody asked for cost three look-ups."""
    return int(_get(h, "discipline", -1)), int(_get(h, "parameterCategory", -1)), int(_get(h, "parameterNumber", -1))


def _level_and_time(h: int) -> tuple[int, float, int, np.datetime64]:
    """(level type, level, step in hours, cycle)."""
    date = int(_get(h, "dataDate", 19700101))
    time = int(_get(h, "dataTime", 0))
    cycle = np.datetime64(f"{date // 10000:04d}-{date // 100 % 100:02d}-{date % 100:02d}T{time // 100:02d}:{time % 100:02d}", "ns")
    step_units = _get(h, "stepUnits", 1)
    end = _get(h, "endStep", 0)
    step_h = int(end) if step_units in (1, "h") else int(_get(h, "forecastTime", 0))
    level_type = _get(h, "typeOfFirstFixedSurface", 255)
    if isinstance(level_type, str):  # some tables map the code to a name
        level_type = int(eccodes.codes_get_long(h, "typeOfFirstFixedSurface"))
    return int(level_type), float(_get(h, "level", 0) or 0), step_h, cycle


def _info(index: int, h: int) -> FieldInfo:
    discipline, category, number = _code(h)
    level_type, level, step_h, cycle = _level_and_time(h)
    return FieldInfo(
        index=index,
        discipline=discipline,
        category=category,
        number=number,
        level_type=level_type,
        level=level,
        step_h=step_h,
        cycle=cycle,
        centre=int(eccodes.codes_get_long(h, "centre")),
        short_name=str(_get(h, "shortName", "unknown")),
        ni=int(_get(h, "Ni", 0) or 0),
        nj=int(_get(h, "Nj", 0) or 0),
    )


def list_fields(path: Path) -> list[FieldInfo]:
    """Every field in a GRIB2 file (each field of a multi-field message counted once)."""
    path = Path(path)
    out = [_info(i, h) for i, h in enumerate(_iter_handles(path))]
    if not out:
        raise DecodeError(path, "no GRIB messages found (empty, truncated or not GRIB)")
    return out


def _grid(h: int, path: Path, max_points: int = MAX_GRID_POINTS) -> GridInfo:
    if _get(h, "gridType") != "regular_ll":
        raise DecodeError(path, f"unsupported grid {_get(h, 'gridType')!r}; expected a regular lat/lon grid")
    ni, nj = int(eccodes.codes_get(h, "Ni")), int(eccodes.codes_get(h, "Nj"))
    if ni <= 1 or nj <= 1 or ni * nj > max_points:
        raise DecodeError(path, f"wrong grid: {ni}×{nj} points declared (at most {max_points} expected); not decoded")
    if int(_get(h, "jPointsAreConsecutive", 0) or 0) or int(_get(h, "alternativeRowScanning", 0) or 0):
        raise DecodeError(path, "unsupported scanning mode (columns first or alternating rows)")
    la1 = eccodes.codes_get_double(h, "latitudeOfFirstGridPointInDegrees")
    la2 = eccodes.codes_get_double(h, "latitudeOfLastGridPointInDegrees")
    lo1 = eccodes.codes_get_double(h, "longitudeOfFirstGridPointInDegrees")
    lo2 = eccodes.codes_get_double(h, "longitudeOfLastGridPointInDegrees")
    if lo2 < lo1:
        lo2 += 360.0
    return GridInfo(lat=np.linspace(la1, la2, nj), lon=np.mod(np.linspace(lo1, lo2, ni), 360.0))


def read_fields(path: Path, wanted: dict[str, tuple[int, int, int, int | None, float | None]],
                fill_value: float | None = None, units: dict[str, str] | None = None,
                max_points: int = MAX_GRID_POINTS) -> tuple[dict[str, dict[int, np.ndarray]], GridInfo | None, np.datetime64 | None]:
    """Values of the wanted fields by name → {step_h: 2-D array (nj, ni), lat and lon ascending}.

    `wanted` maps a name to (discipline, category, number, level_type or None, level or None); `units` maps a name
    to the units eccodes must report for it (e.g. "m s**-1"). Bitmap-missing and non-finite points and, when
    given, points at or above `fill_value` become NaN. Each field is turned to ascending latitude and longitude
    whatever its scanning direction, and must then lie on the same grid as the others. Refused with a
    DecodeError: a declared grid above `max_points` (before its values are decoded), other units, a field on
    another grid or of another reference time, and a second message of one name at one step.
    The grid is None when none of the wanted fields is present.
    """
    path = Path(path)
    out: dict[str, dict[int, np.ndarray]] = {k: {} for k in wanted}
    grid = None
    cycle = None
    n = 0
    codes = {(d, c, num) for d, c, num, _, _ in wanted.values()}
    for h in _iter_handles(path):
        n += 1
        code = _code(h)
        if code not in codes:
            continue
        level_type, level, step_h, field_cycle = _level_and_time(h)
        for name, (d, c, num, lt, lv) in wanted.items():
            if code != (d, c, num):
                continue
            if lt is not None and level_type != lt:
                continue
            if lv is not None and abs(level - lv) > 1e-6:
                continue
            if step_h in out[name]:
                raise DecodeError(path, f"two {name} fields at lead {step_h} h (one message per variable and lead expected)")
            if units and name in units and str(_get(h, "units", "?")) != units[name]:
                raise DecodeError(path, f"{name} is in {_get(h, 'units', '?')!r}, expected {units[name]!r}")
            g = _grid(h, path, max_points)
            lat_order, lon_order = axis_order(g.lat), axis_order(g.lon)
            g = GridInfo(lat=g.lat[lat_order], lon=g.lon[lon_order])
            if grid is None:
                grid = g
            elif (g.lat.size != grid.lat.size or g.lon.size != grid.lon.size
                  or not np.allclose(g.lat, grid.lat, atol=1e-6) or not np.allclose(g.lon, grid.lon, atol=1e-6)):
                raise DecodeError(path, f"field {name} at step {step_h} h has a different grid from the others")
            if cycle is None:
                cycle = field_cycle
            elif field_cycle != cycle:
                raise DecodeError(path, f"field {name} at step {step_h} h has reference time {field_cycle}, "
                                        f"the others {cycle}")
            vals = eccodes.codes_get_values(h).astype(np.float32)
            if int(_get(h, "bitmapPresent", 0) or 0):
                missing = eccodes.codes_get_double(h, "missingValue")
                vals[vals == missing] = np.nan
            vals[~np.isfinite(vals)] = np.nan  # a hole, never a value
            if fill_value is not None:
                vals[vals >= fill_value] = np.nan
            vals = vals.reshape(g.lat.size, g.lon.size)[lat_order][:, lon_order]
            out[name][step_h] = np.ascontiguousarray(vals)
    if n == 0:
        raise DecodeError(path, "no GRIB messages found (empty, truncated or not GRIB)")
    return out, grid, cycle
