"""The node graph all solvers share: N_line lines across the base route, N_point nodes per line.

Line 0 is the departure and line L+1 the arrival (only their centre node is used); lines
1..L are spread evenly along the base route (great circle by default, or rhumb), each
perpendicular to it, with nodes D_point NM apart (the centre node on the base route). A route
is one node per line. An edge (line i, node a) → (line i+1, node b) exists when |a − b| ≤
`max_shift` and the straight (great-circle) leg keeps its clearance from land (clearance.py: `clearance_nm`
outside the port approaches, at sea inside them, checked at ≤ 0.1 NM), stays inside the latitude limits, and
crosses no limit line. Nodes are held to the same clearance.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np

from pipeline.routing import geodesy as geo
from pipeline.routing.clearance import (DEFAULT_APPROACH_NM, DEFAULT_CLEARANCE_NM, Clearance, clearance, edges_clear,
                                        lat_band, nodes_clear)
from pipeline.routing.corridor import lay_out_corridor
from pipeline.routing.land import is_sea, land_grid
from pipeline.routing.sea_route import SeaRoute


class VoyageGeometryError(ValueError):
    """The voyage cannot be laid out (a port on land, no way through)."""


class Graph(NamedTuple):
    """The node graph as the kernels see it: node positions (L+2, P) in degrees, feasible edges (L+1, P, P) and the
    widest node shift of a leg."""

    lat: np.ndarray
    lon: np.ndarray
    edge_ok: np.ndarray
    max_shift: int


@dataclass(frozen=True)
class SearchSpace:
    lat: np.ndarray  # (L+2, P) degrees
    lon: np.ndarray  # (L+2, P) degrees -180..180
    node_ok: np.ndarray  # (L+2, P) bool
    edge_ok: np.ndarray  # (L+1, P, P) bool
    d_point_nm: float
    base: str
    max_shift: int
    base_distance_nm: float
    clearance: Clearance | None = None  # None: land was not checked
    # laid along a sea route (corridor.py; None: across the great circle or rhumb line): the route, which lines are
    # a passage's gates (one node, on the fairway) and each line's node spacing (NM; 0 at the ports and gates)
    sea_route: SeaRoute | None = None
    gate: np.ndarray | None = None  # (L+2,) bool
    line_d_point_nm: np.ndarray | None = None  # (L+2,)

    @property
    def graph(self) -> Graph:
        return Graph(self.lat, self.lon, self.edge_ok, int(self.max_shift))

    @property
    def n_lines(self) -> int:
        return self.lat.shape[0] - 2

    @property
    def n_points(self) -> int:
        return self.lat.shape[1]

    @property
    def centre(self) -> int:
        return self.n_points // 2

    def base_route(self) -> np.ndarray:
        return np.full(self.lat.shape[0], self.centre, dtype=np.int64)


def default_n_lines(distance_nm: float) -> int:
    """About one line every 40 NM, at least 8 and at most 80."""
    return int(min(80, max(8, round(distance_nm / 40.0))))


def default_d_point_nm(distance_nm: float, n_points: int) -> float:
    """Spread the nodes over ±20 % of the voyage length (at least ±60 NM)."""
    half_width = max(60.0, 0.2 * distance_nm)
    return half_width / max(1, n_points // 2)


def _base_point(base, lat0, lon0, lat1, lon1, f):
    if base == "rhumb":
        return geo.rhumb_interpolate(lat0, lon0, lat1, lon1, f)
    return geo.gc_interpolate(lat0, lon0, lat1, lon1, f)


def _segments_cross(ax, ay, bx, by, cx, cy, dx, dy) -> bool:
    def orient(px, py, qx, qy, rx, ry):
        return (qx - px) * (ry - py) - (qy - py) * (rx - px)

    o1, o2 = orient(ax, ay, bx, by, cx, cy), orient(ax, ay, bx, by, dx, dy)
    o3, o4 = orient(cx, cy, dx, dy, ax, ay), orient(cx, cy, dx, dy, bx, by)
    return (o1 * o2 < 0) and (o3 * o4 < 0)


# when the default layout leaves no route at sea: (lines, nodes per line) this many times as many, in turn. More
# nodes along each line, over the same width, find a narrow strait whose corridor falls between two nodes
# (Gibraltar at 21 nodes a line); closer lines thread a coast's islands with shorter legs.
DENSER = ((1, 2), (2, 1), (2, 2), (4, 2), (4, 4))
MIN_LINE_SPACING_NM = 5.0  # never closer than this
MAX_POINTS = 161  # nodes per line at most


def build_search_space(dep: tuple[float, float], arr: tuple[float, float], *, n_lines: int | None = None,
                       **kw) -> SearchSpace:
    """Lay out the node lines for a voyage from `dep` to `arr` ((lat, lon) degrees); legs and nodes keep
    `clearance_nm` from land outside `approach_nm` of either port (see clearance.py). Keywords: those of
    `lay_out_lines`.

    With `n_lines` None the number of lines follows the voyage length (`default_n_lines`); when that leaves no
    route at sea (legs too long to thread a coast's islands and keep their clearance, e.g. Qingdao → Busan past
    Korea's south-west islands; a strait whose clear corridor falls between two nodes of a line, e.g.
    Gibraltar), the lines and the nodes along them are laid `DENSER` times as close, in turn, over the same
    width, before giving up."""
    space = lay_out_lines(dep, arr, n_lines=n_lines, **kw)
    if n_lines is not None or not kw.get("check_land", True) or reachable(space):
        return space
    most = int(space.base_distance_nm / MIN_LINE_SPACING_NM)
    n_points = space.lat.shape[1]
    d_point = kw.pop("d_point_nm", None)
    if d_point is None and kw.get("base_route") is None:  # a corridor's lines take their widths from the open water
        d_point = default_d_point_nm(space.base_distance_nm, n_points)
    max_shift = kw.pop("max_shift", None)
    kw.pop("n_points", None)
    for k_lines, k_points in DENSER:
        lines, points = space.n_lines * k_lines, (n_points // 2) * k_points * 2 + 1
        if (k_lines > 1 and lines > most) or points > MAX_POINTS:  # more nodes along the lines suit any length
            continue
        denser = lay_out_lines(dep, arr, n_lines=lines, n_points=points,
                               d_point_nm=None if d_point is None else d_point * (n_points // 2) / (points // 2),
                               max_shift=None if max_shift is None else max_shift * k_points, **kw)
        if reachable(denser):
            return denser
    return space


def lay_out_lines(dep: tuple[float, float], arr: tuple[float, float], *, n_lines: int | None = None,
                  n_points: int = 21, d_point_nm: float | None = None, base: str = "gc", max_shift: int | None = None,
                  lat_limits: tuple[float, float] = (-75.0, 75.0), limit_lines: list[list[tuple[float, float]]] | None = None,
                  clearance_nm: float = DEFAULT_CLEARANCE_NM, approach_nm: float = DEFAULT_APPROACH_NM,
                  check_land: bool = True, dep_name: str = "departure", arr_name: str = "destination",
                  base_route: SeaRoute | None = None) -> SearchSpace:
    """The node lines for a voyage from `dep` to `arr` with `n_lines` lines (None: `default_n_lines`, or along a
    `base_route` `corridor.default_corridor_lines`). With `base_route` (a `SeaRoute` from `dep` to `arr`) the lines
    are laid along it (corridor.py) and `base` must be 'gc' (its legs are great-circle chords)."""
    if base not in ("gc", "rhumb"):
        raise ValueError(f"base route must be 'gc' or 'rhumb', not {base!r}")
    if base_route is not None and base != "gc":
        raise ValueError(f"a {base} base route cannot be laid along a sea route: its legs are great-circle chords; "
                         "use base 'gc'")
    for name, (la, lo) in ((dep_name, dep), (arr_name, arr)):
        if not (-90 <= la <= 90) or not (-180 <= lo <= 360):
            raise VoyageGeometryError(f"{name} {la:.4f},{lo:.4f} is not a valid position")
        if check_land and not bool(is_sea(la, lo)):
            raise VoyageGeometryError(f"{name} {la:.4f},{lo:.4f} is on land (global land mask); give a position at sea, e.g. the pilot station")
        if not (lat_limits[0] <= la <= lat_limits[1]):
            raise VoyageGeometryError(f"{name} latitude {la:.2f} is outside the latitude limits {lat_limits}")
    lat0, lon0 = dep
    lat1, lon1 = arr
    dist = geo.rhumb_distance_nm(lat0, lon0, lat1, lon1) if base == "rhumb" else geo.gc_distance_nm(lat0, lon0, lat1, lon1)
    if dist < 1.0:
        who, _, dep_short = dep_name.rpartition(": ")  # "voyage V: departure A" and "voyage V: destination B"
        if who and arr_name.startswith(who + ": "):  # name the voyage once
            raise VoyageGeometryError(f"{who}: {dep_short} and {arr_name[len(who) + 2:]} are the same place ({dist:.2f} NM apart)")
        raise VoyageGeometryError(f"{dep_name} and {arr_name} are the same place ({dist:.2f} NM apart)")
    if base_route is not None:
        return _along_sea_route(base_route, dep, arr, dep_name, arr_name, n_lines=n_lines, n_points=n_points,
                                d_point_nm=d_point_nm, max_shift=max_shift, lat_limits=lat_limits,
                                limit_lines=limit_lines, clearance_nm=clearance_nm, approach_nm=approach_nm,
                                check_land=check_land)
    L = n_lines if n_lines is not None else default_n_lines(dist)
    P = int(n_points) | 1  # odd, so there is a centre node
    dp = d_point_nm if d_point_nm is not None else default_d_point_nm(dist, P)
    ms = max_shift if max_shift is not None else max(2, P // 4)
    c = P // 2
    lat = np.empty((L + 2, P))
    lon = np.empty((L + 2, P))
    node_ok = np.zeros((L + 2, P), dtype=bool)
    for i in range(L + 2):
        f = i / (L + 1)
        blat, blon = _base_point(base, lat0, lon0, lat1, lon1, f)
        if i in (0, L + 1):
            lat[i, :], lon[i, :] = blat, geo.wrap180(blon)
            node_ok[i, c] = True
            continue
        nlat, nlon = _base_point(base, lat0, lon0, lat1, lon1, min(1.0, f + 1e-4))
        course = geo.gc_bearing_deg(blat, blon, nlat, nlon)
        for j in range(P):
            off = (j - c) * dp
            if off == 0:
                lat[i, j], lon[i, j] = blat, geo.wrap180(blon)
            else:
                side = course + (90.0 if off > 0 else -90.0)
                lat[i, j], lon[i, j] = geo.destination(blat, blon, side, abs(off))
        node_ok[i] = (lat[i] >= lat_limits[0]) & (lat[i] <= lat_limits[1])
    rule = clearance(dep, arr, clearance_nm, approach_nm) if check_land else None
    edge_ok = np.zeros((L + 1, P, P), dtype=bool)
    if check_land:
        grid = land_grid()
        nodes_clear(grid, rule, lat[1:-1], lon[1:-1], node_ok[1:-1])  # the ports were checked above: at sea
        edges_clear(grid, rule, lat, lon, node_ok, ms, lat_band(lat_limits), edge_ok)
    else:
        for i in range(L + 1):
            for a in range(P):
                for b in range(max(0, a - ms), min(P, a + ms + 1)):
                    edge_ok[i, a, b] = node_ok[i, a] and node_ok[i + 1, b]
    for line in limit_lines or []:
        forbid_crossing(lat, lon, edge_ok, line)
    return SearchSpace(lat=lat, lon=lon, node_ok=node_ok, edge_ok=edge_ok, d_point_nm=float(dp), base=base,
                       max_shift=int(ms), base_distance_nm=float(dist), clearance=rule)


SEA_ROUTE_END_TOL_NM = 1.0  # a sea route must start and end this close to the voyage's ports


def _along_sea_route(route: SeaRoute, dep, arr, dep_name: str, arr_name: str, *, limit_lines, **kw) -> SearchSpace:
    for name, (la, lo), k in ((dep_name, dep, 0), (arr_name, arr, -1)):
        off = geo.gc_distance_nm(la, lo, float(route.lat[k]), float(route.lon[k]))
        if off > SEA_ROUTE_END_TOL_NM:
            raise VoyageGeometryError(f"{name} {la:.4f},{lo:.4f} is {off:.1f} NM from the {'first' if k == 0 else 'last'} "
                                      f"waypoint of its sea route; the route must run from port to port")
    # the ports themselves, to the last decimal, as the route's ends
    wp_lat, wp_lon = np.array(route.lat, np.float64), np.array(route.lon, np.float64)
    wp_lat[0], wp_lon[0], wp_lat[-1], wp_lon[-1] = dep[0], dep[1], arr[0], arr[1]
    try:
        lat, lon, node_ok, edge_ok, d_line, ms, gate, rule, total = lay_out_corridor(
            replace(route, lat=wp_lat, lon=wp_lon), **kw)
    except ValueError as e:
        raise VoyageGeometryError(f"{dep_name} to {arr_name}: {e}") from None
    for line in limit_lines or []:
        forbid_crossing(lat, lon, edge_ok, line)
    return SearchSpace(lat=lat, lon=lon, node_ok=node_ok, edge_ok=edge_ok, d_point_nm=float(d_line.max()), base="gc",
                       max_shift=int(ms), base_distance_nm=float(total), clearance=rule, sea_route=route, gate=gate,
                       line_d_point_nm=d_line)


def forbid_crossing(lat, lon, edge_ok, polyline):
    """Remove edges that cross a limit polyline [(lat, lon), ...] (planar test in a local unwrapped frame)."""
    ref = lon[0, lat.shape[1] // 2]
    pts = [(la, ref + geo.wrap180(lo - ref)) for la, lo in polyline]
    for i, a, b in zip(*np.nonzero(edge_ok)):
        ax, ay = ref + geo.wrap180(lon[i, a] - ref), lat[i, a]
        bx, by = ref + geo.wrap180(lon[i + 1, b] - ref), lat[i + 1, b]
        for (p_lat, p_lon), (q_lat, q_lon) in zip(pts[:-1], pts[1:]):
            if _segments_cross(ax, ay, bx, by, p_lon, p_lat, q_lon, q_lat):
                edge_ok[i, a, b] = False
                break


def reachable(space: SearchSpace) -> bool:
    """True when some route connects departure to arrival through feasible edges."""
    L2, P = space.lat.shape
    can = np.zeros(P, dtype=bool)
    can[space.centre] = True
    for i in range(L2 - 1):
        can = (can[:, None] & space.edge_ok[i]).any(axis=0)
    return bool(can[space.centre])


def limit_lines_from_geojson(obj: dict) -> list[list[tuple[float, float]]]:
    """LineString / MultiLineString / Polygon features of a GeoJSON object → [(lat, lon), ...] polylines."""
    feats = obj.get("features", [obj]) if obj.get("type") == "FeatureCollection" else [obj]
    lines = []
    for f in feats:
        g = f.get("geometry", f)
        t, coords = g.get("type"), g.get("coordinates")
        parts = {"LineString": [coords], "MultiLineString": coords, "Polygon": coords,
                 "MultiPolygon": [r for p in (coords or []) for r in p]}.get(t)
        if parts is None:
            raise ValueError(f"limit line geometry {t!r} is not a LineString, MultiLineString or Polygon")
        lines += [[(float(p[1]), float(p[0])) for p in part] for part in parts]
    return lines


__all__ = ["SearchSpace", "Graph", "VoyageGeometryError", "build_search_space", "reachable", "default_n_lines",
           "default_d_point_nm", "limit_lines_from_geojson"]
