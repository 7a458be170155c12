"""What the operator's console reads from the data root, read-only: the warehouse's snapshot (the analysts' copy, so
the console never blocks the nightly writer) and the weather cube's published cycles.

Every function returns plain pandas DataFrames or arrays; pipeline/export/console_data.py shapes them into the
pages' data. Times are naive UTC, as stored.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path

import duckdb
import numpy as np
import pandas as pd

from storage import cube_window
from storage.layout import DataLayout
from storage.warehouse import snapshot_path

# the weather variables a console map reads from one cube step
STEP_VARIABLES = ("u10", "v10", "swh", "mwd", "uo", "vo")


class NoWarehouseError(FileNotFoundError):
    """The data root has neither a warehouse snapshot nor a warehouse: nothing to show yet."""


def warehouse_to_read(layout: DataLayout) -> Path:
    """The snapshot when there is one (never blocks the writer), else the warehouse itself (an idle pipeline)."""
    snap = snapshot_path(layout.warehouse)
    if snap.exists():
        return snap
    if layout.warehouse.exists():
        return layout.warehouse
    raise NoWarehouseError(f"no warehouse under {layout.root} (neither {snap.name} nor {layout.warehouse.name}): "
                           "run `jitroute demo` or the nightly job first, or pass --data")


def warehouse_version(layout: DataLayout) -> tuple:
    """What changes when the warehouse to read is replaced or written: its path, modification time and size."""
    path = warehouse_to_read(layout)
    st = path.stat()
    return str(path), st.st_mtime_ns, st.st_size


@contextlib.contextmanager
def reader(layout: DataLayout) -> Iterator[duckdb.DuckDBPyConnection]:
    """One short read-only connection to the warehouse to read (see warehouse_to_read)."""
    con = duckdb.connect(str(warehouse_to_read(layout)), read_only=True)
    try:
        yield con
    finally:
        con.close()


def latest_run(con) -> dict | None:
    """The newest routing run (route_runs row as a dict), or None."""
    df = con.execute("SELECT * FROM route_runs ORDER BY started_at DESC, run_id DESC LIMIT 1").fetchdf()
    return None if df.empty else df.iloc[0].to_dict()


# what the fleet page shows of each voyage's plan (latest_routes columns)
FLEET_COLUMNS = ("voyage_id", "imo", "vessel_name", "dep_name", "arr_name", "status", "reason", "run_id", "depart_utc",
                 "eta_utc", "rta_utc", "fuel_t", "savings_total_pct", "stale", "stale_reason", "newer_attempt_failed",
                 "newer_attempt_status", "newer_attempt_reason", "forecast_flag", "hours_beyond_forecast",
                 "hours_before_cycle", "min_land_clearance_nm")


def latest_routes(con) -> pd.DataFrame:
    """The plan to sail per voyage (the warehouse's latest_routes view, FLEET_COLUMNS) with its voyage's departure
    and arrival positions and departure time."""
    return con.execute(f"""
        SELECT {', '.join('r.' + c for c in FLEET_COLUMNS)}, v.dep_lat, v.dep_lon, v.arr_lat, v.arr_lon,
               v.depart_utc AS voyage_depart_utc
        FROM latest_routes r LEFT JOIN voyages v USING (voyage_id)
        ORDER BY r.vessel_name, r.voyage_id""").fetchdf()


def legs_of_latest(con) -> pd.DataFrame:
    """The legs of every voyage's latest plan: (voyage_id, leg, lat0, lon0, lat1, lon1, etd_utc, eta_utc), by leg."""
    return con.execute("""
        SELECT l.voyage_id, l.leg, l.lat0, l.lon0, l.lat1, l.lon1, l.etd_utc, l.eta_utc
        FROM route_legs l JOIN (SELECT run_id, voyage_id FROM latest_routes) p USING (run_id, voyage_id)
        ORDER BY l.voyage_id, l.leg""").fetchdf()


def reports_sailed(con, until_utc) -> pd.DataFrame:
    """Positions each voyage of latest_routes reported between its departure and `until_utc`: noon reports of its
    vessel and an operator's voyage_positions, (voyage_id, ts_utc, lat, lon, source) by time."""
    return con.execute("""
        WITH w AS (SELECT voyage_id, imo, depart_utc FROM voyages WHERE voyage_id IN (SELECT voyage_id FROM latest_routes))
        SELECT w.voyage_id, n.ts_utc, n.lat, n.lon, 'noon report' AS source
        FROM w JOIN noon_reports n ON n.imo = w.imo AND n.ts_utc >= w.depart_utc AND n.ts_utc <= $1
        WHERE n.lat IS NOT NULL AND n.lon IS NOT NULL
        UNION ALL
        SELECT p.voyage_id, p.ts_utc, p.lat, p.lon, 'position' AS source
        FROM voyage_positions p JOIN w USING (voyage_id) WHERE p.ts_utc >= w.depart_utc AND p.ts_utc <= $1
        ORDER BY voyage_id, ts_utc""", [pd.Timestamp(until_utc).to_pydatetime()]).fetchdf()


def voyage_routes(con, voyage_id: str) -> pd.DataFrame:
    """Every plan made for the voyage (one routes row per run, newest first), with the run's start time."""
    return con.execute("""
        SELECT r.*, u.started_at AS run_started_at, u.trigger
        FROM routes r JOIN route_runs u USING (run_id) WHERE r.voyage_id = $1
        ORDER BY u.started_at DESC, r.run_id DESC""", [voyage_id]).fetchdf()


def voyage_row(con, voyage_id: str) -> dict | None:
    df = con.execute("""SELECT v.*, x.name AS vessel_name FROM voyages v LEFT JOIN vessels x USING (imo)
                        WHERE voyage_id = $1""", [voyage_id]).fetchdf()
    return None if df.empty else df.iloc[0].to_dict()


def latest_route_row(con, voyage_id: str) -> dict | None:
    df = con.execute("SELECT * FROM latest_routes WHERE voyage_id = $1", [voyage_id]).fetchdf()
    return None if df.empty else df.iloc[0].to_dict()


def legs_of(con, run_id: str, voyage_id: str) -> pd.DataFrame:
    """Every stored column of one plan's legs, by leg."""
    return con.execute("SELECT * FROM route_legs WHERE run_id = $1 AND voyage_id = $2 ORDER BY leg",
                       [run_id, voyage_id]).fetchdf()


def track_of_plans(con, voyage_id: str, run_ids: list[str]) -> pd.DataFrame:
    """(run_id, leg, lat0, lon0, lat1, lon1) of earlier plans of the voyage, for drawing them."""
    if not run_ids:
        return pd.DataFrame(columns=["run_id", "leg", "lat0", "lon0", "lat1", "lon1"])
    return con.execute("""SELECT run_id, leg, lat0, lon0, lat1, lon1 FROM route_legs
                          WHERE voyage_id = $1 AND list_contains($2, run_id) ORDER BY run_id, leg""",
                       [voyage_id, run_ids]).fetchdf()


def voyage_actual(con, voyage_id: str) -> dict | None:
    """Plan against what was sailed (the voyage_performance view's row), or None."""
    df = con.execute("SELECT * FROM voyage_performance WHERE voyage_id = $1", [voyage_id]).fetchdf()
    return None if df.empty else df.iloc[0].to_dict()


def active_fleet_plan(con) -> tuple[dict | None, pd.DataFrame, pd.DataFrame, pd.DataFrame]:
    """(the newest active fleet plan, its legs with what each voyage became, the contracts it leaves, every vessel)."""
    vessels = con.execute("SELECT imo, name FROM vessels ORDER BY name").fetchdf()
    plans = con.execute("SELECT * FROM fleet_plans WHERE status = 'active' ORDER BY created_at DESC LIMIT 1").fetchdf()
    if plans.empty:
        return None, pd.DataFrame(), pd.DataFrame(), vessels
    plan = plans.iloc[0].to_dict()
    legs = con.execute("""
        SELECT l.*, r.status AS voyage_status, r.eta_utc AS voyage_eta_utc, r.rta_utc AS voyage_rta_utc,
               r.fuel_t AS voyage_fuel_t, r.reason AS voyage_reason
        FROM fleet_plan_legs l LEFT JOIN latest_routes r USING (voyage_id)
        WHERE l.plan_id = $1 ORDER BY l.imo, l.seq""", [plan["plan_id"]]).fetchdf()
    left = con.execute("SELECT * FROM fleet_plan_unassigned WHERE plan_id = $1 ORDER BY contract_code",
                       [plan["plan_id"]]).fetchdf()
    return plan, legs, left, vessels


def runs_history(con, limit: int = 200) -> pd.DataFrame:
    """The newest routing runs with their savings (fleet_savings: claimed, the part the forecast backs, the ensemble's
    P10–P90, and what the analysed weather realised where verified), newest first."""
    return con.execute("""
        SELECT u.run_id, u.started_at, u.finished_at, u.cycle, u.cycle_age_h, u.nominal_utc, u.trigger, u.status,
               u.solver, u.n_voyages, u.n_ok, u.n_failed, u.reason, u.n_export_failed, u.export_errors,
               s.n_on_time, s.n_late, s.n_not_routed, s.n_compared, s.fuel_t, s.honest_baseline_fuel_t,
               s.savings_total_pct, s.savings_speed_profile_pct, s.savings_route_pct, s.savings_vs_discrete_pct,
               s.savings_forecast_pct, s.savings_p10_pct, s.savings_p90_pct, s.n_verified, s.n_verified_compared,
               s.verified_claimed_savings_pct, s.realised_savings_pct
        FROM route_runs u LEFT JOIN fleet_savings s USING (run_id)
        ORDER BY u.started_at DESC, u.run_id DESC LIMIT $1""", [int(limit)]).fetchdf()


def cycles_status(con, limit: int = 60) -> pd.DataFrame:
    return con.execute("SELECT * FROM cycles ORDER BY cycle DESC LIMIT $1", [int(limit)]).fetchdf()


def ingest_failures(con, limit: int = 100) -> pd.DataFrame:
    """The newest ingest attempts that did not fetch their file (missing, corrupt, error), newest first."""
    return con.execute("""SELECT source, cycle, file_name, status, error, started_at FROM ingest_log
                          WHERE status NOT IN ('ok', 'skipped') ORDER BY started_at DESC NULLS LAST LIMIT $1""",
                       [int(limit)]).fetchdf()


def cube_steps(layout: DataLayout, cycle) -> np.ndarray | None:
    """Lead times (hours) of a published cycle of the weather cube, or None when the cube or the cycle is not there."""
    try:
        pub = cube_window.open_published(layout.cube_store)
    except FileNotFoundError:
        return None
    return pub.step_h.astype(np.int64) if np.datetime64(cycle, "ns") in pub.rows else None


def newest_cycle(layout: DataLayout) -> np.datetime64 | None:
    try:
        return cube_window.newest_complete_cycle(layout.cube_store)
    except FileNotFoundError:
        return None


def weather_step(layout: DataLayout, cycle, step_h: int, lat_deg: tuple[float, float],
                 lon_deg: tuple[float, float]) -> tuple[np.ndarray, np.ndarray, dict]:
    """(lat, lon, variable → (lat, lon) values) of one step of a cycle in a box (lon continuous, east ≥ west)."""
    valid = np.datetime64(cycle, "ns") + np.timedelta64(int(step_h), "h")
    win = cube_window.read_window(layout.cube_store, cycle, valid_utc=(valid, valid), lat_deg=lat_deg, lon_deg=lon_deg,
                                  variables=STEP_VARIABLES, margin_cells=1)
    hit = np.flatnonzero(win.step_h == int(step_h))
    if hit.size == 0:
        raise KeyError(f"cycle {np.datetime_as_string(np.datetime64(cycle, 'h'))} has no step {step_h} h; "
                       f"it has {', '.join(str(int(s)) for s in win.step_h)} h near it")
    k = int(hit[0])
    return win.lat, win.lon, {v: a[k] for v, a in win.data.items()}
