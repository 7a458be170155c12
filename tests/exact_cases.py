"""Small voyages for the exact solvers' tests (tests/test_routing_grid_exact.py, tests/test_routing_dp_late_and_long.py):
one ≈ 560 NM crossing in five kinds of weather, its solver instance, and the exhaustive enumeration of the grid DP's
decision space that those tests hold the DP against (it shares nothing with the DP but the legs' kernel and the
objective)."""

from __future__ import annotations

import functools

import numba
import numpy as np

from pipeline.routing.engine import leg as lk
from pipeline.routing.baseline import baseline as find_baseline, evaluate
from pipeline.routing.objectives import route_cost_nb
from pipeline.routing.savings import solver_instance
from tests.routing_cases import field, moving_storm, problem, wavy

DEP, ARR = (30.0, -160.0), (33.0, -150.0)  # ≈ 560 NM: 70 rpm ≈ 57 h, 100 rpm ≈ 40 h in calm water
LIMITED = ("storm-limit", "storm-window")  # the kinds sailed against an Hs limit (4.5 m; storm-window: wind 45 kn too)


@functools.cache  # made once per process: a field is only read (the solvers and kernels never write it)
def weather(kind: str, seed: int):
    if kind == "static":
        return field(wavy(seed))
    if kind == "storm":  # drifting west across the route while the ship sails east: time matters
        return field(moving_storm(seed, 31.5, 206.0, drift_kn=(-12.0, 2.0), hs_peak=7.0), step_h=3, hours=200)
    if kind == "storm-limit":  # a smaller storm along the north of the corridor, against a 4.5 m limit
        return field(moving_storm(seed, 32.8, 209.0, drift_kn=(-12.0, 0.0), radius_nm=60.0, hs_peak=6.0), step_h=3,
                     hours=200)
    if kind == "storm-window":  # on the departure at first, then moving north-east off the route: closed, then open
        return field(moving_storm(seed, 30.0, 200.5, drift_kn=(4.0, 8.0), radius_nm=90.0, hs_peak=5.0), step_h=1,
                     hours=200)
    if kind == "current":
        return field(lambda LA, LO: dict(uo=1.2 * np.sin(np.radians(40 * (LA - 30))), vo=0.8 * np.cos(np.radians(30 * LO)),
                                         swh=2.0 + np.cos(np.radians(20 * LO)), mwd_deg=np.full(LA.shape, 250.0)))
    raise ValueError(kind)


def instance(kind: str, calm_h: float, rpms, n: int, *, obj: str = "jit", n_lines: int = 3):
    """(solver instance, baseline) of DEP → ARR with an RTA `calm_h` after departure, in `weather(kind, n)`, on
    `n_lines` lines × 5 nodes 25 NM apart; the limits of its kind; `f_target` set from the baseline as solve() sets it."""
    pr = problem(DEP, ARR, calm_h, rpm_options=rpms, objective=obj, n_lines=n_lines, n_points=5, max_shift=2,
                 d_point_nm=25.0, max_hs_m=4.5 if kind in LIMITED else None,
                 max_wind_kn=45.0 if kind == "storm-window" else None)
    inst, base_nodes = solver_instance(pr, pr.search_space(), weather(kind, n))
    base = find_baseline(inst, base_nodes)
    if base.ok:
        inst.f_target = max(float(evaluate(inst, base.nodes, base.rpm_idx)[2]), 1e-6)  # as solve() sets it
    return inst, base


def window_problem(n_lines: int = 2):
    """DEP → ARR in 75 h under the limits of storm-window (Hs 4.5 m, wind 45 kn)."""
    return problem(DEP, ARR, 75.0, n_lines=n_lines, n_points=5, max_shift=2, d_point_nm=25.0, max_hs_m=4.5,
                   max_wind_kn=45.0)


@numba.njit(cache=True)
def enumerate_nb(g, v, w, o, times, max_wait_h, wait_tph):
    """Least cost over every plan of the grid space (inf: none), depth first: leave line i at a time of
    times[i] from the first at or after arriving up to max_wait_h later."""
    L2, P = g.lat.shape
    R = v.rpm_options.shape[0]
    c = P // 2
    K = times.shape[1]
    n_choice = K * P * R
    choice = np.full(L2, -1, np.int64)
    t = np.zeros(L2)
    f = np.zeros(L2)
    node = np.zeros(L2, np.int64)
    t[0], node[0] = o.t_dep_h, c
    out = np.empty(lk.N_LEG_OUT)
    best = np.inf
    i = 0
    while i >= 0:
        choice[i] += 1
        if choice[i] >= n_choice:
            i -= 1
            continue
        q, b, r = choice[i] // (P * R), (choice[i] // R) % P, choice[i] % R
        if (i == L2 - 2 and b != c) or not g.edge_ok[i, node[i], b]:
            continue
        k0 = 0
        while k0 < K and times[i, k0] < t[i] - 1e-9:
            k0 += 1
        if k0 + q >= K:
            continue
        td = times[i, k0 + q]
        if td > times[i, k0] + max_wait_h + 1e-9 or td - o.t_dep_h > o.max_hours:
            continue
        fw = f[i] + wait_tph * (td - t[i])
        lk.sail_leg_nb(g.lat[i, node[i]], g.lon[i, node[i]], g.lat[i + 1, b], g.lon[i + 1, b], td, v.rpm_options[r],
                       v, w, out)
        if out[lk.CODE] != lk.OK or td + out[lk.H] - o.t_dep_h > o.max_hours:
            continue
        if i == L2 - 2:
            best = min(best, route_cost_nb(o, td + out[lk.H] - o.t_dep_h, fw + out[lk.FUEL]))
            continue
        t[i + 1], f[i + 1], node[i + 1] = td + out[lk.H], fw + out[lk.FUEL], b
        i += 1
        choice[i] = -1
    return best
