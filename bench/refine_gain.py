"""What searching the route again on a finer graph gains (pipeline/routing/refine_graph.py), on the routing suite.

Per instance (bench/routing_instances.py), over the settings (continuous=False), no engine-change limits:
  graph optimum   the stored DP optimum of the suite's graph (bench/optima.json, certified within 0.1 %);
  refined optimum that optimum's route refined (`refine_route`, split 3): what the finer corridors gain on the best
                  route the graph has, and its CPU;
  bfoa            the default search (seeds 1..N) without and with the refinement (`solve(refine_split=1 / 3)`):
                  each one's gap to the graph optimum (negative: cheaper than any plan of the graph), CPU per solve;
  fine optimum    with --fine-dp, on instances of at most --fine-dp-max-nm: the DP (certified within 0.1 %) on the
                  whole graph 3 × finer across the lines (the same lines; 3·(P−1)+1 nodes a line; a leg's shift up to
                  3 × the graph's), the reference a refinement in corridors is measured against: the refined BFOA's
                  gap to it.
One core, kernels compiled first, CPU time (the thread's). Writes bench/out/refine_gain.json; always exits 0.

    .venv/bin/python bench/refine_gain.py [--seeds 3] [--only NAME ...] [--fine-dp] [--fine-dp-max-nm 2300]
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
sys.path.insert(0, str(ROOT / "bench"))

import numpy as np  # noqa: E402

import routing_instances as suite  # noqa: E402
from pipeline.routing.baseline import baseline as find_baseline, evaluate  # noqa: E402
from pipeline.routing.options import DpOptions  # noqa: E402
from pipeline.routing.refine_graph import refine_route  # noqa: E402
from pipeline.routing.savings import solver_instance  # noqa: E402
from routing import pin_one_core, timed_solve, warm_up  # noqa: E402

SPLIT = 3


def pct(cost: float, ref: float) -> float:
    return 100.0 * (cost - ref) / ref


def fine_optimum(problem, space, weather) -> tuple[float, float]:
    """(cost, CPU s) of the DP on the whole graph SPLIT × finer across the same lines."""
    P = space.lat.shape[1]
    fine = replace(problem, n_points=SPLIT * (P - 1) + 1, d_point_nm=space.d_point_nm / SPLIT,
                   max_shift=SPLIT * space.max_shift, n_lines=space.n_lines)
    fine_space = fine.search_space()
    plan = timed_solve(fine, weather, solver="dp", space=fine_space, options=DpOptions(gap=1e-3), continuous=False)
    return plan.cost, plan.runtime_s


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--only", nargs="+", choices=sorted(suite.BY_NAME))
    ap.add_argument("--fine-dp", action="store_true", help="also the DP on the whole finer graph (slow)")
    ap.add_argument("--fine-dp-max-nm", type=float, default=2300.0)
    ap.add_argument("--out", default=str(ROOT / "bench" / "out" / "refine_gain.json"))
    a = ap.parse_args()
    print(f"refine gain: split {SPLIT}, {a.seeds} BFOA seeds; {pin_one_core()}, NUMBA_NUM_THREADS=1", flush=True)
    optima = suite.read_optima()
    rows = []
    warmed = False
    for spec in [suite.BY_NAME[n] for n in (a.only or sorted(suite.BY_NAME))]:
        problem, space, weather = suite.build(spec)
        if not warmed:
            warm_up(problem, weather)
            warmed = True
        opt = optima.get(spec.name)
        if opt is None:
            print(f"{spec.name}: no stored optimum (run bench/routing_suite.py first)")
            continue
        inst, base_nodes = solver_instance(problem, space, weather)
        base = find_baseline(inst, base_nodes)
        if base.ok:  # as solve() scales the thesis objective
            inst.f_target = max(float(evaluate(inst, base.nodes, base.rpm_idx)[2]), 1e-6)
        g_cost = float(evaluate(inst, np.array(opt["nodes"]), np.array(opt["rpm_idx"]))[0])
        t = time.thread_time()
        r = refine_route(inst, np.array(opt["nodes"]), np.array(opt["rpm_idx"]), SPLIT)
        r_cpu = time.thread_time() - t
        r_cost = r.cost if r is not None else g_cost
        coarse, fine = [], []
        for seed in range(1, a.seeds + 1):
            coarse.append(timed_solve(problem, weather, solver="bfoa", seed=seed, space=space, continuous=False))
            fine.append(timed_solve(problem, weather, solver="bfoa", seed=seed, space=space, continuous=False,
                                    refine_split=SPLIT))
        row = {"instance": spec.name, "distance_nm": round(space.base_distance_nm), "graph_optimum": g_cost,
               "refined_optimum": r_cost, "refined_optimum_gain_pct": -pct(r_cost, g_cost), "refine_cpu_s": r_cpu,
               "bfoa_gap_pct": [pct(p.cost, g_cost) for p in coarse], "bfoa_cpu_s": [p.runtime_s for p in coarse],
               "refined_bfoa_gap_pct": [pct(p.cost, g_cost) for p in fine],
               "refined_bfoa_cpu_s": [p.runtime_s for p in fine]}
        line = (f"{spec.name:16s} {space.base_distance_nm:6.0f} NM  graph opt {g_cost:9.3f}  its route refined "
                f"{-row['refined_optimum_gain_pct']:+6.2f} % ({r_cpu:.2f} s)  bfoa {np.median(row['bfoa_gap_pct']):+6.2f} % "
                f"({np.median(row['bfoa_cpu_s']):.2f} s)  bfoa refined {np.median(row['refined_bfoa_gap_pct']):+6.2f} % "
                f"[{min(row['refined_bfoa_gap_pct']):+.2f}, {max(row['refined_bfoa_gap_pct']):+.2f}] "
                f"({np.median(row['refined_bfoa_cpu_s']):.2f} s)")
        if a.fine_dp and space.base_distance_nm <= a.fine_dp_max_nm and space.sea_route is None:
            f_cost, f_cpu = fine_optimum(problem, space, weather)
            row.update({"fine_optimum": f_cost, "fine_dp_cpu_s": f_cpu,
                        "refined_bfoa_gap_to_fine_pct": [pct(p.cost, f_cost) for p in fine]})
            line += (f"  fine-graph opt {pct(f_cost, g_cost):+6.2f} % ({f_cpu:.1f} s): refined bfoa "
                     f"{np.median(row['refined_bfoa_gap_to_fine_pct']):+.2f} % from it")
        print(line, flush=True)
        rows.append(row)
        out = Path(a.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps({"split": SPLIT, "seeds": a.seeds, "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
