"""What one write to the warehouse costs as `route_legs` grows: the analysts' snapshot is republished after every
write (storage/warehouse.py `connect`: the warehouse is read whole to check it, checkpointed, copied byte for byte,
and the copy read whole again before it replaces the snapshot), so a write's cost follows the archive's size.

Builds a warehouse (migrated as in production) under bench/out/snapshot, fills `route_legs` with synthetic legs
(one year of nightly runs ≈ 10 M rows and more at fleet scale: `--legs 0,1000000,10000000`), and times one small
write (a `route_runs` row, through `warehouse.connect`) at each size: wall and CPU seconds (this process, DuckDB's
threads included), the warehouse and snapshot MB.

    .venv/bin/python bench/snapshot.py [--legs 0,1000000,10000000]
"""

from __future__ import annotations

import argparse
import resource
import shutil
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
OUT = REPO / "bench" / "out" / "snapshot"


def _cpu_s() -> float:
    ru = resource.getrusage(resource.RUSAGE_SELF)
    return ru.ru_utime + ru.ru_stime


def fill_legs(con, first: int, n: int, batch: int = 2_000_000) -> None:
    """Append synthetic legs `first` … `first + n - 1`: 40 legs a voyage, 200 voyages a run, one run a night."""
    done, n = first, first + n
    while done < n:
        k = min(batch, n - done)
        con.execute(f"""
            INSERT INTO route_legs
            SELECT 'run' || lpad(CAST((i // 8000) AS VARCHAR), 5, '0'), 'V' || CAST((i // 40) % 200 AS VARCHAR),
                   CAST(i % 40 AS INTEGER), 30 + (i % 17) * 0.1, 140 + (i % 23) * 0.1, 30.1 + (i % 17) * 0.1,
                   140.1 + (i % 23) * 0.1, (i % 360)::DOUBLE, 55.5, 70.0, 12.1, 11.8, 4.6, 1.23,
                   TIMESTAMP '2020-01-01' + to_hours(CAST(i // 8000 * 24 + i % 40 * 5 AS BIGINT)),
                   TIMESTAMP '2020-01-01' + to_hours(CAST(i // 8000 * 24 + i % 40 * 5 + 5 AS BIGINT)),
                   15.0, 270.0, 2.1, 250.0, 0.4, false
            FROM range({done}, {done + k}) t(i)""")
        done += k


def timed_write(db: Path) -> tuple[float, float]:
    from storage import warehouse

    w0, c0 = time.perf_counter(), _cpu_s()
    with warehouse.connect(db) as con:
        con.execute("INSERT INTO route_runs (run_id, started_at, status) VALUES (?, now(), 'ok')",
                    [f"bench-{time.time_ns()}"])
    return time.perf_counter() - w0, _cpu_s() - c0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--legs", default="0,1000000,10000000", help="route_legs sizes, comma separated, increasing")
    args = ap.parse_args()
    from storage import warehouse

    shutil.rmtree(OUT, ignore_errors=True)
    OUT.mkdir(parents=True)
    db = OUT / "warehouse.duckdb"
    with warehouse.connect(db):
        pass
    print("one small write through warehouse.connect (check, checkpoint, snapshot copy, check of the copy); "
          "wall and CPU seconds, best of 2")
    print(f"{'route_legs rows':>15} {'warehouse MB':>12} {'wall s':>7} {'CPU s':>7}")
    have = 0
    for n in (int(x) for x in args.legs.split(",")):
        if n > have:
            import duckdb

            con = duckdb.connect(str(db))
            fill_legs(con, have, n - have)
            con.execute("CHECKPOINT")
            con.close()
            have = n
        times = [timed_write(db) for _ in range(2)]
        wall, cpu = min(times)
        print(f"{n:>15,} {db.stat().st_size / 1e6:>12.0f} {wall:>7.2f} {cpu:>7.2f}", flush=True)


if __name__ == "__main__":
    main()
