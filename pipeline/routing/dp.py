"""Exact reference: dynamic programming over (line, node, time bucket) with an engine setting per leg.

Labels at (line i, node a) are kept per arrival-time bucket of `bucket_h` hours (the least fuel
in each bucket, with its exact arrival time); every leg is sailed with the same time-dependent
kernel from the label's exact time. At the arrival the best label under the objective wins. The
answer is optimal on the graph up to the merging of labels inside one bucket. A label is not
expanded when an earlier label at the same node has F_A − e·t_A ≤ F_B − e·t_B (e = the early-
arrival penalty rate of `jit`, 0 for `thesis`): under first-in-first-out sailing it reaches the
arrival no later and no dearer.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from pipeline.routing.leg_kernel import CODE, FUEL, H, N_LEG_OUT, OK, sail_leg_nb
from pipeline.routing.objectives import OBJ_JIT, route_cost_nb


@numba.njit(cache=True)
def dp_bucket_nb(bucket_h, g, v, w, o):
    """(nodes, rpm indexes, cost, legs sailed) of the best plan found with labels merged per time bucket."""
    lat, lon, edge_ok, rpm_options, max_shift = g.lat, g.lon, g.edge_ok, v.rpm_options, g.max_shift
    t_dep_h, max_hours = o.t_dep_h, o.max_hours
    L2, P = lat.shape
    R = rpm_options.shape[0]
    nb = int(max_hours / bucket_h) + 1
    c = P // 2
    fuel = np.full((L2, P, nb), np.inf)
    tarr = np.zeros((L2, P, nb))
    par_a = np.full((L2, P, nb), -1, np.int32)
    par_b = np.full((L2, P, nb), -1, np.int32)
    par_r = np.full((L2, P, nb), -1, np.int32)
    fuel[0, c, 0] = 0.0
    tarr[0, c, 0] = t_dep_h
    out = np.empty(N_LEG_OUT)
    n_legs = 0
    dom_early = o.early_t_per_h if o.kind == OBJ_JIT else 0.0
    for i in range(L2 - 1):
        for a in range(P):
            front = np.inf
            for b in range(nb):
                f0 = fuel[i, a, b]
                if f0 == np.inf:
                    continue
                t0 = tarr[i, a, b]
                # dominated by an earlier label at this node: it can reach nothing cheaper
                if f0 - dom_early * t0 >= front:
                    continue
                front = f0 - dom_early * t0
                for a2 in range(max(0, a - max_shift), min(P, a + max_shift + 1)):
                    if not edge_ok[i, a, a2]:
                        continue
                    for r in range(R):
                        sail_leg_nb(lat[i, a], lon[i, a], lat[i + 1, a2], lon[i + 1, a2], t0, rpm_options[r], v, w,
                                    out)
                        n_legs += 1
                        if out[CODE] != OK:
                            continue
                        t1 = t0 + out[H]
                        b1 = int((t1 - t_dep_h) / bucket_h)
                        if b1 >= nb:
                            continue
                        f1 = f0 + out[FUEL]
                        if f1 < fuel[i + 1, a2, b1]:
                            fuel[i + 1, a2, b1] = f1
                            tarr[i + 1, a2, b1] = t1
                            par_a[i + 1, a2, b1] = a
                            par_b[i + 1, a2, b1] = b
                            par_r[i + 1, a2, b1] = r
    best, best_b = np.inf, -1
    for b in range(nb):
        if fuel[L2 - 1, c, b] < np.inf:
            q = route_cost_nb(o, tarr[L2 - 1, c, b] - t_dep_h, fuel[L2 - 1, c, b])
            if q < best:
                best, best_b = q, b
    nodes = np.full(L2, c, np.int64)
    rpm_idx = np.zeros(L2 - 1, np.int64)
    if best_b < 0:
        return nodes, rpm_idx, np.inf, n_legs
    a, b = c, best_b
    for i in range(L2 - 1, 0, -1):
        nodes[i] = a
        rpm_idx[i - 1] = par_r[i, a, b]
        a, b = par_a[i, a, b], par_b[i, a, b]
    nodes[0] = c
    return nodes, rpm_idx, best, n_legs


@dataclass(frozen=True)
class DpOptions:
    bucket_h: float = 0.5  # arrival-time bucket (h) inside which labels are merged


def search(inst, baseline, *, seed: int, options: DpOptions):
    """The solver contract (see solvers.py); `seed` is not used."""
    from pipeline.routing.solvers import Found

    nodes, rpm_idx, cost, n_legs = dp_bucket_nb(float(options.bucket_h), inst.graph, inst.vessel, inst.wx,
                                                inst.objective)
    if not math.isfinite(cost):
        return Found(None, None, n_legs)
    return Found(nodes, rpm_idx, n_legs)
