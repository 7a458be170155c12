"""The grid DP (pipeline/routing/dp_grid.py, exact under weather that changes in time) on the routing suite.

Per instance and grid step: the grid DP's CPU time (the thread's, one core, after compilation), the legs it
sailed, the hours its plan waits, and its cost against the wait-free label DP's stored reference
(bench/optima.json, certified within 0.1 % under the label DP's dominance rule). A line's departure times are the
grid and the times the known wait-free plans leave it (the baseline and the incumbent: BFOA's, seed 1, or with
`--incumbent reference` the stored reference plan); a ship arriving between two waits for the next one (at the
heave-to rate), so other plans pay rounding waits; a cost below the reference means waiting won fuel.
`--wait-free-first` times what `jitroute route --solver dp` runs by default: the label DP first (pruned by the
incumbent's cost), its plan's times joining the grid. Always exits 0.

    .venv/bin/python bench/dp_grid.py [--only NAME ...] [--slot-h 1.0 ...] [--max-wait-h 0] [--gap 0.001]
                                      [--wait-free-first] [--incumbent bfoa|reference]
"""

from __future__ import annotations

import os

os.environ["NUMBA_NUM_THREADS"] = "1"  # before numba is imported anywhere

import argparse  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

import routing_instances as suite  # noqa: E402
from pipeline.routing.baseline import baseline as find_baseline, evaluate  # noqa: E402
from pipeline.routing.dp import search  # noqa: E402
from pipeline.routing.options import DpOptions  # noqa: E402
from pipeline.routing.dp_grid import wait_rate_tph, waited_plan_cost  # noqa: E402
from pipeline.routing.savings import solver_instance  # noqa: E402
from pipeline.routing.solvers import SOLVERS  # noqa: E402
from routing import pin_one_core, warm_up  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="+", choices=sorted(suite.BY_NAME), help="these instances only")
    ap.add_argument("--slot-h", nargs="+", type=float, default=[1.0], help="grid steps (h), default 1")
    ap.add_argument("--max-wait-h", type=float, default=0.0, help="waiting allowed beyond the next grid time (h)")
    ap.add_argument("--gap", type=float, default=1e-3, help="certified gap (default 0.001; 0: exact)")
    ap.add_argument("--wait-free-first", action="store_true",
                    help="what `--solver dp` runs by default: the label DP first (its CPU included), its plan's "
                         "times join the grid")
    ap.add_argument("--incumbent", choices=("bfoa", "reference"), default="bfoa",
                    help="the wait-free plan whose times join the grid: BFOA's (seed 1; default) or the stored "
                         "reference's (the label DP's plan, bench/optima.json)")
    a = ap.parse_args()
    print(f"grid DP; {pin_one_core()}, NUMBA_NUM_THREADS=1, gap {a.gap:g}, max wait {a.max_wait_h:g} h")
    optima = suite.read_optima()
    warmed = False
    for spec in [suite.BY_NAME[n] for n in a.only] if a.only else suite.INSTANCES:
        problem, space, weather = suite.build(spec)
        if not warmed:
            warm_up(problem, weather)
            warmed = True
        inst, base_nodes = solver_instance(problem, space, weather)
        base = find_baseline(inst, base_nodes)
        if base.ok:
            inst.f_target = max(float(evaluate(inst, base.nodes, base.rpm_idx)[2]), 1e-6)  # as solve() sets it
        stored = optima.get(spec.name, {})
        ref = stored.get("cost", float("nan"))
        if a.incumbent == "reference" and "nodes" in stored:
            incumbent = (np.asarray(stored["nodes"], np.int64), np.asarray(stored["rpm_idx"], np.int64))
        else:
            bfoa = SOLVERS["bfoa"]
            found = bfoa.search(inst, base, seed=1, options=bfoa.options())
            incumbent = (found.nodes, found.rpm_idx)
        for slot_h in a.slot_h:
            opts = DpOptions(slot_h=slot_h, max_wait_h=a.max_wait_h, gap=a.gap, wait_free_first=a.wait_free_first)
            t0 = time.thread_time()
            # pruned by the incumbent's cost, as the registry's dp prunes with its incumbent solver's plan
            got = search(inst, base, seed=1, options=opts, incumbent=incumbent,
                         upper=evaluate(inst, *incumbent)[0] if incumbent[0] is not None else math.inf)
            cpu_s = time.thread_time() - t0
            if got.nodes is None:
                print(f"{spec.name:16s} slot {slot_h:g} h: no plan; CPU {cpu_s:.1f} s, {got.n_evals:,} legs")
                continue
            cost = waited_plan_cost(inst, got.nodes, got.rpm_idx, got.wait_h, wait_rate_tph(inst, None))
            print(f"{spec.name:16s} slot {slot_h:g} h: cost {cost:.3f} ({100 * (cost / ref - 1):+.2f} % against the "
                  f"wait-free reference {ref:.3f}), waits {got.wait_h.sum():.1f} h; CPU {cpu_s:.1f} s, "
                  f"{got.n_evals:,} legs")
    return 0


if __name__ == "__main__":
    sys.exit(main())
