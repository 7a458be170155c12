"""The fastest wait-free plan: the route and engine settings that reach the arrival first.

Why: when the RTA cannot be met, the `jit` objective prices a plan at 1000 t plus `late_t_per_h` (10 t per minute)
per hour late plus its fuel, so the optimum is the least-late plan and fuel only breaks near-ties. A late incumbent
prunes next to nothing on fuel alone; the fastest plan, priced with its lateness, makes the exact DP's bound on
the cost (dp.cost_lb_nb: fuel so far and to finish, plus the lateness of the earliest arrival the label can still
make) drop every label that cannot arrive within minutes of it.

How: legs are first-in-first-out, so among wait-free plans the earliest arrival at a node is reached by extending an
earliest arrival at some node of the line before (the arrival over each leg is non-decreasing in the departure
time); one label per node, the earliest (less fuel on a tie), every setting, the vessel's weather limits kept. A
weather limit that closes a leg at the earliest time and opens it later is the one case it can miss (the DP does not
rely on it: it is only an incumbent).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from pipeline.routing.baseline import evaluate
from pipeline.routing.engine.leg import CODE, FUEL, H, N_LEG_OUT, OK, sail_leg_nb


@numba.njit(cache=True)
def fastest_plan_nb(g, v, w, t_dep_h, max_hours):
    """(nodes, rpm indexes, hours, legs sailed) of the wait-free plan arriving first; hours inf when none arrives
    within `max_hours`."""
    lat, lon, edge_ok, rpm_options, max_shift = g.lat, g.lon, g.edge_ok, v.rpm_options, g.max_shift
    L2, P = lat.shape
    R = rpm_options.shape[0]
    c = P // 2
    ea = np.full((L2, P), np.inf)
    fu = np.full((L2, P), np.inf)
    par = np.full((L2, P), -1, np.int64)
    par_r = np.full((L2, P), -1, np.int64)
    ea[0, c], fu[0, c] = t_dep_h, 0.0
    out = np.empty(N_LEG_OUT)
    n_legs = 0
    for i in range(L2 - 1):
        for a in range(P):
            t0 = ea[i, a]
            if t0 == np.inf:
                continue
            for b in range(max(0, a - max_shift), min(P, a + max_shift + 1)):
                if not edge_ok[i, a, b]:
                    continue
                for r in range(R):
                    sail_leg_nb(lat[i, a], lon[i, a], lat[i + 1, b], lon[i + 1, b], t0, rpm_options[r], v, w, out)
                    n_legs += 1
                    if out[CODE] != OK:
                        continue
                    t1, f1 = t0 + out[H], fu[i, a] + out[FUEL]
                    if t1 - t_dep_h > max_hours:
                        continue
                    if t1 < ea[i + 1, b] or (t1 == ea[i + 1, b] and f1 < fu[i + 1, b]):
                        ea[i + 1, b], fu[i + 1, b], par[i + 1, b], par_r[i + 1, b] = t1, f1, a, r
    nodes = np.full(L2, c, np.int64)
    rpm_idx = np.zeros(L2 - 1, np.int64)
    if ea[L2 - 1, c] == np.inf:
        return nodes, rpm_idx, np.inf, n_legs
    a = c
    for i in range(L2 - 1, 0, -1):
        nodes[i] = a
        rpm_idx[i - 1] = par_r[i, a]
        a = par[i, a]
    return nodes, rpm_idx, ea[L2 - 1, c] - t_dep_h, n_legs


def fastest_plan(inst):
    """(nodes, rpm_idx, hours, legs sailed) of `fastest_plan_nb` on the instance; nodes None when no plan arrives."""
    o = inst.objective
    nodes, rpm_idx, hours, n_legs = fastest_plan_nb(inst.graph, inst.vessel, inst.wx, o.t_dep_h, o.max_hours)
    if not np.isfinite(hours):
        return None, None, float(hours), int(n_legs)
    return nodes, rpm_idx, float(hours), int(n_legs)


def cheapest_known(inst, plans) -> tuple:
    """(nodes, rpm_idx) of the cheapest of `plans` (the DP's incumbents) that can be sailed; (None, None) when none
    can."""
    best, pick = math.inf, (None, None)
    for nodes, rpm_idx in plans:
        cost = evaluate(inst, nodes, rpm_idx)[0]
        if cost < best:
            best, pick = cost, (nodes, rpm_idx)
    return pick


def fastest_incumbent(inst, upper: float, known: list) -> tuple[float, int]:
    """(upper, legs sailed): `upper` lowered to the cost of the fastest wait-free plan (`fastest_plan`) when that is
    cheaper, the plan appended to `known`. Worth its few legs only when no plan known is on time: then either none
    is (and the optimum is within minutes of the fastest, which the lateness in the DP's bound then shows) or the
    fastest is, and it is an on-time incumbent."""
    nodes, rpm_idx, _, n_legs = fastest_plan(inst)
    if nodes is not None:
        cost = evaluate(inst, nodes, rpm_idx)[0]
        if cost < upper:
            upper = cost
            known.append((nodes, rpm_idx))
    return upper, n_legs
