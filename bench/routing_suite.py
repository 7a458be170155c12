"""Routing benchmark suite: BFOA, A* and the baseline against the stored DP optimum of every suite instance.

Instances: bench/routing_instances.py (short and ocean voyages, east- and west-bound in the westerlies, a
strait, a storm against weather limits, tight and loose RTAs, hourly weather with a moving storm, the
dateline; each ≤ 5,000 NM). The reference is the DP certified within 0.1 % of the optimum, stored in
bench/optima.json with a hash of the instance: it is computed only when missing or stale (the instance,
its weather or the model changed), or for every instance with --recompute-dp.

Per instance it prints the DP cost and its CPU time (when it was computed), BFOA's gap to it (min / median /
max over the seeds, the share of runs within 1 %) and its median CPU time, A*'s and the baseline's cost and
gap (all over the settings: continuous=False, the space the DP is exact in), and the product's plan (BFOA seed 1
with continuous speed and the engine-change limits): its honest savings split and CPU time. Targets: median gap ≤ 1 % on every instance,
≥ 90 % of all runs ≤ 1 %, one solve ≤ 2 s CPU for 5,000 NM. One core, after compilation, CPU time (the
thread's). Writes bench/out/routing_suite.json; always exits 0.

    .venv/bin/python bench/routing_suite.py [--seeds 10] [--only NAME ...] [--recompute-dp] [--no-bfoa]
                                            [--bfoa FIELD=VALUE ...]

--bfoa sets BfoaParams fields for every BFOA solve (e.g. `--bfoa branch_routes=False polish_fuel=0.003`, the
search as it was before it started bacteria on branch routes), to compare settings in one sitting.
"""

from __future__ import annotations

import os

os.environ["NUMBA_NUM_THREADS"] = "1"  # before numba is imported anywhere

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

import routing_instances as suite  # noqa: E402
from pipeline.routing.solve import PRODUCT, BfoaParams, EngineLimits, product_options  # noqa: E402
from routing import TARGET_GAP_PCT, TARGET_SOLVE_S, pin_one_core, timed_solve, verdict, warm_up  # noqa: E402
from dataclasses import fields, replace  # noqa: E402

TARGET_SHARE_WITHIN = 0.9  # of all BFOA runs within TARGET_GAP_PCT


def dp_reference(spec, problem, space, weather, recompute: bool) -> dict:
    """The stored optimum of the instance, computed (and stored) when missing, stale or asked for."""
    digest = suite.instance_hash(spec, problem, space, weather)
    rec = None if recompute else suite.stored_optimum(spec, digest)
    if rec is not None:
        return {**rec, "stored": True}
    rec, _ = suite.solve_optimum(spec, problem, space, weather)
    optima = suite.read_optima()
    optima[spec.name] = rec
    suite.OPTIMA.write_text(json.dumps(dict(sorted(optima.items())), indent=1) + "\n")
    return {**rec, "stored": False}


def bfoa_params(settings: list[str], base: BfoaParams | None = None) -> BfoaParams:
    """`base` (default: BfoaParams()) with FIELD=VALUE settings (bool, int, float or None, by the field's default)
    applied."""
    kinds = {f.name: type(f.default) for f in fields(BfoaParams)}
    changes = {}
    for item in settings:
        name, _, text = item.partition("=")
        if name not in kinds:
            raise SystemExit(f"--bfoa {item}: BfoaParams has no field {name!r} (fields: {', '.join(kinds)})")
        kind = kinds[name]
        if text == "None":
            changes[name] = None
        elif kind is bool:
            changes[name] = text.lower() in ("1", "true", "yes")
        else:
            changes[name] = (float if kind is type(None) else kind)(text)
    return replace(base or BfoaParams(), **changes)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10, help="BFOA solves per instance, seeds 1..N (default 10)")
    ap.add_argument("--only", nargs="+", choices=sorted(suite.BY_NAME), help="these instances only")
    ap.add_argument("--recompute-dp", action="store_true", help="recompute and store every DP optimum")
    ap.add_argument("--no-bfoa", action="store_true", help="only make sure the stored optima are current")
    ap.add_argument("--bfoa", nargs="+", default=[], metavar="FIELD=VALUE", help="BfoaParams settings (default: its defaults)")
    a = ap.parse_args()
    pinned = pin_one_core()
    specs = [suite.BY_NAME[n] for n in a.only] if a.only else list(suite.INSTANCES)
    out_dir = ROOT / "bench" / "out"
    out_dir.mkdir(parents=True, exist_ok=True)
    print(f"routing suite: {len(specs)} instances, {a.seeds} BFOA seeds each; {pinned}, NUMBA_NUM_THREADS=1")
    params = bfoa_params(a.bfoa)
    if a.bfoa:
        print(f"BFOA settings: {' '.join(a.bfoa)}")
    report, all_gaps = [], []
    warmed = False
    for spec in specs:
        problem, space, weather = suite.build(spec)
        if not warmed:
            warm_up(problem, weather)
            warmed = True
        L2, P = space.lat.shape
        print(f"\n== {spec.name}: {spec.kinds}\n   {space.base_distance_nm:,.0f} NM, {space.n_lines} lines × {P} nodes × "
              f"{len(spec.rpm)} listed rpm + the constant rpm meeting the RTA, {spec.objective}, RTA {problem.t_req_h:.1f} h")
        dp = dp_reference(spec, problem, space, weather, a.recompute_dp)
        when = "stored" if dp["stored"] else "computed now"
        print(f"   DP ({when}, within {100 * dp['gap']:g} %): {dp['status']}, cost {dp['cost']:.3f}, fuel "
              f"{dp['fuel_t']:.2f} t, {dp['hours']:.1f} h; CPU {dp['dp_cpu_s']:.1f} s")
        row = {"name": spec.name, "dp": dp}
        if a.no_bfoa:
            report.append(row)
            continue
        ast = timed_solve(problem, weather, solver="astar", space=space, continuous=False)
        base = ast.baseline
        print(f"   baseline: cost {base.cost:.3f} (gap {100 * (base.cost / dp['cost'] - 1):.2f} %); A*: cost {ast.cost:.3f} "
              f"(gap {100 * (ast.cost / dp['cost'] - 1):.2f} %), CPU {ast.runtime_s:.2f} s")
        plans = [timed_solve(problem, weather, solver="bfoa", seed=s, params=params, space=space, continuous=False)
                 for s in range(1, a.seeds + 1)]
        gaps = np.array([100.0 * (p.cost / dp["cost"] - 1.0) for p in plans])
        secs = np.array([p.runtime_s for p in plans])
        all_gaps.extend(gaps.tolist())
        within = float(np.mean(gaps <= TARGET_GAP_PCT))
        print(f"   BFOA gap %: min {gaps.min():.2f}, median {np.median(gaps):.2f}, max {gaps.max():.2f}; "
              f"{100 * within:.0f} % of runs ≤ {TARGET_GAP_PCT:g} %; CPU median {np.median(secs):.2f} s "
              f"(max {secs.max():.2f}) → gap {verdict(np.median(gaps) <= TARGET_GAP_PCT)}, "
              f"time {verdict(np.median(secs) <= TARGET_SOLVE_S)}")
        # the product's plan (seed 1): refined on the finer corridors, continuous speed, engine-change limits, the
        # savings split
        product = timed_solve(problem, weather, solver="bfoa", seed=1, params=bfoa_params(a.bfoa, product_options("bfoa")),
                              space=space, limits=EngineLimits(), savings=True, refine_split=PRODUCT.refine_split)
        split = product.savings
        if split is not None:
            print(f"   product plan (BFOA seed 1, continuous speed, limits) vs constant rpm at the RTA on the base route: "
                  f"total {split.total_pct:.2f} % = speed profile {split.speed_profile_pct:.2f} % + route "
                  f"{split.route_pct:.2f} %; CPU {product.runtime_s:.2f} s")
        row.update({"baseline_cost": base.cost, "astar": {"cost": ast.cost, "cpu_s": ast.runtime_s},
                    "bfoa": {"gaps_pct": gaps.tolist(), "cpu_s": secs.tolist()},
                    "savings": None if split is None else {"total_pct": split.total_pct,
                                                           "speed_profile_pct": split.speed_profile_pct,
                                                           "route_pct": split.route_pct}})
        report.append(row)
    if all_gaps:
        g = np.array(all_gaps)
        share = float(np.mean(g <= TARGET_GAP_PCT))
        print(f"\nall {len(g)} BFOA runs: {100 * share:.0f} % within {TARGET_GAP_PCT:g} % → "
              f"{verdict(share >= TARGET_SHARE_WITHIN)} (target ≥ {100 * TARGET_SHARE_WITHIN:g} %)")
    (out_dir / "routing_suite.json").write_text(json.dumps(report, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
