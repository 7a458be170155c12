"""A* over (line, node) with the time-constraint weight sweep of the A* paper.

For a weight α the edge cost is α·F/F_ref + (1 − α)·T/T_ref (fuel and hours of the leg, sailed
time-dependently from the label's arrival time); every (line, node) is settled once (first-in,
first-out assumption). The heuristic is the remaining great-circle distance priced at a lower
bound of fuel per mile and an upper bound of speed, so it never overestimates under the stated
bounds (weather lowers the fuel rate by at most 30 % and adds at most 3 kn + 10 %). Sweeping α from
time-only to fuel-only gives a family of routes. A* alone ignores the RTA (a time-heavy α arrives days early
at high rpm), so each route of the sweep then gets the engine plan that meets the RTA on the least fuel: the
DP restricted to that route (`engine_limits.best_engine_plan`, within `engine_gap` of the route's best), which
keeps only plans arriving by the RTA when one can, else the least-late one; a route found again at another α is
not planned again. The route and plan with the best objective value win.

Not exact, and it does not claim to be: settling each node once at its first label is the label DP's dominance
(dp.py) taken further, so in weather that changes in time (a storm whose limits close a leg at one start time
and open it later) a later, dearer label that could have gone on is dropped. A* is a heuristic sweep; the exact
reference under changing weather is the grid DP (dp_grid.py).
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass

import numpy as np

from pipeline.routing import geodesy as geo
from pipeline.routing.contract import Found
from pipeline.routing.engine_limits import best_engine_plan
from pipeline.routing.engine.leg import CODE, FUEL, H, N_LEG_OUT, OK, sail_leg_nb

ALPHAS = (0.0, 0.2, 0.4, 0.6, 0.8, 0.9, 1.0)


def astar_route(inst, alpha: float, rpm_order: np.ndarray, fuel_per_nm_lb: float, speed_ub_kn: float, f_ref: float,
                t_ref_h: float):
    lat, lon, edge_ok = inst.space.lat, inst.space.lon, inst.space.edge_ok
    L2, P = lat.shape
    c = P // 2
    ms = inst.space.max_shift
    alat, alon = lat[-1, c], lon[-1, c]
    rem = np.array([[geo.gc_distance_nm(lat[i, a], lon[i, a], alat, alon) for a in range(P)] for i in range(L2)])
    h = alpha * rem * fuel_per_nm_lb / f_ref + (1 - alpha) * rem / speed_ub_kn / t_ref_h
    out = np.empty(N_LEG_OUT)
    start = (0, c)
    best_g = {start: 0.0}
    label = {start: (inst.t_dep_h, 0.0, None, -1)}  # time, fuel, parent, rpm index
    heap = [(h[0, c], 0.0, 0, c)]
    done = set()
    ves, wx, rpm_options = inst.vessel, inst.wx, inst.rpm_options
    while heap:
        _, g, i, a = heapq.heappop(heap)
        if (i, a) in done:
            continue
        done.add((i, a))
        if i == L2 - 1:
            break
        t0, f0, _, _ = label[(i, a)]
        for a2 in range(max(0, a - ms), min(P, a + ms + 1)):
            if not edge_ok[i, a, a2] or (i + 1, a2) in done:
                continue
            for r in rpm_order:
                sail_leg_nb(lat[i, a], lon[i, a], lat[i + 1, a2], lon[i + 1, a2], t0, rpm_options[r], ves, wx, out)
                if out[CODE] != OK or t0 + out[H] - inst.t_dep_h > inst.max_hours:
                    continue
                g2 = g + alpha * out[FUEL] / f_ref + (1 - alpha) * out[H] / t_ref_h
                key = (i + 1, a2)
                if g2 < best_g.get(key, np.inf):
                    best_g[key] = g2
                    label[key] = (t0 + out[H], f0 + out[FUEL], (i, a), int(r))
                    heapq.heappush(heap, (g2 + h[i + 1, a2], g2, i + 1, a2))
    end = (L2 - 1, c)
    if end not in done:
        return None
    nodes = np.full(L2, c, np.int64)
    rpm_idx = np.zeros(L2 - 1, np.int64)
    key = end
    while label[key][2] is not None:
        i, a = key
        nodes[i] = a
        rpm_idx[i - 1] = label[key][3]
        key = label[key][2]
    return nodes, rpm_idx


@dataclass(frozen=True)
class AstarOptions:
    alphas: tuple[float, ...] = ALPHAS  # fuel weights swept, 0 = time only, 1 = fuel only
    engine_gap: float = 1e-3  # each route's engine plan is within this share of its best (0: exact, far slower)


def search(inst, baseline, *, seed: int, options: AstarOptions):
    """The solver contract (see solvers.py): one A* per α, the plan with the best objective value wins."""
    m, p = inst.problem.model, inst.problem
    rpm = np.asarray(inst.rpm_options)
    stw = m.stw_kn(rpm, p.draft_m, p.trim_m)
    fuel = m.fuel_tph(rpm, p.draft_m, p.trim_m)
    fuel_per_nm_lb = float(np.min(0.7 * fuel / (stw + 3.0)))
    speed_ub = float(np.max(stw) * 1.1 + 3.0)
    best, n_legs, seen = None, 0, set()
    for alpha in options.alphas:
        found = astar_route(inst, alpha, np.arange(len(rpm)), fuel_per_nm_lb, speed_ub, inst.f_target, p.t_req_h)
        if found is None or found[0].tobytes() in seen:
            continue  # neighbouring weights often find the same route: its engine plan is known
        nodes = found[0]
        seen.add(nodes.tobytes())
        rpm_idx, cost, n = best_engine_plan(inst, nodes, gap=options.engine_gap)
        n_legs += n
        if np.isfinite(cost) and (best is None or cost < best[0]):
            best = (cost, (nodes, rpm_idx))
    return Found(None, None, n_legs) if best is None else Found(*best[1], n_legs)

