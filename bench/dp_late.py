"""`--solver dp` on voyages whose RTA cannot be met: a routing-suite instance with its RTA 10 % under the calm-water
passage at full speed along the great circle (#40: such voyages ran the DP for minutes).

For each instance named (default hawaii-la-tight, 2,183 NM) it solves the late voyage with the product's `dp`
(label DP then the grid DP with waits, gap 0.1 %, engine-change limits and the savings split: what `jitroute route
--solver dp` runs) and with the suite's DP (the label DP alone, gap 0.1 %, no limits, over the settings), and prints
CPU time (this thread, one core, after a warm-up solve), status, cost, fuel, hours and legs sailed. Always exits 0.

    .venv/bin/python bench/dp_late.py [--only NAME ...] [--factor 0.9]
"""

from __future__ import annotations

import os

os.environ["NUMBA_NUM_THREADS"] = "1"  # before numba is imported anywhere

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from dataclasses import replace  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import routing_instances as suite  # noqa: E402
from pipeline.routing.options import DpOptions  # noqa: E402
from pipeline.routing.solve import EngineLimits, product_options, solve  # noqa: E402
from routing import pin_one_core  # noqa: E402


def timed(problem, space, weather, product: bool):
    if product:
        kw = dict(options=product_options("dp"), limits=EngineLimits(), savings=True)
    else:
        kw = dict(options=DpOptions(gap=suite.DP_GAP), limits=None, savings=False, continuous=False)
    t0 = time.thread_time()
    plan = solve(problem, weather, solver="dp", space=space, **kw)
    return plan, time.thread_time() - t0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="+", default=["hawaii-la-tight"], choices=sorted(suite.BY_NAME))
    ap.add_argument("--factor", type=float, default=0.9, help="RTA = this × the calm full-speed passage (default 0.9)")
    a = ap.parse_args()
    print(f"{pin_one_core()}, NUMBA_NUM_THREADS=1, CPU time of this thread")
    for name in a.only:
        spec = replace(suite.BY_NAME[name], name=f"{name}-late", rta=("fast", a.factor))
        problem, space, weather = suite.build(spec)
        print(f"{spec.name}: {space.base_distance_nm:,.0f} NM, {space.n_lines} lines × {space.n_points} nodes, RTA "
              f"{problem.t_req_h:.1f} h", flush=True)
        timed(problem, space, weather, product=False)  # compiles (or loads) the kernels
        for product in (True, False):
            plan, s = timed(problem, space, weather, product)
            what = "product dp (label + grid, limits)" if product else "suite dp (label alone)"
            print(f"  {what}: {s:6.2f} s  {plan.status}, cost {plan.cost:.3f}, {plan.fuel_t:.2f} t, {plan.hours:.2f} h, "
                  f"{plan.n_evals:,} legs", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
