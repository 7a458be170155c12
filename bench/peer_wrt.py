"""An isochrone peer on the routing suite: 52North WeatherRoutingTool's isofuel routing against jitroute's DP optimum
and BFOA, every route priced by jitroute's own evaluator.

Per suite instance (bench/routing_instances.py) it hands WRT the instance's weather, ports, departure and a ship
(bench/peer_wrt_io.py: netCDF, deep water, config under bench/out/peer_wrt/<instance>/), runs WRT's isofuel search in
WRT's own interpreter (bench/peer_wrt_run.py, a subprocess: this interpreter never imports WRT), reads back WRT's
route (its GeoJSON) and prices it the way the suite prices a plan: the route's waypoints as a fixed route, the best
engine setting per leg on it (`pipeline.routing.engine_limits.best_engine_plan`, exact over the suite's settings:
the listed rpm and the constant rpm meeting the RTA, continuous=False) under the same RTA, objective, weather and
vessel model. WRT's own fuel and time (its ship: constant speed, added resistance of wind only; no waves, no current,
no RTA) are printed for reference and otherwise ignored: only WRT's geometry is compared.

Printed per instance: the DP optimum (bench/optima.json; computed and stored when stale, as routing_suite.py does),
BFOA's gap min / median / max and median CPU (from bench/out/routing_suite.json when it holds the instance against
the same optimum, else solved here, seeds 1..N), the DP's own route through the same evaluator (a check of the
evaluator: it must come out at the DP's cost or below), WRT's route cost, its gap, legs breaking jitroute's land
clearance, and WRT's CPU (process CPU of the routing call after imports; this process and WRT's are pinned to one
core). Writes bench/out/peer_wrt.json; always exits 0.

    .venv/bin/python bench/peer_wrt.py --wrt-python /tmp/wrt-venv/bin/python --wrt-src /tmp/wrt-src
                                       [--only NAME ...] [--seeds 10] [--step-nm NM] [--wrt KEY=VALUE ...]

Setup of the peer (not a jitroute dependency; see bench/README.md, "An isochrone peer"):
    WRT's source from github.com/52North/WeatherRoutingTool in /tmp/wrt-src, python3.11 -m venv /tmp/wrt-venv,
    /tmp/wrt-venv/bin/pip install -r /tmp/wrt-src/requirements.txt (maridatadownloader from
    github.com/52North/maridatadownloader, geovectorslib from PyPI).
"""

from __future__ import annotations

import os

os.environ["NUMBA_NUM_THREADS"] = "1"  # before numba is imported anywhere

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

import peer_wrt_io as wio  # noqa: E402
import routing_instances as suite  # noqa: E402
from pipeline.routing.baseline import baseline as find_baseline, evaluate  # noqa: E402
from pipeline.routing.engine_limits import best_engine_plan  # noqa: E402
from pipeline.routing.savings import solver_instance  # noqa: E402
from pipeline.routing.solve import BfoaParams  # noqa: E402
from routing import pin_one_core, timed_solve, warm_up  # noqa: E402
from routing_suite import dp_reference  # noqa: E402

OUT = ROOT / "bench" / "out"
RUNNER = Path(__file__).resolve().parent / "peer_wrt_run.py"
SETUP = """WRT is not installed: nothing run. To run the peer (its own venv, never jitroute's):
  1. WRT's source: github.com/52North/WeatherRoutingTool (e.g. `git archive HEAD | tar -x -C /tmp/wrt-src`)
  2. python3.11 -m venv /tmp/wrt-venv
  3. /tmp/wrt-venv/bin/pip install astropy cartopy dask datacube geographiclib geopandas geovectorslib \\
       global_land_mask matplotlib netcdf4 networkx numpy pandas pydantic pymoo scikit-image scipy seaborn \\
       shapely sqlalchemy xarray  <source of github.com/52North/maridatadownloader>
  4. .venv/bin/python bench/peer_wrt.py --wrt-python /tmp/wrt-venv/bin/python --wrt-src /tmp/wrt-src"""


def suite_instance(problem, space, weather):
    """The instance the suite's solvers search, with the thesis fuel scale set as solve() sets it (plan_cost)."""
    inst, base_nodes = solver_instance(problem, space, weather)
    base = find_baseline(inst, base_nodes)
    if base.ok:
        inst.f_target = max(float(evaluate(inst, base.nodes, base.rpm_idx)[2]), 1e-6)
    return inst


def price_route(inst, lat, lon) -> dict:
    """The best plan over the settings on the fixed route through (lat, lon): cost, fuel, hours, legs off jitroute's
    land clearance."""
    rinst = wio.route_instance(inst, lat, lon)
    nodes = np.zeros(len(lat), np.int64)
    rpm_idx, cost, _ = best_engine_plan(rinst, nodes)
    out = {"cost": cost, "fuel_t": math.nan, "hours": math.nan, "waypoints": int(len(lat)),
           "legs_off_clearance": wio.legs_off_clearance(inst, lat, lon)}
    if math.isfinite(cost):
        c, hours, fuel, _ = evaluate(rinst, nodes, rpm_idx)
        out.update(fuel_t=fuel, hours=hours, cost_check=c)
    return out


def bfoa_figures(name: str, dp_cost: float, problem, space, weather, seeds: int) -> dict:
    """BFOA's gaps (%) and CPU (s) per seed: from the suite's last run when it measured against this optimum, else
    solved now with the default parameters."""
    path = OUT / "routing_suite.json"
    if path.exists():
        for row in json.loads(path.read_text()):
            if row.get("name") == name and row.get("bfoa") and abs(row["dp"]["cost"] - dp_cost) <= 1e-9 * dp_cost:
                return {**row["bfoa"], "source": "bench/out/routing_suite.json"}
    plans = [timed_solve(problem, weather, solver="bfoa", seed=s, params=BfoaParams(), space=space, continuous=False)
             for s in range(1, seeds + 1)]
    return {"gaps_pct": [100.0 * (p.cost / dp_cost - 1.0) for p in plans], "cpu_s": [p.runtime_s for p in plans],
            "source": f"solved now, seeds 1..{seeds}"}


def run_wrt(cfg: dict, work: Path, wrt_python: str, wrt_src: str, rerun: bool = False) -> dict:
    """WRT on `cfg` in its own interpreter: {"cpu_s", "wall_s", "route": GeoJSON path} or {"error": …}. A run of the
    same config already in `work` (its route and CPU time) is reused (`reused`: True) unless `rerun`."""
    (work / "route").mkdir(parents=True, exist_ok=True)
    cfg_path, cpu_path = work / "config.json", work / "cpu.json"
    routes = sorted((work / "route").glob("*.json"))
    if not rerun and cfg_path.exists() and cpu_path.exists() and routes and json.loads(cfg_path.read_text()) == cfg:
        return {**json.loads(cpu_path.read_text()), "route": str(routes[0]), "reused": True}
    for old in routes:
        old.unlink()
    cfg_path.write_text(json.dumps(cfg, indent=1))
    cpu_path.unlink(missing_ok=True)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "WRT_FIGURE_PATH", "NUMBA_NUM_THREADS")}
    env.update(PYTHONPATH=str(wrt_src), MPLBACKEND="Agg", OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    with open(work / "wrt.log", "w") as log:
        proc = subprocess.run([wrt_python, str(RUNNER), str(cfg_path), str(cpu_path)], cwd=work, env=env,
                              stdout=log, stderr=subprocess.STDOUT)
    routes = sorted((work / "route").glob("*.json"))
    if proc.returncode != 0 or not cpu_path.exists() or not routes:
        tail = (work / "wrt.log").read_text().strip().splitlines()[-3:]
        return {"error": f"WRT exited {proc.returncode} (log {work / 'wrt.log'}): " + " | ".join(tail)}
    return {**json.loads(cpu_path.read_text()), "route": str(routes[0])}


def parse_overrides(items: list[str]) -> dict:
    out = {}
    for item in items:
        key, _, text = item.partition("=")
        try:
            out[key] = json.loads(text)
        except ValueError:
            out[key] = text
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--wrt-python", help="WRT's interpreter (its own venv); without it: what to install, exit 0")
    ap.add_argument("--wrt-src", help="WRT's source tree (put on its PYTHONPATH)")
    ap.add_argument("--only", nargs="+", choices=sorted(suite.BY_NAME), help="these instances only (default: all)")
    ap.add_argument("--seeds", type=int, default=10, help="BFOA seeds when the suite's last run has none (default 10)")
    ap.add_argument("--step-nm", type=float, default=None,
                    help="length of one isofuel step in calm water (default: the instance's line spacing)")
    ap.add_argument("--rerun", action="store_true", help="run WRT even where bench/out/peer_wrt holds a run of the same "
                    "config (default: reuse it)")
    ap.add_argument("--wrt", nargs="+", default=[], metavar="KEY=VALUE", help="other WRT config settings (JSON values)")
    a = ap.parse_args()
    if not a.wrt_python or not a.wrt_src:
        print(SETUP)
        return 0
    pinned = pin_one_core()
    specs = [suite.BY_NAME[n] for n in a.only] if a.only else list(suite.INSTANCES)
    overrides = parse_overrides(a.wrt)
    print(f"isochrone peer (WRT isofuel) on {len(specs)} suite instances; {pinned} (WRT's subprocess too), "
          f"NUMBA_NUM_THREADS=1, load {os.getloadavg()[0]:.1f}")
    print("every route priced by jitroute: best setting per leg on the fixed route (engine_limits.best_engine_plan), "
          "over the suite's settings; WRT's own fuel/time ignored")
    report, warmed = [], False
    for spec in specs:
        problem, space, weather = suite.build(spec)
        if not warmed:
            warm_up(problem, weather)
            warmed = True
        dist_nm = space.base_distance_nm
        print(f"\n== {spec.name}: {dist_nm:,.0f} NM, RTA {problem.t_req_h:.1f} h, {spec.objective}")
        dp = dp_reference(spec, problem, space, weather, recompute=False)
        dp_cost = float(dp["cost"])
        print(f"   DP optimum (within {100 * dp['gap']:g} %): {dp_cost:.3f}, fuel {dp['fuel_t']:.2f} t, "
              f"{dp['hours']:.1f} h")
        row = {"name": spec.name, "distance_nm": dist_nm, "dp": {k: dp[k] for k in ("cost", "fuel_t", "hours", "gap")}}
        bf = bfoa_figures(spec.name, dp_cost, problem, space, weather, a.seeds)
        g, c = np.array(bf["gaps_pct"]), np.array(bf["cpu_s"])
        print(f"   BFOA ({bf['source']}): gap % min {g.min():.2f} / median {np.median(g):.2f} / max {g.max():.2f}; "
              f"CPU median {np.median(c):.2f} s")
        row["bfoa"] = bf
        inst = suite_instance(problem, space, weather)
        L2 = space.lat.shape[0]
        dp_nodes = np.asarray(dp["nodes"], np.int64)
        own = price_route(inst, space.lat[np.arange(L2), dp_nodes], space.lon[np.arange(L2), dp_nodes])
        print(f"   evaluator check, the DP's route as waypoints: {own['cost']:.3f} (DP {dp_cost:.3f})")
        row["dp_route_priced"] = own
        speed_kn = dist_nm / problem.t_req_h  # the constant speed through water meeting the RTA in calm water
        step_nm = a.step_nm or dist_nm / (spec.n_lines + 1)
        work = OUT / "peer_wrt" / spec.name
        work.mkdir(parents=True, exist_ok=True)
        lat, lon, _ = wio.grid_axes(weather)
        shift = wio.shift_deg(lon)
        wio.weather_dataset(weather, shift).to_netcdf(work / "weather.nc")
        wio.depth_dataset(weather, shift).to_netcdf(work / "depth.nc")
        cfg = wio.wrt_config(problem, weather, shift, speed_kn, step_nm, work,
                             route_steps=int(3 * dist_nm / step_nm) + 10, **overrides)
        cfg["longitude_shift_deg"] = shift
        wrt = run_wrt(cfg, work, a.wrt_python, a.wrt_src, a.rerun)
        row["wrt"] = {"speed_kn": speed_kn, "step_nm": step_nm, "shift_deg": shift, **wrt}
        if "error" in wrt:
            print(f"   WRT: {wrt['error']}")
            report.append(row)
            continue
        wlat, wlon, wrt_fuel_t = wio.read_route(Path(wrt["route"]), shift)
        priced = price_route(inst, wlat, wlon)
        gap = 100.0 * (priced["cost"] / dp_cost - 1.0)
        row["wrt"].update(priced=priced, gap_pct=gap, own_fuel_t=wrt_fuel_t)
        frame = f", handed over turned {shift:g}° (dateline)" if shift else ""
        print(f"   WRT isofuel ({speed_kn:.2f} kn, steps of {step_nm:.0f} NM{frame}): {priced['waypoints']} waypoints, "
              f"cost {priced['cost']:.3f} (fuel {priced['fuel_t']:.2f} t, {priced['hours']:.1f} h), gap {gap:.2f} %; "
              f"{priced['legs_off_clearance']} legs off jitroute's land clearance; CPU {wrt['cpu_s']:.2f} s "
              f"(wall {wrt['wall_s']:.2f} s{', reused' if wrt.get('reused') else ''}); WRT's own fuel {wrt_fuel_t:.2f} t (ignored)")
        if priced["legs_off_clearance"]:
            print("   not like for like: jitroute's graph keeps every leg clear of land by its clearance, WRT's route "
                  "does not (gap marked * below)")
        report.append(row)
    print(f"\n{'instance':<16} {'NM':>6} {'DP optimum':>11} {'BFOA gap % med':>15} {'BFOA CPU s':>11} "
          f"{'WRT cost':>10} {'WRT gap %':>10} {'WRT CPU s':>10}")
    for row in report:
        g = np.median(row["bfoa"]["gaps_pct"])
        c = np.median(row["bfoa"]["cpu_s"])
        w = row["wrt"]
        wc, wg, wcpu = ((f"{w['priced']['cost']:.3f}", f"{w['gap_pct']:.2f}" + ("*" if w["priced"]["legs_off_clearance"]
                         else ""), f"{w['cpu_s']:.2f}") if "priced" in w else ("failed", "-", "-"))
        print(f"{row['name']:<16} {row['distance_nm']:>6,.0f} {row['dp']['cost']:>11.3f} {g:>15.2f} {c:>11.2f} "
              f"{wc:>10} {wg:>10} {wcpu:>10}")
    print(f"load at the end {os.getloadavg()[0]:.1f}; {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}")
    (OUT / "peer_wrt.json").write_text(json.dumps(report, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
