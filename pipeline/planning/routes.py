"""Every feasible sequence of contracts per vessel, best order per set: the columns of the set-partitioning planner.

Sequences grow one contract at a time, each scheduled earliest (problem.py's conventions). Two partial sequences
of the same vessel holding the same contracts and ending at the same one compare by (ready time, fuel cost so
far): one no later and no dearer makes the other useless (every later cost item grows with time; a ballast leg
leaving earlier can sail slower, never dearer), so it is dropped. What is left gives, for each set of contracts a vessel can lift, its least cost and the order achieving
it — exactly what the brute force gets by trying every order. `max_labels` caps the work per vessel; when it
binds, the most promising partial sequences (least cost so far less the penalties they save) are kept,
the enumeration is `complete=False` and the plan is optimal only over the sequences found. A work budget
(work_budget.py, a label made costs PYTHON_LABEL) stops it too (between sequence lengths), also `complete=False`.
"""

from __future__ import annotations

from dataclasses import dataclass

from pipeline.planning.problem import HOURS_PER_DAY, PlanData
from pipeline.planning.work_budget import PYTHON_LABEL, WorkBudget


@dataclass(frozen=True)
class Column:
    k: int
    sequence: tuple[int, ...]
    cost: float  # fuel + out-of-service cost of the vessel lifting `sequence` (problem.schedule's cost)


def vessel_columns(data: PlanData, k: int, max_labels: int = 200_000,
                   among: frozenset[int] | set[int] | None = None, budget: WorkBudget | None = None
                   ) -> tuple[list[Column], bool]:
    """(least-cost column per set of contracts vessel k can lift in a feasible order — of the contracts `among`
    only, when given —, enumeration complete)."""
    v, va = data.vessels[k], data.per_vessel[k]
    dc_h = v.daily_cost / HOURS_PER_DAY
    succ: dict[object, list[int]] = {}
    for (a, b) in va.arcs:
        if b != "e" and (among is None or (b in among and (a == "s" or a in among))):
            succ.setdefault(a, []).append(b)
    best: dict[frozenset, Column] = {}
    # label: (set, last) → [(ready_h, fuel cost so far, busy_h, sequence)]
    level: dict[tuple[frozenset, int], list[tuple[float, float, float, tuple[int, ...]]]] = {}
    for j in succ.get("s", []):
        c = data.contracts[j]
        t = max(va.travel_h[("s", j)], c.early_h)
        fuel = data.leg_cost(k, ("s", j), v.start_h, t)
        level[(frozenset((j,)), j)] = [(t + va.dur_h[j], fuel, va.dur_h[j], (j,))]
    complete, n_labels = True, len(level)
    if budget is not None:
        budget.spend(PYTHON_LABEL * n_labels)
    while level:
        if budget is not None and budget.exhausted():
            complete = False
            break
        for (members, last), labels in level.items():
            for ready, fuel, busy, seq in labels:
                end = ready + va.travel_h[(last, "e")]
                if end > v.end_h + 1e-9:
                    continue
                cost = fuel + data.fuel_cost(k, va.arcs[(last, "e")]) + dc_h * (end - v.start_h - busy)
                if members not in best or cost < best[members].cost - 1e-9:
                    best[members] = Column(k, seq, cost)
        nxt: dict[tuple[frozenset, int], list] = {}
        for (members, last), labels in level.items():
            for j in succ.get(last, []):
                if j in members:
                    continue
                c = data.contracts[j]
                key = (members | {j}, j)
                for ready, fuel, busy, seq in labels:
                    t = max(ready + va.travel_h[(last, j)], c.early_h)
                    if t > c.late_h + 1e-9:
                        continue
                    lab = (t + va.dur_h[j], fuel + data.leg_cost(k, (last, j), ready, t),
                           busy + va.dur_h[j], seq + (j,))
                    kept = nxt.setdefault(key, [])
                    if any(r <= lab[0] + 1e-9 and f <= lab[1] + 1e-9 for r, f, _, _ in kept):
                        continue
                    kept[:] = [x for x in kept if not (lab[0] <= x[0] + 1e-9 and lab[1] <= x[1] + 1e-9)]
                    kept.append(lab)
        size = sum(len(x) for x in nxt.values())
        if n_labels + size > max_labels:  # keep the most promising: least cost so far less the penalties saved
            complete = False
            room = max(0, max_labels - n_labels)
            if room == 0:
                break
            flat = [(fuel + dc_h * (ready - v.start_h - busy) - sum(data.contracts[j].penalty for j in key[0]), key, lab)
                    for key, labs in nxt.items() for lab in labs for ready, fuel, busy, _ in [lab]]
            flat.sort(key=lambda x: x[0])
            nxt = {}
            for _, key, lab in flat[:room]:
                nxt.setdefault(key, []).append(lab)
            size = room
        n_labels += size
        if budget is not None:
            budget.spend(PYTHON_LABEL * size)
        level = nxt
    return list(best.values()), complete
