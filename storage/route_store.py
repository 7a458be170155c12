"""Persistence of fleet routing runs: DuckDB tables `route_runs`, `routes`, the view `route_legs` (its rows are
Parquet files beside the warehouse: storage/route_history.py) and one exported Parquet dataset per table,
hive-partitioned by run: `exports/routes/<table>/run_id=<id>/part-<k>.parquet`.

One writer: a fleet run stores each batch of voyages as it finishes (`write_batch`: its routes and its legs' file
in one transaction, the legs' file written before the commit and listed by it), then ends with `finish_run`; so a
killed run keeps every batch it stored, whole, and none of the others, and a batch stored twice (a retried step)
adds nothing the second time. `write_run_results` stores a whole run at once. The Parquet files follow each
commit, one part per batch; each appears whole (written under a hidden name, then renamed). Their column types are
those of the tables' definitions (schemas/tables/routes.py): times `timestamp[us, tz=UTC]`, and a column name
shared by both tables has the same type in both, so pyarrow, polars and DuckDB read each folder as one table.
Rows are checked against the definitions: a key the table does not have, or a column missing, raises.
"""

from __future__ import annotations

import contextlib
import os
import socket
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from schemas.table import Table
from schemas.tables.routes import ROUTE_LEGS, ROUTE_RUNS, ROUTES
from storage import route_history, warehouse
from storage.run_owners import process_started

# The Parquet columns of each table, from its definition (the partition column run_id is the folder name, not in
# the file).
ROUTE_ARROW = ROUTES.arrow_schema(without=["run_id"])
LEG_ARROW = ROUTE_LEGS.arrow_schema(without=["run_id"])
ROUTE_COLUMNS = ROUTES.names
LEG_COLUMNS = ROUTE_LEGS.names
PARQUET_TABLES = {"routes": ROUTE_ARROW, "route_legs": LEG_ARROW}
DEFINED = {"routes": ROUTES, "route_legs": ROUTE_LEGS}


def _utcnow() -> datetime:
    return datetime.now(timezone.utc).replace(tzinfo=None)


def _frame(rows: list[dict], table: Table, run_id: str) -> pd.DataFrame:
    """The rows as the warehouse takes them, each checked against `table`'s definition (RowShapeError when a key is
    not a column or a column is missing): times UTC, tz-aware, to the microsecond (DuckDB TIMESTAMP's resolution)."""
    table.check_rows(rows)
    df = pd.DataFrame.from_records(rows, columns=table.names)
    df["run_id"] = run_id
    for c in table.columns:
        if c.duckdb == "TIMESTAMP":
            df[c.name] = pd.to_datetime(df[c.name], utc=True).dt.floor("us")
        elif c.duckdb.endswith("[]"):  # a list column missing from older rows is NaN there: Arrow wants null
            df[c.name] = pd.Series([list(v) if isinstance(v, (list, tuple, np.ndarray)) else None for v in df[c.name]],
                                   index=df.index, dtype=object)
    return df


ARROW_SCHEMAS = {"routes": ROUTES.arrow_schema(), "route_legs": ROUTE_LEGS.arrow_schema()}


def _rows_table(rows: list[dict], table: Table, run_id: str) -> pa.Table:
    """The rows as an Arrow table of `table`'s columns and types, each checked against its definition (RowShapeError
    when a key is not a column or a column is missing), `run_id` set: times `timestamp[us, tz=UTC]` (naive datetimes
    are UTC). Made without pandas: a fleet run's host stores a batch of voyages every minute or so, and a
    DataFrame and its conversions cost it about a third of each store's CPU."""
    table.check_rows(rows)
    schema = ARROW_SCHEMAS[table.name]
    data = {f.name: _utc_times([r[f.name] for r in rows]) if pa.types.is_timestamp(f.type)
            else pa.array([r[f.name] for r in rows], type=f.type, from_pandas=True)  # NaN is null, as in a DataFrame
            for f in schema if f.name != "run_id"}
    data["run_id"] = pa.array([run_id] * len(rows), type=schema.field("run_id").type)
    return pa.Table.from_pydict(data, schema=schema)


def _utc_times(values: list) -> pa.Array:
    """Times (datetimes, numpy or pandas times, ISO strings; naive ones are UTC) as `timestamp[us, tz=UTC]`, to the
    microsecond (DuckDB TIMESTAMP's resolution)."""
    utc = pd.to_datetime(pd.Series(values, dtype=object), utc=True).dt.floor("us")
    return pa.array(utc, type=pa.timestamp("us", tz="UTC"), from_pandas=True)


def _naive_utc(data: pa.Table) -> pa.Table:
    """The table with its tz-aware times as naive UTC, as the warehouse's TIMESTAMP columns hold them."""
    return data.cast(pa.schema([f.with_type(pa.timestamp(f.type.unit)) if pa.types.is_timestamp(f.type) and f.type.tz
                                else f for f in data.schema]))


def parquet_dir(exports_dir: Path, table: str) -> Path:
    """The dataset folder of `table` ("routes" or "route_legs"): one `run_id=<id>/part-0.parquet` per run."""
    return Path(exports_dir) / "routes" / table


def _publish_parquet(data: pd.DataFrame | pa.Table, schema: pa.Schema, folder: Path, index: int = 0) -> Path:
    """Write `data` as `folder/part-<index>.parquet`, whole or not at all (a hidden temp name, then a rename)."""
    folder.mkdir(parents=True, exist_ok=True)
    final = folder / route_history.part_name(index)
    tmp = folder / f".{final.name}.tmp{os.getpid()}"
    try:
        table = (data.select(schema.names).cast(schema) if isinstance(data, pa.Table)
                 else pa.Table.from_pandas(data[schema.names], schema=schema, preserve_index=False))
        pq.write_table(table, tmp)
        os.replace(tmp, final)
    finally:
        tmp.unlink(missing_ok=True)
    return final


def _publish_run_parquet(exports_dir: Path, run_id: str, tables: dict[str, pd.DataFrame | pa.Table],
                         index: int = 0) -> None:
    for table, df in tables.items():
        _publish_parquet(df, PARQUET_TABLES[table], parquet_dir(exports_dir, table) / f"run_id={run_id}", index)


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
                df = df.reindex(columns=DEFINED[table].names)  # columns added since are empty in old runs
                tables[table] = _frame(df.to_dict("records"), DEFINED[table], run_id)
        _publish_run_parquet(exports_dir, run_id, tables)
        for table in PARQUET_TABLES:
            (old / f"{table}.parquet").unlink(missing_ok=True)
        with contextlib.suppress(OSError):  # a folder holding anything else is left as it is
            old.rmdir()
        moved.append(run_id)
    return moved


def begin_run(db_path: Path, run_id: str, *, cycle, solver: str, trigger: str, n_voyages: int,
              nominal_utc=None, cycle_age_h: float | None = None) -> set[str]:
    """Record a run as `running`, owned by this host and process (see `run_owners.reap_dead_runs`), with the cycle's age
    (hours) at the run's nominal time. Returns the ids of the runs running now (this one included), read after the
    dead ones were reaped."""
    pid = os.getpid()
    with warehouse.connect(db_path) as con:
        row = {"run_id": run_id, "started_at": _utcnow(),
               "cycle": pd.Timestamp(cycle).to_pydatetime() if cycle is not None else None, "n_voyages": n_voyages,
               "status": "running", "solver": solver, "trigger": trigger, "host": socket.gethostname(), "pid": pid,
               "pid_started": process_started(pid),
               "nominal_utc": pd.Timestamp(nominal_utc).to_pydatetime() if nominal_utc is not None else None,
               "cycle_age_h": cycle_age_h}
        columns = list(row)
        ROUTE_RUNS.check_keys(columns, columns=ROUTE_RUNS.names_except("finished_at", "n_ok", "n_failed", "reason",
                                                                       "n_export_failed", "export_errors"))
        con.execute(f"INSERT INTO route_runs ({', '.join(columns)}) VALUES ({', '.join('?' * len(columns))})",
                    list(row.values()))
        return _running_run_ids(con)


def current_plan_legs(db_path: Path, voyage_ids: list[str]) -> dict[str, list[dict]]:
    """voyage_id → the legs (lat0, lon0, lat1, lon1, etd_utc, eta_utc, rpm, wait_h, wait_fuel_t) of its current
    plan in `latest_routes` (voyages without a plan are absent)."""
    if not voyage_ids:
        return {}
    with warehouse.connect(db_path, write=False) as con:
        df = con.execute(
            "SELECT l.voyage_id, l.leg, l.lat0, l.lon0, l.lat1, l.lon1, l.etd_utc, l.eta_utc, l.rpm, l.wait_h, "
            "l.wait_fuel_t "
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
        return _stale_plans(con)


def _stale_plans(con) -> list[dict]:
    return con.execute("SELECT voyage_id, imo, 'stale' AS status, stale_reason AS reason FROM latest_routes WHERE stale "
                       "ORDER BY voyage_id").fetchdf().to_dict("records")


def _running_run_ids(con) -> set[str]:
    return {r[0] for r in con.execute("SELECT run_id FROM route_runs WHERE status = 'running'").fetchall()}


def _store(con, db_path: Path, run_id: str, routes: pa.Table, legs: pa.Table, index: int) -> None:
    """On a writer connection: the legs as the run's `index`-th file, then the routes and that file's listing in one
    transaction."""
    con.register("routes_df", _naive_utc(routes))
    con.register("legs_df", _naive_utc(legs))
    # the legs' file is written before the commit and joins route_legs with it (storage/route_history.py)
    part = route_history.write_part(con, route_history.history_dir(db_path), run_id,
                                    f"SELECT {', '.join(LEG_COLUMNS)} FROM legs_df", index)
    with warehouse.transaction(con):
        con.execute(f"INSERT INTO routes ({', '.join(ROUTE_COLUMNS)}) SELECT {', '.join(ROUTE_COLUMNS)} FROM routes_df")
        route_history.record_parts(con, [part])
    con.unregister("routes_df")
    con.unregister("legs_df")


def write_batch(db_path: Path, exports_dir: Path, run_id: str, route_rows: list[dict], leg_rows: list[dict]) -> list[str]:
    """Store one finished batch of a running run's voyages: its routes and its legs (one more file of the run's
    history) in one transaction, then its Parquet part. Voyages the run has stored already are left out, so a batch
    stored again adds nothing. Returns the voyage ids stored.

    The writer is not checked and publishes no snapshot (`warehouse.connect(checked=False)`): the run's
    `begin_run` checked the warehouse, and its `finish_run` or `fail_run` publishes the snapshot."""
    routes = _rows_table(route_rows, ROUTES, run_id)
    legs = _rows_table(leg_rows, ROUTE_LEGS, run_id)
    with warehouse.connect(db_path, checked=False) as con:
        stored = {r[0] for r in con.execute("SELECT voyage_id FROM routes WHERE run_id = ? AND voyage_id IN "
                                            "(SELECT unnest(?))", [run_id, routes["voyage_id"].to_pylist()]).fetchall()}
        if stored:
            routes = routes.filter(pc.invert(pc.is_in(routes["voyage_id"], value_set=pa.array(sorted(stored)))))
            legs = legs.filter(pc.invert(pc.is_in(legs["voyage_id"], value_set=pa.array(sorted(stored)))))
        if not routes.num_rows:
            return []
        index = con.execute(f"SELECT count(*) FROM {route_history.PARTS} WHERE run_id = ?", [run_id]).fetchall()[0][0]
        _store(con, db_path, run_id, routes, legs, index)
    _publish_run_parquet(exports_dir, run_id, {"routes": routes, "route_legs": legs}, index)
    return [str(v) for v in routes["voyage_id"].to_pylist()]


def _finish(con, run_id: str, export_errors: list[str] | None) -> tuple[int, int]:
    """On a writer connection: the run's counts from its stored routes, its status and finish time."""
    n, n_ok = con.execute("SELECT count(*), count(*) FILTER (WHERE status IN ('ok', 'late')) FROM routes "
                          "WHERE run_id = ?", [run_id]).fetchall()[0]
    n_failed = n - n_ok
    status = "ok" if n_failed == 0 else ("failed" if n_ok == 0 else "partial")
    con.execute(
        "UPDATE route_runs SET finished_at = ?, n_ok = ?, n_failed = ?, status = ?, n_export_failed = ?, "
        "export_errors = ? WHERE run_id = ?",
        [_utcnow(), n_ok, n_failed, status, len(export_errors or []),
         "\n".join(export_errors) if export_errors else None, run_id],
    )
    return int(n_ok), int(n_failed)


def finish_run(db_path: Path, exports_dir: Path, run_id: str, export_errors: list[str] | None = None) -> dict:
    """End a run whose batches are stored (`write_batch`): its counts and status from its stored routes, and
    `export_errors` (one line per export that failed: voyage, kind, error) kept with it; the snapshot follows.
    Returns the run's summary (`run_summary`), read on the same connection."""
    with warehouse.connect(db_path) as con:
        _finish(con, run_id, export_errors)
        summary = _run_summary(con, run_id)
    migrate_old_parquet_layout(exports_dir)
    return summary


def write_run_results(db_path: Path, exports_dir: Path, run_id: str, route_rows: list[dict],
                      leg_rows: list[dict], export_errors: list[str] | None = None) -> tuple[int, int]:
    """Write all rows of a run in one transaction, then its Parquet files; returns (n_ok, n_failed).

    `export_errors`: one line per export that failed (voyage, kind, error), kept with the run."""
    routes = _rows_table(route_rows, ROUTES, run_id)
    legs = _rows_table(leg_rows, ROUTE_LEGS, run_id)
    with warehouse.connect(db_path) as con:
        _store(con, db_path, run_id, routes, legs, 0)
        counts = _finish(con, run_id, export_errors)
    migrate_old_parquet_layout(exports_dir)
    _publish_run_parquet(exports_dir, run_id, {"routes": routes, "route_legs": legs})
    return counts


def fail_run(db_path: Path, run_id: str, reason: str) -> None:
    """Mark a run failed with the reason (e.g. no cube, interrupted); nothing else of it was written."""
    with warehouse.connect(db_path) as con:
        con.execute("UPDATE route_runs SET finished_at = ?, status = 'failed', reason = ? WHERE run_id = ?",
                    [_utcnow(), reason[:2000], run_id])


def run_summary(db_path: Path, run_id: str) -> dict:
    """The run's row, counts and fuel-weighted savings (as the fleet_savings view), and the voyages needing attention."""
    with warehouse.connect(db_path, write=False) as con:
        return _run_summary(con, run_id)


def _run_summary(con, run_id: str) -> dict:
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
        "savings_route_pct, limits_fuel_t, unlimited_fuel_t, discrete_baseline_fuel_t, savings_vs_discrete_pct, "
        "n_beyond_horizon, n_split, savings_forecast_pct, savings_beyond_forecast_pct, n_ensemble, p_on_time, "
        "savings_p10_pct, savings_p50_pct, savings_p90_pct, n_verified, n_verified_whole, n_verified_compared, "
        "verified_claimed_savings_pct, realised_savings_pct "
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
    out["stale"] = _stale_plans(con)
    out["from_plans"] = {str(k): int(v) for k, v in from_plans.items()}
    errors = out.get("export_errors")
    out["export_failures"] = errors.splitlines() if isinstance(errors, str) and errors else []
    if out.get("cycle") is not None and out.get("cycle") == out.get("cycle"):
        out["cycle"] = pd.Timestamp(out["cycle"]).strftime("%Y-%m-%dT%H")
    return out
