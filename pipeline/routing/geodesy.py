"""Great-circle and rhumb-line geometry on a sphere, dateline-safe.

Angles in degrees, distances in nautical miles (Earth radius 3440.065 NM), bearings clockwise
from true north in [0, 360). Longitudes may come in as -180..180 or 0..360; results of the
interpolating functions are in -180..180. All functions are numba-compiled scalar functions,
callable from Python and from routing kernels alike.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba

from pipeline.routing.sphere import EARTH_RADIUS_NM, KN_PER_MS  # noqa: F401 (re-exported) defined without numba, for the picture process


@numba.njit(cache=True)
def wrap180(lon_deg: float) -> float:
    return ((lon_deg + 180.0) % 360.0) - 180.0


@numba.njit(cache=True)
def gc_distance_nm(lat1, lon1, lat2, lon2):
    p1, p2 = math.radians(lat1), math.radians(lat2)
    dp = p2 - p1
    dl = math.radians(wrap180(lon2 - lon1))
    a = math.sin(dp / 2) ** 2 + math.cos(p1) * math.cos(p2) * math.sin(dl / 2) ** 2
    return 2.0 * EARTH_RADIUS_NM * math.asin(min(1.0, math.sqrt(a)))


@numba.njit(cache=True)
def gc_bearing_deg(lat1, lon1, lat2, lon2):
    """Initial great-circle course from point 1 towards point 2."""
    p1, p2 = math.radians(lat1), math.radians(lat2)
    dl = math.radians(wrap180(lon2 - lon1))
    y = math.sin(dl) * math.cos(p2)
    x = math.cos(p1) * math.sin(p2) - math.sin(p1) * math.cos(p2) * math.cos(dl)
    return math.degrees(math.atan2(y, x)) % 360.0


@numba.njit(cache=True)
def gc_interpolate(lat1, lon1, lat2, lon2, frac):
    """Point at fraction `frac` of the way along the great circle (the short way round)."""
    p1, l1 = math.radians(lat1), math.radians(lon1)
    p2, l2 = math.radians(lat2), math.radians(lon2)
    d = gc_distance_nm(lat1, lon1, lat2, lon2) / EARTH_RADIUS_NM
    if d < 1e-12:
        return lat1, wrap180(lon1)
    a = math.sin((1 - frac) * d) / math.sin(d)
    b = math.sin(frac * d) / math.sin(d)
    x = a * math.cos(p1) * math.cos(l1) + b * math.cos(p2) * math.cos(l2)
    y = a * math.cos(p1) * math.sin(l1) + b * math.cos(p2) * math.sin(l2)
    z = a * math.sin(p1) + b * math.sin(p2)
    return math.degrees(math.atan2(z, math.sqrt(x * x + y * y))), wrap180(math.degrees(math.atan2(y, x)))


class Chord(NamedTuple):
    """A great-circle chord's trigonometry, computed once for stepping along it (`chord`): the sines and cosines
    of its end points' latitude and longitude, its angular length and that length's sine."""

    cp1: float
    sp1: float
    cl1: float
    sl1: float
    cp2: float
    sp2: float
    cl2: float
    sl2: float
    d: float
    sin_d: float
    lat1: float
    lon1: float
    lon2: float


@numba.njit(cache=True)
def chord(lat1, lon1, lat2, lon2):
    """The `Chord` from point 1 to point 2."""
    p1, l1 = math.radians(lat1), math.radians(lon1)
    p2, l2 = math.radians(lat2), math.radians(lon2)
    d = gc_distance_nm(lat1, lon1, lat2, lon2) / EARTH_RADIUS_NM
    return Chord(math.cos(p1), math.sin(p1), math.cos(l1), math.sin(l1), math.cos(p2), math.sin(p2), math.cos(l2),
                 math.sin(l2), d, math.sin(d), lat1, lon1, lon2)


@numba.njit(cache=True)
def chord_point(c, frac):
    """`gc_interpolate` along the chord: the same numbers, with the chord's trigonometry taken from `c`."""
    if c.d < 1e-12:
        return c.lat1, wrap180(c.lon1)
    a = math.sin((1 - frac) * c.d) / c.sin_d
    b = math.sin(frac * c.d) / c.sin_d
    x = a * c.cp1 * c.cl1 + b * c.cp2 * c.cl2
    y = a * c.cp1 * c.sl1 + b * c.cp2 * c.sl2
    z = a * c.sp1 + b * c.sp2
    return math.degrees(math.atan2(z, math.sqrt(x * x + y * y))), wrap180(math.degrees(math.atan2(y, x)))


@numba.njit(cache=True)
def chord_course_deg(c, lat, lon):
    """`gc_bearing_deg` from (lat, lon) to the chord's end: the same numbers, the end's trigonometry from `c`."""
    p1 = math.radians(lat)
    dl = math.radians(wrap180(c.lon2 - lon))
    y = math.sin(dl) * c.cp2
    x = math.cos(p1) * c.sp2 - math.sin(p1) * c.cp2 * math.cos(dl)
    return math.degrees(math.atan2(y, x)) % 360.0


@numba.njit(cache=True)
def destination(lat, lon, bearing_deg, dist_nm):
    """Point reached from (lat, lon) sailing `dist_nm` along the great circle with initial course `bearing_deg`."""
    p1, l1 = math.radians(lat), math.radians(lon)
    th = math.radians(bearing_deg)
    d = dist_nm / EARTH_RADIUS_NM
    p2 = math.asin(math.sin(p1) * math.cos(d) + math.cos(p1) * math.sin(d) * math.cos(th))
    l2 = l1 + math.atan2(math.sin(th) * math.sin(d) * math.cos(p1), math.cos(d) - math.sin(p1) * math.sin(p2))
    return math.degrees(p2), wrap180(math.degrees(l2))


@numba.njit(cache=True)
def _mercator_dpsi(p1, p2):
    return math.log(math.tan(math.pi / 4 + p2 / 2) / math.tan(math.pi / 4 + p1 / 2))


@numba.njit(cache=True)
def rhumb_distance_nm(lat1, lon1, lat2, lon2):
    p1, p2 = math.radians(lat1), math.radians(lat2)
    dp = p2 - p1
    dl = math.radians(wrap180(lon2 - lon1))
    dpsi = _mercator_dpsi(p1, p2)
    q = dp / dpsi if abs(dpsi) > 1e-12 else math.cos(p1)
    return math.sqrt(dp * dp + q * q * dl * dl) * EARTH_RADIUS_NM


@numba.njit(cache=True)
def rhumb_bearing_deg(lat1, lon1, lat2, lon2):
    p1, p2 = math.radians(lat1), math.radians(lat2)
    dl = math.radians(wrap180(lon2 - lon1))
    return math.degrees(math.atan2(dl, _mercator_dpsi(p1, p2))) % 360.0


@numba.njit(cache=True)
def rhumb_interpolate(lat1, lon1, lat2, lon2, frac):
    """Point at fraction `frac` along the rhumb line (constant course, the short way in longitude)."""
    p1, p2 = math.radians(lat1), math.radians(lat2)
    dl = math.radians(wrap180(lon2 - lon1))
    p = p1 + frac * (p2 - p1)
    dpsi_total = _mercator_dpsi(p1, p2)
    if abs(dpsi_total) < 1e-12:
        lon = math.radians(lon1) + frac * dl
    else:
        lon = math.radians(lon1) + dl * _mercator_dpsi(p1, p) / dpsi_total
    return math.degrees(p), wrap180(math.degrees(lon))


@numba.njit(cache=True)
def along_course(u, v, course_deg):
    """Component of the vector (u east, v north) along the course."""
    c = math.radians(course_deg)
    return u * math.sin(c) + v * math.cos(c)
