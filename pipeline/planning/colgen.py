"""Column generation for large fleets: more good columns and a proven lower bound when full enumeration is too big.

The LP relaxation of the set-partitioning master (routes.Column variables y ∈ [0, 1]; each contract and each vessel
at most once) is solved by HiGHS (`scipy.optimize.linprog`); its duals price new columns. Pricing, per vessel, is a
shortest path with resources over its feasible arcs: a label at contract j holds (ready time, reduced cost so far);
one label no later and no dearer than another at the same contract makes it useless (every later cost grows with
time; a ballast leg leaving earlier can sail slower, never dearer). Contracts may repeat along a priced path (no elementarity): a relaxation, so the least reduced cost found is
a lower bound on the true one — with load windows shorter than any cycle of voyages, paths cannot repeat anyway.
Paths that do repeat are not added as columns.

Lower bound (Lasdon): z_LP + Σ_k min(0, least reduced cost of vessel k), valid at every iteration because each
vessel lifts at most one column; at the LP optimum (no negative reduced cost left) it is the LP bound.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np
from scipy import sparse
from scipy.optimize import linprog

from pipeline.planning.problem import HOURS_PER_DAY, SLOWEST_BALLAST_SHARE, PlanData, schedule
from pipeline.planning.routes import Column
from pipeline.planning.work_budget import (IPM_ITERATION_PER_NONZERO, PRICE_LABEL, SCHEDULE,
                                            SIMPLEX_ITERATION_PER_ROW, WorkBudget)

EPS = 1e-6


def _master(data: PlanData, columns: list[Column]):
    n, V, m = len(data.contracts), len(data.vessels), len(columns)
    c = np.array([col.cost - sum(data.contracts[j].penalty for j in col.sequence) for col in columns])
    rows = [j for col in columns for j in col.sequence] + [n + col.k for col in columns]
    cols = [i for i, col in enumerate(columns) for _ in col.sequence] + list(range(m))
    A = sparse.csr_array((np.ones(len(rows)), (rows, cols)), shape=(n + V, m))
    return c, A


def solve_lp(data: PlanData, columns: list[Column], budget: WorkBudget | None = None
             ) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """(LP value including the constant Σ penalty, contract duals π ≤ 0, vessel duals μ ≤ 0, column values y). Its
    iterations are spent from `budget` when given (an LP solve is bounded: it is never cut short)."""
    n, V = len(data.contracts), len(data.vessels)
    const = sum(ct.penalty for ct in data.contracts)
    if not columns:
        return const, np.zeros(n), np.zeros(V), np.zeros(0)
    c, A = _master(data, columns)
    res = linprog(c, A_ub=A, b_ub=np.ones(n + V), bounds=(0, None), method="highs-ipm")  # ~10x the simplex here
    if budget is not None:
        budget.spend(IPM_ITERATION_PER_NONZERO * A.nnz * int(res.nit or 0))
    if res.status == 4:  # HiGHS's interior point sometimes ends in a "solve error" (seen at 20 x 80); the simplex does not
        res = linprog(c, A_ub=A, b_ub=np.ones(n + V), bounds=(0, None), method="highs-ds")
        if budget is not None:
            budget.spend(SIMPLEX_ITERATION_PER_ROW * (n + V) * int(res.nit or 0))
    if res.status != 0:
        raise RuntimeError(f"the planning LP failed: {res.message}")
    duals = res.ineqlin.marginals
    return float(res.fun) + const, duals[:n], duals[n:], res.x


class PricedShip(NamedTuple):
    """One vessel as the pricing takes it: its service window, its ballast speed, fuel rate and speed–fuel curve (kn,
    t/NM; empty: the rate at the cube law), the fuel price and its cost of a day out of service per hour."""

    start_h: float
    end_limit_h: float
    speed_kn: float
    fuel_t_per_nm: float
    curve_kn: np.ndarray
    curve_t_per_nm: np.ndarray
    fuel_price: float
    dc_h: float


class PricedContracts(NamedTuple):
    """The vessel's contracts (local indexes): load windows, hours from loading to ready again, the out-of-service
    cost those hours save, the laden leg's fuel cost, and the end leg's hours and cost."""

    early: np.ndarray
    late: np.ndarray
    dur: np.ndarray
    credit: np.ndarray
    laden_cost: np.ndarray
    end_travel_h: np.ndarray
    end_cost: np.ndarray


class PricedArcs(NamedTuple):
    """The ballast arcs: from the vessel's start (contract, arrival hour, NM each) and, in CSR form, from each contract
    (`ptr`; the next contract, hours and NM each)."""

    s_to: np.ndarray
    s_arrive: np.ndarray
    s_nm: np.ndarray
    ptr: np.ndarray
    to: np.ndarray
    travel_h: np.ndarray
    nm: np.ndarray


@numba.njit(cache=True)
def ballast_fuel_t_nb(nm, ready_h, load_h, speed_kn, fuel_t_per_nm, curve_kn, curve_t_per_nm):
    """PlanVessel.ballast_leg's fuel, compiled. Plain values rather than a PricedShip: gap_columns calls it from
    Python once per arc and label, and numba unboxes a NamedTuple about 5 times slower (1.8 against 0.35 µs)."""
    if nm <= 0.0:
        return 0.0
    fastest_h = nm / speed_kn
    depart = max(ready_h, load_h - fastest_h / SLOWEST_BALLAST_SHARE)
    speed = min(speed_kn, nm / max(load_h - depart, fastest_h))
    if curve_kn.size == 0:
        return nm * (fuel_t_per_nm * (speed / speed_kn) ** 2)
    return nm * np.interp(speed, curve_kn, curve_t_per_nm)


@numba.njit(cache=True)
def _price_nb(prize, mu, ship, jobs, arcs):
    """The label setting of `price` on one vessel's arrays (see pricing_table). Labels are made and processed in
    one order (first in, first out), so a label's index is its place in the queue. Returns (least reduced cost,
    labels of negative reduced cost and their reduced costs, every label's parent and contract)."""
    start_h, end_limit_h, speed_kn, fuel_t_per_nm, curve_kn, curve_t_per_nm, fuel_price, dc_h = ship
    early, late, dur, credit, laden_cost, end_travel_h, end_cost = jobs
    s_to, s_arrive, s_nm, ptr, to, travel_h, nm = arcs
    m = early.size
    cap = 1024
    ready_a = np.empty(cap)
    rc_a = np.empty(cap)
    parent_a = np.empty(cap, np.int64)
    node_a = np.empty(cap, np.int64)
    alive = np.empty(cap, np.bool_)
    fcap = 8
    front = np.empty((m, fcap), np.int64)
    fn = np.zeros(m, np.int64)
    n = 0
    head = -1  # -1: the start arcs, then label `head`
    while head < n:
        if head == -1:
            n_out = s_to.size
            ready0 = start_h
            rc0 = 0.0
        else:
            if not alive[head]:
                head += 1
                continue
            i = node_a[head]
            n_out = ptr[i + 1] - ptr[i]
            ready0 = ready_a[head]
            rc0 = rc_a[head]
        for q in range(n_out):
            if head == -1:
                j = s_to[q]
                t = max(s_arrive[q], early[j])
                d = s_nm[q]
            else:
                a = ptr[node_a[head]] + q
                j = to[a]
                t = ready0 + travel_h[a]
                if t < early[j]:
                    t = early[j]
                elif t > late[j] + 1e-9:
                    continue
                d = nm[a]
            if prize[j] < -1e17:  # blocked contract
                continue
            ready = t + dur[j]
            rc = rc0 + fuel_price * ballast_fuel_t_nb(d, ready0, t, speed_kn, fuel_t_per_nm, curve_kn,
                                                      curve_t_per_nm) + laden_cost[j] - credit[j] - prize[j]
            dominated = False
            for f in range(fn[j]):
                lab = front[j, f]
                if ready_a[lab] <= ready + 1e-9 and rc_a[lab] <= rc + 1e-9:
                    dominated = True
                    break
            if dominated:
                continue
            w = 0
            for f in range(fn[j]):
                lab = front[j, f]
                if ready <= ready_a[lab] + 1e-9 and rc <= rc_a[lab] + 1e-9:
                    alive[lab] = False
                else:
                    front[j, w] = lab
                    w += 1
            fn[j] = w
            if w == fcap:
                fcap *= 2
                grown = np.empty((m, fcap), np.int64)
                grown[:, :w] = front[:, :w]
                front = grown
            if n == cap:
                cap *= 2
                ready_a = np.concatenate((ready_a, np.empty(n)))
                rc_a = np.concatenate((rc_a, np.empty(n)))
                parent_a = np.concatenate((parent_a, np.empty(n, np.int64)))
                node_a = np.concatenate((node_a, np.empty(n, np.int64)))
                alive = np.concatenate((alive, np.empty(n, np.bool_)))
            ready_a[n], rc_a[n], parent_a[n], node_a[n], alive[n] = ready, rc, head, j, True
            front[j, w] = n
            fn[j] = w + 1
            n += 1
        head += 1
    best = 0.0
    found = np.empty(n, np.int64)
    found_rc = np.empty(n)
    n_found = 0
    for j in range(m):
        for f in range(fn[j]):
            lab = front[j, f]
            end = ready_a[lab] + end_travel_h[j]
            if end > end_limit_h + 1e-9:
                continue
            total = rc_a[lab] + end_cost[j] + dc_h * (end - start_h) - mu
            best = min(best, total)
            if total < -EPS:
                found[n_found], found_rc[n_found] = lab, total
                n_found += 1
    return best, found[:n_found], found_rc[:n_found], parent_a[:n], node_a[:n]


def pricing_table(data: PlanData, k: int) -> tuple[np.ndarray, tuple[PricedShip, PricedContracts, PricedArcs]]:
    """Vessel k's arcs as arrays for _price_nb (its contracts renumbered 0..m-1 in `va.contracts` order; successors
    of each contract in CSR form), cached on the vessel's arcs. The arc's fuel depends on when the vessel is ready
    (a ballast leg slows down instead of waiting), so pricing costs it per label."""
    va = data.per_vessel[k]
    if va.successors is None:
        v = data.vessels[k]
        loc = {j: i for i, j in enumerate(va.contracts)}
        cs = data.contracts
        early = np.array([cs[j].early_h for j in va.contracts], float)
        late = np.array([cs[j].late_h for j in va.contracts], float)
        dur = np.array([va.dur_h[j] for j in va.contracts], float)
        laden_cost = np.array([data.fuel_price * va.laden_fuel_t[j] for j in va.contracts], float)
        end_travel = np.array([va.travel_h[(j, "e")] for j in va.contracts], float)
        end_cost = np.array([data.fuel_cost(k, va.arcs[(j, "e")]) for j in va.contracts], float)
        out: dict[object, list[tuple[int, float, float]]] = {}
        for (a, b), nm in va.arcs.items():
            if b != "e":
                out.setdefault(a, []).append((loc[b], va.travel_h[(a, b)], nm))
        start = out.get("s", [])
        rest = [out.get(j, []) for j in va.contracts]
        ptr = np.cumsum([0] + [len(r) for r in rest]).astype(np.int64)
        flat = [x for r in rest for x in r]
        curve = np.array(v.ballast_curve, float).reshape(-1, 2)
        va.successors = (
            np.array(va.contracts, np.int64),
            (PricedShip(float(v.start_h), float(v.end_h), float(v.ballast_speed_kn), float(v.ballast_fuel_t_per_nm),
                        np.ascontiguousarray(curve[:, 0]), np.ascontiguousarray(curve[:, 1]), float(data.fuel_price),
                        v.daily_cost / HOURS_PER_DAY),
             PricedContracts(early, late, dur, v.daily_cost / HOURS_PER_DAY * dur, laden_cost, end_travel, end_cost),
             PricedArcs(np.array([x[0] for x in start], np.int64), np.array([x[1] for x in start], float),
                        np.array([x[2] for x in start], float), ptr, np.array([x[0] for x in flat], np.int64),
                        np.array([x[1] for x in flat], float), np.array([x[2] for x in flat], float))))
    return va.successors


def price(data: PlanData, k: int, pi: np.ndarray, mu: float, max_new: int = 10, budget: WorkBudget | None = None
          ) -> tuple[float, list[Column]]:
    """(least reduced cost of a column of vessel k — a lower bound, see the module doc —, up to `max_new` elementary
    columns of negative reduced cost, cheapest first). A contract whose dual is below -1e17 is blocked (no path
    enters it). The labels made and the columns scheduled are spent from `budget` when given."""
    glob, table = pricing_table(data, k)
    if glob.size == 0:
        return 0.0, []
    prize = np.array([data.contracts[j].penalty for j in glob], float) + pi[glob]
    best, found, found_rc, parent, node = _price_nb(prize, float(mu), *table)
    if budget is not None:
        budget.spend(PRICE_LABEL * parent.size)
    out, seen = [], set()
    for lab in found[np.argsort(found_rc, kind="stable")]:
        seq = []
        while lab >= 0:
            seq.append(int(glob[node[lab]]))
            lab = parent[lab]
        seq = tuple(reversed(seq))
        if seq in seen or len(set(seq)) != len(seq):
            continue
        seen.add(seq)
        if budget is not None:
            budget.spend(SCHEDULE)
        s = schedule(data, k, seq)
        if s is not None:
            out.append(Column(k, seq, s.cost))
        if len(out) >= max_new:
            break
    return float(best), out


def reduced_costs(data: PlanData, columns: list[Column], pi: np.ndarray, mu: np.ndarray) -> np.ndarray:
    return np.array([col.cost - sum(data.contracts[j].penalty + pi[j] for j in col.sequence) - mu[col.k]
                     for col in columns])


def round_lp(data: PlanData, columns: list[Column], y: np.ndarray) -> dict[int, tuple[int, ...]]:
    """A plan from the LP solution: columns by decreasing value, each taken when its vessel and contracts are free
    and it saves more penalty than it costs."""
    used_k, used_j, out = set(), set(), {}
    for i in np.argsort(-y, kind="stable"):
        col = columns[i]
        if y[i] <= 1e-6 or col.k in used_k or used_j.intersection(col.sequence):
            continue
        if col.cost - sum(data.contracts[j].penalty for j in col.sequence) >= 0:
            continue
        used_k.add(col.k)
        used_j.update(col.sequence)
        out[col.k] = col.sequence
    return out


def generate(data: PlanData, columns: list[Column], *, budget: WorkBudget | None = None,
             max_rounds: int = 200, max_new: int = 10) -> tuple[list[Column], float, bool, tuple]:
    """(columns with those priced added, the best proven lower bound on the plan cost, LP optimum reached,
    (π, μ, y) of the last LP); stops between rounds once `budget` (work_budget.py; default: none) is exhausted."""
    budget = WorkBudget() if budget is None else budget
    columns = list(columns)
    have = {(col.k, col.sequence) for col in columns}
    bound, converged = -np.inf, False
    for _ in range(max_rounds):
        z, pi, mu, y = solve_lp(data, columns, budget)
        least, added = 0.0, 0
        for k in range(len(data.vessels)):
            rc, new = price(data, k, pi, float(mu[k]), max_new=max_new, budget=budget)
            least += min(0.0, rc)
            for col in new:
                if (col.k, col.sequence) not in have:
                    have.add((col.k, col.sequence))
                    columns.append(col)
                    added += 1
        bound = max(bound, z + least)
        if least > -EPS * max(1.0, abs(z)) or added == 0:
            converged = least > -EPS * max(1.0, abs(z))
            break
        if budget.exhausted():
            break
    if not converged:  # the last LP without the columns priced after it
        z, pi, mu, y = solve_lp(data, columns, budget)
    return columns, bound, converged, (pi, mu, y)
