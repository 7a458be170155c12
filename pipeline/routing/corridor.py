"""The node lines laid along a sea route (a `SeaRoute`: a polyline round capes, through straits and canals),
instead of across the great circle.

Lines stand perpendicular to the route with the centre node of each line on the route: one at every waypoint where
the route turns (by `MIN_TURN_DEG` or more; so the centre nodes follow the route turn by turn), and between them,
outside the passages, spread evenly about `CORRIDOR_SPACING_NM` apart (the voyage's length / `CORRIDOR_SPACING_NM`
lines, up to `CORRIDOR_MAX_LINES`: more on long voyages than the great-circle layout's 80, plus those at turns).
A line's half-width comes from the open water beside the route, not from the voyage's length: at most
`default_half_width_nm` (±20 % of the voyage, 60..`CORRIDOR_HALF_WIDTH_NM`), on each side no further than the first
point where the perpendicular comes within the clearance of land, and on the inside of a bend no further than where
it would cross its neighbour line. Nodes are spread over the wider side's width (so the centre node stays on the
route); those beyond their own side's reach are not used. A line none of whose nodes keeps the clearance (the route
passes closer to land there) is left out.

Passages are fixed gates: every waypoint of a passage's fairway is a line of one node, on the fairway, and no other
line is laid inside a passage. Legs between two fairway waypoints are the fairway as the sea-route layer gave it
(not checked against the land mask, which does not see a canal); legs into and out of a fairway need only be at sea
within the port-approach radius of its end (as at a port), and keep the clearance beyond it.

Longitudes are wrapped to -180..180 at every node; every leg is the great-circle chord between two nodes, so a
corridor crossing the antimeridian needs nothing special.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from pipeline.routing import geodesy as geo
from pipeline.routing.clearance import Clearance, clearance, edges_clear, lat_band, line_edges_clear, nodes_clear, point_is_clear_nb
from pipeline.routing.land import land_grid
from pipeline.routing.sea_route import SeaRoute

CORRIDOR_SPACING_NM = 40.0  # about one line this far apart, as across the great circle
CORRIDOR_MAX_LINES = 140  # evenly spread lines of a long voyage at most (a 10,000 NM voyage: one every 75 NM)
CORRIDOR_MIN_LINES = 8
CORRIDOR_HALF_WIDTH_NM = 150.0  # the widest a line reaches to either side of the route
MIN_NODE_SPACING_NM = 0.5  # nodes of a line never closer than this (a line in a narrow channel)
OPEN_WATER_STEP_NM = 1.0  # the perpendicular is probed for land this often
MIN_TURN_DEG = 2.0  # a waypoint where the route turns this much or more has a line of its own
BEND_MARGIN = 0.9  # a line stops this fraction of the way to where it would cross its neighbour


def default_corridor_lines(dist_nm: float) -> int:
    """About one line every CORRIDOR_SPACING_NM, at least CORRIDOR_MIN_LINES and at most CORRIDOR_MAX_LINES."""
    return int(min(CORRIDOR_MAX_LINES, max(CORRIDOR_MIN_LINES, round(dist_nm / CORRIDOR_SPACING_NM))))


def default_half_width_nm(dist_nm: float) -> float:
    """±20 % of the voyage (at least ±60 NM, as across the great circle), at most CORRIDOR_HALF_WIDTH_NM."""
    return min(CORRIDOR_HALF_WIDTH_NM, max(60.0, 0.2 * dist_nm))


def route_arrays(route: SeaRoute) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(lat, lon, distance along the route at each waypoint in NM) of a sea route; ValueError when it has fewer
    than two waypoints or a passage names waypoints it does not have."""
    lat = np.asarray(route.lat, np.float64).ravel()
    lon = geo_wrap(np.asarray(route.lon, np.float64).ravel())
    if lat.size < 2 or lat.size != lon.size:
        raise ValueError(f"a sea route needs at least two waypoints with a latitude and a longitude each, got "
                         f"{lat.size} latitudes and {lon.size} longitudes")
    for p in route.passages:
        if not (0 <= p.start_index <= p.end_index < lat.size):
            raise ValueError(f"passage {p.name}: waypoints {p.start_index}..{p.end_index} are not on the route's "
                             f"{lat.size} waypoints")
    seg = np.array([geo.gc_distance_nm(lat[k], lon[k], lat[k + 1], lon[k + 1]) for k in range(lat.size - 1)])
    return lat, lon, np.concatenate(([0.0], np.cumsum(seg)))


def geo_wrap(lon: np.ndarray) -> np.ndarray:
    return (np.asarray(lon, np.float64) + 180.0) % 360.0 - 180.0


def point_at(lat: np.ndarray, lon: np.ndarray, s_nm: np.ndarray, s: float) -> tuple[float, float]:
    """The point `s` NM along the route (clipped to its ends), on the great circle of its segment."""
    s = min(max(s, 0.0), float(s_nm[-1]))
    k = int(min(np.searchsorted(s_nm, s, side="right") - 1, s_nm.size - 2))
    seg = s_nm[k + 1] - s_nm[k]
    f = 0.0 if seg <= 0.0 else (s - s_nm[k]) / seg
    if f <= 0.0:
        return float(lat[k]), float(lon[k])
    if f >= 1.0:
        return float(lat[k + 1]), float(lon[k + 1])
    la, lo = geo.gc_interpolate(lat[k], lon[k], lat[k + 1], lon[k + 1], f)
    return float(la), float(geo.wrap180(lo))


def _turn_deg(lat: np.ndarray, lon: np.ndarray, k: int) -> float:
    """How far the route turns at waypoint k (degrees, 0..180)."""
    into = geo.gc_bearing_deg(lat[k - 1], lon[k - 1], lat[k], lon[k])
    out = geo.gc_bearing_deg(lat[k], lon[k], lat[k + 1], lon[k + 1])
    return abs(float(geo.wrap180(out - into)))


def line_positions(lat: np.ndarray, lon: np.ndarray, s_nm: np.ndarray, route: SeaRoute,
                   n_lines: int) -> tuple[np.ndarray, np.ndarray]:
    """(distance along the route of lines 1..L, whether each is a passage gate). Every waypoint of a passage is a
    gate, and every waypoint where the route turns by `MIN_TURN_DEG` or more is a line (so the centre nodes follow
    the route turn by turn, even in a winding strait); between them, outside the passages, lines are spread evenly
    about total / (`n_lines` + 1) apart."""
    total = float(s_nm[-1])
    in_passage = np.zeros(s_nm.size, bool)
    spans = []
    for p in route.passages:
        in_passage[p.start_index:p.end_index + 1] = True
        spans.append((float(s_nm[p.start_index]), float(s_nm[p.end_index])))
    spacing = total / (n_lines + 1)
    cuts, gate_at = [0.0], {}
    for k in range(1, s_nm.size - 1):  # the waypoints between the ports
        if s_nm[k] - s_nm[k - 1] <= 1e-6 or total - s_nm[k] <= 1e-6:
            continue
        if in_passage[k] or _turn_deg(lat, lon, k) >= MIN_TURN_DEG:
            cuts.append(float(s_nm[k]))
            gate_at[float(s_nm[k])] = bool(in_passage[k])
    cuts.append(total)
    pos, gate = [c for c in cuts[1:-1]], [gate_at[c] for c in cuts[1:-1]]
    for a, b in zip(cuts[:-1], cuts[1:]):  # the open stretches between them
        if b - a <= 1e-6 or any(lo - 1e-6 <= a and b <= hi + 1e-6 for lo, hi in spans):
            continue
        n = max(0, int(round((b - a) / spacing)) - 1)
        pos += [a + (b - a) * (j + 1) / (n + 1) for j in range(n)]
        gate += [False] * n
    order = np.argsort(pos, kind="stable")
    return np.asarray(pos, np.float64)[order], np.asarray(gate, bool)[order]


@numba.njit(cache=True)
def _open_water_nm(grid, rule, lat, lon, bearing, cap_nm, step_nm):
    """How far (NM, up to cap_nm) the ship can go from (lat, lon) along `bearing` before a point of that great
    circle is no longer clear of land (clearance.point_is_clear_nb), probed every `step_nm`."""
    d = step_nm
    while d <= cap_nm + 1e-9:
        plat, plon = geo.destination(lat, lon, bearing, d)
        if not point_is_clear_nb(grid, rule, plat, plon):
            return d - step_nm
        d += step_nm
    return cap_nm


def lay_out_corridor(route: SeaRoute, *, n_lines: int | None = None, n_points: int = 21,
                     d_point_nm: float | None = None, half_width_nm: float | None = None, max_shift: int | None = None,
                     lat_limits: tuple[float, float] = (-75.0, 75.0), clearance_nm: float = 2.0,
                     approach_nm: float = 10.0, check_land: bool = True):
    """The node lines along `route` (see the module's docstring). Returns (lat, lon, node_ok, edge_ok, d_point per
    line (L+2,) NM, max_shift, gate (L+2,) bool, the clearance rule or None, the route's length NM).

    `d_point_nm`: one node spacing for every line (the width then follows it, still cut by land and bends);
    None: from each line's open water, at most `half_width_nm` (None: `default_half_width_nm`)."""
    rlat, rlon, s_nm = route_arrays(route)
    total = float(s_nm[-1])
    L_asked = n_lines if n_lines is not None else default_corridor_lines(total)
    pos, gate_mid = line_positions(rlat, rlon, s_nm, route, L_asked)
    L = pos.size
    P = int(n_points) | 1
    c = P // 2
    cap = float(half_width_nm) if half_width_nm is not None else default_half_width_nm(total)
    if d_point_nm is not None:
        cap = float(d_point_nm) * c
    ms = max_shift if max_shift is not None else max(2, P // 4)
    s_all = np.concatenate(([0.0], pos, [total]))
    gate = np.concatenate(([False], gate_mid, [False]))
    dep, arr = (float(rlat[0]), float(rlon[0])), (float(rlat[-1]), float(rlon[-1]))
    rule = clearance(dep, arr, clearance_nm, approach_nm) if check_land else None
    grid = land_grid() if check_land else None

    blat = np.empty(L + 2)
    blon = np.empty(L + 2)
    course = np.zeros(L + 2)
    for i, s in enumerate(s_all):
        blat[i], blon[i] = point_at(rlat, rlon, s_nm, s)
        if 0 < i < L + 1 and not gate[i]:
            half = 0.5 * min(s - s_all[i - 1], s_all[i + 1] - s)  # the route's mean course around the line
            a_lat, a_lon = point_at(rlat, rlon, s_nm, s - half)
            b_lat, b_lon = point_at(rlat, rlon, s_nm, s + half)
            course[i] = geo.gc_bearing_deg(a_lat, a_lon, b_lat, b_lon)
    # each side's reach: open water, and on the inside of a bend short of the neighbour line
    reach = np.full((L + 2, 2), cap)  # [:, 0] port (left), [:, 1] starboard (right)
    for i in range(1, L + 1):
        if gate[i]:
            continue
        for j in (i - 1, i + 1):
            if j in (0, L + 1) or gate[j]:
                continue
            turn = math.radians(geo.wrap180(course[j] - course[i]) * (1 if j > i else -1))
            if abs(turn) > 1e-6:
                limit = BEND_MARGIN * abs(s_all[j] - s_all[i]) / math.tan(min(abs(turn), math.radians(89.0)))
                side = 1 if turn > 0 else 0  # turning to starboard: the lines meet on the starboard side
                reach[i, side] = min(reach[i, side], limit)
        if check_land:
            for side, sign in ((0, -1.0), (1, 1.0)):
                reach[i, side] = min(reach[i, side], _open_water_nm(grid, rule, blat[i], blon[i], course[i] + 90.0 * sign,
                                                                    reach[i, side], OPEN_WATER_STEP_NM))
    d_line = np.zeros(L + 2)
    lat = np.empty((L + 2, P))
    lon = np.empty((L + 2, P))
    node_ok = np.zeros((L + 2, P), dtype=bool)
    for i in range(L + 2):
        lat[i, :], lon[i, :] = blat[i], geo.wrap180(blon[i])
        if i in (0, L + 1) or gate[i]:
            node_ok[i, c] = True
            continue
        width = max(reach[i]) if d_point_nm is None else cap
        d_line[i] = max(MIN_NODE_SPACING_NM, width / max(1, c))
        for j in range(P):
            off = (j - c) * d_line[i]
            if off != 0:
                lat[i, j], lon[i, j] = geo.destination(blat[i], blon[i], course[i] + (90.0 if off > 0 else -90.0), abs(off))
                lon[i, j] = geo.wrap180(lon[i, j])
            node_ok[i, j] = abs(off) <= reach[i, 1 if off > 0 else 0] + 1e-9 and lat_limits[0] <= lat[i, j] <= lat_limits[1]
    if check_land:
        free = ~gate
        free[0] = free[-1] = False  # the ports are at sea (checked by the caller)
        rows = np.nonzero(free)[0]
        if rows.size:
            sub = node_ok[rows].copy()
            nodes_clear(grid, rule, lat[rows], lon[rows], sub)
            node_ok[rows] = sub
        # a line with no node clear of land (the route itself passes closer to land there) is left out: the legs
        # from the line before it to the line after it are checked as any other
        keep = node_ok.any(axis=1) | gate
        keep[0] = keep[-1] = True
        if not keep.all():
            lat, lon, node_ok, d_line, gate = lat[keep], lon[keep], node_ok[keep], d_line[keep], gate[keep]
            L = lat.shape[0] - 2
    edge_ok = np.zeros((L + 1, P, P), dtype=bool)
    if check_land:
        band = lat_band(lat_limits)
        edges_clear(grid, rule, lat, lon, node_ok, ms, band, edge_ok)
        _gate_edges(grid, rule, lat, lon, node_ok, gate, ms, band, edge_ok)
    else:
        for i in range(L + 1):
            for a in range(P):
                for b in range(max(0, a - ms), min(P, a + ms + 1)):
                    edge_ok[i, a, b] = node_ok[i, a] and node_ok[i + 1, b]
    return lat, lon, node_ok, edge_ok, d_line, int(ms), gate, rule, total


def _gate_edges(grid, rule: Clearance, lat, lon, node_ok, gate, ms, band, edge_ok) -> None:
    """Legs touching a passage's gate: along the fairway (gate to gate) as given; into and out of it at sea within
    the approach radius of the gate (the nearer port keeps its own approach), the clearance beyond."""
    L2, P = lat.shape
    c = P // 2
    for i in range(L2 - 1):
        if not (gate[i] or gate[i + 1]):
            continue
        if gate[i] and gate[i + 1]:
            edge_ok[i, c, c] = True
            continue
        g_lat, g_lon = (lat[i, c], lon[i, c]) if gate[i] else (lat[i + 1, c], lon[i + 1, c])
        near_dep = geo.gc_distance_nm(g_lat, g_lon, rule.dep_lat, rule.dep_lon) <= \
            geo.gc_distance_nm(g_lat, g_lon, rule.arr_lat, rule.arr_lon)
        port = (rule.dep_lat, rule.dep_lon) if near_dep else (rule.arr_lat, rule.arr_lon)
        at_gate = Clearance(rule.clearance_nm, rule.approach_nm, float(g_lat), float(g_lon), float(port[0]), float(port[1]))
        line_edges_clear(grid, at_gate, lat, lon, node_ok, i, ms, band, edge_ok)


__all__ = ["lay_out_corridor", "line_positions", "route_arrays", "default_corridor_lines", "default_half_width_nm",
           "CORRIDOR_HALF_WIDTH_NM", "CORRIDOR_SPACING_NM", "CORRIDOR_MAX_LINES"]
