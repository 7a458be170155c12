"""Local search on a plan: move single contracts between vessels and the spot market while the plan gets cheaper.

Moves, each judged exactly (problem.schedule's earliest schedule and cost of the two sequences it changes):
- relocate: take a contract off its vessel (or off the spot market) and insert it into another vessel's sequence at
  the best position, or leave it to the spot market (its penalty);
- exchange: a contract of one vessel and a contract of another (or a contract left) trade places.
First improvement, repeated until no move saves anything or the work budget is spent (work_budget.py: each
sequence costed spends SCHEDULE, each looked up again MEMO_HIT). Used on large fleets after each LP dive
(branch_price.dive), whose plans it often improves.
"""

from __future__ import annotations

import math

from pipeline.planning.problem import PlanData, schedule
from pipeline.planning.work_budget import MEMO_HIT, SCHEDULE, WorkBudget

TOL = 1e-6


class _Costs:
    """Memoised cost of a vessel's sequence (inf: infeasible)."""

    def __init__(self, data: PlanData, budget: WorkBudget):
        self.data = data
        self.budget = budget
        self.memo: dict[tuple[int, tuple[int, ...]], float] = {}
        self.arcs = [va.arcs for va in data.per_vessel]

    def __call__(self, k: int, seq: tuple[int, ...]) -> float:
        key = (k, seq)
        got = self.memo.get(key)
        if got is not None:
            self.budget.spend(MEMO_HIT)
        else:
            self.budget.spend(SCHEDULE)
            arcs, prev = self.arcs[k], "s"
            for j in seq:  # cheap test first: every arc must exist
                if (prev, j) not in arcs:
                    self.memo[key] = math.inf
                    return math.inf
                prev = j
            s = schedule(self.data, k, seq)
            got = math.inf if s is None else s.cost
            self.memo[key] = got
        return got


def _insertions(arcs: dict, seq: tuple[int, ...], j: int):
    """Sequences with `j` inserted into `seq` where both arcs around it exist."""
    prev = "s"
    for pos in range(len(seq) + 1):
        nxt = seq[pos] if pos < len(seq) else None
        if (prev, j) in arcs and (nxt is None or (j, nxt) in arcs):
            yield seq[:pos] + (j,) + seq[pos:]
        prev = nxt


def improve(data: PlanData, sequences: dict[int, tuple[int, ...]], *, budget: WorkBudget | None = None
            ) -> dict[int, tuple[int, ...]]:
    """A plan no dearer than `sequences` (vessel index → contract indices in order) after local search, within
    `budget` (default: until no move improves it)."""
    budget = WorkBudget() if budget is None else budget
    cost = _Costs(data, budget)
    V, n = len(data.vessels), len(data.contracts)
    seqs = {k: tuple(sequences.get(k, ())) for k in range(V)}
    cur = {k: (cost(k, s) if s else 0.0) for k, s in seqs.items()}
    owner = {j: k for k, s in seqs.items() for j in s}
    pen = [c.penalty for c in data.contracts]
    can = [set(va.contracts) for va in data.per_vessel]
    lifters = [[k for k in range(V) if j in can[k]] for j in range(n)]

    def without(k: int, j: int) -> tuple[int, ...]:
        return tuple(x for x in seqs[k] if x != j)

    def best_insert(k: int, base: tuple[int, ...], j: int) -> tuple[float, tuple[int, ...] | None]:
        best, arg = math.inf, None
        for s in _insertions(data.per_vessel[k].arcs, base, j):
            c = cost(k, s)
            if c < best:
                best, arg = c, s
        return best, arg

    def apply(changes: dict[int, tuple[int, ...]]):
        for k, s in changes.items():
            for j in seqs[k]:
                owner.pop(j, None)
        for k, s in changes.items():
            seqs[k] = s
            cur[k] = cost(k, s) if s else 0.0
            for j in s:
                owner[j] = k

    improved = True
    while improved and not budget.exhausted():
        improved = False
        for j in range(n):  # relocate j
            if budget.exhausted():
                break
            a = owner.get(j)
            if a is None:
                out_delta, rest = -pen[j], None  # taking it off the spot market saves its penalty
            else:
                rest = without(a, j)
                out_delta = (cost(a, rest) if rest else 0.0) - cur[a]
                if out_delta + pen[j] < -TOL:  # cheaper left to the spot market
                    apply({a: rest})
                    improved = True
                    continue
            best, move = 0.0 if a is not None else math.inf, None
            for b in lifters[j]:
                if b == a:
                    continue
                c, s = best_insert(b, seqs[b], j)
                d = out_delta + c - cur[b]
                if d < best - TOL and d < -TOL:
                    best, move = d, (b, s)
            if move is not None:
                apply({move[0]: move[1]} if a is None else {a: rest, move[0]: move[1]})
                improved = True
        if budget.exhausted():
            break
        for i in range(n):  # exchange i (on vessel a) with j (on another vessel, or left)
            a = owner.get(i)
            if a is None:
                continue
            rest_a = without(a, i)
            for j in range(n):
                if budget.exhausted():
                    break
                b = owner.get(j)
                if b == a or j == i or a not in lifters[j]:
                    continue
                if b is not None and b not in lifters[i]:
                    continue
                ca, sa = best_insert(a, rest_a, j)
                if sa is None:
                    continue
                if b is None:
                    d = ca - cur[a] + pen[i] - pen[j]
                    if d < -TOL:
                        apply({a: sa})
                        improved = True
                        break
                    continue
                cb, sb = best_insert(b, without(b, j), i)
                if sb is not None and ca - cur[a] + cb - cur[b] < -TOL:
                    apply({a: sa, b: sb})
                    improved = True
                    break
            if budget.exhausted():
                break
    return {k: s for k, s in seqs.items() if s}
