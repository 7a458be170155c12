"""Persistence of fleet routing runs: DuckDB tables `route_runs`, `routes`, `route_legs` and
Parquet partitions `exports/routes/run_id=<id>/{routes,route_legs}.parquet`.

One writer: the flow collects every voyage's rows and calls `write_run_results` once, inside
one transaction, so a killed run leaves either all of a run's rows or none.
"""

from __future__ import annotations

import os
import socket
from datetime import datetime, timezone
from pathlib import Path

import pandas as pd

from storage import warehouse

ROUTE_COLUMNS = [
    "run_id", "voyage_id", "imo", "solver", "objective", "status", "reason", "depart_utc", "eta_utc",
    "rta_utc", "hours", "fuel_t", "baseline_fuel_t", "baseline_hours", "savings_pct", "distance_nm",
    "cost", "model_version", "cycle", "seed", "runtime_s", "n_legs", "beyond_forecast", "forecast_flag",
    "hours_beyond_forecast", "hours_before_cycle", "honest_baseline_rpm", "honest_baseline_fuel_t",
    "honest_baseline_hours", "profile_fuel_t", "savings_total_pct", "savings_speed_profile_pct", "savings_route_pct",
    "min_engine_hold_h", "engine_change_cost_t", "n_engine_changes", "unlimited_fuel_t", "limits_fuel_t",
]
LEG_COLUMNS = [
    "run_id", "voyage_id", "leg", "lat0", "lon0", "lat1", "lon1", "course_deg", "dist_nm", "rpm",
    "stw_kn", "sog_kn", "hours", "fuel_t", "etd_utc", "eta_utc", "wind_kn", "wind_dir_deg", "hs_m",
    "wave_dir_deg", "current_kn", "beyond_forecast",
]


def _utcnow() -> datetime:
    return datetime.now(timezone.utc).replace(tzinfo=None)


def _frame(rows: list[dict], columns: list[str], run_id: str) -> pd.DataFrame:
    df = pd.DataFrame.from_records(rows, columns=columns)
    df["run_id"] = run_id
    for c in columns:
        if c.endswith("_utc") or c == "cycle":
            df[c] = pd.to_datetime(df[c], utc=True).dt.tz_localize(None)
    return df


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


def begin_run(db_path: Path, run_id: str, *, cycle, solver: str, trigger: str, n_voyages: int) -> None:
    """Record a run as `running`, owned by this host and process (see `reap_dead_runs`)."""
    pid = os.getpid()
    with warehouse.connect(db_path) as con:
        con.execute(
            "INSERT INTO route_runs (run_id, started_at, cycle, n_voyages, status, solver, trigger, host, pid, pid_started) "
            "VALUES (?, ?, ?, ?, 'running', ?, ?, ?, ?, ?)",
            [run_id, _utcnow(), pd.Timestamp(cycle).to_pydatetime() if cycle is not None else None,
             n_voyages, solver, trigger, socket.gethostname(), pid, process_started(pid)],
        )


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
    """Write all rows of a run in one transaction, then the Parquet partition; returns (n_ok, n_failed).

    `export_errors`: one line per export that failed (voyage, kind, error), kept with the run."""
    routes = _frame(route_rows, ROUTE_COLUMNS, run_id)
    legs = _frame(leg_rows, LEG_COLUMNS, run_id)
    n_ok = int(routes["status"].isin(["ok", "late"]).sum()) if len(routes) else 0
    n_failed = len(routes) - n_ok
    status = "ok" if n_failed == 0 else ("failed" if n_ok == 0 else "partial")
    with warehouse.connect(db_path) as con:
        con.execute("BEGIN TRANSACTION")
        try:
            con.register("routes_df", routes)
            con.register("legs_df", legs)
            con.execute(f"INSERT INTO routes ({', '.join(ROUTE_COLUMNS)}) SELECT {', '.join(ROUTE_COLUMNS)} FROM routes_df")
            con.execute(f"INSERT INTO route_legs ({', '.join(LEG_COLUMNS)}) SELECT {', '.join(LEG_COLUMNS)} FROM legs_df")
            con.execute(
                "UPDATE route_runs SET finished_at = ?, n_ok = ?, n_failed = ?, status = ?, n_export_failed = ?, "
                "export_errors = ? WHERE run_id = ?",
                [_utcnow(), n_ok, n_failed, status, len(export_errors or []),
                 "\n".join(export_errors) if export_errors else None, run_id],
            )
            con.execute("COMMIT")
        except Exception:
            con.execute("ROLLBACK")
            raise
    part = Path(exports_dir) / "routes" / f"run_id={run_id}"
    part.mkdir(parents=True, exist_ok=True)
    routes.drop(columns=["run_id"]).to_parquet(part / "routes.parquet", index=False)
    legs.drop(columns=["run_id"]).to_parquet(part / "route_legs.parquet", index=False)
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
    out = run.iloc[0].to_dict() if len(run) else {"run_id": run_id}
    out.update({k: (int(v) if k.startswith("n") and v == v else v) for k, v in totals.iloc[0].to_dict().items()})
    if len(savings):
        out.update({k: (None if v is None or v != v else (int(v) if k.startswith("n_") else float(v)))
                    for k, v in savings.iloc[0].to_dict().items()})
    out["problems"] = problems.to_dict("records")
    errors = out.get("export_errors")
    out["export_failures"] = errors.splitlines() if isinstance(errors, str) and errors else []
    if out.get("cycle") is not None and out.get("cycle") == out.get("cycle"):
        out["cycle"] = pd.Timestamp(out["cycle"]).strftime("%Y-%m-%dT%H")
    return out
