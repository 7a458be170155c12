"""One entry point for every solver: `solve(problem, weather, solver=…, seed=…)` → `Plan`.

Solvers: `bfoa` (default, improved BFOA), `dp` (exact reference on the same graph, up to the time
bucket), `astar` (A* with the α sweep), `gc` and `rhumb` (baselines: the shortest sea route along
the great circle / rhumb-line graph at the slowest constant rpm that meets the RTA, else the
fastest). Every plan carries the great-circle baseline for its savings %.
"""

from __future__ import annotations

import math
import time

import numpy as np

from pipeline.routing import leg_kernel as lk
from pipeline.routing.astar import ALPHAS, astar_route
from pipeline.routing.bfoa import BfoaParams, bfoa_nb
from pipeline.routing.dp import dp_nb
from pipeline.routing.objectives import route_cost_nb
from pipeline.routing.plan import Plan, legs_of_route
from pipeline.routing.problem import Instance, RoutingInputError, RoutingProblem
from pipeline.routing.search_space import SearchSpace, VoyageGeometryError, reachable
from pipeline.routing.weather_field import WeatherField

SOLVERS = ("bfoa", "dp", "astar", "gc", "rhumb")


def shortest_route(space: SearchSpace) -> np.ndarray | None:
    """Least-distance node path through feasible edges (the base line itself when it is at sea)."""
    from pipeline.routing.geodesy import gc_distance_nm

    L2, P = space.lat.shape
    c = space.centre
    dist = np.full(P, np.inf)
    dist[c] = 0.0
    parent = np.full((L2, P), -1, np.int64)
    for i in range(L2 - 1):
        nxt = np.full(P, np.inf)
        for a in np.flatnonzero(np.isfinite(dist)):
            for b in np.flatnonzero(space.edge_ok[i, a]):
                d = dist[a] + gc_distance_nm(space.lat[i, a], space.lon[i, a], space.lat[i + 1, b], space.lon[i + 1, b])
                if d < nxt[b] - 1e-9 or (abs(d - nxt[b]) <= 1e-9 and abs(a - c) < abs(parent[i + 1, b] - c)):
                    nxt[b] = d
                    parent[i + 1, b] = a
        dist = nxt
    if not np.isfinite(dist[c]):
        return None
    nodes = np.full(L2, c, np.int64)
    for i in range(L2 - 1, 0, -1):
        nodes[i - 1] = parent[i, nodes[i]]
    return nodes


def _evaluate(inst: Instance, nodes, rpm_idx) -> tuple[float, float, float, int]:
    """(cost, hours, fuel, code) of a route."""
    L2 = len(nodes)
    ct, cf = np.empty(L2), np.empty(L2)
    code, _ = lk.sail_route_nb(np.asarray(nodes, np.int64), np.asarray(rpm_idx, np.int64), 0, *inst.numba_args()[:12],
                               ct, cf)
    if code != lk.OK:
        return math.inf, math.nan, math.nan, code
    p = inst.problem
    hours, fuel = ct[-1] - inst.t_dep_h, cf[-1]
    return route_cost_nb(inst.obj, hours, fuel, p.t_req_h, p.window_h, inst.f_target, p.early_t_per_h,
                         p.late_t_per_h), hours, fuel, lk.OK


def constant_rpm_route(inst: Instance, nodes: np.ndarray) -> tuple[np.ndarray, int]:
    """Slowest allowed rpm, held on every leg, that arrives by the RTA; else the fastest. (rpm_idx, code)."""
    n = len(inst.rpm_options)
    last_code = lk.OK
    fastest = None
    for r in range(n):
        rpm_idx = np.full(len(nodes) - 1, r, np.int64)
        _, hours, _, code = _evaluate(inst, nodes, rpm_idx)
        if code != lk.OK:
            last_code = code
            continue
        fastest = rpm_idx
        if hours <= inst.problem.t_req_h + 1e-9:
            return rpm_idx, lk.OK
    return (fastest, lk.OK) if fastest is not None else (np.full(len(nodes) - 1, n - 1, np.int64), last_code)


def _plan(inst: Instance, solver: str, nodes, rpm_idx, *, seed=None, t0=0.0, history=None, n_evals=0,
          reason_if_infeasible: str | None = None) -> Plan:
    p = inst.problem
    plan = Plan(voyage_id=p.voyage_id, imo=p.imo, solver=solver, objective=p.objective, status="infeasible",
                reason=reason_if_infeasible, depart_utc=p.depart_utc, rta_utc=p.rta_utc, seed=seed, history=history,
                n_evals=n_evals, model_version=p.model.version, cycle=inst.weather.cycle)
    if nodes is not None:
        legs, code, bad_leg = legs_of_route(inst, nodes, rpm_idx)
        if code == lk.OK:
            plan.legs = legs
            plan.cost, _, _, _ = _evaluate(inst, nodes, rpm_idx)
            late_h = plan.hours - p.t_req_h
            if late_h > 1e-6:
                plan.status = "late"
                plan.reason = f"RTA cannot be met: arrives {late_h:.1f} h late at the fastest feasible plan"
            else:
                plan.status = "ok"
                early_h = p.t_req_h - p.window_h - plan.hours
                plan.reason = f"arrives {early_h:.1f} h before the arrival window" if early_h > 1e-6 else None
            if plan.n_beyond_forecast:
                note = f"{plan.n_beyond_forecast} legs beyond the forecast horizon (last step persisted)"
                plan.reason = note if plan.reason is None else f"{plan.reason}; {note}"
        else:
            plan.reason = f"leg {bad_leg}: {lk.REASONS[code]}"
    plan.runtime_s = time.perf_counter() - t0
    return plan


def _infeasible_reason(inst: Instance, base_nodes, base_code) -> str:
    if base_nodes is None:
        return "no route at sea between the ports inside the search corridor and limits"
    return f"every route is blocked; the shortest sea route fails: {lk.REASONS.get(base_code, 'unknown')}"


def solve(problem: RoutingProblem, weather: WeatherField, *, solver: str = "bfoa", seed: int = 1,
          params: BfoaParams | None = None, space: SearchSpace | None = None, bucket_h: float = 0.5) -> Plan:
    """Route one voyage. Never raises for a voyage that simply cannot be sailed: the plan says why."""
    if solver not in SOLVERS:
        raise RoutingInputError(f"unknown solver {solver!r}; use one of {', '.join(SOLVERS)}")
    t0 = time.perf_counter()
    if solver == "rhumb" and space is None:
        from dataclasses import replace

        space = replace(problem, base="rhumb").search_space()
    space = space if space is not None else problem.search_space()
    inst = Instance.build(problem, space, weather)
    base_nodes = shortest_route(space)
    base_rpm, base_code = (constant_rpm_route(inst, base_nodes) if base_nodes is not None else (None, lk.NO_EDGE))
    if base_nodes is not None and base_code == lk.OK:
        _, _, f_base, _ = _evaluate(inst, base_nodes, base_rpm)
        inst.f_target = max(float(f_base), 1e-6)
    baseline = _plan(inst, "gc" if space.base == "gc" else "rhumb", base_nodes, base_rpm, t0=t0,
                     reason_if_infeasible=_infeasible_reason(inst, base_nodes, base_code))
    if solver in ("gc", "rhumb"):
        plan = baseline
        plan.solver = solver
    elif not reachable(space):
        plan = _plan(inst, solver, None, None, seed=seed, t0=t0, reason_if_infeasible=_infeasible_reason(inst, None, 0))
    elif solver == "bfoa":
        prm = params or BfoaParams()
        ip, fp = prm.arrays(space.n_lines)
        seed_nodes = base_nodes if base_nodes is not None else space.base_route()
        seed_rpm = base_rpm if base_rpm is not None else np.zeros(len(seed_nodes) - 1, np.int64)
        nodes, rpm_idx, cost, history, n_evals = bfoa_nb(int(seed), ip, fp, seed_nodes, seed_rpm, *inst.numba_args(),
                                                         space.max_shift)
        ok = math.isfinite(cost)
        plan = _plan(inst, "bfoa", nodes if ok else None, rpm_idx, seed=seed, t0=t0, history=history, n_evals=n_evals,
                     reason_if_infeasible=_infeasible_reason(inst, base_nodes, base_code))
    elif solver == "dp":
        nodes, rpm_idx, cost, n_legs = dp_nb(float(bucket_h), *inst.numba_args(), space.max_shift)
        plan = _plan(inst, "dp", nodes if math.isfinite(cost) else None, rpm_idx, t0=t0, n_evals=n_legs,
                     reason_if_infeasible=_infeasible_reason(inst, base_nodes, base_code))
    else:
        plan = _astar(inst, base_nodes, base_code, t0)
    plan.baseline = baseline if solver not in ("gc", "rhumb") else None
    if solver in ("gc", "rhumb") and space.base == "gc":
        plan.baseline = None
    return plan


def _astar(inst: Instance, base_nodes, base_code, t0) -> Plan:
    m, p = inst.problem.model, inst.problem
    rpm = np.asarray(p.rpm_options)
    stw = m.stw_kn(rpm, p.draft_m, p.trim_m)
    fuel = m.fuel_tph(rpm, p.draft_m, p.trim_m)
    fuel_per_nm_lb = float(np.min(0.7 * fuel / (stw + 3.0)))
    speed_ub = float(np.max(stw) * 1.1 + 3.0)
    f_ref = inst.f_target
    best = None
    for alpha in ALPHAS:
        found = astar_route(inst, alpha, np.arange(len(rpm)), fuel_per_nm_lb, speed_ub, f_ref, p.t_req_h)
        if found is None:
            continue
        cost = _evaluate(inst, *found)[0]
        if best is None or cost < best[0]:
            best = (cost, found)
    if best is None:
        return _plan(inst, "astar", None, None, t0=t0, reason_if_infeasible=_infeasible_reason(inst, base_nodes, base_code))
    return _plan(inst, "astar", *best[1], t0=t0)


__all__ = ["solve", "SOLVERS", "RoutingProblem", "RoutingInputError", "VoyageGeometryError", "BfoaParams", "Plan",
           "shortest_route"]
