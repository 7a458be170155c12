"""Persistence of fleet routing runs: DuckDB tables `route_runs`, `routes`, `route_legs` and one
Parquet dataset per table, hive-partitioned by run: `exports/routes/<table>/run_id=<id>/part-0.parquet`.

One writer: the flow collects every voyage's rows and calls `write_run_results` once, inside
one transaction, so a killed run leaves either all of a run's rows or none. The Parquet files follow
the commit; each appears whole (written under a hidden name, then renamed). Their column types are
fixed here (`ROUTE_ARROW`, `LEG_ARROW`): times `timestamp[us, tz=UTC]`, and a column name shared by
both tables has the same type in both, so pyarrow, polars and DuckDB read each folder as one table.
"""

from __future__ import annotations

import contextlib
import os
import socket
from datetime import datetime, timezone
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from storage import warehouse

_UTC = pa.timestamp("us", tz="UTC")
_F64, _I32, _STR = pa.float64(), pa.int32(), pa.string()

# The Parquet columns of each table (the partition column run_id is the folder name, not in the file).
ROUTE_ARROW = pa.schema([
    ("voyage_id", _STR), ("imo", pa.int64()), ("solver", _STR), ("objective", _STR), ("status", _STR),
    ("reason", _STR), ("depart_utc", _UTC), ("eta_utc", _UTC), ("rta_utc", _UTC), ("hours", _F64),
    ("fuel_t", _F64), ("baseline_fuel_t", _F64), ("baseline_hours", _F64), ("savings_pct", _F64),
    ("distance_nm", _F64), ("cost", _F64), ("model_version", _I32), ("cycle", _UTC), ("seed", _I32),
    ("runtime_s", _F64), ("n_legs", _I32), ("n_legs_beyond_forecast", _I32), ("forecast_flag", _STR),
    ("hours_beyond_forecast", _F64), ("hours_before_cycle", _F64), ("min_land_clearance_nm", _F64),
    ("honest_baseline_rpm", _F64), ("honest_baseline_fuel_t", _F64), ("honest_baseline_hours", _F64),
    ("profile_fuel_t", _F64), ("savings_total_pct", _F64), ("savings_speed_profile_pct", _F64),
    ("savings_route_pct", _F64), ("min_engine_hold_h", _F64), ("engine_change_cost_t", _F64),
    ("n_engine_changes", _I32), ("unlimited_fuel_t", _F64), ("limits_fuel_t", _F64),
    ("start_kind", _STR), ("start_lat", _F64), ("start_lon", _F64), ("start_utc", _UTC), ("start_position_utc", _UTC),
    ("start_advanced_h", _F64), ("start_note", _STR), ("voyage_fingerprint", _STR),
])
LEG_ARROW = pa.schema([
    ("voyage_id", _STR), ("leg", _I32), ("lat0", _F64), ("lon0", _F64), ("lat1", _F64), ("lon1", _F64),
    ("course_deg", _F64), ("dist_nm", _F64), ("rpm", _F64), ("stw_kn", _F64), ("sog_kn", _F64), ("hours", _F64),
    ("fuel_t", _F64), ("etd_utc", _UTC), ("eta_utc", _UTC), ("wind_kn", _F64), ("wind_dir_deg", _F64),
    ("hs_m", _F64), ("wave_dir_deg", _F64), ("current_kn", _F64), ("beyond_forecast", pa.bool_()),
])
ROUTE_COLUMNS = ["run_id", *ROUTE_ARROW.names]
LEG_COLUMNS = ["run_id", *LEG_ARROW.names]
PARQUET_TABLES = {"routes": ROUTE_ARROW, "route_legs": LEG_ARROW}


def _utcnow() -> datetime:
    return datetime.now(timezone.utc).replace(tzinfo=None)


def _frame(rows: list[dict], columns: list[str], run_id: str) -> pd.DataFrame:
    """The rows as the warehouse takes them: times UTC, tz-aware, to the microsecond (DuckDB TIMESTAMP's resolution)."""
    df = pd.DataFrame.from_records(rows, columns=columns)
    df["run_id"] = run_id
    for c in columns:
        if c.endswith("_utc") or c == "cycle":
            df[c] = pd.to_datetime(df[c], utc=True).dt.floor("us")
    return df


def _naive_utc(df: pd.DataFrame) -> pd.DataFrame:
    """The frame with its tz-aware columns as naive UTC, as the warehouse's TIMESTAMP columns hold them."""
    return df.assign(**{c: df[c].dt.tz_localize(None) for c in df.columns if isinstance(df[c].dtype, pd.DatetimeTZDtype)})


def parquet_dir(exports_dir: Path, table: str) -> Path:
    """The dataset folder of `table` ("routes" or "route_legs"): one `run_id=<id>/part-0.parquet` per run."""
    return Path(exports_dir) / "routes" / table


def _publish_parquet(df: pd.DataFrame, schema: pa.Schema, folder: Path) -> Path:
    """Write `df` as `folder/part-0.parquet`, whole or not at all (a hidden temp name, then a rename)."""
    folder.mkdir(parents=True, exist_ok=True)
    final = folder / "part-0.parquet"
    tmp = folder / f".part-0.parquet.tmp{os.getpid()}"
    try:
        pq.write_table(pa.Table.from_pandas(df[schema.names], schema=schema, preserve_index=False), tmp)
        os.replace(tmp, final)
    finally:
        tmp.unlink(missing_ok=True)
    return final


def _publish_run_parquet(exports_dir: Path, run_id: str, tables: dict[str, pd.DataFrame]) -> None:
    for table, df in tables.items():
        _publish_parquet(df, PARQUET_TABLES[table], parquet_dir(exports_dir, table) / f"run_id={run_id}")


def migrate_old_parquet_layout(exports_dir: Path) -> list[str]:
    """Move runs written as `exports/routes/run_id=<id>/{routes,route_legs}.parquet` (both tables in one folder,
    naive times, `beyond_forecast` counting legs in routes) into the per-table datasets; returns the run ids moved."""
    moved = []
    for old in sorted((Path(exports_dir) / "routes").glob("run_id=*")):
        run_id = old.name.removeprefix("run_id=")
        tables = {}
        for table in PARQUET_TABLES:
            f = old / f"{table}.parquet"
            if f.exists():
                df = pd.read_parquet(f)
                if table == "routes":
                    df = df.rename(columns={"beyond_forecast": "n_legs_beyond_forecast"})
                tables[table] = _frame(df.reindex(columns=PARQUET_TABLES[table].names).to_dict("records"),
                                       PARQUET_TABLES[table].names, run_id)
        _publish_run_parquet(exports_dir, run_id, tables)
        for table in PARQUET_TABLES:
            (old / f"{table}.parquet").unlink(missing_ok=True)
        with contextlib.suppress(OSError):  # a folder holding anything else is left as it is
            old.rmdir()
        moved.append(run_id)
    return moved


def process_started(pid: int) -> str | None:
    """The start time of process `pid` (clock ticks after boot, from /proc), None when it does not exist."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return stat.rsplit(")", 1)[1].split()[19]  # field 22 (starttime); the name in (…) may hold spaces


def process_alive(pid: int | None, started: str | None) -> bool:
    """Process `pid` exists and is the one that started at `started` (not a later process given the same PID)."""
    if not pid:
        return False
    now = process_started(int(pid))
    return now is not None and (started is None or now == started)


def begin_run(db_path: Path, run_id: str, *, cycle, solver: str, trigger: str, n_voyages: int,
              nominal_utc=None, cycle_age_h: float | None = None) -> None:
    """Record a run as `running`, owned by this host and process (see `reap_dead_runs`), with the cycle's age
    (hours) at the run's nominal time."""
    pid = os.getpid()
    with warehouse.connect(db_path) as con:
        con.execute(
            "INSERT INTO route_runs (run_id, started_at, cycle, n_voyages, status, solver, trigger, host, pid, pid_started, "
            "nominal_utc, cycle_age_h) VALUES (?, ?, ?, ?, 'running', ?, ?, ?, ?, ?, ?, ?)",
            [run_id, _utcnow(), pd.Timestamp(cycle).to_pydatetime() if cycle is not None else None,
             n_voyages, solver, trigger, socket.gethostname(), pid, process_started(pid),
             pd.Timestamp(nominal_utc).to_pydatetime() if nominal_utc is not None else None, cycle_age_h],
        )


def current_plan_legs(db_path: Path, voyage_ids: list[str]) -> dict[str, list[dict]]:
    """voyage_id → the legs (lat0, lon0, lat1, lon1, etd_utc, eta_utc) of its current plan in `latest_routes`
    (voyages without a plan are absent)."""
    if not voyage_ids:
        return {}
    with warehouse.connect(db_path, write=False) as con:
        df = con.execute(
            "SELECT l.voyage_id, l.leg, l.lat0, l.lon0, l.lat1, l.lon1, l.etd_utc, l.eta_utc "
            "FROM route_legs l JOIN latest_routes r USING (run_id, voyage_id) "
            "WHERE r.status IN ('ok', 'late') AND l.voyage_id IN (SELECT unnest(?)) ORDER BY l.voyage_id, l.leg",
            [list(voyage_ids)]).fetchdf()
    out: dict[str, list[dict]] = {}
    for rec in df.to_dict("records"):
        out.setdefault(str(rec["voyage_id"]), []).append(rec)
    return out


def stale_plans(db_path: Path) -> list[dict]:
    """Current plans (latest_routes) made for a voyage that has changed since: voyage_id, imo, status, reason."""
    with warehouse.connect(db_path, write=False) as con:
        return con.execute(
            "SELECT voyage_id, imo, 'stale' AS status, stale_reason AS reason FROM latest_routes WHERE stale "
            "ORDER BY voyage_id").fetchdf().to_dict("records")


def reap_dead_runs(con) -> list[str]:
    """Mark this host's `running` runs whose process is gone as failed ("process died"); returns their ids.

    Called by every writer connection (storage.warehouse.connect), so a SIGKILLed run is settled by the
    next command that opens the warehouse. Runs of other hosts are left to their own host.
    """
    try:
        rows = con.execute("SELECT run_id, pid, pid_started FROM route_runs WHERE status = 'running' AND host = ?",
                           [socket.gethostname()]).fetchall()
    except Exception:  # a warehouse older than the owner columns (before its migration)
        return []
    dead = [(rid, pid) for rid, pid, started in rows if not process_alive(pid, started)]
    for rid, pid in dead:
        con.execute("UPDATE route_runs SET status = 'failed', finished_at = ?, reason = ? WHERE run_id = ?",
                    [_utcnow(), f"process died (host {socket.gethostname()}, pid {pid} no longer runs)", rid])
    return [rid for rid, _pid in dead]


def running_run_ids(db_path: Path) -> set[str]:
    with warehouse.connect(db_path, write=False) as con:
        return {r[0] for r in con.execute("SELECT run_id FROM route_runs WHERE status = 'running'").fetchall()}


def write_run_results(db_path: Path, exports_dir: Path, run_id: str, route_rows: list[dict],
                      leg_rows: list[dict], export_errors: list[str] | None = None) -> tuple[int, int]:
    """Write all rows of a run in one transaction, then its Parquet files; returns (n_ok, n_failed).

    `export_errors`: one line per export that failed (voyage, kind, error), kept with the run."""
    routes = _frame(route_rows, ROUTE_COLUMNS, run_id)
    legs = _frame(leg_rows, LEG_COLUMNS, run_id)
    n_ok = int(routes["status"].isin(["ok", "late"]).sum()) if len(routes) else 0
    n_failed = len(routes) - n_ok
    status = "ok" if n_failed == 0 else ("failed" if n_ok == 0 else "partial")
    with warehouse.connect(db_path) as con:
        with warehouse.transaction(con):
            con.register("routes_df", _naive_utc(routes))
            con.register("legs_df", _naive_utc(legs))
            con.execute(f"INSERT INTO routes ({', '.join(ROUTE_COLUMNS)}) SELECT {', '.join(ROUTE_COLUMNS)} FROM routes_df")
            con.execute(f"INSERT INTO route_legs ({', '.join(LEG_COLUMNS)}) SELECT {', '.join(LEG_COLUMNS)} FROM legs_df")
            con.execute(
                "UPDATE route_runs SET finished_at = ?, n_ok = ?, n_failed = ?, status = ?, n_export_failed = ?, "
                "export_errors = ? WHERE run_id = ?",
                [_utcnow(), n_ok, n_failed, status, len(export_errors or []),
                 "\n".join(export_errors) if export_errors else None, run_id],
            )
    migrate_old_parquet_layout(exports_dir)
    _publish_run_parquet(exports_dir, run_id, {"routes": routes, "route_legs": legs})
    return n_ok, n_failed


def fail_run(db_path: Path, run_id: str, reason: str) -> None:
    """Mark a run failed with the reason (e.g. no cube, interrupted); nothing else of it was written."""
    with warehouse.connect(db_path) as con:
        con.execute("UPDATE route_runs SET finished_at = ?, status = 'failed', reason = ? WHERE run_id = ?",
                    [_utcnow(), reason[:2000], run_id])


def run_summary(db_path: Path, run_id: str) -> dict:
    """The run's row, counts and fuel-weighted savings (as the fleet_savings view), and the voyages needing attention."""
    with warehouse.connect(db_path, write=False) as con:
        run = con.execute("SELECT * FROM route_runs WHERE run_id = ?", [run_id]).fetchdf()
        totals = con.execute(
            """SELECT count(*) AS n, count(*) FILTER (WHERE status = 'ok') AS n_ok,
                      count(*) FILTER (WHERE status = 'late') AS n_late,
                      count(*) FILTER (WHERE status NOT IN ('ok', 'late')) AS n_failed,
                      count(*) FILTER (WHERE coalesce(start_kind, 'port') = 'port') AS n_from_port,
                      count(*) FILTER (WHERE coalesce(start_kind, 'port') <> 'port') AS n_replanned,
                      sum(fuel_t) AS fuel_t
               FROM routes WHERE run_id = ?""",
            [run_id],
        ).fetchdf()
        savings = con.execute(
            "SELECT n_compared, honest_baseline_fuel_t, profile_fuel_t, savings_total_pct, savings_speed_profile_pct, "
            "savings_route_pct, limits_fuel_t, unlimited_fuel_t, discrete_baseline_fuel_t, savings_vs_discrete_pct "
            "FROM fleet_savings WHERE run_id = ?",
            [run_id],
        ).fetchdf()
        problems = con.execute(
            "SELECT voyage_id, imo, CASE WHEN status = 'ok' THEN 'ok, ' || forecast_flag ELSE status END AS status, reason "
            "FROM routes WHERE run_id = ? AND (status <> 'ok' OR forecast_flag IS NOT NULL) ORDER BY voyage_id",
            [run_id],
        ).fetchdf()
        # voyages made by a fleet plan (voyages.plan_id): which plans the run routed, and how many of their voyages
        from_plans = dict(con.execute(
            "SELECT v.plan_id, count(*) FROM routes r JOIN voyages v USING (voyage_id) "
            "WHERE r.run_id = ? AND v.plan_id IS NOT NULL GROUP BY v.plan_id ORDER BY v.plan_id", [run_id]).fetchall())
    out = run.iloc[0].to_dict() if len(run) else {"run_id": run_id}
    out.update({k: (int(v) if k.startswith("n") and v == v else v) for k, v in totals.iloc[0].to_dict().items()})
    if len(savings):
        out.update({k: (None if v is None or v != v else (int(v) if k.startswith("n_") else float(v)))
                    for k, v in savings.iloc[0].to_dict().items()})
    out["problems"] = problems.to_dict("records")
    out["stale"] = stale_plans(db_path)
    out["from_plans"] = {str(k): int(v) for k, v in from_plans.items()}
    errors = out.get("export_errors")
    out["export_failures"] = errors.splitlines() if isinstance(errors, str) and errors else []
    if out.get("cycle") is not None and out.get("cycle") == out.get("cycle"):
        out["cycle"] = pd.Timestamp(out["cycle"]).strftime("%Y-%m-%dT%H")
    return out
