"""Cube chunking for voyage windows: bytes fetched and CPU per voyage for a few (lat, lon) chunk shapes.

Takes the demo cycle of bench/fleet.py's data root (built there once) and the windows of its 200 voyages (each
voyage's steps and lat/lon box, as a routing worker asks for them), writes the same cycle into one store per
chunking under bench/out/cube_chunks, and reads every window through storage/cube_window.py:

- cold: the chunk cache emptied before each voyage (a worker's first voyage in a region): bytes and chunk files
  fetched per voyage, CPU per voyage (fetch + decompress + cut out the window);
- one worker: all voyages in turn with the process's chunk cache (its default bound): bytes fetched per voyage and
  in all, against the window bytes (what the voyages' windows cover, float32) and the cycle's stored size.

    .venv/bin/python bench/cube_chunks.py [--voyages 200]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
OUT = REPO / "bench" / "out" / "cube_chunks"
CYCLE = "2020-12-01T00"


def windows(root: Path, n: int) -> list:
    """The weather windows of the bench fleet's first `n` voyages, as routing asks for them."""
    import numpy as np

    from flows.jobs.fleet import fleet_jobs
    from flows.settings import load_settings
    from pipeline.routing.job import RoutingOptions, routing_problem

    s = load_settings(data_root=root)
    ids = [f"B{k:04d}" for k in range(n)]
    jobs = fleet_jobs(s, s.layout.warehouse, np.datetime64(CYCLE, "ns"), "bench", ids,
                      RoutingOptions.from_settings(s.routing), False)
    out = []
    for job in jobs:
        problem = routing_problem(job)
        out.append(problem.weather_window(problem.search_space()))
    return out


def store_for(root: Path, shape: tuple[int, int, int]) -> Path:
    """The demo cycle in a store chunked (1, *shape) = (1, steps, lat, lon), written once."""
    import numpy as np

    from storage import cube

    path = OUT / f"weather_{shape[0]}x{shape[1]}x{shape[2]}.zarr"
    if not (path / "zarr.json").exists():
        ds = cube.load_cycle(root / "cubes" / "weather.zarr", np.datetime64(CYCLE, "ns"))
        cube.write_cycle(path, ds, complete=True, chunks=shape)
    return path


def stored_bytes(path: Path, variables) -> int:
    return sum(f.stat().st_size for v in variables for f in (path / v / "c").rglob("*") if f.is_file())


def measure(path: Path, wins: list) -> dict:
    import numpy as np

    from pipeline.routing import weather_field as wf
    from storage import cube_window

    cache = cube_window.CHUNK_CACHE
    pub = cube_window.open_published(path)
    c = np.datetime64(CYCLE, "ns")

    def read(w):
        return cube_window.read_window(path, c, valid_utc=(w.from_utc, w.to_utc), lat_deg=w.lat_deg, lon_deg=w.lon_deg,
                                       variables=wf.CUBE_VARIABLES, published=pub)

    cold_bytes, cold_chunks, cold_cpu, covered = [], [], [], []
    union = np.zeros((pub.step_h.size, pub.lat.size, pub.lon.size), bool)  # the cells any window covers
    for w in wins:
        cache.clear()
        t0 = time.process_time()
        win = read(w)
        cold_cpu.append(time.process_time() - t0)
        cold_bytes.append(cache.fetched_bytes)
        cold_chunks.append(cache.fetched_chunks)
        covered.append(sum(a.nbytes for a in win.data.values()))
        steps = np.isin(pub.step_h, win.step_h)
        rows = np.isin(pub.lat, win.lat)
        cols = np.isin(pub.lon, np.mod(win.lon, 360.0))
        union |= steps[:, None, None] & rows[None, :, None] & cols[None, None, :]
    cache.clear()
    t0 = time.process_time()
    for w in wins:
        read(w)
    warm_cpu = time.process_time() - t0
    return {"cold_mb": np.mean(cold_bytes) / 1e6, "cold_chunks": np.mean(cold_chunks), "cold_ms": 1e3 * np.mean(cold_cpu),
            "covered_mb": np.mean(covered) / 1e6, "worker_mb": cache.fetched_bytes / 1e6 / len(wins),
            "worker_total_mb": cache.fetched_bytes / 1e6, "worker_ms": 1e3 * warm_cpu / len(wins),
            "cycle_mb": stored_bytes(path, wf.CUBE_VARIABLES) / 1e6, "union_share": union.mean()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--voyages", type=int, default=200)
    args = ap.parse_args()
    os.environ.setdefault("PREFECT_LOGGING_LEVEL", "WARNING")
    os.environ.setdefault("PREFECT_HOME", str(REPO / "bench" / "out" / "fleet" / "prefect"))
    from bench.fleet import prepare
    from storage import cube_window

    root = prepare(args.voyages)
    OUT.mkdir(parents=True, exist_ok=True)
    wins = windows(root, args.voyages)
    nstep, nlat, nlon = 23, 321, 720  # the default 0.5° grid, −80…80, 0–132 h
    shapes = {"3×3 (before)": (nstep, -(-nlat // 3), -(-nlon // 3)), "8×8": (nstep, -(-nlat // 8), -(-nlon // 8)),
              "16×16": (nstep, -(-nlat // 16), -(-nlon // 16)), "8×8, 8 steps": (8, -(-nlat // 8), -(-nlon // 8)),
              "16×16, 8 steps": (8, -(-nlat // 16), -(-nlon // 16))}
    print(f"{len(wins)} voyages, cycle {CYCLE}, variables a voyage reads; chunk cache bound "
          f"{cube_window.CHUNK_CACHE.max_bytes / 2**20:.0f} MB; CPU is process time")
    print("covered MB: the cycle's stored MB × the share of its cells (step, lat, lon) inside any window; "
          "ratio: what one worker fetched for all the voyages / covered MB (target ≤ 1.2)")
    print(f"{'chunking':<22} {'chunk':>9} {'cycle MB':>9} | {'cold: MB':>9} {'chunks':>7} {'CPU ms':>7} | "
          f"{'window MB':>9} | {'1 worker: MB/voy':>16} {'total MB':>9} {'CPU ms/voy':>10} | {'covered MB':>10} {'ratio':>6}")
    for name, shape in shapes.items():
        m = measure(store_for(root, shape), wins)
        print(f"{name:<22} {shape[1]:>4}×{shape[2]:<4} {m['cycle_mb']:>9.1f} | {m['cold_mb']:>9.2f} {m['cold_chunks']:>7.1f} "
              f"{m['cold_ms']:>7.1f} | {m['covered_mb']:>9.2f} | {m['worker_mb']:>16.3f} {m['worker_total_mb']:>9.1f} "
              f"{m['worker_ms']:>10.1f} | {m['union_share'] * m['cycle_mb']:>10.2f} "
              f"{m['worker_total_mb'] / (m['union_share'] * m['cycle_mb']):>6.2f}")


if __name__ == "__main__":
    main()
