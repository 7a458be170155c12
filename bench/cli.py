"""Command-line overhead: the interactive commands against the same work called as functions, both in fresh processes.

Without a configured Prefect API the CLI runs its jobs as plain functions, so a command should cost its
work plus a fraction of a second (start-up of the command line, printing). For each command this
prints the best-of-N wall time of `jitroute …` and of `python -c "<the same job as a function call>"`
on the same data root, their difference and ratio. Target: difference ≤ 1 s.

Set-up (a generated fleet with a year of noon reports, one ingested cycle) is not timed.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
OUT = REPO / "bench" / "out" / "cli"
BIN = Path(sys.executable).parent


def prepare() -> Path:
    from flows.jobs.ingest import ingest_cycle
    from flows.jobs.refit import refit_job
    from pipeline.synthetic.fleet import generate_fleet, write_fleet
    from pipeline.synthetic.mirror import write_mirror

    root = OUT / "data"
    if (root / ".ready").exists():
        return root
    shutil.rmtree(root, ignore_errors=True)
    mirror = OUT / "mirror"
    if not (mirror / ".complete").exists():
        write_mirror(mirror, "2020-12-01", "2020-12-01", cycles=(0,), seed=0)
        (mirror / ".complete").write_text("ok\n")
    ingest_cycle("2020-12-01T00", data_root=str(root), rish_url=(mirror / "rish").as_uri() + "/",
                 oscar_url=(mirror / "oscar").as_uri() + "/")
    write_fleet(generate_fleet("2020-12-01T00", n_vessels=12, days=365, seed=7), OUT / "fleet")
    from cli.fleet import _import_fleet

    _import_fleet(OUT / "fleet", root)
    refit_job(data_root=str(root))
    (root / ".ready").write_text("ok\n")
    return root


def timed(cmd: list[str], env: dict) -> float:
    t0 = time.perf_counter()
    r = subprocess.run(cmd, env=env, capture_output=True, text=True)
    dt = time.perf_counter() - t0
    if r.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({r.returncode}):\n{r.stderr[-2000:]}")
    return dt


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    root = prepare()
    env = {k: v for k, v in os.environ.items() if not k.startswith("PREFECT_API")}
    env["PREFECT_HOME"] = str(OUT / "no-prefect-home")  # no profile with an API: the CLI's default
    py = str(BIN / "python")
    noon = str(OUT / "fleet" / "noon_reports.csv")
    cases = {
        "noon import": ([str(BIN / "jitroute"), "noon", "import", noon, "--data", str(root)],
                        [py, "-c", f"from flows.jobs.refit import import_noon_file; import_noon_file({noon!r}, data_root={str(root)!r})"]),
        "fleet import": ([str(BIN / "jitroute"), "fleet", "import", str(OUT / "fleet"), "--data", str(root)],
                         [py, "-c", "import pandas as pd; from storage import fleet_store; "
                                    "from flows.jobs.refit import import_noon_file; "
                                    f"db={str(root / 'warehouse.duckdb')!r}; "
                                    f"fleet_store.import_vessels(db, pd.read_csv({str(OUT / 'fleet' / 'vessels.csv')!r})); "
                                    f"fleet_store.import_voyages(db, pd.read_csv({str(OUT / 'fleet' / 'voyages.csv')!r})); "
                                    f"import_noon_file({noon!r}, data_root={str(root)!r})"]),
        "refit": ([str(BIN / "jitroute"), "refit", "--data", str(root)],
                  [py, "-c", f"from flows.jobs.refit import refit_job; refit_job(data_root={str(root)!r})"]),
        "route": ([str(BIN / "jitroute"), "route", "--voyage", "V20003", "--data", str(root), "--json"],
                  [py, "-c", "from flows.jobs.route_worker import cube_weather; from flows.settings import load_settings; "
                             "from pipeline.routing.job import RouteJob, RoutingOptions, plan_voyage; "
                             "from storage import fleet_store; import json; "
                             f"db={str(root / 'warehouse.duckdb')!r}; "
                             "v=fleet_store.load_voyages(db, voyage_ids=['V20003']).iloc[0].to_dict(); "
                             "ves=fleet_store.load_vessels(db); ves=ves[ves.imo==int(v['imo'])].iloc[0].to_dict(); "
                             "from pipeline.performance.model import model_from_stored; "
                             "m=model_from_stored(fleet_store.active_model(db, int(v['imo'])), int(v['imo'])); "
                             "job=RouteJob(voyage=v, vessel=ves, model=m.to_json(), run_id='adhoc', "
                             "cycle='2020-12-01T00:00:00', exports=False, options=RoutingOptions()); "
                             f"p,_=plan_voyage(job, cube_weather({str(root / 'cubes' / 'weather.zarr')!r}, job)); "
                             "print(json.dumps(p.to_json(), default=str)[:10])"]),
    }
    print(f"{'command':<14} {'jitroute s':>10} {'function s':>10} {'overhead s':>10} {'ratio':>6}")
    worst = 0.0
    for name, (cli_cmd, fn_cmd) in cases.items():
        timed(cli_cmd, env)  # warm the page cache and numba's on-disk cache
        cli_s = min(timed(cli_cmd, env) for _ in range(args.repeat))
        fn_s = min(timed(fn_cmd, env) for _ in range(args.repeat))
        worst = max(worst, cli_s - fn_s)
        print(f"{name:<14} {cli_s:>10.2f} {fn_s:>10.2f} {cli_s - fn_s:>10.2f} {cli_s / fn_s:>6.2f}")
    print(f"largest overhead {worst:.2f} s (target ≤ 1 s: {'met' if worst <= 1.0 else 'NOT met'})")


if __name__ == "__main__":
    main()
