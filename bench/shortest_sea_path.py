"""The shortest path at sea on a fine raster, string-pulled: the exact reference the sea-route bench measures the
product's routes against (bench/sea_routes_reference.py), independent of the product's sea graph.

Pure: the land is given as a function `dist_nm(lat, lon, limit_nm)` (NM from each point to the nearest land, exact
below `limit_nm`, at least `limit_nm` beyond; 0 on land), so a test can give a synthetic island and the bench the
product's own mask (pipeline.routing.land.distance_to_land_nm).

The rule is the product's (pipeline/routing/clearance.py): every point of a leg at sea and at least `clearance_nm`
from land, except within `approach_nm` of the departure or the arrival, where it need only be at sea; a leg joining
a fairway's end (a passage, pipeline/routing/passages.py) need only be at sea within `fairway_end_approach_nm` of that
end. Fairways are sailed vertex by vertex (one way only for a traffic lane, entered at its first vertex and left at
its last); no leg outside a fairway crosses a gate.

How:
1. A raster of `res_deg` over the box (lat_lo, lat_hi, lon_lo, lon_hi; longitudes continuous, may pass 180): a cell
   is a node when its centre keeps the rule; 16 moves per node (the 8 around and the 8 a knight's move away), an
   edge when the great-circle leg between the centres keeps the rule at every point: certain when the distances at
   its ends allow no land nearer than the clearance between them (the distance to land changes by at most 1 NM per
   NM), else sampled every `step_nm` (0.1 NM). Edges across a gate are left out.
2. The ports join the cells within `join_cells` cells and every fairway vertex within `join_nm`; a fairway's ends
   join the cells within `fairway_join_nm` and the other fairways' vertices within `join_nm`; a direct leg counts.
3. Dijkstra (scipy.sparse.csgraph) from the departure; the path's length is the grid's.
4. String-pulling (any-angle): a waypoint is dropped while the great-circle leg between its neighbours keeps the rule
   (sampled every `step_nm`) and crosses no gate; fairway vertices stay. Passes repeat until none drops.
The length is the sum of the great-circle legs (the bench's measure). The grid path's homotopy is the raster's choice:
where two ways round an obstacle differ by less than the 16-move metric's error (at most 2.7 %) the longer may be
taken; `touches_box` says the path runs along the box's edge (a larger box may find a shorter way).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from pipeline.routing.sphere import EARTH_RADIUS_NM, gc_points

# the 8 moves of the 16 whose reverse is the other 8 (row, column); rows run north to south
HALF_MOVES = ((0, 1), (1, 0), (1, 1), (1, -1), (1, 2), (1, -2), (2, 1), (2, -1))
COARSE_NM = 2.0  # a leg's distance to land is first taken every this many NM; only where that allows land nearer
# than the clearance between two samples is it sampled every step_nm
MAX_TIGHTEN_ROUNDS = 40
TIGHTEN_STOP_NM = 0.01  # corner cutting stops when a round gains less than this
CUT_MIN_NM = 0.05


@dataclass(frozen=True)
class Fairway:
    name: str
    points: tuple[tuple[float, float], ...]  # (lat, lon) in the order of travel for a one-way lane
    one_way: bool = False


@dataclass(frozen=True)
class Problem:
    dep: tuple[float, float]
    arr: tuple[float, float]
    clearance_nm: float
    approach_nm: float
    fairways: tuple[Fairway, ...] = ()
    gates: tuple[tuple[tuple[float, float], tuple[float, float]], ...] = ()
    fairway_end_approach_nm: float = 5.0
    join_nm: float = 40.0
    fairway_join_nm: float = 15.0
    join_cells: int = 3
    step_nm: float = 0.1


@dataclass
class Route:
    lat: np.ndarray
    lon: np.ndarray  # continuous (may pass ±180)
    dist_nm: float
    grid_nm: float  # the raster path's length before pulling
    touches_box: bool
    fairways: list[str] = field(default_factory=list)
    n_nodes: int = 0
    fairway_runs: list[tuple[str, int, int]] = field(default_factory=list)  # (fairway, first, last waypoint) sailed


def haversine_nm(lat0, lon0, lat1, lon1):
    p0, p1 = np.radians(lat0), np.radians(lat1)
    dl = np.radians((np.asarray(lon1) - lon0 + 180.0) % 360.0 - 180.0)
    a = np.sin((p1 - p0) / 2) ** 2 + np.cos(p0) * np.cos(p1) * np.sin(dl / 2) ** 2
    return 2.0 * EARTH_RADIUS_NM * np.arcsin(np.minimum(1.0, np.sqrt(a)))


def _unit(lat, lon):
    p, lam = np.radians(lat), np.radians(lon)
    return np.stack([np.cos(p) * np.cos(lam), np.cos(p) * np.sin(lam), np.sin(p)], axis=-1)


def arcs_cross(a0, a1, b0, b1) -> np.ndarray:
    """Whether great-circle arcs a0–a1 and b0–b1 (each shorter than half the globe) cross; arguments (..., 3) unit
    vectors that broadcast together."""
    na, nb = np.cross(a0, a1), np.cross(b0, b1)
    s0, s1 = np.sum(na * b0, -1), np.sum(na * b1, -1)
    t0, t1 = np.sum(nb * a0, -1), np.sum(nb * a1, -1)
    straddle = (s0 * s1 < 0.0) & (t0 * t1 < 0.0)
    c = np.cross(na, nb)
    c = np.where((np.sum(c * (a0 + a1), -1) < 0.0)[..., None], -c, c)
    return straddle & (np.sum(c * (b0 + b1), -1) > 0.0)


class _Rule:
    """The clearance rule with the approach discs of the ports (and, per leg, of the fairway ends it joins)."""

    def __init__(self, problem: Problem, dist_nm):
        self.p, self.dist_nm = problem, dist_nm
        self.c = problem.clearance_nm

    def need(self, lat, lon, extra_discs=()):
        p = self.p
        near = (haversine_nm(lat, lon, *p.dep) <= p.approach_nm) | (haversine_nm(lat, lon, *p.arr) <= p.approach_nm)
        for la, lo, r in extra_discs:
            near |= haversine_nm(lat, lon, la, lo) <= r
        return np.where(near, 0.0, self.c)

    def points_ok(self, lat, lon, extra_discs=()):
        d = self.dist_nm(lat, lon, self.c + 1.0)
        return (d > 0.0) & (d >= self.need(lat, lon, extra_discs))

    def leg_ok(self, lat0, lon0, lat1, lon1, extra_discs=()) -> bool:
        """The great-circle leg keeps the rule at every point (to the sampling `step_nm`)."""
        length = float(haversine_nm(lat0, lon0, lat1, lon1))
        n = max(2, int(math.ceil(length / COARSE_NM)) + 1)
        f = np.linspace(0.0, 1.0, n)
        la, lo = gc_points(lat0, lon0, lat1, lon1, f)
        d = self.dist_nm(la, lo, self.c + COARSE_NM + 1.0)
        if not np.all((d > 0.0) & (d >= self.need(la, lo, extra_discs))):
            return False
        s = length / (n - 1)
        doubt = np.flatnonzero(0.5 * (d[:-1] + d[1:] - s) < max(self.c, 1e-9))
        if doubt.size == 0:
            return True
        m = max(2, int(math.ceil(s / self.p.step_nm)) + 1)
        g = (f[doubt, None] + np.linspace(0.0, 1.0, m)[None, :] * (f[1] - f[0])).ravel()
        la, lo = gc_points(lat0, lon0, lat1, lon1, g)
        return bool(np.all(self.points_ok(la, lo, extra_discs)))


def _raster_edges(rule: _Rule, LA, LO, ok, d, res_deg, gate_vecs):
    """Directed edges (both ways) of the raster: (from, to, NM)."""
    ny, nx = LA.shape
    idx = np.arange(ny * nx).reshape(ny, nx)
    c = rule.c
    src, dst, w = [], [], []
    for di, dj in HALF_MOVES:
        i0, i1 = 0, ny - di
        j0, j1 = max(0, -dj), nx - max(0, dj)
        a = (slice(i0, i1), slice(j0, j1))
        b = (slice(i0 + di, i1 + di), slice(j0 + dj, j1 + dj))
        both = ok[a] & ok[b]
        ia, ib = idx[a][both], idx[b][both]
        la0, lo0, la1, lo1 = LA.flat[ia], LO.flat[ia], LA.flat[ib], LO.flat[ib]
        length = haversine_nm(la0, lo0, la1, lo1)
        sure = 0.5 * (d.flat[ia] + d.flat[ib] - length) >= max(c, 1e-9)
        doubt = np.flatnonzero(~sure)
        good = sure.copy()
        if doubt.size:
            m = int(math.ceil(length[doubt].max() / rule.p.step_nm)) + 1
            f = np.linspace(0.0, 1.0, m)
            for chunk in np.array_split(doubt, max(1, doubt.size * m // 2_000_000 + 1)):
                pl, po = gc_points(la0[chunk, None], lo0[chunk, None], la1[chunk, None], lo1[chunk, None], f[None, :])
                good[chunk] = rule.points_ok(pl, po).all(axis=1)
        if gate_vecs is not None and good.any():
            g = np.flatnonzero(good)
            u0, u1 = _unit(la0[g], lo0[g]), _unit(la1[g], lo1[g])
            cross = np.zeros(g.size, bool)
            for q0, q1 in gate_vecs:
                cross |= arcs_cross(u0, u1, q0, q1)
            good[g[cross]] = False
        ia, ib, length = ia[good], ib[good], length[good]
        src += [ia, ib]
        dst += [ib, ia]
        w += [length, length]
    return np.concatenate(src), np.concatenate(dst), np.concatenate(w)


def _pull(pts, clear):
    """Drop each waypoint (not fixed) while the leg between the kept one before it and the one after it is clear."""
    changed = True
    while changed:
        changed = False
        out = [pts[0]]
        for k in range(1, len(pts)):
            if k == len(pts) - 1 or pts[k][2] or not clear(out[-1], pts[k + 1]):
                out.append(pts[k])
            else:
                changed = True
        pts = out
    return pts


def _cut_corners(pts, clear):
    """Each waypoint v (not fixed) between a and b is replaced by v1 on a–v and v2 on v–b, each as far from v as
    the cut v1–v2 stays clear (bisection on the distance along the legs, down to CUT_MIN_NM): the route only gets
    shorter (a–v1 and v2–b lie on legs already clear), and a curve round an obstacle tightens towards it."""
    out, gain = [pts[0]], 0.0
    for k in range(1, len(pts) - 1):
        v, b = pts[k], pts[k + 1]
        a = out[-1]
        if v[2]:
            out.append(v)
            continue
        la_, lb_ = float(haversine_nm(a[0], a[1], v[0], v[1])), float(haversine_nm(v[0], v[1], b[0], b[1]))
        hi = 0.5 * min(la_, lb_)
        lo, best, first = 0.0, None, True
        while first or hi - lo > CUT_MIN_NM:
            mid = hi if first else 0.5 * (lo + hi)
            p1 = gc_points(v[0], v[1], a[0], a[1], mid / la_)
            p2 = gc_points(v[0], v[1], b[0], b[1], mid / lb_)
            q1 = (float(p1[0]), float(a[1] + (float(p1[1]) - a[1] + 180.0) % 360.0 - 180.0), False, (), None)
            q2 = (float(p2[0]), float(b[1] + (float(p2[1]) - b[1] + 180.0) % 360.0 - 180.0), False, (), None)
            if clear(q1, q2):
                lo, best = mid, (q1, q2)
                if first:
                    break
            else:
                hi = mid
            first = False
        if best is None:
            out.append(v)
            continue
        q1, q2 = best
        g = 2.0 * lo - float(haversine_nm(q1[0], q1[1], q2[0], q2[1]))
        if g <= 1e-6:
            out.append(v)
            continue
        gain += g
        out += [q1, q2]
    out.append(pts[-1])
    return out, gain


def shortest_route(problem: Problem, dist_nm, box: tuple[float, float, float, float], res_deg: float) -> Route:
    """The shortest route (see the module docstring) over the raster of `res_deg` on `box` (lat_lo, lat_hi, lon_lo,
    lon_hi). ValueError when the raster joins no path."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra

    rule = _Rule(problem, dist_nm)
    lat_lo, lat_hi, lon_lo, lon_hi = box
    lats = np.arange(lat_hi, lat_lo - 1e-9, -res_deg)
    lons = np.arange(lon_lo, lon_hi + 1e-9, res_deg)
    LA, LO = np.meshgrid(lats, lons, indexing="ij")
    longest_nm = 60.0 * res_deg * math.sqrt(5.0)
    d = dist_nm(LA, LO, rule.c + longest_nm + 1.0)
    ok = (d > 0.0) & (d >= rule.need(LA, LO))
    gates = [((a[0], a[1]), (b[0], b[1])) for a, b in problem.gates]
    gate_vecs = [(_unit(*a), _unit(*b)) for a, b in gates] or None
    src, dst, w = _raster_edges(rule, LA, LO, ok, d, res_deg, gate_vecs)
    n_cells = LA.size

    # the extra nodes: departure, arrival, fairway vertices
    xlat, xlon = [problem.dep[0], problem.arr[0]], [lon_lo + (problem.dep[1] - lon_lo) % 360.0,
                                                    lon_lo + (problem.arr[1] - lon_lo) % 360.0]
    xfw, xk = [-1, -1], [-1, -1]
    for q, fw in enumerate(problem.fairways):
        for k, (la, lo) in enumerate(fw.points):
            xlat.append(la)
            xlon.append(lon_lo + (lo - lon_lo) % 360.0)
            xfw.append(q)
            xk.append(k)
    xlat, xlon = np.array(xlat), np.array(xlon)
    DEP, ARR = n_cells, n_cells + 1
    es, ed, ew = [], [], []

    def crosses_gate(la0, lo0, la1, lo1) -> bool:
        if gate_vecs is None:
            return False
        u0, u1 = _unit(la0, lo0), _unit(la1, lo1)
        return any(bool(arcs_cross(u0, u1, q0, q1)) for q0, q1 in gate_vecs)

    def add(a, b, la0, lo0, la1, lo1, discs=(), forward=True, backward=True):
        if not (forward or backward) or crosses_gate(la0, lo0, la1, lo1):
            return
        if not rule.leg_ok(la0, lo0, la1, lo1, discs):
            return
        nm = float(haversine_nm(la0, lo0, la1, lo1))
        if forward:
            es.append(a), ed.append(b), ew.append(nm)
        if backward:
            es.append(b), ed.append(a), ew.append(nm)

    def cells_near(la, lo, radius_nm):
        near = (haversine_nm(LA, LO, la, lo) <= radius_nm) & ok
        return np.flatnonzero(near.ravel())

    def end_discs(n):
        return ((xlat[n - n_cells], xlon[n - n_cells], problem.fairway_end_approach_nm),)

    ends = set()
    for n in range(n_cells + 2, n_cells + xlat.size):
        fw = problem.fairways[xfw[n - n_cells]]
        if xk[n - n_cells] in (0, len(fw.points) - 1):
            ends.add(n)
    entry_only = {n for n in ends if problem.fairways[xfw[n - n_cells]].one_way and xk[n - n_cells] == 0}
    exit_only = {n for n in ends if problem.fairways[xfw[n - n_cells]].one_way and xk[n - n_cells] > 0}

    port_radius = problem.join_cells * 60.0 * res_deg * 1.01
    for port, sign in ((DEP, 1), (ARR, -1)):
        la, lo = xlat[port - n_cells], xlon[port - n_cells]
        for cell in cells_near(la, lo, port_radius):
            add(port, cell, la, lo, LA.flat[cell], LO.flat[cell], forward=sign > 0, backward=sign < 0)
        for n in range(n_cells + 2, n_cells + xlat.size):
            if haversine_nm(la, lo, xlat[n - n_cells], xlon[n - n_cells]) <= problem.join_nm:
                add(port, n, la, lo, xlat[n - n_cells], xlon[n - n_cells], forward=sign > 0, backward=sign < 0)
    if haversine_nm(*problem.dep, *problem.arr) <= 3 * problem.join_nm:
        add(DEP, ARR, *problem.dep, *problem.arr, backward=False)
    for n in range(n_cells + 2, n_cells + xlat.size):  # the fairways' own edges
        k, fw = xk[n - n_cells], problem.fairways[xfw[n - n_cells]]
        if k + 1 < len(fw.points):
            nm = float(haversine_nm(xlat[n - n_cells], xlon[n - n_cells], xlat[n + 1 - n_cells], xlon[n + 1 - n_cells]))
            es.append(n), ed.append(n + 1), ew.append(nm)
            if not fw.one_way:
                es.append(n + 1), ed.append(n), ew.append(nm)
    for e in sorted(ends):
        la, lo = xlat[e - n_cells], xlon[e - n_cells]
        fwd, bwd = e not in entry_only, e not in exit_only  # e → elsewhere, elsewhere → e
        for cell in cells_near(la, lo, problem.fairway_join_nm):
            add(e, cell, la, lo, LA.flat[cell], LO.flat[cell], end_discs(e), forward=fwd, backward=bwd)
        for n in range(n_cells + 2, n_cells + xlat.size):
            if xfw[n - n_cells] == xfw[e - n_cells] or (n in ends and n < e):  # pairs of ends: once
                continue
            if haversine_nm(la, lo, xlat[n - n_cells], xlon[n - n_cells]) <= problem.join_nm:
                add(e, n, la, lo, xlat[n - n_cells], xlon[n - n_cells], end_discs(e) + (end_discs(n) if n in ends else ()),
                    forward=fwd and n not in exit_only, backward=bwd and n not in entry_only)

    n_all = n_cells + xlat.size
    graph = coo_matrix((np.concatenate([w, np.array(ew)]), (np.concatenate([src, np.array(es, np.int64)]),
                                                             np.concatenate([dst, np.array(ed, np.int64)]))),
                       shape=(n_all, n_all)).tocsr()
    dist, pred = dijkstra(graph, directed=True, indices=DEP, return_predecessors=True)
    if not np.isfinite(dist[ARR]):
        raise ValueError(f"no path on the raster of {res_deg:g}° over {box} at {problem.clearance_nm:g} NM from land")
    path = [ARR]
    while path[-1] != DEP:
        path.append(int(pred[path[-1]]))
    path.reverse()
    plat = np.array([LA.flat[n] if n < n_cells else xlat[n - n_cells] for n in path])
    plon = np.array([LO.flat[n] if n < n_cells else xlon[n - n_cells] for n in path])
    touches = any(n < n_cells and (n // LA.shape[1] in (0, LA.shape[0] - 1) or n % LA.shape[1] in (0, LA.shape[1] - 1))
                  for n in path)
    # fairway vertices sailed (joined to a vertex of the same fairway on the path) stay
    fixed = np.zeros(len(path), bool)
    used = []
    for k, n in enumerate(path):
        if n >= n_cells + 2:
            q = xfw[n - n_cells]
            for m in (k - 1, k + 1):
                if 0 <= m < len(path) and path[m] >= n_cells + 2 and xfw[path[m] - n_cells] == q:
                    fixed[k] = True
            if fixed[k] and (not used or used[-1] != problem.fairways[q].name):
                used.append(problem.fairways[q].name)
    fixed[0] = fixed[-1] = True

    sailed = [problem.fairways[xfw[n - n_cells]].name if fixed[k] and n >= n_cells + 2 else None
              for k, n in enumerate(path)]
    pts = [(float(plat[k]), float(plon[k]), bool(fixed[k]), end_discs(path[k]) if path[k] in ends else (), sailed[k])
           for k in range(len(path))]

    def clear(a, b) -> bool:
        return (not crosses_gate(a[0], a[1], b[0], b[1])) and rule.leg_ok(a[0], a[1], b[0], b[1], a[3] + b[3])

    pts = _pull(pts, clear)
    for _ in range(MAX_TIGHTEN_ROUNDS):
        pts, gain = _cut_corners(pts, clear)
        pts = _pull(pts, clear)
        if gain < TIGHTEN_STOP_NM:
            break
    plat, plon = np.array([p[0] for p in pts]), np.array([p[1] for p in pts])
    runs = []  # (fairway, first, last waypoint) of each fairway sailed
    for k, p in enumerate(pts):
        if p[4] is not None and k > 0 and pts[k - 1][4] == p[4] and runs and runs[-1][2] == k - 1:
            runs[-1] = (p[4], runs[-1][1], k)
        elif p[4] is not None:
            runs.append((p[4], k, k))
    keep = np.arange(len(pts))
    lat, lon = plat[keep], plon[keep]
    length = float(np.sum(haversine_nm(lat[:-1], lon[:-1], lat[1:], lon[1:])))
    return Route(lat=lat, lon=lon, dist_nm=length, grid_nm=float(dist[ARR]), touches_box=touches, fairways=used,
                 n_nodes=int(ok.sum()), fairway_runs=[r for r in runs if r[2] > r[1]])


__all__ = ["Fairway", "Problem", "Route", "arcs_cross", "haversine_nm", "shortest_route"]
