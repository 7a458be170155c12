"""Persistence of plan verification (`plan_verification`): which stored plans to re-sail, their legs and baselines,
and the rows of what they realised (one row per plan, replaced as newer cycles arrive)."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from schemas.tables.routes import PLAN_VERIFICATION
from storage import warehouse

# what re-sailing a plan needs of its routes row
_PLAN_COLUMNS = ("run_id", "voyage_id", "imo", "solver", "status", "depart_utc", "eta_utc", "rta_utc", "hours", "fuel_t",
                 "cycle", "model_version", "start_kind", "honest_baseline_fuel_t", "savings_total_pct",
                 "baseline_lat_deg", "baseline_lon_deg", "baseline_leg_rpm")
_LEG_COLUMNS = ("lat0", "lon0", "lat1", "lon1", "rpm", "wait_h", "wait_fuel_t")


def plans_to_verify(db_path: Path, *, analysed_from_utc, analysed_until_utc, newest_cycle,
                    run_id: str | None = None) -> list[dict]:
    """Stored plans (ok or late, with legs) whose passage meets the analysed valid times analysed_from..until and
    which are not verified yet with `newest_cycle` (nor wholly verified before); only run `run_id`'s when given.
    Each a dict of _PLAN_COLUMNS, oldest run first."""
    q = (f"SELECT {', '.join('r.' + c for c in _PLAN_COLUMNS)} FROM routes r JOIN route_runs u USING (run_id) "
         "WHERE r.status IN ('ok', 'late') AND r.n_legs > 0 AND r.depart_utc < ? AND r.eta_utc > ? "
         "AND NOT EXISTS (SELECT 1 FROM plan_verification p WHERE p.run_id = r.run_id AND p.voyage_id = r.voyage_id "
         "                AND (p.coverage = 'verified' OR p.newest_cycle >= ?))")
    params: list = [_naive(analysed_until_utc), _naive(analysed_from_utc), _naive(newest_cycle)]
    if run_id is not None:
        q += " AND r.run_id = ?"
        params.append(run_id)
    with warehouse.connect(db_path, write=False) as con:
        return con.execute(q + " ORDER BY u.started_at, r.run_id, r.voyage_id", params).fetchdf().to_dict("records")


def plan_legs(db_path: Path, plans: list[dict]) -> dict[tuple[str, str], list[dict]]:
    """(run_id, voyage_id) → the plan's legs in order (waypoints, rpm, waits) from `route_legs`."""
    if not plans:
        return {}
    keys = pd.DataFrame({"run_id": [str(p["run_id"]) for p in plans], "voyage_id": [str(p["voyage_id"]) for p in plans]})
    with warehouse.connect(db_path, write=False) as con:
        con.register("wanted", keys)
        df = con.execute(f"SELECT l.run_id, l.voyage_id, {', '.join('l.' + c for c in _LEG_COLUMNS)} FROM route_legs l "
                         "JOIN wanted USING (run_id, voyage_id) ORDER BY l.run_id, l.voyage_id, l.leg").fetchdf()
        con.unregister("wanted")
    out: dict[tuple[str, str], list[dict]] = {}
    for rec in df.to_dict("records"):
        out.setdefault((str(rec.pop("run_id")), str(rec.pop("voyage_id"))), []).append(
            {k: (0.0 if k.startswith("wait") and v != v else v) for k, v in rec.items()})
    return out


def write_verifications(db_path: Path, rows: list[dict]) -> int:
    """Store `rows` (every column of plan_verification), replacing the rows of the same plans; returns their number."""
    if not rows:
        return 0
    PLAN_VERIFICATION.check_rows(rows)
    df = pd.DataFrame.from_records(rows, columns=PLAN_VERIFICATION.names)
    for c in PLAN_VERIFICATION.columns:
        if c.duckdb == "TIMESTAMP":
            df[c.name] = pd.to_datetime(df[c.name], utc=True).dt.tz_localize(None).dt.floor("us")
    names = ", ".join(PLAN_VERIFICATION.names)
    with warehouse.connect(db_path) as con:
        con.register("verified_df", df)
        with warehouse.transaction(con):
            con.execute("DELETE FROM plan_verification p WHERE EXISTS (SELECT 1 FROM verified_df d "
                        "WHERE d.run_id = p.run_id AND d.voyage_id = p.voyage_id)")
            con.execute(f"INSERT INTO plan_verification ({names}) SELECT {names} FROM verified_df")
        con.unregister("verified_df")
    return len(rows)


def verifications(db_path: Path, run_id: str | None = None) -> pd.DataFrame:
    """The stored rows (of run `run_id`, or all), newest run first, each with `route_hs_mean_m`: the forecast's
    severity along the plan's route (the hours-weighted mean Hs its stored legs meet inside the forecast, as
    pipeline.routing.calibration.route_hs_mean_m; empty without such legs), which the error model may be split by."""
    q = ("SELECT p.*, (SELECT sum(l.hours * l.hs_m) FILTER (WHERE NOT coalesce(l.beyond_forecast, false)) "
         "/ nullif(sum(l.hours) FILTER (WHERE NOT coalesce(l.beyond_forecast, false) AND l.hs_m IS NOT NULL), 0) "
         "FROM route_legs l WHERE l.run_id = p.run_id AND l.voyage_id = p.voyage_id) AS route_hs_mean_m "
         "FROM plan_verification p JOIN route_runs u USING (run_id)")
    params: list = []
    if run_id is not None:
        q += " WHERE p.run_id = ?"
        params.append(run_id)
    with warehouse.connect(db_path, write=False) as con:
        return con.execute(q + " ORDER BY u.started_at DESC, p.voyage_id", params).fetchdf()


def _naive(t) -> pd.Timestamp:
    ts = pd.Timestamp(t)
    return ts.tz_convert("UTC").tz_localize(None) if ts.tzinfo else ts
