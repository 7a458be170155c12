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

import time
from collections import deque

import numpy as np
from scipy import sparse
from scipy.optimize import linprog

from pipeline.planning.problem import HOURS_PER_DAY, PlanData, schedule
from pipeline.planning.routes import Column

EPS = 1e-6
DIVE_FIX = 0.8  # a dive fixes every column the LP takes at least this much (lower: faster, worse plans)


def _master(data: PlanData, columns: list[Column]):
    n, V, m = len(data.contracts), len(data.vessels), len(columns)
    c = np.array([col.cost - sum(data.contracts[j].penalty for j in col.sequence) for col in columns])
    rows = [j for col in columns for j in col.sequence] + [n + col.k for col in columns]
    cols = [i for i, col in enumerate(columns) for _ in col.sequence] + list(range(m))
    A = sparse.csr_array((np.ones(len(rows)), (rows, cols)), shape=(n + V, m))
    return c, A


def solve_lp(data: PlanData, columns: list[Column]) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """(LP value including the constant Σ penalty, contract duals π ≤ 0, vessel duals μ ≤ 0, column values y)."""
    n, V = len(data.contracts), len(data.vessels)
    const = sum(ct.penalty for ct in data.contracts)
    if not columns:
        return const, np.zeros(n), np.zeros(V), np.zeros(0)
    c, A = _master(data, columns)
    res = linprog(c, A_ub=A, b_ub=np.ones(n + V), bounds=(0, None), method="highs-ipm")  # ~10x the simplex here
    if res.status == 4:  # HiGHS's interior point sometimes ends in a "solve error" (seen at 20 x 80); the simplex does not
        res = linprog(c, A_ub=A, b_ub=np.ones(n + V), bounds=(0, None), method="highs-ds")
    if res.status != 0:
        raise RuntimeError(f"the planning LP failed: {res.message}")
    duals = res.ineqlin.marginals
    return float(res.fun) + const, duals[:n], duals[n:], res.x


def _successors(data: PlanData, k: int) -> dict[object, list[tuple]]:
    """Per origin ('s' or a contract) of vessel k: (j, ballast hours, j's arc, early_j, late_j, dur_j, the
    out-of-service credit of j's busy hours); cached on the vessel's arcs. The arc's fuel depends on when the vessel
    is ready (a ballast leg slows down instead of waiting), so pricing costs it per label (PlanData.leg_cost)."""
    va = data.per_vessel[k]
    if va.successors is None:
        dc_h = data.vessels[k].daily_cost / HOURS_PER_DAY
        succ: dict[object, list[tuple]] = {}
        for (a, b), nm in va.arcs.items():
            if b != "e":
                c = data.contracts[b]
                succ.setdefault(a, []).append((b, va.travel_h[(a, b)], (a, b), c.early_h, c.late_h, va.dur_h[b],
                                               dc_h * va.dur_h[b]))
        va.successors = succ
    return va.successors


def _sequence(label) -> tuple[int, ...]:
    seq = []
    while label is not None:
        seq.append(label[3])
        label = label[2]
    return tuple(reversed(seq))


def price(data: PlanData, k: int, pi: np.ndarray, mu: float, max_new: int = 10) -> tuple[float, list[Column]]:
    """(least reduced cost of a column of vessel k — a lower bound, see the module doc —, up to `max_new` elementary
    columns of negative reduced cost, cheapest first)."""
    v, va = data.vessels[k], data.per_vessel[k]
    dc_h = v.daily_cost / HOURS_PER_DAY
    prize = {j: data.contracts[j].penalty + pi[j] for j in va.contracts}
    succ = _successors(data, k)
    front: dict[int, list[list]] = {j: [] for j in va.contracts}  # label: [ready, rc, parent label, j, alive]
    queue: deque = deque()

    def offer(j, ready, rc, parent):
        labs = front[j]
        for lab in labs:
            if lab[0] <= ready + 1e-9 and lab[1] <= rc + 1e-9:
                return
        keep = []
        for lab in labs:
            if ready <= lab[0] + 1e-9 and rc <= lab[1] + 1e-9:
                lab[4] = False
            else:
                keep.append(lab)
        new = [ready, rc, parent, j, True]
        keep.append(new)
        front[j] = keep
        queue.append(new)

    leg_cost = data.leg_cost
    for j, travel, arc, early, late, dur, credit in succ.get("s", []):
        t = max(travel, early)  # start arcs: travel is the arrival time
        offer(j, t + dur, leg_cost(k, arc, v.start_h, t) - credit - prize[j], None)
    while queue:
        lab = queue.popleft()
        if not lab[4]:
            continue
        ready, rc, i = lab[0], lab[1], lab[3]
        for j, travel, arc, early, late, dur, credit in succ.get(i, ()):
            t = ready + travel
            if t < early:
                t = early
            elif t > late + 1e-9:
                continue
            offer(j, t + dur, rc + leg_cost(k, arc, ready, t) - credit - prize[j], lab)
    best, found = 0.0, []
    for j, labs in front.items():
        for lab in labs:
            end = lab[0] + va.travel_h[(j, "e")]
            if end > v.end_h + 1e-9:
                continue
            total = lab[1] + data.fuel_cost(k, va.arcs[(j, "e")]) + dc_h * (end - v.start_h) - mu
            best = min(best, total)
            if total < -EPS:
                found.append((total, lab))
    found.sort(key=lambda x: x[0])
    out, seen = [], set()
    for _, lab in found:
        seq = _sequence(lab)
        if seq in seen or len(set(seq)) != len(seq):
            continue
        seen.add(seq)
        s = schedule(data, k, seq)
        if s is not None:
            out.append(Column(k, seq, s.cost))
        if len(out) >= max_new:
            break
    return best, out


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


def generate(data: PlanData, columns: list[Column], *, time_limit_s: float = 30.0,
             max_rounds: int = 200) -> tuple[list[Column], float, bool, tuple]:
    """(columns with those priced added, the best proven lower bound on the plan cost, LP optimum reached,
    (π, μ, y) of the last LP)."""
    t0 = time.perf_counter()
    columns = list(columns)
    have = {(col.k, col.sequence) for col in columns}
    bound, converged = -np.inf, False
    for _ in range(max_rounds):
        z, pi, mu, y = solve_lp(data, columns)
        least, added = 0.0, 0
        for k in range(len(data.vessels)):
            rc, new = price(data, k, pi, float(mu[k]))
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
        if time.perf_counter() - t0 > time_limit_s:
            break
    if not converged:  # the last LP without the columns priced after it
        z, pi, mu, y = solve_lp(data, columns)
    return columns, bound, converged, (pi, mu, y)


def dive(data: PlanData, columns: list[Column], *, time_limit_s: float = 20.0,
         reprice: bool = True) -> tuple[dict[int, tuple[int, ...]], list[Column]]:
    """A plan by diving on the LP: fix the columns the LP (nearly) takes — those at ≥ DIVE_FIX, else the largest —,
    drop the vessels and contracts they use, re-solve the LP over what is left (pricing new columns for it when
    `reprice`), until the LP takes nothing more. Returns (vessel → sequence, columns with those priced added)."""
    t0 = time.perf_counter()
    columns = list(columns)
    have = {(c.k, c.sequence) for c in columns}
    fixed: dict[int, tuple[int, ...]] = {}
    taken: set[int] = set()
    while True:
        free = [c for c in columns if c.k not in fixed and not taken.intersection(c.sequence)]
        if not free:
            break
        _, pi, mu, y = solve_lp(data, free)
        if reprice and time.perf_counter() - t0 < time_limit_s:
            blocked = pi.copy()
            blocked[list(taken)] = -1e18  # contracts already lifted: no prize
            added = 0
            for k in range(len(data.vessels)):
                if k in fixed:
                    continue
                _, new = price(data, k, blocked, float(mu[k]), max_new=5)
                for col in new:
                    if (col.k, col.sequence) not in have and not taken.intersection(col.sequence):
                        have.add((col.k, col.sequence))
                        columns.append(col)
                        free.append(col)
                        added += 1
            if added:
                _, pi, mu, y = solve_lp(data, free)
        order = np.argsort(-y, kind="stable")
        pick = [i for i in order if y[i] >= DIVE_FIX] or ([order[0]] if len(order) and y[order[0]] > 1e-6 else [])
        progress = False
        for i in pick:
            col = free[i]
            if col.k in fixed or taken.intersection(col.sequence):
                continue
            if col.cost - sum(data.contracts[j].penalty for j in col.sequence) >= 0:
                continue
            fixed[col.k] = col.sequence
            taken.update(col.sequence)
            progress = True
        if not progress:
            break
    return fixed, columns
