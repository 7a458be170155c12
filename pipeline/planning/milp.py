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


def _set_partitioning(data: PlanData, columns: list, time_limit_s: float, mip_rel_gap: float, scale: float):
    """HiGHS on the set-partitioning MILP over `columns`: (vessel → sequence or None, HiGHS's dual bound on the
    plan cost over these columns, finished)."""
    n, V, m = len(data.contracts), len(data.vessels), len(columns)
    penalty_total = sum(ct.penalty for ct in data.contracts)
    c = np.array([col.cost - sum(data.contracts[j].penalty for j in col.sequence) for col in columns] + [penalty_total])
    rows = [V + j for col in columns for j in col.sequence] + [col.k for col in columns]
    cols_idx = [i for i, col in enumerate(columns) for _ in col.sequence] + list(range(m))
    A = sparse.csr_array((np.ones(len(rows)), (rows, cols_idx)), shape=(V + n, m + 1))
    res = milp(c * scale, integrality=np.concatenate([np.ones(m), [0]]),
               bounds=Bounds(np.concatenate([np.zeros(m), [1.0]]), np.ones(m + 1)),
               constraints=LinearConstraint(A, -np.inf, 1.0),
               options={"time_limit": max(1.0, float(time_limit_s)), "mip_rel_gap": float(mip_rel_gap),
                        "presolve": True})
    sequences = None if res.x is None else {columns[i].k: columns[i].sequence for i in np.flatnonzero(res.x[:m] > 0.5)}
    dual = getattr(res, "mip_dual_bound", None)
    bound = float(dual) / scale if dual is not None and np.isfinite(dual) else -np.inf
    return sequences, bound, res.status == 0


def solve(data: PlanData, *, time_limit_s: float = 60.0, mip_rel_gap: float = 0.0,
          max_labels: int = 20_000) -> FleetPlan:
    """The least-cost plan of `data`.

    Small and medium fleets: set partitioning over every vessel's feasible contract sequences
    (routes.vessel_columns, at most `max_labels` partial sequences per vessel), solved by HiGHS — proven optimal
    when it finishes within half the time limit. Otherwise (enumeration too big, or HiGHS unfinished): column
    generation (colgen.generate) reaches the LP optimum of the set-partitioning master over *every* feasible
    sequence, a proven lower bound; a dive on that LP with pricing at each step (colgen.dive, up to 60 % of the
    time left), improved by local search (local_search.py), gives a plan; HiGHS then searches the columns priced
    so far (those whose reduced cost exceeds the gap dropped: they are in no better plan) for the rest of the time.
    The best plan found is returned with `gap`, its proven relative gap to the best lower bound. The time limit
    covers all of it (HiGHS may overrun it by about a second)."""
    t0 = time.perf_counter()

    def left() -> float:
        return float(time_limit_s) - (time.perf_counter() - t0)

    columns, complete = [], True
    for k in range(len(data.vessels)):
        cols, done = vessel_columns(data, k, max_labels=max_labels)
        columns += cols
        complete &= done
        if not complete:
            break
    if complete and not columns:
        return assemble(data, {}, solver="milp", status="optimal", gap=0.0, runtime_s=time.perf_counter() - t0)
    candidates: list[dict[int, tuple[int, ...]]] = []
    bound = -np.inf
    if complete:
        sequences, bound, finished = _set_partitioning(data, columns, 0.5 * left(), mip_rel_gap, 1.0)
        if finished and sequences is not None:
            status = "optimal" if mip_rel_gap == 0 else "feasible"
            plan = assemble(data, sequences, solver="milp", status=status, gap=0.0, runtime_s=0.0,
                            n_columns=len(columns))
            gap = 0.0 if mip_rel_gap == 0 else max(0.0, (plan.cost - bound) / abs(plan.cost)) if plan.cost else 0.0
            return assemble(data, sequences, solver="milp", status=status, gap=gap,
                            runtime_s=time.perf_counter() - t0, n_columns=len(columns))
        if sequences is not None:
            candidates.append(sequences)
    priced, lp_bound, _, (pi, mu, _) = colgen.generate(data, [], time_limit_s=max(1.0, 0.4 * left()))
    bound = max(bound, lp_bound)
    dived, priced = colgen.dive(data, priced, time_limit_s=max(1.0, 0.6 * left()))
    dived = local_search.improve(data, dived, time_limit_s=max(0.5, 0.2 * left()))
    candidates.append(dived)
    best = min((assemble(data, s, solver="milp", status="feasible", gap=np.nan, runtime_s=0.0) for s in candidates),
               key=lambda p: p.cost)
    # reduced-cost fixing: a column whose reduced cost exceeds (best plan − LP bound) is in no better plan (at the LP
    # optimum; otherwise this only narrows the search)
    rc = colgen.reduced_costs(data, priced, pi, mu)
    pool = [col for col, r in zip(priced, rc) if r <= best.cost - lp_bound + 1e-6 * abs(best.cost)]
    if pool and left() > 1.0:
        # costs of ~1e7 make HiGHS warn and its heuristics weaker: scaled (its absolute gap tolerance of 1e-6 then
        # allows a small suboptimality, which the proven gap below accounts for)
        scale = 1.0 / max(1.0, max(abs(col.cost) for col in pool), max(ct.penalty for ct in data.contracts))
        sequences, _, _ = _set_partitioning(data, pool, left(), mip_rel_gap, scale)
        if sequences is not None:
            plan = assemble(data, sequences, solver="milp", status="feasible", gap=np.nan, runtime_s=0.0)
            best = min(best, plan, key=lambda p: p.cost)
    sequences = {s.k: s.sequence for s in best.schedules}
    gap = max(0.0, (best.cost - bound) / abs(best.cost)) if np.isfinite(bound) and best.cost else np.inf
    status = "optimal" if gap <= 1e-9 else "feasible"
    return assemble(data, sequences, solver="milp", status=status, gap=gap, runtime_s=time.perf_counter() - t0,
                    n_columns=len(columns) + len(priced))
