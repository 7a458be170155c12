"""The baseline every plan is compared with: the shortest sea route through the graph (the base line itself
when it is at sea) at the slowest constant rpm that meets the RTA, else the fastest."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from pipeline.routing import leg_kernel as lk
from pipeline.routing.geodesy import gc_distance_nm
from pipeline.routing.objectives import route_cost_nb
from pipeline.routing.search_space import SearchSpace


@dataclass(frozen=True)
class Baseline:
    """The shortest sea route (None: there is none) and its constant engine setting per leg; `code` is the
    leg_kernel code of sailing it (OK, or why it cannot be sailed)."""

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


def baseline(inst) -> Baseline:
    nodes = shortest_route(inst.space)
    if nodes is None:
        return Baseline(None, None, lk.NO_EDGE)
    rpm_idx, code = constant_rpm_route(inst, nodes)
    return Baseline(nodes, rpm_idx, code)
