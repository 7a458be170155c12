"""What one write to the warehouse costs as `route_legs` grows: the analysts' snapshot is republished after every
write (storage/warehouse.py `connect`: the DuckDB file is read whole to check it, checkpointed, copied byte for
byte, and the copy read whole again before it replaces the snapshot), so a write's cost follows the DuckDB file's size.

Builds a warehouse (migrated as in production) under bench/out/snapshot, fills the history with synthetic runs of
200 voyages × 40 legs (one year of nightly runs at fleet scale ≈ 10 M legs: `--legs 0,1000000,10000000`), each run
with its 200 `routes` rows and its `route_runs` row, and times one small write (a `route_runs` row, through
`warehouse.connect`) at each size: wall and CPU seconds (this process, DuckDB's threads included), the DuckDB
file's MB and the legs' Parquet files' MB. The legs go where the checkout keeps them: the `route_legs` table of a
checkout before storage/route_history.py, one Parquet file per run (`route_history.write_part`) since; `--code DIR`
runs another checkout (e.g. `git archive` of an older commit) for a before/after in one sitting.

    .venv/bin/python bench/snapshot.py [--legs 0,1000000,10000000] [--code DIR]
"""

from __future__ import annotations

import argparse
import resource
import shutil
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "bench" / "out" / "snapshot"
LEGS_PER_RUN = 8000  # 200 voyages × 40 legs


def _cpu_s() -> float:
    ru = resource.getrusage(resource.RUSAGE_SELF)
    return ru.ru_utime + ru.ru_stime


_LEGS_SQL = """
    SELECT 'run' || lpad(CAST((i // 8000) AS VARCHAR), 5, '0') AS run_id, 'V' || CAST((i // 40) % 200 AS VARCHAR) AS voyage_id,
           CAST(i % 40 AS INTEGER) AS leg, 30 + (i % 17) * 0.1 AS lat0, 140 + (i % 23) * 0.1 AS lon0, 30.1 + (i % 17) * 0.1 AS lat1,
           140.1 + (i % 23) * 0.1 AS lon1, (i % 360)::DOUBLE AS course_deg, 55.5 AS dist_nm, 70.0 AS rpm, 12.1 AS stw_kn,
           11.8 AS sog_kn, 4.6 AS hours, 1.23 AS fuel_t,
           TIMESTAMP '2020-01-01' + to_hours(CAST(i // 8000 * 24 + i % 40 * 5 AS BIGINT)) AS etd_utc,
           TIMESTAMP '2020-01-01' + to_hours(CAST(i // 8000 * 24 + i % 40 * 5 + 5 AS BIGINT)) AS eta_utc,
           15.0 AS wind_kn, 270.0 AS wind_dir_deg, 2.1 AS hs_m, 250.0 AS wave_dir_deg, 0.4 AS current_kn,
           false AS beyond_forecast, 0.0 AS hours_beyond_forecast, 0.0 AS hours_before_cycle, 0.0 AS hours_without_wind
    FROM range({a}, {b}) t(i)"""


def fill_runs(con, first_leg: int, n_legs: int) -> None:
    """Append synthetic runs holding legs `first_leg` … `first_leg + n_legs - 1` (whole runs of 8,000 legs), each
    with its route_runs row and 200 routes rows; the legs into the route_legs table or, where the checkout keeps
    them in Parquet, one file per run through `route_history.write_part`."""
    in_table = con.execute("SELECT table_type FROM information_schema.tables WHERE table_name = 'route_legs'"
                           ).fetchone()[0] == "BASE TABLE"
    columns = [r[0] for r in con.execute("SELECT column_name FROM information_schema.columns "
                                         "WHERE table_name = 'route_legs' ORDER BY ordinal_position").fetchall()]
    for r in range(first_leg // LEGS_PER_RUN, (first_leg + n_legs) // LEGS_PER_RUN):
        run_id = f"run{r:05d}"
        con.execute("INSERT INTO route_runs (run_id, started_at, status, n_voyages, n_ok, n_failed) "
                    "VALUES (?, TIMESTAMP '2020-01-01' + to_days(?), 'ok', 200, 200, 0)", [run_id, r])
        con.execute("INSERT INTO routes (run_id, voyage_id, imo, status, depart_utc, eta_utc, rta_utc, hours, fuel_t, "
                    "distance_nm, n_legs) SELECT ?, 'V' || CAST(v AS VARCHAR), 9000000 + v, 'ok', "
                    "TIMESTAMP '2020-01-01' + to_days(?), TIMESTAMP '2020-01-09' + to_days(?), "
                    "TIMESTAMP '2020-01-09' + to_days(?), 200.0, 49.2, 2220.0, 40 FROM range(200) t(v)",
                    [run_id, r, r, r])
        legs = _LEGS_SQL.format(a=r * LEGS_PER_RUN, b=(r + 1) * LEGS_PER_RUN)
        if in_table:
            con.execute(f"INSERT INTO route_legs SELECT {', '.join(columns)} FROM ({legs})")
        else:
            from storage import route_history

            part = route_history.write_part(con, route_history.history_dir(route_history.warehouse_file(con)),
                                            run_id, f"SELECT {', '.join(columns)} FROM ({legs})")
            route_history.record_parts(con, [part])


def _parquet_mb(db: Path) -> float:
    folder = db.with_name(db.stem + ".history")
    return sum(f.stat().st_size for f in folder.rglob("*.parquet")) / 1e6 if folder.exists() else 0.0


def timed_write(db: Path) -> tuple[float, float]:
    from storage import warehouse

    w0, c0 = time.perf_counter(), _cpu_s()
    with warehouse.connect(db) as con:
        con.execute("INSERT INTO route_runs (run_id, started_at, status) VALUES (?, now(), 'ok')",
                    [f"bench-{time.time_ns()}"])
    return time.perf_counter() - w0, _cpu_s() - c0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--legs", default="0,1000000,10000000", help="route_legs sizes, comma separated, increasing "
                                                                "(rounded down to whole runs of 8,000 legs)")
    ap.add_argument("--code", type=Path, default=REPO, help="checkout whose storage/ is measured (default: this one)")
    args = ap.parse_args()
    sys.path.insert(0, str(args.code.resolve()))
    from storage import warehouse

    print(f"code: {warehouse.__file__}")
    shutil.rmtree(OUT, ignore_errors=True)
    OUT.mkdir(parents=True)
    db = OUT / "warehouse.duckdb"
    with warehouse.connect(db):
        pass
    print("one small write through warehouse.connect (check, checkpoint, snapshot copy, check of the copy); "
          "wall and CPU seconds, best of 2")
    print(f"{'route_legs rows':>15} {'routes rows':>11} {'DuckDB MB':>9} {'legs Parquet MB':>15} {'wall s':>7} {'CPU s':>7}")
    have = 0
    for n in (int(x) // LEGS_PER_RUN * LEGS_PER_RUN for x in args.legs.split(",")):
        if n > have:
            import duckdb

            con = duckdb.connect(str(db))
            fill_runs(con, have, n - have)
            con.execute("CHECKPOINT")
            con.close()
            have = n
        times = [timed_write(db) for _ in range(2)]
        wall, cpu = min(times)
        print(f"{n:>15,} {n // 40:>11,} {db.stat().st_size / 1e6:>9.1f} {_parquet_mb(db):>15.2f} {wall:>7.2f} {cpu:>7.2f}",
              flush=True)


if __name__ == "__main__":
    main()
