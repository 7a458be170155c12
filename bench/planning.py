"""Fleet planning: plan time and optimality gap for 10 vessels × 30 contracts and 50 vessels × 200 contracts.

Random instances (`pipeline/synthetic/contracts.py`: ports on a 3,000 NM square, load windows of 1–4 days over
60 days, 2–4 of 4 cargo types per vessel, three deadweight classes). Per size and seed:
- the planner (`pipeline.planning.milp.solve`: the set-partitioning LP bound, by column generation when enumerating
  every sequence is too big, a dive fixing whole columns, HiGHS over the columns within the gap when few enough,
  then branch-and-price for the work left) at `--effort` (work counted, not time: pipeline/planning/work_budget.py),
  wall and CPU time from building the problem to the plan, work units spent, cost, status and proven gap;
- the reference, in the same run: the textbook arc-flow MILP (per-vessel arcs, big-M time windows) on the same
  HiGHS with `--time-limit` seconds (default 60) — its best objective (ballast legs costed at their slowest speed, so at most its
  plan's cost) and its own dual bound — and the gap of the planner's plan to the best lower bound either proves;
- with `--long E`, the planner again at effort E: the best plan known, to tell how much of the gap is the plan
  (incumbent) and how much the bound.

Times: wall (the target) and CPU of this process (`time.process_time`; HiGHS runs single-threaded here), since a
busy machine inflates wall time.

Targets: 10 × 30 exact (proven optimal) in ≤ 10 s; 50 × 200 in ≤ 60 s with a gap ≤ 1 % (at the default effort).

    .venv/bin/python bench/planning.py [--seeds 1] [--effort 1] [--time-limit 60] [--only 10x30] [--long 10]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

SIZES = {"10x30": (10, 30, 10.0, 0.0), "50x200": (50, 200, 60.0, 0.01)}  # vessels, contracts, target s, target gap


def arc_flow(data, time_limit_s: float) -> tuple[float, float, float]:
    """(best objective or inf, dual bound, seconds) of the arc-flow MILP."""
    from scipy.optimize import Bounds, LinearConstraint, milp

    from pipeline.planning.milp import _arc_model

    t0 = time.perf_counter()
    arcs, c, A, lo, hi, lb, ub, integrality = _arc_model(data)
    res = milp(c, integrality=integrality, bounds=Bounds(lb, ub), constraints=LinearConstraint(A, lo, hi),
               options={"time_limit": time_limit_s})
    cost = float(res.fun) if res.x is not None else np.inf
    bound = getattr(res, "mip_dual_bound", None)
    return cost, float(bound) if bound is not None and np.isfinite(bound) else -np.inf, time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=1)
    ap.add_argument("--effort", type=float, default=1.0, help="the planner's effort (default 1, the default)")
    ap.add_argument("--time-limit", type=float, default=60.0, help="the arc-flow reference's time limit, seconds")
    ap.add_argument("--only", choices=sorted(SIZES))
    ap.add_argument("--long", type=float, default=0.0, help="also run the planner at this effort (best known plan)")
    a = ap.parse_args()

    from pipeline.planning import milp, problem
    from pipeline.synthetic.contracts import random_instance

    print(f"{'size':8} {'seed':>4} {'plan s':>7} {'cpu s':>6} {'units':>11} {'status':>9} {'incumbent':>13} {'bound':>13} {'gap %':>6} "
          f"{'assigned':>8}   {'arc-flow s':>10} {'arc objective':>13} {'arc bound':>13} {'gap to best bound %':>20}"
          f"{'   best known  (s)   its gap %' if a.long else ''}  target")
    for name, (n_v, n_c, target_s, target_gap) in SIZES.items():
        if a.only and name != a.only:
            continue
        for seed in range(a.seeds):
            vessels, contracts, dist = random_instance(n_v, n_c, seed=seed + 1)
            t0, c0 = time.perf_counter(), time.process_time()
            data = problem.build(vessels, contracts, dist, fuel_price=600.0)
            plan = milp.solve(data, effort=a.effort)
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
            ref_cost, ref_bound, ref_s = arc_flow(data, a.time_limit)
            own_bound = plan.cost * (1 - plan.gap) if np.isfinite(plan.gap) else -np.inf
            best = max(own_bound, ref_bound)
            gap_best = (plan.cost - best) / plan.cost if np.isfinite(best) else np.inf
            ok = wall <= target_s and (plan.status == "optimal" if target_gap == 0 else gap_best <= target_gap)
            long = ""
            if a.long:
                t1 = time.perf_counter()
                known = min(plan.cost, milp.solve(data, effort=a.long).cost)
                long = f"   {known:13,.0f} ({time.perf_counter() - t1:4.0f}) {100 * (known - best) / known:7.2f}"
            print(f"{name:8} {seed:>4} {wall:7.1f} {cpu:6.1f} {plan.work_units:11,.0f} {plan.status:>9} {plan.cost:13,.0f} {best:13,.0f} "
                  f"{100 * plan.gap:6.2f} {n_c - len(plan.unassigned):>4}/{n_c:<3}   {ref_s:10.1f} {ref_cost:13,.0f} "
                  f"{ref_bound:13,.0f} {100 * gap_best:20.2f}{long}  {'met' if ok else 'MISSED'} (≤ {target_s:g} s, "
                  f"{'exact' if target_gap == 0 else f'gap ≤ {100 * target_gap:g} %'})", flush=True)


if __name__ == "__main__":
    main()
