"""Every column that can be in a plan cheaper than the incumbent: reduced-cost enumeration, for an exact finish.

At duals π ≤ 0 (contracts), μ ≤ 0 (vessels) of the set-partitioning LP (colgen.py) with Lagrangian bound LB, a plan
costs LB plus the reduced costs of its columns plus −π of each contract it leaves and −μ of each vessel it does not
use, all ≥ 0 (less, per vessel, its least reduced cost when the LP is not at its optimum, which LB counts). So every
plan cheaper than an incumbent UB is made of columns of reduced cost ≤ UB − LB only, and the set-partitioning MILP
over all of them holds every such plan: solved, its plan is optimal; stopped early, its dual bound is a proven bound
on the whole problem (reduced-cost fixing made complete).

Enumeration per vessel: partial sequences as in routes.vessel_columns (elementary; two with the same contracts ending
at the same one compare by ready time and reduced cost so far), pruned by a completion bound — the least reduced cost
any path (contracts may repeat: a relaxation) can add after contract j when j ends at its earliest. Costs never fall
as time goes on (problem.py), so a later end only adds more. Practical while UB − LB is small (the number of columns
grows fast with it); `max_labels` caps the work and reports the enumeration incomplete.
"""

from __future__ import annotations

import numpy as np

from pipeline.planning.colgen import ballast_fuel_t_nb, pricing_table
from pipeline.planning.problem import PlanData, schedule
from pipeline.planning.routes import Column
from pipeline.planning.work_budget import GAP_ARC, WorkBudget, unlimited


def completion_bound(table: tuple, prize: np.ndarray, mu: float) -> np.ndarray:
    """Per contract j of the vessel (its local index): a lower bound on the reduced cost a sequence adds after j
    ends (the rest of its contracts, the end leg and its days out of service from its start, less μ)."""
    ship, (early, late, dur, credit, laden_cost, end_travel_h, end_cost), arcs = table
    start_h, end_limit_h, speed_kn, fuel_t_per_nm, curve_kn, curve_t_per_nm, fuel_price, dc_h = ship
    ptr, to, travel_h, nm = arcs.ptr, arcs.to, arcs.travel_h, arcs.nm
    ready = early + dur  # the earliest each contract can end
    stop = end_cost + dc_h * (ready + end_travel_h - start_h) - mu
    stop = np.where(ready + end_travel_h > end_limit_h + 1e-9, np.inf, stop)
    src = np.repeat(np.arange(early.size), np.diff(ptr))
    load = np.maximum(ready[src] + travel_h, early[to])
    arc = np.array([fuel_price * ballast_fuel_t_nb(nm[a], ready[src[a]], load[a], speed_kn, fuel_t_per_nm, curve_kn,
                                                   curve_t_per_nm) for a in range(src.size)])
    arc = np.where(load <= late[to] + 1e-9, arc + laden_cost[to] - credit[to] - prize[to], np.inf)
    bound = stop.copy()
    for _ in range(early.size):  # paths of at most i more contracts after i sweeps; every elementary one after m
        nxt = stop.copy()
        np.minimum.at(nxt, src, arc + bound[to])
        if np.array_equal(nxt, bound):
            break
        bound = nxt
    return bound


def vessel_columns_within(data: PlanData, k: int, pi: np.ndarray, mu: float, slack: float,
                          max_labels: int = 500_000, budget: WorkBudget | None = None) -> tuple[list[Column], bool]:
    """(least-cost column per set of contracts vessel k can lift whose reduced cost under (π, μ) is ≤ `slack`,
    enumeration complete). Past `max_labels` partial sequences or once `budget` is exhausted (each arc tried from a
    label, and each of the completion bound's, costs GAP_ARC) it stops: ([], False)."""
    budget = unlimited() if budget is None else budget
    glob, table = pricing_table(data, k)
    if glob.size == 0:
        return [], True
    if budget.exhausted():  # before the completion bound, which alone takes a while on a large fleet
        return [], False
    ship, (early, late, dur, credit, laden_cost, end_travel_h, end_cost), arcs = table
    start_h, end_limit_h, speed_kn, fuel_t_per_nm, curve_kn, curve_t_per_nm, fuel_price, dc_h = ship
    s_to, s_arrive, s_nm, ptr, to, travel_h, nm = arcs
    prize = np.array([data.contracts[j].penalty for j in glob], float) + pi[glob]
    rest = completion_bound(table, prize, mu)
    budget.spend(GAP_ARC * to.size)  # its arcs' fuel, one by one (the sweeps after it are vectorised)
    gain = laden_cost - credit - prize  # what lifting each contract adds, besides its ballast leg

    def ballast(d, ready, load):
        return fuel_price * ballast_fuel_t_nb(d, ready, load, speed_kn, fuel_t_per_nm, curve_kn, curve_t_per_nm)

    # a label: (ready time, reduced cost so far without the end, sequence); keyed by (contracts as bits, last)
    level: dict[tuple[int, int], list[tuple[float, float, tuple[int, ...]]]] = {}
    for q in range(s_to.size):
        j = int(s_to[q])
        load = max(s_arrive[q], early[j])
        if load > late[j] + 1e-9:
            continue
        so_far = ballast(s_nm[q], start_h, load) + gain[j]
        if so_far + rest[j] <= slack:
            level.setdefault((1 << j, j), []).append((load + dur[j], so_far, (j,)))
    best: dict[int, tuple[float, tuple[int, ...]]] = {}
    n_labels = sum(len(x) for x in level.values())
    while level:
        nxt: dict[tuple[int, int], list[tuple[float, float, tuple[int, ...]]]] = {}
        for (members, last), labels in level.items():
            if budget.exhausted():  # a level alone can take seconds on a large fleet
                return [], False
            budget.spend(GAP_ARC * len(labels) * (1 + ptr[last + 1] - ptr[last]))
            for ready, so_far, seq in labels:
                end = ready + end_travel_h[last]
                if end <= end_limit_h + 1e-9:
                    rc = so_far + end_cost[last] + dc_h * (end - start_h) - mu
                    if rc <= slack and (members not in best or rc < best[members][0]):
                        best[members] = (rc, seq)
                for a in range(ptr[last], ptr[last + 1]):
                    j = int(to[a])
                    if members >> j & 1:
                        continue
                    load = max(ready + travel_h[a], early[j])
                    if load > late[j] + 1e-9:
                        continue
                    cost = so_far + ballast(nm[a], ready, load) + gain[j]
                    if cost + rest[j] > slack:
                        continue
                    lab = (load + dur[j], cost, seq + (j,))
                    kept = nxt.setdefault((members | 1 << j, j), [])
                    if any(r <= lab[0] + 1e-9 and c <= lab[1] + 1e-9 for r, c, _ in kept):
                        continue
                    kept[:] = [x for x in kept if not (lab[0] <= x[0] + 1e-9 and lab[1] <= x[1] + 1e-9)]
                    kept.append(lab)
        n_labels += sum(len(x) for x in nxt.values())
        if n_labels > max_labels or budget.exhausted():
            return [], False
        level = nxt
    columns = []
    for _, seq in best.values():
        s = schedule(data, k, tuple(int(glob[i]) for i in seq))
        if s is not None:
            columns.append(Column(k, s.sequence, s.cost))
    return columns, True
