"""The global sea-route layer: the shortest route between any two points at sea, over the whole ocean.

`sea_route(dep, arr)` returns a `SeaRoute` (sea_route.py) clear of land by `clearance_nm` (the product's land mask
and clearance rule, clearance.py: at sea only within `approach_nm` of either port), round capes and through the
straits and canals of passages.py, or raises `NoSeaRoute` naming what blocks it.

How:
1. A coarse graph over the whole ocean (sea_graph.py): 0.125° cells that keep the clearance, 16 moves each, every
   edge a great-circle leg checked at ≤ 0.1 NM. The passages' fairways are chains of extra nodes whose two ends join
   the cells and the other passages' vertices within `JOIN_NM` by clear legs (at sea only within
   FAIRWAY_END_APPROACH_NM of the end, as for a port); grid edges across a passage's gate are removed, so a strait with a gate
   is sailed on its fairway only. The areas to avoid (passages.AREAS_TO_AVOID) are closed the same way: their
   outlines' sides are gates.
2. The ports join the graph (cells and fairway vertices within `JOIN_NM`, widening to `JOIN_MAX_NM`) by legs clear
   under the voyage's rule; a direct leg between them counts too.
3. A* from departure to arrival (numba, an indexed binary heap; the great circle to the arrival as heuristic, so the
   path is the graph's shortest). Avoided passages' fairway edges are skipped.
4. String-pulling: between fixed points (the ports and the fairway vertices used) a waypoint is dropped while the
   great-circle leg that replaces it stays clear (and crosses no gate), so the route is near-geodesic: its legs
   touch the coast's clearance line rather than following cell centres.
5. Corners cut: each waypoint left (not a fairway vertex) slides towards the midpoint of its neighbours as far as
   its legs stay clear, in rounds while they shorten the route, then the route is pulled again: a bend is no longer
   held a cell (0.125°) off the tangent (on the bench's 26 pairs with an exact reference the product is 0.0–1.6 %
   above the exact shortest route, 0.0–3.0 % before).
A pair takes 0.03–0.3 s warm (up to about 0.9 s for an ocean-wide search such as Santos–Shanghai); the first call
in a process loads the graph (or, once per machine and clearance, builds it: about 25 s).
"""

from __future__ import annotations

import math
import threading
from typing import NamedTuple

import numba
import numpy as np

from pipeline.routing import geodesy as geo
from pipeline.routing.clearance import DEFAULT_APPROACH_NM, DEFAULT_CLEARANCE_NM, clearance, leg_is_clear_nb
from pipeline.routing.land import distance_to_land_nm, is_sea, land_grid
from pipeline.routing.passages import PASSAGES, Passage, area_gates, check_avoid
from pipeline.routing.sea_graph import (LAT_LIMITS_DEG, MOVES, N_COLS, N_ROWS, OPPOSITE, RES_DEG, cell_lat, cell_lon,
                                        sea_graph)
from pipeline.routing.sea_route import NoSeaRoute, PassageTransit, SeaRoute
from pipeline.routing.sphere import EARTH_RADIUS_NM

JOIN_NM = 40.0  # a port or a fairway end joins the cells within this distance...
JOIN_MAX_NM = 160.0  # ...widening (×2) up to this when none is clear
FAIRWAY_END_APPROACH_NM = 5.0  # a fairway's end joins the graph as a port does: at sea only within this of it
CORNER_ROUNDS = 20  # a pulled route's corners are cut (`_cut_corners`) in at most this many rounds...
CORNER_MIN_GAIN_NM = 0.01  # ...while a round shortens it by at least this
CORNER_MARGIN_NM = 0.05  # a cut corner keeps the clearance plus this: a leg moved onto the clearance line is
# checked at 0.1 NM steps, and a check sampled elsewhere along it could find it a hair nearer
N_GRID = N_ROWS * N_COLS


class _Layer(NamedTuple):
    """The graph for one clearance, passages joined: grid edges (gates removed) and the extra nodes."""

    edges: np.ndarray  # (N_ROWS, N_COLS) uint16, see sea_graph
    xlat: np.ndarray  # (E,) extra nodes (fairway vertices), ids N_GRID + k
    xlon: np.ndarray
    xoff: np.ndarray  # (N_GRID + E + 1,) int32 CSR offsets of extra edges per node
    xdst: np.ndarray  # extra edges: destination node id,
    xcost: np.ndarray  # length NM,
    xpass: np.ndarray  # passage index (fairway edge) or -1 (a join to the grid)
    gates: np.ndarray  # (n, 4) lat0, lon0, lat1, lon1
    vpass: np.ndarray  # (E,) passage index of each extra node


# ---------------------------------------------------------------------------------------------- sphere helpers

@numba.njit(cache=True)
def _unit(lat, lon):
    p, l = math.radians(lat), math.radians(lon)
    return math.cos(p) * math.cos(l), math.cos(p) * math.sin(l), math.sin(p)


@numba.njit(cache=True)
def _arcs_cross(alat0, alon0, alat1, alon1, blat0, blon0, blat1, blon1):
    """True when the great-circle arcs A and B (each shorter than half the globe) cross."""
    ax0, ay0, az0 = _unit(alat0, alon0)
    ax1, ay1, az1 = _unit(alat1, alon1)
    bx0, by0, bz0 = _unit(blat0, blon0)
    bx1, by1, bz1 = _unit(blat1, blon1)
    # the normals of the two planes; the endpoints of B on opposite sides of A's plane and vice versa
    nax, nay, naz = ay0 * az1 - az0 * ay1, az0 * ax1 - ax0 * az1, ax0 * ay1 - ay0 * ax1
    nbx, nby, nbz = by0 * bz1 - bz0 * by1, bz0 * bx1 - bx0 * bz1, bx0 * by1 - by0 * bx1
    s0 = nax * bx0 + nay * by0 + naz * bz0
    s1 = nax * bx1 + nay * by1 + naz * bz1
    t0 = nbx * ax0 + nby * ay0 + nbz * az0
    t1 = nbx * ax1 + nby * ay1 + nbz * az1
    if s0 * s1 >= 0.0 or t0 * t1 >= 0.0:
        return False
    # both pairs straddle: the arcs cross unless they straddle at the antipodal point (A's midpoint side check)
    mx, my, mz = ax0 + ax1, ay0 + ay1, az0 + az1
    cx, cy, cz = nay * nbz - naz * nby, naz * nbx - nax * nbz, nax * nby - nay * nbx
    if cx * mx + cy * my + cz * mz < 0.0:
        cx, cy, cz = -cx, -cy, -cz
    return cx * (bx0 + bx1) + cy * (by0 + by1) + cz * (bz0 + bz1) > 0.0


@numba.njit(cache=True)
def _crosses_gate(gates, lat0, lon0, lat1, lon1):
    for g in range(gates.shape[0]):
        if _arcs_cross(lat0, lon0, lat1, lon1, gates[g, 0], gates[g, 1], gates[g, 2], gates[g, 3]):
            return True
    return False


@numba.njit(cache=True)
def _leg_ok(grid, rule, gates, lat0, lon0, lat1, lon1, lo, hi):
    """The great-circle leg crosses no gate and keeps the clearance `rule` (and latitudes lo..hi) all along."""
    return not _crosses_gate(gates, lat0, lon0, lat1, lon1) and leg_is_clear_nb(grid, rule, lat0, lon0, lat1, lon1, lo,
                                                                                hi)


@numba.njit(cache=True)
def _node_pos(xlat, xlon, n):
    if n < N_GRID:
        return cell_lat(n // N_COLS), cell_lon(n % N_COLS)
    return xlat[n - N_GRID], xlon[n - N_GRID]


# ---------------------------------------------------------------------------------------------- the layer

@numba.njit(cache=True)
def _remove_gate_edges(edges, gates, moves, opposite):
    nr, nc = edges.shape
    for g in range(gates.shape[0]):
        lo_lat = min(gates[g, 0], gates[g, 2]) - 1.0
        hi_lat = max(gates[g, 0], gates[g, 2]) + 1.0
        i0 = max(0, int((LAT_LIMITS_DEG[1] - hi_lat) / RES_DEG))
        i1 = min(nr - 1, int((LAT_LIMITS_DEG[1] - lo_lat) / RES_DEG))
        span = abs(geo.wrap180(gates[g, 3] - gates[g, 1])) / 2.0 + 1.0
        jc = int((geo.wrap180(0.5 * (gates[g, 1] + gates[g, 3])) + 180.0) / RES_DEG)
        dj = int(span / RES_DEG) + 1
        for i in range(i0, i1 + 1):
            for jr in range(jc - dj, jc + dj + 1):
                j = jr % nc
                for k in range(moves.shape[0]):
                    if not (edges[i, j] >> k) & 1:
                        continue
                    ii, jj = i + moves[k, 0], (j + moves[k, 1]) % nc
                    if _arcs_cross(cell_lat(i), cell_lon(j), cell_lat(ii), cell_lon(jj),
                                   gates[g, 0], gates[g, 1], gates[g, 2], gates[g, 3]):
                        edges[i, j] &= np.uint16(~(1 << k) & 0xFFFF)
                        edges[ii, jj] &= np.uint16(~(1 << opposite[k]) & 0xFFFF)


@numba.njit(cache=True)
def _joins(grid, rule, layer, lat, lon, radius_nm, with_extra, out_node, out_cost):
    """Graph nodes of the `layer` within `radius_nm` of (lat, lon) joined to it by a leg clear under `rule` crossing no
    gate: grid cells (nodes with an edge), and the extra nodes when `with_extra`. Returns how many (filled in out_*)."""
    edges, xlat, xlon, gates = layer.edges, layer.xlat, layer.xlon, layer.gates
    n = 0
    dlat = radius_nm / 60.0
    coslat = max(math.cos(math.radians(min(abs(lat) + dlat, 89.0))), 1e-3)
    dlon = min(radius_nm / (60.0 * coslat), 180.0)
    i0 = max(0, int((LAT_LIMITS_DEG[1] - (lat + dlat)) / RES_DEG))
    i1 = min(edges.shape[0] - 1, int((LAT_LIMITS_DEG[1] - (lat - dlat)) / RES_DEG))
    jc = int((geo.wrap180(lon) + 180.0) / RES_DEG)
    dj = min(int(dlon / RES_DEG) + 1, edges.shape[1] // 2)
    lo, hi = LAT_LIMITS_DEG[0], LAT_LIMITS_DEG[1]
    for i in range(i0, i1 + 1):
        for jr in range(jc - dj, jc + dj + 1):
            j = jr % edges.shape[1]
            if edges[i, j] == 0 or n >= out_node.size:
                continue
            la, lo_ = cell_lat(i), cell_lon(j)
            d = geo.gc_distance_nm(lat, lon, la, lo_)
            if d > radius_nm:
                continue
            if not _leg_ok(grid, rule, gates, lat, lon, la, lo_, lo, hi):
                continue
            out_node[n] = i * edges.shape[1] + j
            out_cost[n] = d
            n += 1
    if with_extra:
        for k in range(xlat.size):
            if n >= out_node.size:
                break
            d = geo.gc_distance_nm(lat, lon, xlat[k], xlon[k])
            if d > radius_nm:
                continue
            if not _leg_ok(grid, rule, gates, lat, lon, xlat[k], xlon[k], lo, hi):
                continue
            out_node[n] = N_GRID + k
            out_cost[n] = d
            n += 1
    return n


def _join(rule, layer: _Layer, lat: float, lon: float, with_extra: bool) -> tuple[np.ndarray, np.ndarray]:
    """The nodes a point joins (`_joins`), widening the radius from JOIN_NM to JOIN_MAX_NM until some are found."""
    radius = JOIN_NM
    out_node, out_cost = np.empty(4096, np.int64), np.empty(4096)
    while True:
        n = _joins(land_grid(), rule, layer, float(lat), float(lon), radius, with_extra, out_node, out_cost)
        if n or radius >= JOIN_MAX_NM:
            return out_node[:n].copy(), out_cost[:n].copy()
        radius *= 2.0


ESCAPE_BOX_DEG = 1.0
ESCAPE_STEP_DEG = 0.0125  # 0.75 NM: the graph's cell centres lie on this fine grid, every ESCAPE_EVERY nodes
ESCAPE_EVERY = int(round(RES_DEG / ESCAPE_STEP_DEG))
ESCAPE_MARGIN_NM = 0.55  # fine nodes keep this much more than the rule, so the diagonals between them keep the rule


def _escape(rule, layer: _Layer, lat: float, lon: float) -> tuple[np.ndarray, np.ndarray, dict[int, list]]:
    """When no graph node is one clear leg from a port (a bay whose mouth is narrower than the graph's cells, e.g.
    Manila Bay): the shortest paths on a fine grid (ESCAPE_STEP_DEG, ± ESCAPE_BOX_DEG round the port) from the
    port to the graph's cells in the box, through fine nodes that keep the rule (plus ESCAPE_MARGIN_NM). Returns the
    cells reached, their path lengths (NM) and each one's path (fine points from the port's side, the cell excluded)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra

    step, half = ESCAPE_STEP_DEG, 0.5 * RES_DEG
    top = LAT_LIMITS_DEG[1] - half
    lat0 = top - RES_DEG * math.ceil((top - (lat - ESCAPE_BOX_DEG)) / RES_DEG)
    lon0 = -180.0 + half + RES_DEG * math.floor((lon - ESCAPE_BOX_DEG + 180.0 - half) / RES_DEG)
    n = int(round(2 * ESCAPE_BOX_DEG / step)) + 2 * ESCAPE_EVERY + 1
    la = lat0 + step * np.arange(n)
    lo = lon0 + step * np.arange(n)
    LA, LO = np.meshgrid(la, lo, indexing="ij")
    d = distance_to_land_nm(LA, LO, limit_nm=rule.clearance_nm + 2.0)
    near = np.minimum(_haversine_nm(LA, LO, rule.dep_lat, rule.dep_lon), _haversine_nm(LA, LO, rule.arr_lat, rule.arr_lon))
    ok = d >= np.where(near <= rule.approach_nm, 0.0, rule.clearance_nm) + ESCAPE_MARGIN_NM
    ok &= (LA >= LAT_LIMITS_DEG[0]) & (LA <= LAT_LIMITS_DEG[1])
    idx = np.arange(n * n).reshape(n, n)
    rows, cols, w = [], [], []
    for di, dj in ((0, 1), (1, 0), (1, 1), (1, -1)):
        i0, i1, j0, j1 = max(0, -di), n - max(0, di), max(0, -dj), n - max(0, dj)
        good = ok[i0:i1, j0:j1] & ok[i0 + di:i1 + di, j0 + dj:j1 + dj]
        cost = 60.0 * step * np.hypot(di, dj * np.cos(np.radians(LA[i0:i1, j0:j1])))
        rows.append(idx[i0:i1, j0:j1][good])
        cols.append(idx[i0 + di:i1 + di, j0 + dj:j1 + dj][good])
        w.append(cost[good])
    graph = coo_matrix((np.concatenate(w), (np.concatenate(rows), np.concatenate(cols))), shape=(n * n, n * n)).tocsr()
    grid = land_grid()
    order = np.argsort(_haversine_nm(LA, LO, lat, lon), axis=None)
    source, first_nm = -1, 0.0
    for k in order[:400]:
        if ok.flat[k] and leg_is_clear_nb(grid, rule, lat, lon, LA.flat[k], LO.flat[k], -90.0, 90.0):
            source, first_nm = int(k), float(geo.gc_distance_nm(lat, lon, LA.flat[k], LO.flat[k]))
            break
    if source < 0:
        return np.zeros(0, np.int64), np.zeros(0), {}
    dist, pred = dijkstra(graph, directed=False, indices=source, return_predecessors=True)
    nodes, costs, paths = [], [], {}
    for a in range(0, n, ESCAPE_EVERY):  # the cell centres
        for b in range(0, n, ESCAPE_EVERY):
            k = idx[a, b]
            i = int(round((LAT_LIMITS_DEG[1] - half - la[a]) / RES_DEG))
            j = int(round((geo.wrap180(lo[b]) + 180.0 - half) / RES_DEG)) % N_COLS
            if not np.isfinite(dist[k]) or not (0 <= i < N_ROWS) or layer.edges[i, j] == 0:
                continue
            path, m = [], int(pred[k])
            while m >= 0:
                path.append((float(LA.flat[m]), float(geo.wrap180(LO.flat[m]))))
                m = int(pred[m])
            node = i * N_COLS + j
            nodes.append(node)
            costs.append(first_nm + float(dist[k]))
            paths[node] = path[::-1]
    return np.array(nodes, np.int64), np.array(costs), paths


def _build_layer(clearance_nm: float) -> _Layer:
    base = sea_graph(clearance_nm)
    edges = base.edges.copy()
    sides = [g for p in PASSAGES for g in p.gates] + list(area_gates())
    gates = np.array([(a[0], a[1], b[0], b[1]) for a, b in sides], np.float64).reshape(-1, 4)
    _remove_gate_edges(edges, gates, MOVES, OPPOSITE)
    xlat, xlon, vpass = [], [], []
    adj: dict[int, list[tuple[int, float, int]]] = {}

    def add(a: int, b: int, cost: float, pid: int, forward: bool = True, backward: bool = True) -> None:
        if forward:
            adj.setdefault(a, []).append((b, cost, pid))
        if backward:
            adj.setdefault(b, []).append((a, cost, pid))

    ends = []
    entry_only, exit_only = set(), set()  # a one-way lane is entered only at its first vertex, left at its last
    for pid, p in enumerate(PASSAGES):
        first = N_GRID + len(xlat)
        for la, lo in p.fairway:
            xlat.append(la)
            xlon.append(lo)
            vpass.append(pid)
        for k in range(len(p.fairway) - 1):
            (la0, lo0), (la1, lo1) = p.fairway[k], p.fairway[k + 1]
            add(first + k, first + k + 1, float(geo.gc_distance_nm(la0, lo0, la1, lo1)), pid, backward=not p.one_way)
        ends += [first, first + len(p.fairway) - 1]
        if p.one_way:
            entry_only.add(first)
            exit_only.add(first + len(p.fairway) - 1)
    joined: set[tuple[int, int]] = set()
    layer = _Layer(edges, np.array(xlat), np.array(xlon), np.zeros(1, np.int32), np.zeros(0, np.int64), np.zeros(0),
                   np.zeros(0, np.int64), gates, np.array(vpass, np.int64))
    for e in ends:
        end = (xlat[e - N_GRID], xlon[e - N_GRID])
        # the cells near the end, and the other passages' vertices (a fairway may lead into another, e.g. Durian
        # Strait into the Singapore Strait)
        nodes, costs = _join(clearance(end, end, clearance_nm, FAIRWAY_END_APPROACH_NM), layer, *end, with_extra=True)
        own = vpass[e - N_GRID]
        for nd, c in zip(nodes, costs):
            if nd < N_GRID or (vpass[nd - N_GRID] != own and (int(nd), e) not in joined):
                nd = int(nd)
                add(e, nd, float(c), -1, forward=e not in entry_only and nd not in exit_only,
                    backward=nd not in entry_only and e not in exit_only)
                joined.add((e, nd))
    n_all = N_GRID + len(xlat)
    counts = np.zeros(n_all + 1, np.int32)
    for a, lst in adj.items():
        counts[a + 1] = len(lst)
    xoff = np.cumsum(counts).astype(np.int32)
    xdst = np.empty(xoff[-1], np.int64)
    xcost = np.empty(xoff[-1])
    xpass = np.empty(xoff[-1], np.int64)
    for a, lst in adj.items():
        s = xoff[a]
        for m, (b, c, pid) in enumerate(lst):
            xdst[s + m], xcost[s + m], xpass[s + m] = b, c, pid
    return layer._replace(xoff=xoff, xdst=xdst, xcost=xcost, xpass=xpass)


_LAYERS: dict[float, _Layer] = {}
_LOCK = threading.Lock()


def _layer(clearance_nm: float) -> _Layer:
    key = round(float(clearance_nm), 6)
    if key not in _LAYERS:
        with _LOCK:
            if key not in _LAYERS:
                _LAYERS[key] = _build_layer(key)
    return _LAYERS[key]


# ---------------------------------------------------------------------------------------------- the search

@numba.njit(cache=True)
def _row_tables(moves):
    """Per row: the NM length of each move, and the unit vectors' row parts for the heuristic."""
    cost = np.empty((N_ROWS, moves.shape[0]))
    for i in range(N_ROWS):
        for k in range(moves.shape[0]):
            ii = i + moves[k, 0]
            if ii < 0 or ii >= N_ROWS:
                cost[i, k] = np.inf
            else:
                cost[i, k] = geo.gc_distance_nm(cell_lat(i), 0.0, cell_lat(ii), moves[k, 1] * RES_DEG)
    return cost


@numba.njit(cache=True)
def _h(lat, lon, tx, ty, tz):
    x, y, z = _unit(lat, lon)
    return _h_xyz(x, y, z, tx, ty, tz)


@numba.njit(cache=True)
def _h_xyz(x, y, z, tx, ty, tz):
    """Great-circle NM between unit vectors (the chord's angle): the A* heuristic, admissible."""
    ch = math.sqrt((x - tx) ** 2 + (y - ty) ** 2 + (z - tz) ** 2)
    return 2.0 * EARTH_RADIUS_NM * math.asin(min(1.0, 0.5 * ch))


@numba.njit(cache=True)
def _trig_tables():
    """cos and sin of every row's latitude and every column's longitude."""
    rc, rs = np.empty(N_ROWS), np.empty(N_ROWS)
    cc, cs = np.empty(N_COLS), np.empty(N_COLS)
    for i in range(N_ROWS):
        rc[i], rs[i] = math.cos(math.radians(cell_lat(i))), math.sin(math.radians(cell_lat(i)))
    for j in range(N_COLS):
        cc[j], cs[j] = math.cos(math.radians(cell_lon(j))), math.sin(math.radians(cell_lon(j)))
    return rc, rs, cc, cs


@numba.njit(cache=True)
def _sift_up(hf, hn, pos, k):
    while k > 0:
        p = (k - 1) // 2
        if hf[p] <= hf[k]:
            break
        hf[p], hf[k] = hf[k], hf[p]
        hn[p], hn[k] = hn[k], hn[p]
        pos[hn[p]], pos[hn[k]] = p, k
        k = p


@numba.njit(cache=True)
def _heap_set(hf, hn, pos, size, f, n):
    """Put node n in the heap with key f, or lower its key to f (keys only fall: the heuristic is consistent)."""
    k = pos[n]
    if k >= 0:
        hf[k] = f
        _sift_up(hf, hn, pos, k)
        return hf, hn, size
    if size >= hf.size:
        nf = np.empty(hf.size * 2)
        nn = np.empty(hf.size * 2, np.int64)
        nf[:size] = hf[:size]
        nn[:size] = hn[:size]
        hf, hn = nf, nn
    hf[size], hn[size] = f, n
    pos[n] = size
    _sift_up(hf, hn, pos, size)
    return hf, hn, size + 1


@numba.njit(cache=True)
def _heap_pop(hf, hn, pos, size):
    f, n = hf[0], hn[0]
    pos[n] = -1
    size -= 1
    if size == 0:
        return f, n, size
    hf[0], hn[0] = hf[size], hn[size]
    pos[hn[0]] = 0
    k = 0
    while True:
        a, b, m = 2 * k + 1, 2 * k + 2, k
        if a < size and hf[a] < hf[m]:
            m = a
        if b < size and hf[b] < hf[m]:
            m = b
        if m == k:
            break
        hf[m], hf[k] = hf[k], hf[m]
        hn[m], hn[k] = hn[k], hn[m]
        pos[hn[m]], pos[hn[k]] = m, k
        k = m
    return f, n, size


class _Ends(NamedTuple):
    """A search's two ends on the graph: the departure's joins (nodes, NM to them), the arrival's joins (nodes, NM
    from them), the direct leg's length when it is clear (inf: none), and the arrival's position (the heuristic's
    target)."""

    src_node: np.ndarray
    src_cost: np.ndarray
    dst_node: np.ndarray
    dst_cost: np.ndarray
    direct_nm: float
    tlat: float
    tlon: float


@numba.njit(cache=True)
def _astar(layer, move_cost, moves, avoided, ends, parent):
    """Shortest path source → target over the `layer` (passages in `avoided` left out) between the `ends` (an `_Ends`);
    returns (length NM, last graph node before the target, or -1 for the direct leg, -2 for none). `parent`
    (N_GRID + E) is filled (−1: from the source)."""
    edges, xlat, xlon, xoff, xdst, xcost, xpass = (layer.edges, layer.xlat, layer.xlon, layer.xoff, layer.xdst,
                                                   layer.xcost, layer.xpass)
    src_node, src_cost, dst_node, dst_cost = ends.src_node, ends.src_cost, ends.dst_node, ends.dst_cost
    direct_nm, tlat, tlon = ends.direct_nm, ends.tlat, ends.tlon
    n_all = xoff.size - 1
    g = np.full(n_all, np.inf)
    order = np.argsort(dst_node)  # the arrival's joins, by node, for a binary search per node taken from the heap
    dst_sorted, dst_sorted_cost = dst_node[order], dst_cost[order]
    tx, ty, tz = _unit(tlat, tlon)
    rc, rs, cc, cs = _trig_tables()
    hf = np.empty(1 << 16)
    hn = np.empty(1 << 16, np.int64)
    pos = np.full(n_all, -1, np.int32)  # each node's place in the heap (-1: not in it)
    size = 0
    for k in range(src_node.size):
        n = src_node[k]
        if src_cost[k] < g[n]:
            g[n] = src_cost[k]
            parent[n] = -1
            la, lo = _node_pos(xlat, xlon, n)
            hf, hn, size = _heap_set(hf, hn, pos, size, g[n] + _h(la, lo, tx, ty, tz), n)
    best, last = direct_nm, (-1 if direct_nm < np.inf else -2)
    nc = edges.shape[1]
    while size > 0:
        f, n, size = _heap_pop(hf, hn, pos, size)
        if f >= best:
            break
        gn = g[n]
        q = np.searchsorted(dst_sorted, n)
        while q < dst_sorted.size and dst_sorted[q] == n:
            if gn + dst_sorted_cost[q] < best:
                best, last = gn + dst_sorted_cost[q], n
            q += 1
        if n < N_GRID:
            i, j = n // nc, n % nc
            e = edges[i, j]
            for k in range(moves.shape[0]):
                if not (e >> k) & 1:
                    continue
                ii, jj = i + moves[k, 0], (j + moves[k, 1]) % nc
                m = ii * nc + jj
                gm = gn + move_cost[i, k]
                if gm < g[m]:
                    g[m] = gm
                    parent[m] = n
                    hm = _h_xyz(rc[ii] * cc[jj], rc[ii] * cs[jj], rs[ii], tx, ty, tz)
                    hf, hn, size = _heap_set(hf, hn, pos, size, gm + hm, m)
        for q in range(xoff[n], xoff[n + 1]):
            if xpass[q] >= 0 and avoided[xpass[q]]:
                continue
            m = xdst[q]
            gm = gn + xcost[q]
            if gm < g[m]:
                g[m] = gm
                parent[m] = n
                la, lo = _node_pos(xlat, xlon, m)
                hf, hn, size = _heap_set(hf, hn, pos, size, gm + _h(la, lo, tx, ty, tz), m)
    return best, last


@numba.njit(cache=True)
def _reach_count(layer, moves, avoided, src_node, limit):
    """How many graph nodes of the `layer` the sources reach (stopping at `limit`): tells an enclosed sea from open
    water."""
    edges, xoff, xdst, xpass = layer.edges, layer.xoff, layer.xdst, layer.xpass
    n_all = xoff.size - 1
    seen = np.zeros(n_all, np.bool_)
    stack = np.empty(n_all, np.int64)
    top, count = 0, 0
    for k in range(src_node.size):
        if not seen[src_node[k]]:
            seen[src_node[k]] = True
            stack[top] = src_node[k]
            top += 1
    nc = edges.shape[1]
    while top > 0 and count < limit:
        top -= 1
        n = stack[top]
        count += 1
        if n < N_GRID:
            i, j = n // nc, n % nc
            for k in range(moves.shape[0]):
                if (edges[i, j] >> k) & 1:
                    m = (i + moves[k, 0]) * nc + (j + moves[k, 1]) % nc
                    if not seen[m]:
                        seen[m] = True
                        stack[top] = m
                        top += 1
        for q in range(xoff[n], xoff[n + 1]):
            if xpass[q] >= 0 and avoided[xpass[q]]:
                continue
            m = xdst[q]
            if not seen[m]:
                seen[m] = True
                stack[top] = m
                top += 1
    return count


# the latitudes a pulled or cut leg may reach: the graph's limits and 1° more, for the bulge of a great circle
PULLED_LAT_LO, PULLED_LAT_HI = LAT_LIMITS_DEG[0] - 1.0, LAT_LIMITS_DEG[1] + 1.0


@numba.njit(cache=True)
def _pull(grid, rule, gates, lat, lon, fixed, keep):
    """String-pulling: keep[k] for the waypoints that stay. The ports and the fixed points (fairway vertices) stay;
    between two of them, from each kept waypoint the route goes on to the farthest following one that a single
    clear leg (crossing no gate) reaches, passing over those in between. Consecutive path points are joined by clear
    legs (graph edges), so this always ends."""
    n = lat.size
    keep[:] = False
    a = 0
    keep[0] = True
    k = 1
    while k < n:
        if fixed[k] or k == n - 1:
            keep[k] = True
            a = k
        elif not _leg_ok(grid, rule, gates, lat[a], lon[a], lat[k + 1], lon[k + 1], PULLED_LAT_LO, PULLED_LAT_HI):
            keep[k] = True
            a = k
        k += 1


@numba.njit(cache=True)
def _slide_ok(grid, rule, gates, la, loa, t_lat, t_lon, lb, lob):
    """Both legs through the moved waypoint (t_lat, t_lon), from its neighbour a and on to its neighbour b, are clear."""
    lo, hi = PULLED_LAT_LO, PULLED_LAT_HI
    return _leg_ok(grid, rule, gates, la, loa, t_lat, t_lon, lo, hi) and _leg_ok(grid, rule, gates, t_lat, t_lon, lb, lob,
                                                                                lo, hi)


@numba.njit(cache=True)
def _cut_corners(grid, rule, gates, lat, lon, fixed):
    """Shorten a pulled route in place: each waypoint that is not fixed slides along the great circle towards the
    midpoint of its neighbours as far as both its legs stay clear and cross no gate (halving the step from the
    whole way, then bisecting towards the blocked side). Pulling keeps only the graph's nodes (0.125°), so a bend
    round an island or a headland sits up to a cell off the tangent; here it moves onto it. A move is kept only
    when it shortens the two legs, so the route never lengthens; rounds repeat (at most CORNER_ROUNDS) while one
    gains ≥ CORNER_MIN_GAIN_NM."""
    n = lat.size
    for _round in range(CORNER_ROUNDS):
        gain = 0.0
        for k in range(1, n - 1):
            if fixed[k]:
                continue
            la, loa, lb, lob = lat[k - 1], lon[k - 1], lat[k + 1], lon[k + 1]
            before = geo.gc_distance_nm(la, loa, lat[k], lon[k]) + geo.gc_distance_nm(lat[k], lon[k], lb, lob)
            m_lat, m_lon = geo.gc_interpolate(la, loa, lb, lob, 0.5)
            ok, bad = 0.0, 1.0
            step = 1.0
            while step > 1.0 / 64.0:  # the largest clear slide among 1, 1/2, 1/4, ...
                t_lat, t_lon = geo.gc_interpolate(lat[k], lon[k], m_lat, m_lon, step)
                if _slide_ok(grid, rule, gates, la, loa, t_lat, t_lon, lb, lob):
                    ok = step
                    break
                bad = step
                step *= 0.5
            if ok == 0.0:
                continue
            for _ in range(4):  # towards the blocked side
                mid = 0.5 * (ok + bad)
                if bad <= ok:
                    break
                t_lat, t_lon = geo.gc_interpolate(lat[k], lon[k], m_lat, m_lon, mid)
                if _slide_ok(grid, rule, gates, la, loa, t_lat, t_lon, lb, lob):
                    ok = mid
                else:
                    bad = mid
            n_lat, n_lon = geo.gc_interpolate(lat[k], lon[k], m_lat, m_lon, ok)
            after = geo.gc_distance_nm(la, loa, n_lat, n_lon) + geo.gc_distance_nm(n_lat, n_lon, lb, lob)
            if after < before:
                lat[k], lon[k] = n_lat, n_lon
                gain += before - after
        if gain < CORNER_MIN_GAIN_NM:
            break


# ---------------------------------------------------------------------------------------------- the entry point

_MOVE_COST = None


def _move_cost() -> np.ndarray:
    global _MOVE_COST
    if _MOVE_COST is None:
        _MOVE_COST = _row_tables(MOVES)
    return _MOVE_COST


def passage_names() -> tuple[str, ...]:
    return tuple(p.name for p in PASSAGES)


def _position(p) -> tuple[float, float]:
    """(lat, lon) as floats, the longitude in -180..180 (left as given when it already is)."""
    lat, lon = float(p[0]), float(p[1])
    return lat, (lon if -180.0 <= lon <= 180.0 else float(geo.wrap180(lon)))


def _fmt(p: tuple[float, float]) -> str:
    return f"{p[0]:.4f},{p[1]:.4f}"


def sea_route(dep: tuple[float, float], arr: tuple[float, float], *, avoid=frozenset(),
              clearance_nm: float = DEFAULT_CLEARANCE_NM, approach_nm: float = DEFAULT_APPROACH_NM,
              dep_name: str = "departure", arr_name: str = "arrival") -> SeaRoute:
    """The shortest sea route from `dep` to `arr` ((lat, lon) degrees), avoiding the passages named in `avoid`
    (passages.PASSAGES names, e.g. {"suez"}; a traffic separation scheme's lanes cannot be avoided: ValueError);
    NoSeaRoute (naming what blocks it) when there is none."""
    avoid = check_avoid(avoid)
    for name, (la, lo) in ((dep_name, dep), (arr_name, arr)):
        if not (-90.0 <= la <= 90.0) or not math.isfinite(lo):
            raise NoSeaRoute(f"{name} {la},{lo} is not a valid position")
        if not (LAT_LIMITS_DEG[0] <= la <= LAT_LIMITS_DEG[1]):
            raise NoSeaRoute(f"{name} {_fmt((la, lo))} is beyond the ice limits of the sea routes (latitude "
                             f"{LAT_LIMITS_DEG[0]:g}..{LAT_LIMITS_DEG[1]:g})")
        if not bool(is_sea(la, lo)):
            raise NoSeaRoute(f"{name} {_fmt((la, lo))} is on land (global land mask, which holds lakes and the Caspian Sea as land); give a position at sea, e.g. the pilot station")
    dep, arr = (_position(p) for p in (dep, arr))
    rule = clearance(dep, arr, clearance_nm, approach_nm)
    layer = _layer(rule.clearance_nm)
    grid = land_grid()
    gc = float(geo.gc_distance_nm(*dep, *arr))
    direct = (gc if gc <= 3 * JOIN_MAX_NM and _leg_ok(grid, rule, layer.gates, *dep, *arr, PULLED_LAT_LO, PULLED_LAT_HI)
              else math.inf)
    src_node, src_cost = _join(rule, layer, *dep, with_extra=True)
    dst_node, dst_cost = _join(rule, layer, *arr, with_extra=True)
    src_paths: dict[int, list] = {}
    dst_paths: dict[int, list] = {}
    if not src_node.size:
        src_node, src_cost, src_paths = _escape(rule, layer, *dep)
    if not dst_node.size:
        dst_node, dst_cost, dst_paths = _escape(rule, layer, *arr)
    if direct == math.inf:
        for name, pos, nodes in ((dep_name, dep, src_node), (arr_name, arr, dst_node)):
            if not nodes.size:
                raise NoSeaRoute(f"{name} {_fmt(pos)} is enclosed at this clearance: no way from it to open water keeps "
                                 f"{rule.clearance_nm:g} NM from land outside its {rule.approach_nm:g} NM approach (a "
                                 f"harbour or bay whose way out is narrower than twice that); give a position outside it, "
                                 f"e.g. the pilot station, or a wider port approach")
    avoided = np.array([p.name in avoid for p in PASSAGES], np.bool_)
    parent = np.full(layer.xoff.size - 1, -1, np.int32)
    ends = _Ends(src_node, src_cost, dst_node, dst_cost, float(direct), float(arr[0]), float(arr[1]))
    best, last = _astar(layer, _move_cost(), MOVES, avoided, ends, parent)
    if last == -2:
        raise NoSeaRoute(_why_none(layer, avoid, avoided, src_node, dst_node, dep, arr, dep_name, arr_name, rule.clearance_nm))
    nodes = []
    while last >= 0:
        nodes.append(int(last))
        last = int(parent[last])
    nodes.reverse()
    prefix = src_paths.get(nodes[0], []) if nodes else []
    suffix = dst_paths.get(nodes[-1], [])[::-1] if nodes else []
    at = 1 + len(prefix)  # path index of nodes[0]
    pts = ([dep] + prefix + [tuple(float(v) for v in _node_pos(layer.xlat, layer.xlon, n)) for n in nodes] + suffix
           + [arr])
    lat = np.array([p[0] for p in pts])
    lon = np.array([p[1] for p in pts])
    # fairway vertices on the path (a passage used over at least one of its edges) are fixed
    fixed = np.zeros(len(pts), np.bool_)
    used: list[tuple[int, int, int]] = []  # (passage index, first, last) path index
    for k, n in enumerate(nodes):
        if n >= N_GRID:
            pid = int(layer.vpass[n - N_GRID])
            prev_same = k > 0 and nodes[k - 1] >= N_GRID and int(layer.vpass[nodes[k - 1] - N_GRID]) == pid
            nxt_same = k + 1 < len(nodes) and nodes[k + 1] >= N_GRID and int(layer.vpass[nodes[k + 1] - N_GRID]) == pid
            if prev_same or nxt_same:
                fixed[k + at] = True
                if prev_same and used and used[-1][0] == pid and used[-1][2] == k + at - 1:
                    used[-1] = (pid, used[-1][1], k + at)
                else:
                    used.append((pid, k + at, k + at))
    keep = np.zeros(len(pts), np.bool_)
    _pull(grid, rule, layer.gates, lat, lon, fixed, keep)
    new_index = np.cumsum(keep) - 1
    lat, lon, fixed = lat[keep], lon[keep], fixed[keep]
    cut_rule = clearance(dep, arr, clearance_nm + CORNER_MARGIN_NM, approach_nm)
    _cut_corners(grid, cut_rule, layer.gates, lat, lon, fixed)  # then waypoints the slides made needless are dropped
    keep = np.zeros(lat.size, np.bool_)
    _pull(grid, rule, layer.gates, lat, lon, fixed, keep)
    new_index = (np.cumsum(keep) - 1)[new_index]
    lat, lon = lat[keep], lon[keep]
    transits = []
    for pid, a, b in used:
        p: Passage = PASSAGES[pid]
        transits.append(PassageTransit(p.name, p.kind, int(new_index[a]), int(new_index[b]), p.transit_h, p.wait_h))
    dist = float(sum(geo.gc_distance_nm(lat[k], lon[k], lat[k + 1], lon[k + 1]) for k in range(lat.size - 1)))
    return SeaRoute(lat=lat, lon=lon, dist_nm=dist, passages=tuple(transits))


def _why_none(layer, avoid, avoided, src_node, dst_node, dep, arr, dep_name, arr_name, clearance_nm) -> str:
    """The reason two points have no route: an avoided passage (the route exists without `avoid`), an enclosed sea
    (one end reaches few nodes), or separate waters."""
    base = f"no sea route from {dep_name} {_fmt(dep)} to {arr_name} {_fmt(arr)} at {clearance_nm:g} NM from land"
    if avoid:
        none = np.zeros_like(avoided)
        parent = np.full(layer.xoff.size - 1, -1, np.int32)
        ends = _Ends(src_node, np.zeros(src_node.size), dst_node, np.zeros(dst_node.size), math.inf, float(arr[0]),
                     float(arr[1]))
        _, last = _astar(layer, _move_cost(), MOVES, none, ends, parent)
        if last != -2:
            return f"{base}: every route goes through the avoided passage(s) {', '.join(sorted(avoid))}"
    limit = 200_000
    none = np.zeros_like(avoided)
    for name, pos, nodes in ((dep_name, dep, src_node), (arr_name, arr, dst_node)):
        n = _reach_count(layer, MOVES, none, nodes, limit)
        if n < limit:
            area = n * (RES_DEG * 60.0) ** 2 * math.cos(math.radians(pos[0]))
            return (f"{base}: the {name} lies in an enclosed sea or lake (about {area:,.0f} NM² of open water, "
                    f"no way out to the ocean at that clearance)")
    return f"{base}: the two lie in separate waters"


def least_clearance_outside_passages_nm(route: SeaRoute, approach_nm: float = DEFAULT_APPROACH_NM,
                                        step_nm: float = 0.1) -> float:
    """Least distance to land (NM, capped at 25) along `route`, sampled every `step_nm`, outside its passages'
    fairways, the port approaches (`approach_nm` of the first and last waypoint) and the fairways' end approaches
    (FAIRWAY_END_APPROACH_NM): what the route promises to keep (its clearance). 0 means a sample on land."""
    from pipeline.routing.sphere import gc_points

    inside = np.zeros(route.lat.size - 1, bool)
    spots = [(route.lat[0], route.lon[0], approach_nm), (route.lat[-1], route.lon[-1], approach_nm)]
    for p in route.passages:
        inside[p.start_index:p.end_index] = True
        for k in (p.start_index, p.end_index):
            spots.append((route.lat[k], route.lon[k], FAIRWAY_END_APPROACH_NM))
    best = 25.0
    for k in np.flatnonzero(~inside):
        la0, lo0, la1, lo1 = route.lat[k], route.lon[k], route.lat[k + 1], route.lon[k + 1]
        n = int(geo.gc_distance_nm(la0, lo0, la1, lo1) / step_nm) + 2
        lat, lon = gc_points(la0, lo0, la1, lo1, np.linspace(0.0, 1.0, n))
        free = np.ones(n, bool)
        for sla, slo, r in spots:
            free &= _haversine_nm(lat, lon, sla, slo) > r
        if free.any():
            best = min(best, float(distance_to_land_nm(lat[free], lon[free], limit_nm=best).min()))
    return best


def _haversine_nm(lat, lon, lat0, lon0):
    p1, p2 = np.radians(lat0), np.radians(lat)
    dl = np.radians((lon - lon0 + 180.0) % 360.0 - 180.0)
    a = np.sin((p2 - p1) / 2) ** 2 + np.cos(p1) * np.cos(p2) * np.sin(dl / 2) ** 2
    return 2.0 * EARTH_RADIUS_NM * np.arcsin(np.minimum(1.0, np.sqrt(a)))


__all__ = ["NoSeaRoute", "SeaRoute", "least_clearance_outside_passages_nm", "passage_names", "sea_route"]
