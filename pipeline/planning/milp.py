"""The fleet planner: mixed-integer programmes solved by HiGHS through `scipy.optimize.milp`.

`solve` — set partitioning: a binary y per column (a vessel lifting a set of contracts in its best feasible order,
routes.vessel_columns), each vessel at most one column, each contract in at most one; minimised: Σ column cost
(fuel + out of service) + Σ penalty of the contracts in no chosen column. Its LP relaxation (over every column:
enumerated, or by column generation, colgen.py) bounds the cost from below; HiGHS then solves the MILP over only
the columns that can be in a plan cheaper than the best one found (gap_columns.py), which proves that plan optimal
or gives a proven gap.

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
from pipeline.planning import branch_price, colgen, gap_columns, local_search
from pipeline.planning.master_lp import MasterLP
from pipeline.planning.routes import vessel_columns
from pipeline.planning.work_budget import MILP_NODE_PER_COLUMN, MILP_ROOT_PER_COLUMN, UNITS_PER_S, WorkBudget

# the reduced-cost enumeration is tried on large fleets only when the plan is within this share of the LP bound (it
# completed at 1.2 % on 20 x 80; at 2 % on 50 x 200 it runs out of time after ~10 s spent on completion bounds)
ENUMERABLE_GAP = 0.015


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


def _set_partitioning(data: PlanData, columns: list, budget: WorkBudget, mip_rel_gap: float, scale: float):
    """HiGHS on the set-partitioning MILP over `columns`: (vessel → sequence or None, HiGHS's dual bound on the
    plan cost over these columns, finished). HiGHS gets a node limit from what `budget` has left (its root costs
    MILP_ROOT_PER_COLUMN per column, each further node MILP_NODE_PER_COLUMN), and what it solved is spent."""
    n, V, m = len(data.contracts), len(data.vessels), len(columns)
    penalty_total = sum(ct.penalty for ct in data.contracts)
    c = np.array([col.cost - sum(data.contracts[j].penalty for j in col.sequence) for col in columns] + [penalty_total])
    rows = [V + j for col in columns for j in col.sequence] + [col.k for col in columns]
    cols_idx = [i for i, col in enumerate(columns) for _ in col.sequence] + list(range(m))
    A = sparse.csr_array((np.ones(len(rows)), (rows, cols_idx)), shape=(V + n, m + 1))
    root, per_node = MILP_ROOT_PER_COLUMN * max(1, m), MILP_NODE_PER_COLUMN * max(1, m)
    res = milp(c * scale, integrality=np.concatenate([np.ones(m), [0]]),
               bounds=Bounds(np.concatenate([np.zeros(m), [1.0]]), np.ones(m + 1)),
               constraints=LinearConstraint(A, -np.inf, 1.0),
               options={**budget.highs_options(root, per_node), "mip_rel_gap": float(mip_rel_gap), "presolve": True})
    budget.spend(root + per_node * max(0, int(getattr(res, "mip_node_count", None) or 1) - 1))
    sequences = None if res.x is None else {columns[i].k: columns[i].sequence for i in np.flatnonzero(res.x[:m] > 0.5)}
    dual = getattr(res, "mip_dual_bound", None)
    bound = float(dual) / scale if dual is not None and np.isfinite(dual) else -np.inf
    return sequences, bound, res.status == 0


def _exact_within_gap(data: PlanData, pool: list, best: FleetPlan, bound: float, budget: WorkBudget,
                      mip_rel_gap: float) -> tuple[FleetPlan, float, bool]:
    """HiGHS on the set-partitioning MILP over `pool`, every column of reduced cost ≤ best.cost − bound
    (gap_columns.py): it holds every plan cheaper than `best`. Returns (the better plan, the proven lower bound,
    solved to optimality). Not started when `budget` has less left than its root is counted to cost."""
    if not pool:  # no column can be in a cheaper plan
        return best, best.cost, True
    if budget.left() < MILP_ROOT_PER_COLUMN * len(pool):  # its root alone would cost more than the work left
        return best, bound, False
    sequences, pool_bound, finished = _set_partitioning(data, pool, budget, mip_rel_gap, 1.0)
    if sequences is not None:
        plan = assemble(data, sequences, solver="milp", status="feasible", gap=np.nan, runtime_s=0.0)
        best = min(best, plan, key=lambda p: p.cost)
    if finished and mip_rel_gap == 0:
        return best, best.cost, True
    return best, max(bound, min(pool_bound, best.cost)), False


def stopped_by(status: str, gap: float, budget: WorkBudget, mip_rel_gap: float = 0.0) -> str:
    """What ended the search, as the plan stores it: "proven optimal", "gap G % within the X % asked",
    "time limit (safety cap): N s, gap G %" or "effort: N units spent, gap G %"."""
    if status == "optimal":
        return "proven optimal"
    gap_text = f"gap {100 * gap:.2f} %" if np.isfinite(gap) else "no lower bound yet"
    if mip_rel_gap > 0 and gap <= mip_rel_gap:
        return f"{gap_text} within the {100 * mip_rel_gap:g} % asked"
    if budget.capped:
        return f"time limit (safety cap): {budget.wall_limit_s:g} s, {gap_text}"
    return f"effort: {budget.spent:,.0f} units spent, {gap_text}"


def solve(data: PlanData, *, effort: float = 1.0, time_limit_s: float | None = None, mip_rel_gap: float = 0.0,
          max_labels: int = 20_000, max_gap_labels: int = 200_000, budget: WorkBudget | None = None) -> FleetPlan:
    """The least-cost plan of `data`, searched within a work budget: `effort` × work_budget.UNITS_PER_EFFORT units
    (effort 1, the default, reaches on the bench's 50 × 200 fleet the plan a 60 s search did on a quiet machine), or
    `budget` when given (a caller may start it before building `data`). The work is counted, not timed
    (work_budget.py), so the same data and effort give the same plan on any machine under any load. `time_limit_s`
    is only a wall-clock safety cap (default none): when it stops the search, the plan says so and may differ from
    run to run.

    First a lower bound, the LP optimum of the set-partitioning master over every feasible sequence, and a plan:
    - small and medium fleets (every vessel's feasible sequences enumerated, routes.vessel_columns, at most
      `max_labels` partial sequences per vessel, within a tenth of the budget): the LP over all of them, and the plan
      of its rounding improved by local search (local_search.py);
    - otherwise: column generation to the LP optimum (branch_price.solve_root, the LP kept warm in
      master_lp.MasterLP; up to 40 % of the budget from the start), and a dive on that LP fixing whole columns with
      pricing at each step (branch_price.dive, up to 30 % of what is left), then dives with dearer penalties
      (branch_price.penalty_dives, up to 30 % of what is left), each improved by local search. (HiGHS's own search
      over the priced columns is not used: on 50 × 200 it found no plan better than the dive's in 20 s, started
      from it or not.)
    Then the exact finish (gap_columns.py): HiGHS solves the set-partitioning MILP over every column whose reduced
    cost is at most the gap between plan and bound — the enumerated ones filtered, or, for large fleets, enumerated
    afresh under that reduced cost (at most `max_gap_labels` partial sequences per vessel, and a tenth of the
    budget, given up once it falls behind four times an even pace over the vessels; half the work left for
    HiGHS, as a node limit). That MILP holds every cheaper plan: solved, the plan is proven optimal; stopped by its
    node limit, its dual bound is a proven bound. For large fleets not proven optimal so far, branch-and-price
    (branch_price.search) takes the rest of the budget: it raises the bound by branching on vessel–contract pairs
    and dives for better plans. The best plan is returned with `gap`, its proven relative gap to the best lower
    bound, `stopped_by` (see `stopped_by`), `work_units` spent and `runtime_s` (wall clock, reported only). Every
    step stops once the budget is spent (one LP solve or pricing of one vessel may finish past it)."""
    t0 = time.perf_counter()  # for the runtime reported, never for a decision
    if budget is None:
        budget = WorkBudget.of_effort(effort, wall_limit_s=time_limit_s)
    total = budget.units

    def plan_of(sequences: dict) -> FleetPlan:
        return assemble(data, sequences, solver="milp", status="feasible", gap=np.nan, runtime_s=0.0)

    def result(best: FleetPlan, bound: float, optimal: bool, n_columns: int) -> FleetPlan:
        gap = 0.0 if optimal else (max(0.0, (best.cost - bound) / abs(best.cost)) if np.isfinite(bound) and best.cost
                                   else np.inf)
        status = "optimal" if optimal or gap <= 1e-9 else "feasible"
        return assemble(data, {s.k: s.sequence for s in best.schedules}, solver="milp", status=status, gap=gap,
                        runtime_s=time.perf_counter() - t0, n_columns=n_columns,
                        stopped_by=stopped_by(status, gap, budget, mip_rel_gap), work_units=budget.spent)

    columns, complete = [], True
    enumeration = budget.phase(0.1 * total)
    for k in range(len(data.vessels)):
        cols, done = vessel_columns(data, k, max_labels=max_labels, budget=enumeration)
        columns += cols
        complete &= done
        if not complete:
            break
    if complete and not columns:
        return assemble(data, {}, solver="milp", status="optimal", gap=0.0, runtime_s=time.perf_counter() - t0,
                        stopped_by="proven optimal", work_units=budget.spent)
    if complete:
        bound, pi, mu, y = colgen.solve_lp(data, columns, budget)
        best = plan_of(local_search.improve(data, colgen.round_lp(data, columns, y),
                                            budget=budget.phase(0.1 * budget.left())))
        rc = colgen.reduced_costs(data, columns, pi, mu)
        pool = [col for col, r in zip(columns, rc) if r <= _slack(best.cost, bound)]
        best, bound, optimal = _exact_within_gap(data, pool, best, bound, budget, mip_rel_gap)
        return result(best, bound, optimal, len(columns))
    master = MasterLP(data)
    bound, converged = branch_price.solve_root(data, master, budget.phase(0.4 * total - budget.spent))
    _, pi, mu, _ = master.solve(budget)
    dived = branch_price.dive(data, master, (), budget.phase(0.3 * budget.left()))
    best = plan_of(local_search.improve(data, dived, budget=budget.phase(min(0.1 * total, 0.5 * budget.left()))))
    for sequences in branch_price.penalty_dives(data, master, budget.phase(0.3 * budget.left())):
        better = plan_of(local_search.improve(data, sequences,
                                              budget=budget.phase(min(UNITS_PER_S, 0.1 * budget.left()))))
        best = min(best, better, key=lambda p: p.cost)
    finish_bound = -np.inf
    if converged and budget.left() > UNITS_PER_S and best.cost - bound <= ENUMERABLE_GAP * best.cost:
        # a short try: when the gap is too wide the enumeration grows past any budget, and the branching gets the work
        # (given up as soon as it falls behind 4 × an even pace over the vessels, counting at least a second's work:
        # on 50 × 200 at a 1.2 % gap its second vessel alone takes ~2 s to pass `max_gap_labels`, and 48 more follow)
        pool, complete = [], True
        enumeration = budget.phase(min(0.5 * budget.left(), 0.1 * total))
        V = len(data.vessels)
        for k in range(V):
            pace = min(enumeration.units, max(UNITS_PER_S, 4.0 * enumeration.units * (k + 1) / V))
            cols, complete = gap_columns.vessel_columns_within(data, k, pi, float(mu[k]), _slack(best.cost, bound),
                                                                max_labels=max_gap_labels,
                                                                budget=enumeration.phase(pace - enumeration.spent))
            if not complete:
                break
            pool += cols
        if complete:
            best, finish_bound, optimal = _exact_within_gap(data, pool, best, bound,
                                                            budget.phase(0.5 * budget.left()), mip_rel_gap)
            if optimal:
                return result(best, finish_bound, True, len(master.columns) + len(pool))
    tree = branch_price.search(data, master, best, budget, root_bound=bound, rel_gap=mip_rel_gap)
    return result(tree.plan, max(tree.bound, finish_bound), tree.closed and mip_rel_gap == 0, len(master.columns))


def _slack(incumbent: float, bound: float) -> float:
    """The reduced cost a column may have and still be in a plan cheaper than `incumbent` (with a margin for the
    LP's tolerances)."""
    return incumbent - bound + 1e-6 * max(1.0, abs(incumbent))
