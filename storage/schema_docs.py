"""What each warehouse table, view and column holds, with units, as DuckDB comments (`COMMENT ON`).

Tables and their columns are described where they are defined (schemas/tables); the views are described here.

Analysts and BI tools read them from `duckdb_tables()`, `duckdb_views()` and `duckdb_columns()`. They are
applied by one migration that comes after all others and is named by a digest of its text and of every other
migration's name: a changed description, or any new migration (a new column, a rebuilt table), makes it new, so
it runs again and every comment matches this module. A column without a description fails a test.
"""

import hashlib

from schemas.tables import TABLES as DEFINED
from storage.migration import Migration

UTC = "(UTC)"

# the tables' descriptions are their definitions' (schemas/tables); the views below reuse the columns they show
_ROUTES = DEFINED["routes"].comments()
_RUNS = DEFINED["route_runs"].comments()
_VESSELS = DEFINED["vessels"].comments()
_MODELS = DEFINED["perf_models"].comments()
_HULL = DEFINED["hull_performance_monthly"].comments()
_VOYAGES = DEFINED["voyages"].comments()
_CYCLES = DEFINED["cycles"].comments()
_SAVINGS = {
    "run_id": _RUNS["run_id"], "started_at": _RUNS["started_at"], "cycle": _RUNS["cycle"], "trigger": _RUNS["trigger"],
    "run_status": _RUNS["status"], "n_voyages": "voyages routed in the run",
    "n_on_time": "voyages planned to arrive by the RTA (status ok)", "n_late": "voyages planned to arrive late",
    "n_infeasible": "voyages with no route", "n_failed": "voyages not routed (failed)",
    "n_not_routed": "n_infeasible + n_failed", "n_export_failed": _RUNS["n_export_failed"],
    "n_compared": "voyages with an honest constant-rpm baseline (the sums below are over these)",
    "fuel_t": "planned fuel burnt in tonnes, voyages with an honest baseline only",
    "honest_baseline_fuel_t": "fuel burnt in tonnes sailing the base route at the one constant rpm that arrives at the RTA",
    "profile_fuel_t": "fuel burnt in tonnes by the best engine plan on the base route",
    "savings_total_pct": "fuel saved against the honest baseline, percent (fuel-weighted over the voyages)",
    "savings_speed_profile_pct": "part of savings_total_pct from the speed profile (best engine plan on the base route), percent",
    "savings_route_pct": "part of savings_total_pct from the route, percent",
    "n_beyond_horizon": "voyages whose plan sails past the forecast's last valid time (forecast_flag beyond horizon)",
    "n_split": "voyages whose saving is split into forecast and beyond-forecast parts (the split sums are over these)",
    "fuel_beyond_forecast_t": "planned fuel burnt in tonnes after the forecast's last valid time",
    "honest_baseline_fuel_beyond_forecast_t": "honest baseline's fuel burnt in tonnes after the forecast's last valid time",
    "savings_forecast_pct": "the saving the forecast backs: fuel saved within the forecast's valid times, percent of "
                            "the honest baseline's fuel (fuel-weighted); the figure to quote",
    "savings_beyond_forecast_pct": "fuel saved after the forecast's last valid time (neutral weather there: an "
                                   "assumption, not a forecast), percent; with savings_forecast_pct it makes the total",
    "margin_cost_pct": "what the plans' arrival margins cost (aiming before the RTA), percent of the honest baseline's "
                       "fuel, fuel-weighted; savings_total_pct already counts it (0 for plans aiming at the RTA)",
    "limits_fuel_t": "fuel the engine-change limits cost, tonnes (plan minus the best plan on its route without them)",
    "unlimited_fuel_t": "fuel burnt in tonnes by the best engine plans on the same routes without engine-change limits",
    "discrete_baseline_fuel_t": "fuel burnt in tonnes on the discrete-rpm baseline (arrives early: overstates savings)",
    "savings_vs_discrete_pct": "fuel saved against the discrete-rpm baseline, percent (arrives early: overstated)",
    "n_ensemble": "voyages whose plan was sailed through a lagged ensemble of cycles (p_on_time is over these)",
    "p_on_time": "mean over those voyages of the share of ensemble members in which the plan arrives on time, 0..1",
    "savings_p10_pct": "10th percentile of each voyage's saving across the ensemble, fuel-weighted by the baseline's "
                       "fuel (as savings_total_pct), percent",
    "savings_p50_pct": "median of each voyage's saving across the ensemble, fuel-weighted, percent",
    "savings_p90_pct": "90th percentile of each voyage's saving across the ensemble, fuel-weighted, percent",
    "n_verified": "plans of the run re-sailed in the analysed weather of later cycles (plan_verification)",
    "n_verified_whole": "of which the whole passage lies in analysed weather (coverage verified)",
    "verified_hours_analysed": "hours of those passages in analysed weather",
    "verified_hours_total": "hours of those passages in all",
    "n_verified_compared": "verified plans with a realised baseline (the realised sums below are over these)",
    "verified_claimed_fuel_t": "planned fuel of those plans, tonnes",
    "realised_fuel_t": "their fuel re-sailed in the analysed weather, tonnes",
    "realised_baseline_fuel_t": "their baselines' fuel re-sailed in the same weather, tonnes",
    "verified_claimed_savings_pct": "the saving those plans claimed, fuel-weighted, percent: compare with "
                                    "realised_savings_pct",
    "realised_savings_pct": "the saving those plans realised against their baselines in the analysed weather, "
                            "fuel-weighted, percent",
    "n_realised_on_time": "verified plans arriving by the RTA (+ 0.5 h) when re-sailed",
}


def _view_of(base: dict, **extra: str) -> dict:
    return {**base, **extra}


# route_legs is a view over Parquet files once a writer has opened the warehouse (storage/route_history.py makes it
# and its comments); before that a table that may lack the columns added since, so it is not commented here
TABLES: dict[str, tuple[str, dict[str, str]]] = {name: (t.description, t.comments()) for name, t in DEFINED.items()
                                                 if name != "route_legs"}
VIEWS: dict[str, tuple[str, dict[str, str]]] = {
    "hull_performance": ("hull and propeller performance per vessel and month, with the trend", _view_of(
        {k: v for k, v in _HULL.items() if k != "computed_at"}, vessel_name=_VESSELS["name"],
        trend_pct_per_month="least-squares slope of the vessel's monthly speed loss, percent per month")),
    "latest_routes": ("the plan to sail per voyage: its newest plan, flagged when a newer attempt failed (none for a "
                      "voyage a fleet re-plan replaced)", _view_of(
        _ROUTES, dep_name=_VOYAGES["dep_name"], arr_name=_VOYAGES["arr_name"], vessel_name=_VESSELS["name"],
        newer_attempt_failed="true when a newer attempt made no plan (this one is still the plan)",
        newer_attempt_run_id="run of that newer attempt", newer_attempt_status="status of that newer attempt",
        newer_attempt_reason="why that newer attempt made no plan",
        newer_attempt_at=f"when that newer attempt's run started {UTC}",
        stale="true when the voyage changed (RTA, ports, vessel, draft) since this plan was made: re-plan it",
        stale_reason="what changed, when stale")),
    "fleet_savings": ("fuel and savings per routing run", _SAVINGS),
    "model_quality": ("fit quality of each vessel's active models", _view_of(
        {k: _MODELS[k] for k in ("imo", "target", "form", "version", "fitted_at", "n_rows", "r2", "rmse", "cv_rmse",
                                 "n_holdout", "holdout_rmse", "data_to_utc", "flag")},
        vessel_name=_VESSELS["name"], n_reports="noon reports of the vessel",
        n_rejected="noon reports of the vessel refused on import")),
    "ingest_health": ("per forecast cycle: completeness and what the files did", _view_of(
        _CYCLES, files_downloaded="files fetched (status ok)", files_skipped="files already had",
        files_missing="files not found", files_corrupt="files that did not decode")),
    "voyage_performance": ("each voyage's plan against what its noon reports show", {
        "voyage_id": _VOYAGES["voyage_id"], "imo": _VOYAGES["imo"], "vessel_name": _VESSELS["name"],
        "dep_name": _VOYAGES["dep_name"], "arr_name": _VOYAGES["arr_name"], "depart_utc": _VOYAGES["depart_utc"],
        "rta_utc": _VOYAGES["rta_utc"], "run_id": "run of the plan (latest_routes)", "plan_status": _ROUTES["status"],
        "model_version": _ROUTES["model_version"],
        "plan_start_kind": "where the plan starts: port, or a position at sea (a re-plan, compared from its start)",
        "compared_from_utc": f"the time plan and actual are compared from: the departure, or a re-plan's start {UTC}",
        "planned_fuel_t": "planned fuel burnt in tonnes from compared_from_utc",
        "planned_eta_utc": f"planned arrival {UTC}", "n_reports": "noon reports at sea after compared_from_utc",
        "actual_fuel_t": "fuel burnt in tonnes after compared_from_utc, from the noon reports (a re-plan's first report "
                         "pro rata for its hours after the start)",
        "actual_hours": "hours steamed after compared_from_utc, from the noon reports",
        "actual_dist_nm": "distance sailed after compared_from_utc, nautical miles, from the noon reports",
        "arrived": "true when the voyage has ended: a noon report within 10 NM of the destination, or (without "
                   "positions) the vessel's next voyage has departed; false for a ship still at sea",
        "last_report_utc": f"the voyage's last noon report at sea so far {UTC}",
        "actual_arrival_utc": f"the arrival: the first noon report within 10 NM of the destination, else the last report at "
                              f"sea before the next voyage; empty while the ship is at sea {UTC}",
        "fuel_error_pct": "planned minus actual fuel from compared_from_utc, percent of actual; empty while at sea",
        "arrival_error_h": "actual minus planned arrival, hours; empty while at sea",
        "late_h": "actual arrival minus RTA, hours; empty while at sea"}),
}


def _quoted(text: str) -> str:
    return "'" + text.replace("'", "''") + "'"


def comments_sql(tables: dict[str, tuple[str, dict[str, str]]], kind: str) -> str:
    """COMMENT ON statements for `tables` ({name: (description, {column: description})}); kind TABLE or VIEW."""
    lines = []
    for name, (about, columns) in tables.items():
        lines.append(f"COMMENT ON {kind} {name} IS {_quoted(about)};")
        lines += [f"COMMENT ON COLUMN {name}.{col} IS {_quoted(text)};" for col, text in columns.items()]
    return "\n".join(lines)


def comments_migration(after: list[str]) -> Migration:
    """The migration applying every comment, named anew whenever its text or the migrations `after` change."""
    sql = comments_sql(TABLES, "TABLE") + "\n" + comments_sql(VIEWS, "VIEW")
    digest = hashlib.sha256("\n".join([sql, *after]).encode()).hexdigest()[:12]
    return Migration(f"docs_comments_{digest}", sql)
