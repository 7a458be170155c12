"""The fleet planner: mixed-integer programmes solved by HiGHS through `scipy.optimize.milp`.

`solve` — set partitioning (with column generation, colgen.py, when enumeration is too big): a binary y per column (a vessel lifting a set of contracts in its best feasible order,
routes.vessel_columns), each vessel at most one column, each contract in at most one; minimised: Σ column cost
(fuel + out of service) + Σ penalty of the contracts in no chosen column. With every vessel's sequences
enumerated this is the exact problem, and its LP relaxation is tight, so HiGHS proves optimality fast.

`arc_lower_bound` — the arc-flow model, an independent check of the bound (tests):
- x[k, a] ∈ {0, 1} for each feasible arc a of vessel k: start → contract j, contract i → j, contract j → end;
- t[j] ∈ [early_j, late_j]: load start of contract j (shared by the vessels, at most one of which lifts it);
- e[k] ≥ 0: when vessel k's last leg ends (hours after as_of; 0 when unused).
Each contract is entered at most once over all vessels; flow is conserved at each contract per vessel; each
vessel leaves its start at most once. Times follow the arcs through big-M constraints with the tightest M each
arc allows. Minimised: fuel price × fuel + daily cost × (e[k] − start − busy hours)/24 + Σ penalty of contracts
not entered, with each ballast leg to a load port costed at the slowest speed the schedule may sail it (its true
fuel depends on the waiting it replaces). Its relaxation is weak (the big-M rows), hence only a bound.

The plan returned is re-scheduled earliest (problem.schedule) and costed there, so every solver's plan is costed
the same way.
"""

from __future__ import annotations

import time

import numpy as np
from scipy import sparse
from scipy.optimize import Bounds, LinearConstraint, milp

from pipeline.planning.problem import HOURS_PER_DAY, SLOWEST_BALLAST_SHARE, FleetPlan, PlanData, assemble
from pipeline.planning import colgen, local_search
from pipeline.planning.routes import vessel_columns


def _arc_model(data: PlanData):
    """The arc-flow model: (arcs, c, A, row bounds lo/hi, variable bounds lb/ub, integrality)."""
    n, V = len(data.contracts), len(data.vessels)
    arcs: list[tuple[int, object, object]] = [(va.k, a[0], a[1]) for va in data.per_vessel for a in va.arcs]
    nx = len(arcs)
    it, ie = nx, nx + n  # offsets of t[j] and e[k]
    i1 = nx + n + V  # a variable fixed at 1 carrying the constant Σ penalty, so HiGHS's gap is relative to the cost
    nvar = i1 + 1
    c = np.zeros(nvar)
    c[i1] = sum(ct.penalty for ct in data.contracts)
    rows, cols, vals, lo, hi = [], [], [], [], []
    r = 0

    def row(entries, lb, ub):
        nonlocal r
        for col, val in entries:
            rows.append(r)
            cols.append(col)
            vals.append(val)
        lo.append(lb)
        hi.append(ub)
        r += 1

    into: dict[int, list[int]] = {j: [] for j in range(n)}
    flow: dict[tuple[int, int], list[tuple[int, float]]] = {}
    starts: dict[int, list[int]] = {k: [] for k in range(V)}
    # e[k] ≥ every ballast and busy hour of the vessel after its start (waiting ≥ 0): no big-M, so the LP bound
    # counts ballast days out of service (without it the relaxation makes them nearly free)
    span: dict[int, list[tuple[int, float]]] = {k: [(ie + k, 1.0)] for k in range(V)}
    for x, (k, a, b) in enumerate(arcs):
        v, va = data.vessels[k], data.per_vessel[k]
        dc_h = v.daily_cost / HOURS_PER_DAY
        bal_nm = va.arcs[(a, b)]
        span[k].append((x, -(va.travel_h[(a, b)] + (va.dur_h[b] if b != "e" else 0.0))))
        if b == "e":
            c[x] = data.fuel_cost(k, ballast_nm=bal_nm)
            flow.setdefault((k, a), []).append((x, -1.0))
            delta = va.dur_h[a] + va.travel_h[(a, b)]
            big = data.contracts[a].late_h + delta
            row([(ie + k, 1.0), (it + a, -1.0), (x, -big)], delta - big, np.inf)
            if np.isfinite(v.end_h):
                big2 = data.contracts[a].late_h + delta - v.end_h
                if big2 > 0:
                    row([(it + a, 1.0), (x, big2)], -np.inf, v.end_h - delta + big2)
            continue
        j = b
        cj = data.contracts[j]
        slowest_t = bal_nm * v.ballast_at(SLOWEST_BALLAST_SHARE * v.ballast_speed_kn)  # a bound: it may slow down
        c[x] = data.fuel_price * (slowest_t + va.laden_fuel_t[j]) - dc_h * va.dur_h[j] - cj.penalty
        into[j].append(x)
        flow.setdefault((k, j), []).append((x, 1.0))
        if a == "s":
            c[x] -= dc_h * v.start_h
            starts[k].append(x)
            arrive = va.travel_h[(a, b)]
            if arrive > cj.early_h:
                row([(it + j, 1.0), (x, -(arrive - cj.early_h))], cj.early_h, np.inf)
        else:
            flow.setdefault((k, a), []).append((x, -1.0))
            tau = va.dur_h[a] + va.travel_h[(a, b)]
            big = data.contracts[a].late_h + tau - cj.early_h
            if big > 0:
                row([(it + j, 1.0), (it + a, -1.0), (x, -big)], tau - big, np.inf)
    for j, xs in into.items():
        if len(xs) > 1:
            row([(x, 1.0) for x in xs], -np.inf, 1.0)
    for entries in flow.values():
        row(entries, 0.0, 0.0)
    for k, xs in starts.items():
        if len(xs) > 1:
            row([(x, 1.0) for x in xs], -np.inf, 1.0)
        c[ie + k] = data.vessels[k].daily_cost / HOURS_PER_DAY
        row(span[k], 0.0, np.inf)
    A = sparse.csr_array((vals, (rows, cols)), shape=(r, nvar))
    lb = np.concatenate([np.zeros(nx), [ct.early_h for ct in data.contracts], np.zeros(V), [1.0]])
    ub = np.concatenate([np.ones(nx), [ct.late_h for ct in data.contracts], np.full(V, np.inf), [1.0]])
    integrality = np.concatenate([np.ones(nx), np.zeros(n + V + 1)])
    return arcs, c, A, lo, hi, lb, ub, integrality


def arc_lower_bound(data: PlanData, *, time_limit_s: float = 60.0, integer: bool = False) -> float:
    """A proven lower bound on the least plan cost: the arc-flow model's LP relaxation (or with `integer`, the
    dual bound HiGHS reaches on the integer model within the time limit)."""
    arcs, c, A, lo, hi, lb, ub, integrality = _arc_model(data)
    if not arcs:
        return sum(ct.penalty for ct in data.contracts)
    res = milp(c, integrality=integrality if integer else None, bounds=Bounds(lb, ub),
               constraints=LinearConstraint(A, lo, hi), options={"time_limit": float(time_limit_s)})
    if integer:
        bound = getattr(res, "mip_dual_bound", None)
        return float(bound) if bound is not None and np.isfinite(bound) else -np.inf
    return float(res.fun) if res.status == 0 else -np.inf


def solve(data: PlanData, *, time_limit_s: float = 60.0, mip_rel_gap: float = 0.0,
          max_labels: int = 20_000, init_labels: int = 100) -> FleetPlan:
    """The least-cost plan of `data`: set partitioning over every vessel's feasible contract sequences
    (routes.vessel_columns), solved by HiGHS — proven optimal when every vessel's sequences were enumerated (at
    most `max_labels` partial sequences each) and HiGHS finished. Otherwise the columns are the `init_labels`
    most promising per vessel plus those column generation prices (colgen.py, up to 45 % of the time left); a dive
    on the LP (up to 75 % of what is left then), improved by local search (local_search.py), gives a plan, the restricted MILP gets the rest of the time, the
    better of the two is returned, and `gap` is its proven relative gap to colgen's lower bound. The time limit
    covers all of it (HiGHS may overrun it by about a second)."""
    t0 = time.perf_counter()
    columns, complete = [], True
    for k in range(len(data.vessels)):
        cols, done = vessel_columns(data, k, max_labels=max_labels)
        columns += cols
        complete &= done
        if not complete:
            break
    bound, rounded = -np.inf, None
    if not complete:
        columns = [c for k in range(len(data.vessels)) for c in vessel_columns(data, k, max_labels=init_labels)[0]]
        left = float(time_limit_s) - (time.perf_counter() - t0)
        columns, bound, _, (pi, mu, y) = colgen.generate(data, columns, time_limit_s=max(1.0, 0.45 * left))
        left = float(time_limit_s) - (time.perf_counter() - t0)
        dived, columns = colgen.dive(data, columns, time_limit_s=max(1.0, 0.75 * left))
        left = float(time_limit_s) - (time.perf_counter() - t0)
        dived = local_search.improve(data, dived, time_limit_s=max(0.5, 0.2 * left))
        rounded = assemble(data, dived, solver="milp", status="feasible", gap=np.nan, runtime_s=0.0)
        # reduced-cost fixing: a column whose reduced cost exceeds (rounded plan − bound) is in no better plan
        rc = colgen.reduced_costs(data, columns, pi, mu)
        keep = rc <= rounded.cost - bound + 1e-6 * abs(rounded.cost)
        columns = [col for col, kept in zip(columns, keep) if kept]
    if not columns:
        return assemble(data, {}, solver="milp", status="optimal", gap=0.0, runtime_s=time.perf_counter() - t0)
    n, V, m = len(data.contracts), len(data.vessels), len(columns)
    penalty_total = sum(ct.penalty for ct in data.contracts)
    c = np.array([col.cost - sum(data.contracts[j].penalty for j in col.sequence) for col in columns] + [penalty_total])
    rows = [V + j for col in columns for j in col.sequence] + [col.k for col in columns]
    cols_idx = [i for i, col in enumerate(columns) for _ in col.sequence] + list(range(m))
    A = sparse.csr_array((np.ones(len(rows)), (rows, cols_idx)), shape=(V + n, m + 1))
    # costs of ~1e7 make HiGHS warn and its heuristics weaker; scaled only for large fleets, as HiGHS's absolute gap
    # tolerance (1e-6) would then allow a small suboptimality in a plan it calls optimal
    scale = 1.0 if complete else 1.0 / max(1.0, float(np.abs(c).max()))
    res = milp(c * scale, integrality=np.concatenate([np.ones(m), [0]]),
               bounds=Bounds(np.concatenate([np.zeros(m), [1.0]]), np.ones(m + 1)),
               constraints=LinearConstraint(A, -np.inf, 1.0),
               options={"time_limit": max(1.0, float(time_limit_s) - (time.perf_counter() - t0)),
                        "mip_rel_gap": float(mip_rel_gap), "presolve": True})
    if res.x is None and rounded is None:
        return assemble(data, {}, solver="milp", status="no plan", gap=np.inf, runtime_s=time.perf_counter() - t0,
                        n_columns=m, left_reason=f"the planner found no plan within {time_limit_s:g} s ({res.message})")
    sequences = {} if res.x is None else {columns[i].k: columns[i].sequence for i in np.flatnonzero(res.x[:m] > 0.5)}
    if rounded is not None and (res.x is None or rounded.cost < assemble(data, sequences, solver="milp", status="",
                                                                          gap=0.0, runtime_s=0.0).cost):
        sequences = {s.k: s.sequence for s in rounded.schedules}
    if complete:
        dual = getattr(res, "mip_dual_bound", None)
        bound = float(dual) / scale if dual is not None and np.isfinite(dual) else -np.inf
        if res.status == 0 and mip_rel_gap == 0:
            return assemble(data, sequences, solver="milp", status="optimal", gap=0.0,
                            runtime_s=time.perf_counter() - t0, n_columns=m)
    plan = assemble(data, sequences, solver="milp", status="feasible", gap=np.nan, runtime_s=0.0, n_columns=m)
    gap = max(0.0, (plan.cost - bound) / abs(plan.cost)) if np.isfinite(bound) and plan.cost else np.inf
    status = "optimal" if gap <= 1e-9 else "feasible"
    return assemble(data, sequences, solver="milp", status=status, gap=gap, runtime_s=time.perf_counter() - t0, n_columns=m)
