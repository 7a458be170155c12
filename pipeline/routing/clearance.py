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
from pipeline.routing.land import BOUND_CAP_NM, distance_to_land_nb, distance_to_land_nm, land_grid

MIN_STEP_NM = 0.1
# a route's least clearance (least_clearance_nb) is sampled to MIN_STEP_NM, or to this share of the least distance
# found when that is more: 0.1 NM near the clearance a route must keep, 1 NM at the 25 NM cap (the distance field
# itself is known to its 0.5 NM cells)
CLEARANCE_REL_TOL = 0.04
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
def nodes_clear(grid, rule, lat, lon, out):
    """out[i, j] &= whether node (i, j) is clear of land under `rule`."""
    for i in range(lat.shape[0]):
        for j in range(lat.shape[1]):
            out[i, j] = out[i, j] and point_is_clear_nb(grid, rule, lat[i, j], lon[i, j])


def lat_band(lat_limits) -> tuple[float, float]:
    """The latitude limits (lo, hi) as the edge kernels take them: two floats, whatever the caller gave (one compiled
    signature)."""
    return float(lat_limits[0]), float(lat_limits[1])


@numba.njit(cache=True)
def line_edges_clear(grid, rule, lat, lon, node_ok, i, max_shift, band, out):
    """Whether each leg from a usable node of line i to a usable node of line i + 1 (at most `max_shift` nodes
    aside) is clear of land under `rule` and within the latitudes `band` = (lo, hi), into out[i]."""
    lat_lo, lat_hi = band
    P = lat.shape[1]
    for a in range(P):
        if not node_ok[i, a]:
            continue
        for b in range(max(0, a - max_shift), min(P, a + max_shift + 1)):
            if node_ok[i + 1, b]:
                out[i, a, b] = leg_is_clear_nb(grid, rule, lat[i, a], lon[i, a], lat[i + 1, b], lon[i + 1, b],
                                               lat_lo, lat_hi)


@numba.njit(cache=True)
def edges_clear(grid, rule, lat, lon, node_ok, max_shift, band, out):
    """`line_edges_clear` for every line."""
    for i in range(lat.shape[0] - 1):
        line_edges_clear(grid, rule, lat, lon, node_ok, i, max_shift, band, out)


@numba.njit(cache=True)
def least_clearance_nb(grid, c, lat, lon):
    """Least distance to land along the route through waypoints (lat, lon), outside the port approaches, to
    0.1 NM or CLEARANCE_REL_TOL of it when that is more; BOUND_CAP_NM when it is at least that."""
    best = BOUND_CAP_NM
    for k in range(lat.size - 1):
        dist = geo.gc_distance_nm(lat[k], lon[k], lat[k + 1], lon[k + 1])
        chord = geo.chord(lat[k], lon[k], lat[k + 1], lon[k + 1])
        s = 0.0
        outside_to = -1.0  # up to here along the leg no point is inside a port approach (known from an earlier point)
        while True:
            f = min(1.0, s / dist) if dist > 0.0 else 1.0
            plat, plon = geo.chord_point(chord, f)
            if s < outside_to:
                inside, gap = False, 0.0
            else:
                inside, gap = _approach(c, plat, plon)
                if not inside:  # the next `gap` NM along the leg cannot reach an approach (margin for rounding)
                    outside_to = s + gap - 1e-6
            if inside:
                step = gap
            else:
                d = distance_to_land_nb(grid, plat, plon, best)
                if d < best:
                    best = d
                # every point within d − best + tol of here is at least `best` − tol from land
                step = d - best + CLEARANCE_REL_TOL * best
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


def least_clearance_outside_nm(waypoints: list[tuple[float, float]], rule: Clearance, gate=None) -> float:
    """`least_clearance_nm` of a route with one waypoint per line, leaving out the legs between two gate lines
    (`gate` (L+2,) bool: a passage's fairway, whose banks a canal sails between) and the approach radius at each end
    of a fairway, as at a port (the legs into and out of a passage need only be at sea there, corridor.py). NaN when
    the whole route is fairway."""
    if gate is None or not np.any(gate):
        return least_clearance_nm(waypoints, rule)
    pts = np.asarray(waypoints, np.float64)
    best, start = float("nan"), 0
    for k in range(1, len(pts)):
        fairway = bool(gate[k - 1] and gate[k])
        if fairway or k == len(pts) - 1:
            end = k - 1 if fairway else k
            if end > start:  # the stretch start..end between ports or fairway ends
                part = rule._replace(dep_lat=float(pts[start, 0]), dep_lon=float(pts[start, 1]),
                                     arr_lat=float(pts[end, 0]), arr_lon=float(pts[end, 1]))
                d = least_clearance_nm([tuple(p) for p in pts[start:end + 1]], part)
                best = d if not best <= d else best
            start = k
    return best


WIDEST_BOX_DEG = 6.0  # voyages whose box is larger than this are not diagnosed (the grid would be too coarse)
WIDEST_STEP_DEG = 0.01  # ≈ 0.6 NM: the widest corridor is known to about that


def widest_corridor_nm(rule: Clearance, pad_deg: float = 0.5) -> float | None:
    """The most clearance from land (NM) at which some path at sea joins the two ports, outside their approaches:
    on a 0.01° grid over the voyage's box (± `pad_deg`), the largest c for which the ports' cells are connected
    through cells at least c from land (or inside an approach), up to the clearance + 1 NM (a larger answer means
    "more than that"). About ± 0.6 NM; None when the box is too large to
    diagnose (over WIDEST_BOX_DEG) or a port is on land. It says why a voyage has no route at sea: a strait
    whose widest corridor keeps less than the clearance asked is closed by the rule, not by the graph."""
    from scipy import ndimage

    lat_lo, lat_hi = sorted((rule.dep_lat, rule.arr_lat))
    lon_a, lon_b = rule.dep_lon, rule.dep_lon + geo.wrap180(rule.arr_lon - rule.dep_lon)
    lon_lo, lon_hi = sorted((lon_a, lon_b))
    if max(lat_hi - lat_lo, lon_hi - lon_lo) > WIDEST_BOX_DEG:
        return None
    la = np.arange(lat_lo - pad_deg, lat_hi + pad_deg + WIDEST_STEP_DEG, WIDEST_STEP_DEG)
    lo = np.arange(lon_lo - pad_deg, lon_hi + pad_deg + WIDEST_STEP_DEG, WIDEST_STEP_DEG)
    LA, LO = np.meshgrid(la, lo, indexing="ij")
    LO = geo.wrap180(LO)
    cap = rule.clearance_nm + 1.0  # beyond that the answer is "more than the clearance": the graph is at fault
    d = distance_to_land_nm(LA, LO, limit_nm=cap)
    dep_nm, arr_nm = np.empty(LA.shape), np.empty(LA.shape)
    _distances_from_nb(LA.ravel(), LO.ravel(), rule.dep_lat, rule.dep_lon, dep_nm.reshape(-1))
    _distances_from_nb(LA.ravel(), LO.ravel(), rule.arr_lat, rule.arr_lon, arr_nm.reshape(-1))
    near = (dep_nm <= rule.approach_nm) | (arr_nm <= rule.approach_nm)
    sea = d > 0.0
    i0, i1 = np.unravel_index(np.argmin(dep_nm), LA.shape), np.unravel_index(np.argmin(arr_nm), LA.shape)

    def joined(c: float) -> bool:
        labels, _ = ndimage.label(sea & ((d >= c) | near))
        return labels[i0] != 0 and labels[i0] == labels[i1]

    if not joined(0.0):
        return None
    lo_c, hi_c = 0.0, cap
    for _ in range(10):  # to ≈ 0.003 NM, well below the grid's own resolution
        mid = 0.5 * (lo_c + hi_c)
        lo_c, hi_c = (mid, hi_c) if joined(mid) else (lo_c, mid)
    return lo_c


@numba.njit(cache=True)
def _distances_from_nb(lat, lon, lat0, lon0, out):
    """out[k] = geodesy.gc_distance_nm from (lat0, lon0) to (lat[k], lon[k])."""
    for k in range(lat.size):
        out[k] = geo.gc_distance_nm(lat0, lon0, lat[k], lon[k])
