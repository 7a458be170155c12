"""`--solver dp` as the product runs it, on every voyage of the benches: CPU against the 60 s target (#39, #40).

The voyages: the routing suite's 10 instances (bench/routing_instances.py, 580–5,000 NM), each again with its RTA 10 %
under the calm full-speed passage (a voyage whose RTA cannot be met, as bench/dp_late.py), and the 10,470 NM
Shanghai–Rotterdam voyage through Suez (bench/corridor_long.py). Each is solved with the product's `dp`
(`product_options("dp")`: the label DP paced by legs sailed, then the grid DP with waits; engine-change limits and
the savings split: what `jitroute route --solver dp` runs); with `--uncapped` also with `max_label_legs=none` (every
label kept, however long it takes), to show what pacing the label DP by work costs in plan. Prints the CPU time (this
thread, one core, after a warm-up solve), status, cost and whether the label search was capped; writes
bench/out/dp_product.json; always exits 0.

    .venv/bin/python bench/dp_product.py [--only NAME ...] [--no-late] [--no-long] [--uncapped]
"""

from __future__ import annotations

import os

os.environ["NUMBA_NUM_THREADS"] = "1"  # before numba is imported anywhere

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from dataclasses import replace  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import routing_instances as suite  # noqa: E402
from pipeline.routing.solve import EngineLimits, product_options, solve  # noqa: E402
from routing import pin_one_core, verdict  # noqa: E402

TARGET_S = 60.0
LONG = "shanghai-rotterdam"


def voyages(names, late: bool, long: bool):
    """(name, problem, space, weather) of each voyage asked for, built when reached."""
    for name in names:
        yield (name, *suite.build(suite.BY_NAME[name]))
        if late:
            spec = replace(suite.BY_NAME[name], name=f"{name}-late", rta=("fast", 0.9))
            yield (spec.name, *suite.build(spec))
    if long:
        from corridor_long import voyage

        problem, space, weather, _ = voyage()
        yield LONG, problem, space, weather


def timed(problem, space, weather, uncapped: bool = False):
    opts = product_options("dp")
    if uncapped:
        opts = replace(opts, max_label_legs=None)
    t0 = time.thread_time()
    plan = solve(problem, weather, solver="dp", space=space, options=opts, limits=EngineLimits(), savings=True)
    return plan, time.thread_time() - t0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="+", default=[s.name for s in suite.INSTANCES], choices=sorted(suite.BY_NAME))
    ap.add_argument("--no-late", action="store_true", help="skip the voyages whose RTA cannot be met")
    ap.add_argument("--no-long", action="store_true", help=f"skip the {LONG} voyage")
    ap.add_argument("--uncapped", action="store_true", help="also solve with every label kept (max_label_legs=none)")
    a = ap.parse_args()
    print(f"{pin_one_core()}, NUMBA_NUM_THREADS=1, CPU time of this thread; product dp: {product_options('dp')}")
    rows, warm = [], False
    for name, problem, space, weather in voyages(a.only, not a.no_late, not a.no_long):
        if not warm:
            timed(problem, space, weather)  # compiles (or loads) the kernels
            warm = True
        plan, s = timed(problem, space, weather)
        capped = "labels per node" in (plan.reason or "")
        row = {"voyage": name, "distance_nm": space.base_distance_nm, "cpu_s": s, "status": plan.status,
               "cost": plan.cost, "fuel_t": plan.fuel_t, "capped": capped}
        line = (f"{name:24s} {space.base_distance_nm:7,.0f} NM  {s:7.2f} s  {plan.status:4s} cost {plan.cost:10.3f}"
                f"{'  label search capped' if capped else ''}")
        if a.uncapped and capped:
            every, s_every = timed(problem, space, weather, uncapped=True)
            row.update(uncapped_cpu_s=s_every, uncapped_cost=every.cost)
            line += f"  | every label: {s_every:7.2f} s, cost {every.cost:10.3f} ({100 * (plan.cost / every.cost - 1):+.3f} %)"
        print(line, flush=True)
        rows.append(row)
    worst = max(r["cpu_s"] for r in rows)
    print(f"slowest: {worst:.2f} s CPU against the {TARGET_S:g} s target → {verdict(worst <= TARGET_S)}")
    out = ROOT / "bench" / "out"
    out.mkdir(parents=True, exist_ok=True)
    (out / "dp_product.json").write_text(json.dumps(rows, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
