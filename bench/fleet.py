"""Fleet routing throughput and worker memory: 200 voyages with 1 and with 2 local dask workers.

Builds (once, under bench/out/fleet) a data root with one ingested demo cycle, a 12-vessel fleet
with fitted models and 200 voyages on the demo's port pairs with staggered departures, then runs
the `route-fleet` flow (exports off; `--exports`: with the exports the demo and the nightly write) against a
local dask cluster of 1 and of 2 single-threaded worker processes (passed as an existing scheduler address, as
in production) and prints voyages per minute (per worker) and the ratio. Each cluster is warmed up first
(imports, numba caches) so both timings measure routing, not start-up.

Memory: the peak resident memory (VmHWM, the RSS high-water mark) of each worker process over its cluster's runs, and,
to judge the voyages' share, what a fresh interpreter holds with the routing code imported and the land structure loaded.

Targets: scaling 1 → 2 workers ≥ 1.7×; peak worker memory ≤ 300 MB.

    .venv/bin/python bench/fleet.py [--voyages 200] [--workers 1,2] [--exports]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
OUT = REPO / "bench" / "out" / "fleet"


def prepare(n_voyages: int) -> Path:
    import pandas as pd

    from cli.fleet import _import_fleet
    from flows.jobs.ingest import ingest_cycle
    from flows.jobs.refit import refit_job
    from pipeline.synthetic.fleet import generate_fleet, write_fleet
    from pipeline.synthetic.mirror import write_mirror
    from storage import fleet_store

    root = OUT / "data"
    marker = root / f".ready-{n_voyages}"
    if marker.exists():
        return root
    root.mkdir(parents=True, exist_ok=True)
    mirror = OUT / "mirror"
    if not (mirror / ".complete").exists():
        write_mirror(mirror, "2020-12-01", "2020-12-01", cycles=(0,), seed=0)
        (mirror / ".complete").write_text("ok\n")
    ingest_cycle("2020-12-01T00", data_root=str(root), rish_url=(mirror / "rish").as_uri() + "/",
                   oscar_url=(mirror / "oscar").as_uri() + "/")
    fl = generate_fleet("2020-12-01T00", n_vessels=12, days=365, seed=7)
    write_fleet(fl, OUT / "fleet_csv")
    _import_fleet(OUT / "fleet_csv", root)
    refit_job(data_root=str(root))
    base = fl.voyages
    rows = []
    for k in range(n_voyages):
        v = base.iloc[k % len(base)].copy()
        v["voyage_id"] = f"B{k:04d}"
        shift = pd.Timedelta(hours=(k // len(base)) * 3)
        v["depart_utc"] += shift
        v["rta_utc"] += shift
        rows.append(v)
    fleet_store.import_voyages(root / "warehouse.duckdb", pd.DataFrame(rows))
    marker.write_text("ok\n")
    return root


def run(root: Path, address: str, voyages: list[str], exports: bool = False) -> float:
    from flows.jobs.fleet import route_fleet_job

    os.environ["JITROUTE_DASK_ADDRESS"] = address
    t0 = time.perf_counter()
    s = route_fleet_job(cycle="2020-12-01T00", voyages=voyages, data_root=str(root), exports=exports, trigger="bench")
    dt = time.perf_counter() - t0
    assert s["n"] == len(voyages), s
    return dt


def _status_mb(field: str) -> float:
    """A memory figure of this process from /proc/self/status (Linux reports kB)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1]) / 1024.0
    raise KeyError(field)


def peak_rss_mb() -> float:
    """This process's resident-memory high-water mark in MB: VmHWM, which starts afresh with the process image
    (getrusage's ru_maxrss would carry over the peak of the parent a worker process was forked from)."""
    return _status_mb("VmHWM")


def baseline_mb() -> tuple[float, float]:
    """(resident MB of a fresh interpreter that imported what a worker routes with, what loading the land structure
    adds to it): the part of a worker's peak that is not the voyages' weather and work."""
    code = (f"import sys; sys.path.insert(0, {str(REPO)!r}); from bench.fleet import _status_mb; "
            "import flows.jobs.route_worker; a = _status_mb('VmRSS'); "
            "from pipeline.routing.land import land_grid; land_grid(); print(a, _status_mb('VmRSS') - a)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    return float(out[0]), float(out[1])


def main() -> None:
    import logging

    from distributed import Client, LocalCluster

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--voyages", type=int, default=200)
    ap.add_argument("--workers", default="1,2", help="cluster sizes to time, comma separated")
    ap.add_argument("--exports", action="store_true",
                    help="workers also render each voyage's RTZ, GeoJSON and PNGs, as the demo and the nightly do")
    args = ap.parse_args()
    sizes = [int(w) for w in args.workers.split(",")]
    os.environ.setdefault("PREFECT_LOGGING_LEVEL", "WARNING")
    OUT.mkdir(parents=True, exist_ok=True)
    os.environ.setdefault("PREFECT_HOME", str(OUT / "prefect"))
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")
    os.environ.setdefault("PREFECT_SERVER_ANALYTICS_ENABLED", "false")
    root = prepare(args.voyages)
    ids = [f"B{k:04d}" for k in range(args.voyages)]
    times, peaks = {}, {}
    for workers in sizes:
        with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                          silence_logs=logging.WARNING) as cluster:
            os.environ["JITROUTE_DASK_WORKERS"] = str(workers)
            run(root, cluster.scheduler_address, ids[: 2 * workers], args.exports)  # warm-up: imports, numba caches
            times[workers] = run(root, cluster.scheduler_address, ids, args.exports)
            with Client(cluster.scheduler_address) as client:
                peaks[workers] = max(client.run(peak_rss_mb).values())
    imports, land = baseline_mb()
    print(f"exports {'on' if args.exports else 'off'}")
    print(f"{'workers':>8} {'seconds':>9} {'voyages/min':>12} {'per worker':>11} {'peak worker MB':>15}")
    for w in sizes:
        v = args.voyages / times[w] * 60
        print(f"{w:>8} {times[w]:>9.1f} {v:>12.1f} {v / w:>11.1f} {peaks[w]:>15.0f}")
    print(f"of a worker's peak: {imports:.0f} MB a fresh interpreter with the routing code imported, {land:.0f} MB the land "
          f"structure (target ≤ 300 MB in all: {'met' if max(peaks.values()) <= 300 else 'NOT met'})")
    if 1 in times and 2 in times:
        ratio = times[1] / times[2]
        print(f"scaling 1 → 2 workers: {ratio:.2f}× (target ≥ 1.7×: {'met' if ratio >= 1.7 else 'NOT met'})")


if __name__ == "__main__":
    main()
