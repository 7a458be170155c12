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

`--s3`: as in production instead: the cube and the exports on a local S3 server (moto, as the test suite's S3
fixture; bench/s3_counting_server.py counts what it serves), a `dask scheduler` and `dask worker --nthreads 1
--no-nanny` processes started in an empty folder with no data root. The numba caches are compiled in this process
before the workers start. Prints besides voyages/min and peak worker MB: each worker's picture process (the child
that draws its PNGs with `--exports`: peak, Rss and Pss at the end) and the two together, cube bytes and GETs per
voyage (what the S3 server served under `cubes/`), export requests per voyage, and the flow host's CPU per voyage (this
process: user + system time over the timed run). `--code DIR` runs another checkout's code (e.g. an export of
the main branch) in this process and in the workers, so before/after figures come from one sitting.

    .venv/bin/python bench/fleet.py --s3 [--exports] [--voyages 60] [--code /tmp/main-export] [--profile-host FILE]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
CODE = Path(sys.argv[sys.argv.index("--code") + 1]).resolve() if "--code" in sys.argv[:-1] else REPO
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(CODE))  # the code under test comes first
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


BIG_LIBRARIES = ("pandas", "pyarrow", "xarray", "matplotlib", "duckdb", "scipy", "PIL", "numba", "zarr", "s3fs")


def worker_memory() -> dict:
    """In a worker: its memory now (MB) from /proc/self/smaps_rollup (Rss; Pss, which splits pages shared with other
    processes between them; Private, its own pages; Anonymous, heap and stacks), the high-water mark, and which of
    the big libraries it has imported."""
    import sys

    now = {}
    for line in Path("/proc/self/smaps_rollup").read_text().splitlines()[1:]:
        key, value = line.split(":", 1)
        now[key] = int(value.split()[0]) / 1024.0
    return {"rss": now["Rss"], "pss": now["Pss"], "private": now["Private_Clean"] + now["Private_Dirty"],
            "anonymous": now["Anonymous"], "peak": peak_rss_mb(),
            "imported": sorted({m.split(".")[0] for m in sys.modules} & set(BIG_LIBRARIES)), "pictures": picture_memory()}


def picture_memory() -> dict | None:
    """In a worker: its picture process's memory (flows/jobs/picture_process.py: Rss, Pss, peak MB), None when it
    has none running (or the code under test draws in the worker)."""
    picture_process = sys.modules.get("flows.jobs.picture_process")
    pid = picture_process.of_this_process().pid if picture_process is not None and hasattr(picture_process, "of_this_process") else None
    if pid is None:
        return None
    rollup = {}
    for line in Path(f"/proc/{pid}/smaps_rollup").read_text().splitlines()[1:]:
        key, value = line.split(":", 1)
        rollup[key] = int(value.split()[0]) / 1024.0
    peak = next(int(line.split()[1]) / 1024.0 for line in Path(f"/proc/{pid}/status").read_text().splitlines()
                if line.startswith("VmHWM:"))
    return {"rss": rollup["Rss"], "pss": rollup["Pss"], "peak": peak}


def baseline_mb() -> tuple[float, float]:
    """(resident MB of a fresh interpreter that imported what a worker routes with, what loading the land structure
    adds to it): the part of a worker's peak that is not the voyages' weather and work."""
    code = (f"import sys; sys.path.insert(0, {str(REPO)!r}); from bench.fleet import _status_mb; "
            "import flows.jobs.route_worker; a = _status_mb('VmRSS'); "
            "from pipeline.routing.land import land_grid; land_grid(); print(a, _status_mb('VmRSS') - a)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    return float(out[0]), float(out[1])


def _free_port() -> int:
    import socket

    with socket.socket() as sk:
        sk.bind(("127.0.0.1", 0))
        return sk.getsockname()[1]


def _wait_port(port: int, proc, what: str, timeout_s: float = 120.0) -> None:
    import socket

    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"{what} exited with {proc.returncode}")
        with socket.socket() as sk:
            if sk.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.2)
    raise RuntimeError(f"{what} did not listen on port {port} within {timeout_s:.0f} s")


def _start(args: list[str], env: dict, log: Path, cwd: Path):
    return subprocess.Popen(args, env=env, cwd=cwd, stdout=open(log, "w"), stderr=subprocess.STDOUT,
                            start_new_session=True)


def _stop(procs: list) -> None:
    for p in procs:
        if p.poll() is None:
            p.terminate()
    for p in procs:
        try:
            p.wait(20)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


def _s3_counts(endpoint: str, reset: bool = False) -> dict:
    import json
    import urllib.request

    req = urllib.request.Request(f"{endpoint}/__reset" if reset else f"{endpoint}/__counts",
                                 method="POST" if reset else "GET")
    with urllib.request.urlopen(req, timeout=30) as r:
        return {} if reset else json.loads(r.read())


def _host_cpu_s() -> float:
    import resource

    ru = resource.getrusage(resource.RUSAGE_SELF)
    return ru.ru_utime + ru.ru_stime


def _main_thread_cpu_s() -> float:
    """CPU seconds (user + system) of this process's main thread, where the flow runs; the rest of the process's CPU
    is its other threads' (the dask client's and fsspec's event loops)."""
    import threading

    fields = Path(f"/proc/self/task/{threading.main_thread().native_id}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime, stime (fields 14, 15)


def _warm_numba(root: Path, cube_url: str, options: dict, ids: list[str], exports: bool) -> None:
    """Route one voyage in this process so the numba caches (in the code's __pycache__) exist before workers start."""
    import inspect

    import numpy as np

    from flows.jobs.fleet import fleet_jobs
    from flows.jobs.route_worker import route_one
    from flows.settings import load_settings
    from pipeline.routing.job import RoutingOptions

    s = load_settings(data_root=root)
    job = fleet_jobs(s, s.layout.warehouse, np.datetime64("2020-12-01T00", "ns"), "warm", ids[:1],
                     RoutingOptions.from_settings(s.routing), exports)[0]
    if "exports_to" in inspect.signature(route_one).parameters:
        route_one(job, cube_url, options, (str(OUT / "warm-exports"), {}))
    else:
        route_one(job, cube_url, options)


def worker_cube_reads(reset: bool = False) -> dict:
    """In a worker: the cube GETs (with their bytes) and HEADs this process made through s3fs since the last reset.
    Counted by wrapping s3fs's two calls zarr reads with (a bench instrument: the S3 server cannot tell a worker's
    requests from the flow host's)."""
    import s3fs

    cls = s3fs.S3FileSystem
    counts = getattr(cls, "_bench_cube_reads", None)
    if counts is None:
        counts = cls._bench_cube_reads = {"get": 0, "bytes": 0, "head": 0}
        cat, info = cls._cat_file, cls._info

        async def _cat_file(self, path, *a, **k):
            out = await cat(self, path, *a, **k)
            if "/cubes/" in path:
                counts["get"] += 1
                counts["bytes"] += len(out)
            return out

        async def _info(self, path, *a, **k):
            if "/cubes/" in path:
                counts["head"] += 1
            return await info(self, path, *a, **k)

        cls._cat_file, cls._info = _cat_file, _info
    out = dict(counts)
    if reset:
        counts.update(get=0, bytes=0, head=0)
    return out


def worker_chunk_cache() -> dict:
    """In a worker: its cube chunk cache's counters (storage/cube_window.py)."""
    from storage import cube_window

    return cube_window.CHUNK_CACHE.stats()


def stored_cycle_mb(root: Path) -> float:
    """Stored MB of the data chunks a voyage reads, of the bench's one cycle (the S3 copy is chunked the same)."""
    from pipeline.routing import weather_field as wf

    store = root / "cubes" / "weather.zarr"
    return sum(f.stat().st_size for v in wf.CUBE_VARIABLES for f in (store / v / "c").rglob("*") if f.is_file()) / 1e6


def _host_profiler(path: Path | None):
    """A started cProfile of the flow host (this process) when `--profile-host` asked for one, else None. It counts
    the process's CPU time (all its threads: the dask client's and fsspec's event loops run beside the flow's), so
    what the other threads spend shows under the flow's waits."""
    if path is None:
        return None
    import cProfile

    profiler = cProfile.Profile(time.process_time)
    profiler.enable()
    return profiler


def s3_processes(n_voyages: int, sizes: list[int], exports: bool, profile_host: Path | None = None) -> None:
    """The bench on a scheduler and worker processes, with the cube and exports on a local S3 server."""
    import json
    import shutil

    import boto3
    import numpy as np

    root0 = prepare(max(n_voyages, 200))  # the data root bench/fleet.py builds; the first n voyages are timed
    ids = [f"B{k:04d}" for k in range(n_voyages)]
    work = OUT / "s3"
    shutil.rmtree(work, ignore_errors=True)
    (work / "elsewhere").mkdir(parents=True)
    root = work / "data"
    root.mkdir()
    shutil.copy(root0 / "warehouse.duckdb", root / "warehouse.duckdb")
    py, bin_ = sys.executable, Path(sys.executable).parent
    s3_port = _free_port()
    procs = [_start([py, str(REPO / "bench" / "s3_counting_server.py"), str(s3_port)], dict(os.environ),
                    work / "s3.log", work)]
    try:
        _wait_port(s3_port, procs[0], "the S3 server")
        endpoint = f"http://127.0.0.1:{s3_port}"
        boto3.client("s3", endpoint_url=endpoint, aws_access_key_id="testing", aws_secret_access_key="testing",
                     region_name="us-east-1").create_bucket(Bucket="jitroute")
        options = {"endpoint_url": endpoint, "key": "testing", "secret": "testing"}
        os.environ.update(JITROUTE_OBJECT_ROOT="s3://jitroute/bench", JITROUTE_STORAGE_OPTIONS=json.dumps(options))
        from flows.settings import load_settings
        from storage import cube

        layout = load_settings(data_root=root).layout.ensure()
        cycle_ds = cube.load_cycle(root0 / "cubes" / "weather.zarr", np.datetime64("2020-12-01T00", "ns"))
        cube.write_cycle(layout.cube_store, cycle_ds, complete=True, lock_dir=layout.cube_lock_dir,
                         storage_options=options)
        del cycle_ds
        _warm_numba(root, layout.weather_cube_url, options, ids, exports)
        import flows

        print(f"code: {Path(flows.__file__).parents[1]}; cube {layout.weather_cube_url} on {endpoint}")
        env = {k: v for k, v in os.environ.items() if not k.startswith("JITROUTE_")}
        env.update(PYTHONPATH=str(CODE), AWS_ENDPOINT_URL=endpoint, AWS_ACCESS_KEY_ID="testing",
                   AWS_SECRET_ACCESS_KEY="testing", NUMBA_NUM_THREADS="1")
        rows = {}
        for workers in sizes:
            port = _free_port()
            address = f"tcp://127.0.0.1:{port}"
            cluster = [_start([str(bin_ / "dask"), "scheduler", "--host", "127.0.0.1", "--port", str(port),
                               "--no-dashboard"], env, work / "scheduler.log", work / "elsewhere")]
            try:
                _wait_port(port, cluster[0], "the dask scheduler")
                for k in range(workers):
                    cluster.append(_start([str(bin_ / "dask"), "worker", address, "--nthreads", "1", "--no-nanny",
                                           "--no-dashboard", "--name", f"w{k}", "--local-directory",
                                           str(work / "elsewhere")], env, work / f"worker{k}.log", work / "elsewhere"))
                from distributed import Client

                # not the default client: the flow host's own dask computations (xarray in the weather maps) stay
                # in its process, as in production
                with Client(address, set_as_default=False) as client:
                    client.wait_for_workers(workers, timeout=300)
                    where = set(client.run(lambda: __import__("flows").__file__).values())
                    client.run(worker_cube_reads)  # counts from here: the warm-up meets the cube first
                    run(root, address, ids[: 2 * workers], exports)  # warm-up: imports in the workers
                    _s3_counts(endpoint, reset=True)
                    cpu0, main0 = _host_cpu_s(), _main_thread_cpu_s()
                    profiler = _host_profiler(profile_host)
                    seconds = run(root, address, ids, exports)
                    cpu, main_cpu = _host_cpu_s() - cpu0, _main_thread_cpu_s() - main0
                    if profiler is not None:
                        profiler.disable()
                        profiler.dump_stats(profile_host.with_suffix(f".{workers}w.prof"))
                    counts = _s3_counts(endpoint)
                    reads = list(client.run(worker_cube_reads).values())
                    caches = list(client.run(worker_chunk_cache).values())
                    memory = list(client.run(worker_memory).values())
                    peaks = [m["peak"] for m in memory]
                rows[workers] = (seconds, peaks, counts, cpu, where, reads, caches, memory)
                print(f"{workers} worker(s): flow host CPU {cpu:.2f} s in all, {main_cpu:.2f} s of it in the flow's "
                      f"thread, {cpu - main_cpu:.2f} s in its other threads (dask client, fsspec)")
            finally:
                _stop(cluster[::-1])
    finally:
        _stop(procs)
    n = n_voyages
    print(f"exports {'on' if exports else 'off'}, {n} voyages, workers `dask worker --nthreads 1 --no-nanny`, cube and exports on S3 (moto)")
    print("worker cube: what the workers fetched from the cube (GET bytes and requests, HEADs) per voyage routed, over "
          "the warm-up and the timed run (every fetch of the cycle); all cube: what the S3 server served under cubes/ "
          "in the timed run to everyone (the flow host's weather maps and cycle checks too) per voyage")
    print("peak worker MB: its RSS high-water mark; +pictures: that plus its picture process's (what a machine must "
          "hold for one worker, an upper bound: the two peaks need not coincide)")
    print(f"{'workers':>7} {'seconds':>8} {'voy/min':>8} {'peak worker MB':>14} {'+pictures MB':>12} "
          f"{'worker cube MB/voy':>18} {'GET/voy':>8} {'HEAD/voy':>8} {'all cube MB/voy':>15} {'export req/voy':>14} "
          f"{'host CPU s/voy':>14}")
    for w, (seconds, peaks, counts, cpu, where, reads, caches, memory) in rows.items():
        routed, peak = n + 2 * w, max(peaks)
        together = max(m["peak"] + (m["pictures"] or {}).get("peak", 0.0) for m in memory)
        cube_get = counts.get("GET cubes", {"requests": 0, "bytes": 0})
        export_req = sum(v["requests"] for k, v in counts.items() if k.endswith("exports"))
        print(f"{w:>7} {seconds:>8.1f} {n / seconds * 60:>8.1f} {peak:>14.0f} {together:>12.0f} "
              f"{sum(r['bytes'] for r in reads) / 1e6 / routed:>18.3f} {sum(r['get'] for r in reads) / routed:>8.1f} "
              f"{sum(r['head'] for r in reads) / routed:>8.1f} {cube_get['bytes'] / 1e6 / n:>15.3f} {export_req / n:>14.1f} "
              f"{cpu / n:>14.4f}")
    cycle_mb = stored_cycle_mb(root0)
    print(f"chunk cache of each worker over the cycle (warm-up and timed run): MB fetched from the store, MB of the "
          f"distinct chunks among them, their ratio (1.00: no chunk fetched twice; target ≤ 1.2), against the cycle's "
          f"{cycle_mb:.1f} MB stored (never more); peak MB of each worker")
    for w, (seconds, peaks, counts, cpu, where, reads, caches, memory) in rows.items():
        for k, (c, m) in enumerate(zip(caches, memory)):
            ratio = c["fetched_bytes"] / c["distinct_bytes"] if c["distinct_bytes"] else float("nan")
            print(f"  {w} worker(s), worker {k}: fetched {c['fetched_bytes'] / 1e6:.2f} MB, distinct "
                  f"{c['distinct_bytes'] / 1e6:.2f} MB, ratio {ratio:.2f}, cache bound {c['max_bytes'] / 2**20:.0f} MB; "
                  f"peak {m['peak']:.0f} MB; at the end Rss {m['rss']:.0f}, Pss {m['pss']:.0f}, private {m['private']:.0f}, "
                  f"anonymous {m['anonymous']:.0f} MB; imported {', '.join(m['imported'])}")
            if m.get("pictures"):
                p = m["pictures"]
                print(f"    its picture process: peak {p['peak']:.0f} MB; at the end Rss {p['rss']:.0f}, Pss {p['pss']:.0f} MB")
                print(f"    worker + picture process: peak {m['peak'] + p['peak']:.0f} MB (the sum of their peaks); at "
                      f"the end Rss {m['rss'] + p['rss']:.0f}, Pss {m['pss'] + p['pss']:.0f} MB")
    if 1 in rows and 2 in rows:
        print(f"scaling 1 → 2 workers: {rows[1][0] / rows[2][0]:.2f}×")
    print("S3 requests by kind in the last run:", json.dumps(rows[sizes[-1]][2], sort_keys=True))
    print("workers imported the code from:", ", ".join(sorted({str(Path(p).parents[1]) for r in rows.values() for p in r[4]})))


def main() -> None:
    import logging

    from distributed import Client, LocalCluster

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--voyages", type=int, default=200)
    ap.add_argument("--workers", default="1,2", help="cluster sizes to time, comma separated")
    ap.add_argument("--exports", action="store_true",
                    help="workers also render each voyage's RTZ, GeoJSON and PNGs, as the demo and the nightly do")
    ap.add_argument("--s3", action="store_true", help="scheduler and worker processes, cube and exports on a local S3")
    ap.add_argument("--code", default=str(REPO), help="checkout whose code runs (default this one)")
    ap.add_argument("--profile-host", type=Path, default=None, metavar="FILE",
                    help="with --s3: cProfile the flow host's timed run into FILE.<N>w.prof (its CPU figure then "
                         "includes the profiler's overhead)")
    args = ap.parse_args()
    sizes = [int(w) for w in args.workers.split(",")]
    os.environ.setdefault("PREFECT_LOGGING_LEVEL", "WARNING")
    OUT.mkdir(parents=True, exist_ok=True)
    os.environ.setdefault("PREFECT_HOME", str(OUT / "prefect"))
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")
    os.environ.setdefault("PREFECT_SERVER_ANALYTICS_ENABLED", "false")
    if args.s3:
        s3_processes(args.voyages, sizes, args.exports, args.profile_host)
        return
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
