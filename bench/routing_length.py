"""What one voyage costs through the product path as it grows longer: is the cost linear in length?

Voyages start off the Kii Peninsula (33.0 N 136.0 E) and follow the great circle towards Los Angeles, cut at
500, 1,000, 2,000, 3,500 and 5,000 NM, in the same hourly analytic weather as bench/routing.py (a storm crossing
the North Pacific). Each is routed as the fleet routes it (`job.plan_voyage`'s call): the default search space
(a line about every 40 NM, at most 80, 21 nodes), the listed settings 70 / 85 / 100 rpm plus the constant rpm
meeting the RTA, RTA = the great circle at 70 rpm in calm water minus 10 %, BFOA with its default options, the
default engine-change limits (a setting held 12 h, 0.05 t per change) and the savings split. The cost is the
whole solve's CPU time (search, limits, the unlimited reference, the split; the thread's time, one core, after
compilation), the median over seeds.

Targets (#22): ≤ 2 s CPU at 5,000 NM and ≤ 3× the 2,000 NM cost (2.5× the length). Prints a table and the
ratios; writes bench/out/routing_length.json; always exits 0.

    .venv/bin/python bench/routing_length.py [--seeds 3] [--lengths 500 2000 5000]
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

import numpy as np  # noqa: E402

from pipeline.performance.model import reference_model  # noqa: E402
from pipeline.routing import geodesy as geo  # noqa: E402
from pipeline.routing.solve import EngineLimits, RoutingProblem, solve  # noqa: E402
from routing import ARR, DEP, DEPART_UTC, RPM, pin_one_core, verdict, voyage_weather, warm_up  # noqa: E402

TARGET_5000_S = 2.0
TARGET_RATIO = 3.0  # 5,000 NM against 2,000 NM
MODEL = reference_model(14.0, 100.0, 1.5)


def voyage(length_nm: float):
    """(problem with its RTA, search space, weather) of the voyage cut at `length_nm` along the great circle."""
    bearing = geo.gc_bearing_deg(DEP[0], DEP[1], ARR[0], ARR[1])
    lat, lon = geo.destination(DEP[0], DEP[1], bearing, length_nm)
    loose = RoutingProblem(dep=DEP, arr=(float(lat), float(geo.wrap180(lon))), depart_utc=DEPART_UTC,
                           rta_utc=DEPART_UTC + np.timedelta64(60, "D"), model=MODEL, rpm_options=RPM,
                           voyage_id=f"LENGTH-{length_nm:.0f}")
    space = loose.search_space()
    slow_kn = float(MODEL.stw_kn(RPM[0], loose.draft_m, loose.trim_m))
    weather = voyage_weather(space, DEPART_UTC, 1.6 * space.base_distance_nm / slow_kn + 24.0)
    rta = DEPART_UTC + np.timedelta64(int(round(0.9 * space.base_distance_nm / slow_kn * 60)), "m")
    return replace(loose, rta_utc=rta), space, weather


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3, help="solves per length, seeds 1..N (default 3)")
    ap.add_argument("--lengths", type=float, nargs="+", default=[500.0, 1000.0, 2000.0, 3500.0, 5000.0])
    a = ap.parse_args()
    pinned = pin_one_core()
    print(f"routing cost against voyage length: product path (bfoa + engine limits + savings split), "
          f"{a.seeds} seeds; {pinned}, NUMBA_NUM_THREADS=1, CPU time")
    rows = []
    for n, length in enumerate(sorted(a.lengths)):
        problem, space, weather = voyage(length)
        if n == 0:
            warm_up(problem, weather)
        secs, plans = [], []
        for seed in range(1, a.seeds + 1):
            t0 = time.thread_time()
            plan = solve(problem, weather, solver="bfoa", seed=seed, space=space, limits=EngineLimits(), savings=True)
            secs.append(time.thread_time() - t0)
            plans.append(plan)
        cpu = float(np.median(secs))
        p = plans[0]
        sav = p.savings.total_pct if p.savings is not None else float("nan")
        rows.append({"length_nm": length, "lines": space.n_lines, "nodes": space.lat.shape[1], "cpu_s": cpu,
                     "cpu_s_all": secs, "status": p.status, "fuel_t": p.fuel_t, "savings_total_pct": sav})
        print(f"  {length:6,.0f} NM  {space.n_lines:3d} lines × {space.lat.shape[1]} nodes  CPU median {cpu:6.2f} s "
              f"({1000 * cpu / length:.3f} s per 1,000 NM)  {p.status}, {p.fuel_t:.1f} t, savings vs constant speed "
              f"{sav:.2f} %", flush=True)
    by = {r["length_nm"]: r["cpu_s"] for r in rows}
    if 5000.0 in by:
        print(f"\n5,000 NM: {by[5000.0]:.2f} s CPU against the {TARGET_5000_S:g} s target "
              f"({by[5000.0] / TARGET_5000_S:.2f}×) → {verdict(by[5000.0] <= TARGET_5000_S)}")
        if 2000.0 in by:
            ratio = by[5000.0] / by[2000.0]
            print(f"5,000 NM / 2,000 NM: {ratio:.2f}× (length 2.5×; target ≤ {TARGET_RATIO:g}×) → "
                  f"{verdict(ratio <= TARGET_RATIO)}")
    out = ROOT / "bench" / "out"
    out.mkdir(parents=True, exist_ok=True)
    (out / "routing_length.json").write_text(json.dumps(rows, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
