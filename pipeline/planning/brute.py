"""The brute-force reference planner for small instances: every order of every subset of contracts per vessel,
then every way of sharing the contracts among the vessels. Exponential; for tests and the bench's reference.
Each sequence is scheduled earliest (problem.schedule), the convention every solver shares."""

from __future__ import annotations

import itertools
import math
import time

from pipeline.planning.problem import FleetPlan, PlanData, assemble, schedule


def best_per_subset(data: PlanData, k: int) -> dict[frozenset, tuple[float, tuple[int, ...]]]:
    """Least cost and order of every feasible subset of contracts vessel k can lift (the empty set costs 0)."""
    best: dict[frozenset, tuple[float, tuple[int, ...]]] = {frozenset(): (0.0, ())}
    pool = data.per_vessel[k].contracts
    for size in range(1, len(pool) + 1):
        for seq in itertools.permutations(pool, size):
            s = schedule(data, k, seq)
            if s is None:
                continue
            key = frozenset(seq)
            if key not in best or s.cost < best[key][0] - 1e-9:
                best[key] = (s.cost, seq)
    return best


def solve(data: PlanData) -> FleetPlan:
    t0 = time.perf_counter()
    n = len(data.contracts)
    tables = [best_per_subset(data, k) for k in range(len(data.vessels))]
    best_cost, best_pick = math.inf, None

    def walk(k: int, used: frozenset, cost: float, pick: list):
        nonlocal best_cost, best_pick
        if k == len(tables):
            total = cost + sum(data.contracts[j].penalty for j in range(n) if j not in used)
            if total < best_cost - 1e-9:
                best_cost, best_pick = total, list(pick)
            return
        for subset, (c, seq) in tables[k].items():
            if subset & used:
                continue
            pick.append(seq)
            walk(k + 1, used | subset, cost + c, pick)
            pick.pop()

    walk(0, frozenset(), 0.0, [])
    sequences = {k: seq for k, seq in enumerate(best_pick or [])}
    return assemble(data, sequences, solver="brute", status="optimal", gap=0.0, runtime_s=time.perf_counter() - t0)
