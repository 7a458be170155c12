"""Safe water: how far from land a route must keep, checked along every leg at ≤ 0.1 NM.

A point must be at least `clearance_nm` from land (distance to the nearest land cell of the land grid, see
land.py), except within `approach_nm` of the departure or the arrival, where it need only be at sea. Ports
(pilot stations, anchorages) lie close to land by nature, and a vessel reaches them along a fairway the mask
cannot see; a fixed radius around each port is predictable for the operator (the same for every voyage,
shown in the settings), where a radius derived from the port's own distance to clear water would change
from port to port and would open long corridors along coasts for ports up rivers. Nodes are held to the
same rule. Outside the approaches a strait narrower than 2 × `clearance_nm` is closed.

Legs are checked by sphere tracing on the distance field: from a point at distance d from land the next
point checked is max(0.1, d − c) NM further on (c the clearance required there), so no point of the leg
closer than c to land is stepped over, and near land the leg is sampled every 0.1 NM.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from pipeline.routing import geodesy as geo
from pipeline.routing.land import BOUND_CAP_NM, distance_to_land_nb, land_grid

MIN_STEP_NM = 0.1
DEFAULT_CLEARANCE_NM = 2.0
DEFAULT_APPROACH_NM = 10.0


class Clearance(NamedTuple):
    """What a route must keep from land: `clearance_nm`, except within `approach_nm` of either port (at sea there)."""

    clearance_nm: float
    approach_nm: float
    dep_lat: float
    dep_lon: float
    arr_lat: float
    arr_lon: float


def clearance(dep: tuple[float, float], arr: tuple[float, float], clearance_nm: float = DEFAULT_CLEARANCE_NM,
              approach_nm: float = DEFAULT_APPROACH_NM) -> Clearance:
    if not (clearance_nm >= 0.0 and approach_nm >= 0.0):
        raise ValueError(f"land clearance {clearance_nm} NM and port approach {approach_nm} NM must be ≥ 0")
    return Clearance(float(clearance_nm), float(approach_nm), float(dep[0]), float(dep[1]), float(arr[0]),
                     float(arr[1]))


@numba.njit(cache=True)
def _approach(c, lat, lon):
    """(inside a port approach, NM to the nearest approach boundary)."""
    d0 = geo.gc_distance_nm(lat, lon, c.dep_lat, c.dep_lon)
    d1 = geo.gc_distance_nm(lat, lon, c.arr_lat, c.arr_lon)
    gap = min(abs(d0 - c.approach_nm), abs(d1 - c.approach_nm))
    return (d0 <= c.approach_nm or d1 <= c.approach_nm), gap


@numba.njit(cache=True)
def point_is_clear_nb(grid, c, lat, lon):
    """At sea, and at least the clearance from land unless inside a port approach."""
    inside, _ = _approach(c, lat, lon)
    need = 0.0 if inside else c.clearance_nm
    d = distance_to_land_nb(grid, lat, lon, need + 1.0)
    return d > 0.0 and d >= need


@numba.njit(cache=True)
def leg_is_clear_nb(grid, c, lat0, lon0, lat1, lon1, lat_lo, lat_hi):
    """The great-circle leg keeps the clearance (and the latitude limits) at every point, checked at ≤ 0.1 NM."""
    dist = geo.gc_distance_nm(lat0, lon0, lat1, lon1)
    chord = geo.chord(lat0, lon0, lat1, lon1)
    s = 0.0
    while True:
        f = min(1.0, s / dist) if dist > 0.0 else 1.0
        plat, plon = geo.chord_point(chord, f)
        if plat < lat_lo or plat > lat_hi:
            return False
        inside, gap = _approach(c, plat, plon)
        need = 0.0 if inside else c.clearance_nm
        d = distance_to_land_nb(grid, plat, plon, need + 1.0)
        if d <= 0.0 or d < need:
            return False
        if f >= 1.0:
            return True
        s += max(MIN_STEP_NM, min(d - need, gap))  # never past the approach boundary, where the rule changes


@numba.njit(cache=True)
def least_clearance_nb(grid, c, lat, lon):
    """Least distance to land along the route through waypoints (lat, lon), outside the port approaches, to
    0.1 NM; BOUND_CAP_NM when it is at least that."""
    best = BOUND_CAP_NM
    for k in range(lat.size - 1):
        dist = geo.gc_distance_nm(lat[k], lon[k], lat[k + 1], lon[k + 1])
        chord = geo.chord(lat[k], lon[k], lat[k + 1], lon[k + 1])
        s = 0.0
        while True:
            f = min(1.0, s / dist) if dist > 0.0 else 1.0
            plat, plon = geo.chord_point(chord, f)
            inside, gap = _approach(c, plat, plon)
            if inside:
                step = gap
            else:
                d = distance_to_land_nb(grid, plat, plon, best)
                if d < best:
                    best = d
                step = d - best  # every point within d − best of here is at least `best` from land
            if f >= 1.0:
                break
            s += max(MIN_STEP_NM, step)
    return best


def least_clearance_nm(waypoints: list[tuple[float, float]], rule: Clearance) -> float:
    """Least distance to land (NM) along a route outside its port approaches (BOUND_CAP_NM: at least that)."""
    if len(waypoints) < 2:
        return float("nan")
    pts = np.asarray(waypoints, np.float64)
    return float(least_clearance_nb(land_grid(), rule, np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1])))
