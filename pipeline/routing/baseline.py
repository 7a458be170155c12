"""The baseline every plan is compared with: the shortest sea route through the graph (the base line itself
when it is at sea) sailed at one constant rpm.

`constant_rpm_for_rta` finds the one constant rpm anywhere between the lowest and the highest allowed setting
that arrives at the RTA on a route in the voyage's weather (bisection; the slowest when even that is early, the
fastest, late, when none is in time). solve.py adds that rpm to the settings the solvers may use, so the
constant-speed voyage on the base route is a plan of every solver's space (`baseline` then picks it: it is the
slowest setting that meets the RTA), and no plan returned burns more than it."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from pipeline.routing.engine import leg as lk
from pipeline.routing.geodesy import gc_distance_nm
from pipeline.routing.objectives import route_cost_nb
from pipeline.routing.search_space import SearchSpace


@dataclass(frozen=True)
class Baseline:
    """The shortest sea route (None: there is none) and its constant engine setting per leg; `code` is the
    engine.leg code of sailing it (OK, or why it cannot be sailed)."""

    nodes: np.ndarray | None
    rpm_idx: np.ndarray | None
    code: int

    @property
    def ok(self) -> bool:
        return self.nodes is not None and self.code == lk.OK


@numba.njit(cache=True)
def _shortest_nb(lat, lon, edge_ok, c, parent):
    """Least distance from the centre node of line 0 to every node of the last line; `parent` (L+2, P) filled.
    Ties go to the node nearer the centre line."""
    L2, P = lat.shape
    dist = np.full(P, np.inf)
    dist[c] = 0.0
    nxt = np.empty(P)
    for i in range(L2 - 1):
        nxt[:] = np.inf
        for a in range(P):
            if not np.isfinite(dist[a]):
                continue
            for b in range(P):
                if not edge_ok[i, a, b]:
                    continue
                d = dist[a] + gc_distance_nm(lat[i, a], lon[i, a], lat[i + 1, b], lon[i + 1, b])
                if d < nxt[b] - 1e-9 or (abs(d - nxt[b]) <= 1e-9 and abs(a - c) < abs(parent[i + 1, b] - c)):
                    nxt[b] = d
                    parent[i + 1, b] = a
        dist[:] = nxt
    return dist


def shortest_route(space: SearchSpace) -> np.ndarray | None:
    """Least-distance node path through feasible edges (the base line itself when it is at sea)."""
    L2, P = space.lat.shape
    c = space.centre
    parent = np.full((L2, P), -1, np.int64)
    dist = _shortest_nb(space.lat, space.lon, space.edge_ok, c, parent)
    if not np.isfinite(dist[c]):
        return None
    nodes = np.full(L2, c, np.int64)
    for i in range(L2 - 1, 0, -1):
        nodes[i - 1] = parent[i, nodes[i]]
    return nodes


def evaluate(inst, nodes, rpm_idx) -> tuple[float, float, float, int]:
    """(cost, hours, fuel, code) of a route (node per line, rpm index per leg) in the instance."""
    L2 = len(nodes)
    ct, cf = np.empty(L2), np.empty(L2)
    code, _ = lk.sail_route_nb(np.asarray(nodes, np.int64), np.asarray(rpm_idx, np.int64), 0, inst.graph, inst.vessel,
                               inst.wx, inst.objective, ct, cf)
    if code != lk.OK:
        return math.inf, math.nan, math.nan, code
    hours, fuel = ct[-1] - inst.t_dep_h, cf[-1]
    return route_cost_nb(inst.objective, hours, fuel), hours, fuel, lk.OK


def sail_constant(inst, nodes: np.ndarray, rpm: float) -> tuple[float, float]:
    """(hours, fuel) of the route at a constant rpm (inf hours when a leg cannot be sailed)."""
    v = inst.vessel._replace(rpm_options=np.array([float(rpm)]))
    L2 = len(nodes)
    ct, cf = np.empty(L2), np.empty(L2)
    code, _ = lk.sail_route_nb(np.ascontiguousarray(nodes, np.int64), np.zeros(L2 - 1, np.int64), 0, inst.graph, v,
                               inst.wx, inst.objective, ct, cf)
    return (ct[-1] - inst.t_dep_h, cf[-1]) if code == lk.OK else (math.inf, math.nan)


def constant_rpm_for_rta(inst, nodes: np.ndarray, tol_h: float = 1e-5) -> tuple[float, float, float] | None:
    """(rpm, hours, fuel) of the one constant rpm between the allowed extremes that arrives at the RTA on `nodes`
    (bisection: hours fall as rpm rises; when it lies in one of the engine's barred ranges, the top of that range);
    None when the route cannot be sailed at the extremes."""
    lo, hi = float(inst.rpm_options[0]), float(inst.rpm_options[-1])
    t_req = inst.problem.t_req_h
    h_lo, f_lo = sail_constant(inst, nodes, lo)
    if h_lo <= t_req:
        return lo, h_lo, f_lo
    h_hi, f_hi = sail_constant(inst, nodes, hi)
    if not math.isfinite(h_hi) or h_hi >= t_req:
        return (hi, h_hi, f_hi) if math.isfinite(h_hi) else None
    for _ in range(60):  # keep the on-time end: its plan arrives by the RTA
        mid = 0.5 * (lo + hi)
        h, f = sail_constant(inst, nodes, mid)
        if h <= t_req:
            hi, h_hi, f_hi = mid, h, f
        else:
            lo = mid
        if t_req - h_hi <= tol_h:
            break
    for b_lo, b_hi in inst.problem.barred_rpm:
        if b_lo < hi < b_hi:  # the engine cannot be held there: the top of the barred range, arriving early
            h_b, f_b = sail_constant(inst, nodes, b_hi)
            return (b_hi, h_b, f_b) if math.isfinite(h_b) else None
    return hi, h_hi, f_hi


def with_setting(rpm_options: np.ndarray, rpm: float, rel_tol: float = 1e-9) -> np.ndarray:
    """The sorted settings with `rpm` added (unless one is already that rpm)."""
    rpm_options = np.asarray(rpm_options, np.float64)
    if np.any(np.abs(rpm_options - rpm) <= rel_tol * max(abs(rpm), 1.0)):
        return rpm_options
    return np.sort(np.append(rpm_options, float(rpm)))


def constant_rpm_route(inst, nodes: np.ndarray) -> tuple[np.ndarray, int]:
    """Slowest allowed rpm, held on every leg, that arrives by the RTA; else the fastest. (rpm_idx, code)."""
    n = len(inst.rpm_options)
    last_code = lk.OK
    fastest = None
    for r in range(n):
        rpm_idx = np.full(len(nodes) - 1, r, np.int64)
        _, hours, _, code = evaluate(inst, nodes, rpm_idx)
        if code != lk.OK:
            last_code = code
            continue
        fastest = rpm_idx
        if hours <= inst.problem.t_req_h + 1e-9:
            return rpm_idx, lk.OK
    return (fastest, lk.OK) if fastest is not None else (np.full(len(nodes) - 1, n - 1, np.int64), last_code)


def baseline(inst, nodes: np.ndarray | None = None) -> Baseline:
    """The shortest sea route (`nodes`, found when not given) at the slowest setting that meets the RTA."""
    nodes = shortest_route(inst.space) if nodes is None else nodes
    if nodes is None:
        return Baseline(None, None, lk.NO_EDGE)
    rpm_idx, code = constant_rpm_route(inst, nodes)
    return Baseline(nodes, rpm_idx, code)
