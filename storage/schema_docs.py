"""What each warehouse table, view and column holds, with units, as DuckDB comments (`COMMENT ON`).

Analysts and BI tools read them from `duckdb_tables()`, `duckdb_views()` and `duckdb_columns()`. They are
applied by one migration that comes after all others and is named by a digest of its text and of every other
migration's name: a changed description, or any new migration (a new column, a rebuilt table), makes it new, so
it runs again and every comment matches this module. A column without a description fails a test.
"""

import hashlib

from storage.warehouse import Migration

UTC = "(UTC)"

# --- columns shared by several tables -----------------------------------------------------------------------------
_NOON = {
    "imo": "IMO number of the vessel",
    "ts_utc": f"time of the noon report {UTC}",
    "lat": "latitude at report time, degrees north", "lon": "longitude at report time, degrees east",
    "rpm": "mean main engine speed since the last report, revolutions per minute",
    "draft_m": "mean draft, metres", "trim_m": "trim (aft minus fore draft), metres",
    "stw_kn": "mean speed through water since the last report, knots",
    "sog_kn": "mean speed over ground since the last report, knots",
    "dist_nm": "distance sailed since the last report, nautical miles",
    "hours": "hours steamed since the last report",
    "fuel_t": "fuel burnt since the last report, tonnes (all grades)",
    "fuel_hfo_t": "heavy fuel oil burnt since the last report, tonnes",
    "fuel_mgo_t": "marine gas oil burnt since the last report, tonnes",
    "wind_kn": "true wind speed, knots",
    "wind_dir_rel_deg": "wind coming from, degrees relative to the bow (0 head, 180 following)",
    "wave_m": "significant wave height, metres",
    "wave_dir_rel_deg": "waves coming from, degrees relative to the bow (0 head, 180 following)",
    "current_kn": "current speed, knots",
    "current_dir_rel_deg": "current setting towards, degrees relative to the bow",
    "months_since_drydock": "months since the last dry-docking (hull fouling)",
    "source_file": "file the row was imported from",
}
_REJECTED = {
    "raw": "the row as it came in",
    "reason": "why the row was refused",
    "rejected_at": f"when the row was refused {UTC}",
}

_ROUTES = {
    "run_id": "routing run that made this plan (route_runs.run_id)",
    "voyage_id": "voyage routed (voyages.voyage_id)",
    "imo": "IMO number of the vessel",
    "solver": "routing solver used (e.g. bfoa, dp, astar)",
    "objective": "what the solver minimised (e.g. jit: least fuel arriving by the RTA)",
    "status": "ok (on time) | late (arrives after the RTA) | infeasible (no route) | failed (not routed: reason)",
    "reason": "why the plan is not ok, or notes on it",
    "depart_utc": f"planned departure {UTC}",
    "eta_utc": f"planned arrival {UTC}",
    "rta_utc": f"required time of arrival {UTC}",
    "hours": "planned passage time, hours",
    "fuel_t": "planned fuel burnt in tonnes",
    "baseline_fuel_t": "fuel burnt in tonnes on the baseline (great circle, constant speed) route",
    "baseline_hours": "passage time of the baseline route, hours",
    "savings_pct": "fuel saved against the baseline, percent",
    "distance_nm": "planned distance, nautical miles",
    "cost": "solver objective value (dimensionless)",
    "model_version": "performance model version used (perf_models.version)",
    "cycle": f"weather forecast cycle used, its init time {UTC}",
    "seed": "random seed of the solver",
    "runtime_s": "solver run time, seconds",
    "n_legs": "number of legs of the plan",
    "n_legs_beyond_forecast": "number of legs sailed past the forecast horizon (weather of the last step persisted)",
    "forecast_flag": "'beyond horizon', 'before cycle', 'weather missing' (a hole in the cube's wind, sailed as calm; the reason names the legs), comma separated, or empty when the voyage lies in the forecast",
    "hours_beyond_forecast": "hours sailed past the last forecast step",
    "hours_before_cycle": "hours sailed before the forecast cycle's init time",
    "honest_baseline_rpm": "the one constant rpm (between the vessel's limits) at which the base route arrives at the RTA",
    "honest_baseline_fuel_t": "fuel burnt in tonnes on the base route at honest_baseline_rpm, same weather and model",
    "honest_baseline_hours": "passage time at honest_baseline_rpm, hours",
    "profile_fuel_t": "fuel burnt in tonnes by the best engine plan on the base route",
    "savings_total_pct": "fuel saved against the honest baseline, percent (= speed profile + route)",
    "savings_speed_profile_pct": "part of the saving from the speed profile (best engine plan on the base route), percent",
    "savings_route_pct": "part of the saving from the route, percent",
    "min_engine_hold_h": "least hours each engine setting is held (engine-change limit), hours",
    "engine_change_cost_t": "cost of one engine change in the objective, tonnes of fuel",
    "n_engine_changes": "engine setting changes along the plan",
    "unlimited_fuel_t": "fuel burnt in tonnes by the best engine plan on the same route without engine-change limits",
    "limits_fuel_t": "what the engine-change limits cost, tonnes (fuel_t minus unlimited_fuel_t)",
    "min_land_clearance_nm": "least distance to land along the plan outside its port approaches, nautical miles (0.1 NM sampling; 25 means at least 25)",
    "start_kind": "where the plan starts: port (the departure) | noon report | operator position | advanced along plan "
                  "(an old report moved on along the previous plan)",
    "start_lat": "latitude the plan starts at, degrees north", "start_lon": "longitude the plan starts at, degrees east",
    "start_utc": f"time the plan starts at {UTC}",
    "start_position_utc": f"time of the position report the plan starts from {UTC}; empty from the port",
    "start_advanced_h": "hours an old position report was moved on along the previous plan (0: used as reported)",
    "start_note": "how the start was chosen when the report was old or missing",
    "voyage_fingerprint": "digest of the voyage (vessel, ports, RTA, draft) the plan was made for; latest_routes.stale compares it",
}
_LEGS = {
    "run_id": _ROUTES["run_id"], "voyage_id": _ROUTES["voyage_id"],
    "leg": "leg number along the route, from 0",
    "lat0": "leg start latitude, degrees north", "lon0": "leg start longitude, degrees east",
    "lat1": "leg end latitude, degrees north", "lon1": "leg end longitude, degrees east",
    "course_deg": "course over ground, degrees true",
    "dist_nm": "leg distance, nautical miles",
    "rpm": "main engine speed, revolutions per minute",
    "stw_kn": "speed through water, knots",
    "sog_kn": "speed over ground, knots",
    "hours": "leg time, hours",
    "fuel_t": "fuel burnt in tonnes on the leg",
    "etd_utc": f"leg start time {UTC}",
    "eta_utc": f"leg end time {UTC}",
    "wind_kn": "true wind speed on the leg, knots",
    "wind_dir_deg": "wind coming from, degrees true",
    "hs_m": "significant wave height on the leg, metres",
    "wave_dir_deg": "waves coming from, degrees true",
    "current_kn": "current speed on the leg, knots",
    "beyond_forecast": "true when the leg is sailed past the forecast horizon (weather of the last step persisted)",
}
_RUNS = {
    "run_id": "routing run id",
    "started_at": f"when the run started {UTC}",
    "finished_at": f"when the run finished {UTC}",
    "cycle": f"weather forecast cycle routed on, its init time {UTC}",
    "n_voyages": "voyages in the run",
    "n_ok": "voyages with a plan (ok or late)",
    "n_failed": "voyages without a plan (infeasible or failed)",
    "status": "running | ok (every voyage planned) | partial (some) | failed (none, or the run died: reason)",
    "solver": "routing solver used",
    "trigger": "what started the run: nightly | backfill | manual",
    "host": "host the run ran on",
    "pid": "process id of the run on its host",
    "pid_started": "start time of that process (clock ticks after boot), so a reused pid is not taken for it",
    "reason": "why the run failed",
    "n_export_failed": "exports (RTZ, GeoJSON, PNG) that failed",
    "export_errors": "one line per failed export: voyage, kind, error",
    "nominal_utc": f"the run's nominal time (the nightly's scheduled time, or the newest cycle it targeted) {UTC}",
    "cycle_age_h": "hours from the routed cycle's init time to nominal_utc",
}
_VESSELS = {
    "imo": "IMO number of the vessel", "name": "vessel name", "type": "vessel type",
    "dwt": "deadweight, tonnes", "design_speed_kn": "design speed, knots", "mcr_kw": "maximum continuous rating, kW",
    "rpm_max": "maximum main engine speed, revolutions per minute",
    "design_fuel_tph": "design fuel consumption, tonnes per hour",
}
_MODELS = {
    "imo": "IMO number of the vessel",
    "version": "model version, per vessel and target",
    "fitted_at": f"when the model was fitted {UTC}",
    "form": "model form: thesis | physical | mlp",
    "target": "what the model predicts: speed (knots through water) | fuel (tonnes per hour)",
    "coefficients": "JSON {regressor: value}",
    "n_rows": "noon reports fitted on",
    "r2": "coefficient of determination on the fitted rows",
    "rmse": "root mean square error on the fitted rows (knots for speed, tonnes per hour for fuel)",
    "cv_rmse": "cross-validated root mean square error (units of the target)",
    "status": "active | rejected (failed validation: reason) | superseded (a newer model is active)",
    "reason": "why the model was activated or rejected",
    "active": "true for the model routing uses",
    "months_dd": "months since dry-docking the model was fitted at",
    "holdout_rmse": "root mean square error on the newest reports, fitted without them (units of the target)",
    "n_holdout": "newest reports held out for holdout_rmse",
    "data_hash": "digest of the rows, form and fit settings (the same inputs give the same model)",
    "data_to_utc": f"newest report the coefficients were fitted on {UTC}",
    "flag": "why new reports contradict this active model",
    "envelope": "JSON of the conditions fitted on: rpm and draft_m [least, largest], largest wind_kn and hs_m; routing "
                "clips rpm settings to it and evaluates the model inside it",
    "gate": "the gate the refit applied: 'default' or the settings that differed (jitroute refit --gate NAME=VALUE)",
}
_HULL = {
    "imo": "IMO number of the vessel", "month": "calendar month (its first day, UTC)",
    "n_reports": "noon reports of the month with a reference speed",
    "speed_loss_pct": "median speed loss over the month's reports, percent: 100·(1 − measured STW / the active model's STW with a clean hull "
                      "in the report's conditions)",
    "flag": "speed loss above the threshold (settings.performance.hull_flag_pct, 5 % by default)",
    "model_version": "version of the active model used as the reference",
    "computed_at": f"when the month was computed {UTC}",
}
_VOYAGES = {
    "voyage_id": "voyage id", "imo": "IMO number of the vessel",
    "dep_name": "departure port", "dep_lat": "departure latitude, degrees north", "dep_lon": "departure longitude, degrees east",
    "arr_name": "arrival port", "arr_lat": "arrival latitude, degrees north", "arr_lon": "arrival longitude, degrees east",
    "depart_utc": f"departure time {UTC}", "rta_utc": f"required time of arrival {UTC}",
    "draft_m": "draft, metres", "trim_m": "trim (aft minus fore draft), metres",
    "rpm_options": "main engine speeds the solver may choose, revolutions per minute",
    "max_hs_m": "highest significant wave height allowed, metres", "max_wind_kn": "highest wind allowed, knots",
    "status": "voyage status from the voyages file (planned voyages are routed)",
    "plan_id": "fleet plan that made this voyage (fleet_plans.plan_id); NULL for voyages from a voyages file",
}
_PLAN_COST = "in the currency of the fuel price (e.g. USD)"
_PLANNING = {
    "ports": ("ports the planner may use, with the position of their pilot station (at sea)", {
        "port": "port name", "lat": "latitude, degrees north", "lon": "longitude, degrees east",
        "source_file": _NOON["source_file"]}),
    "ports_rejected": ("rows of ports files refused on import", {"port": "port name", **_REJECTED,
                                                                 "source_file": _NOON["source_file"]}),
    "vessel_availability": ("when and where each vessel is available for planning, and what it may do", {
        "imo": "IMO number of the vessel", "from_utc": f"available from {UTC}", "from_port": "port it is available at",
        "until_utc": f"must be at until_port by then {UTC} (NULL: open-ended)", "until_port": "port where its availability ends",
        "port_hours": "average time in port per call, hours", "daily_cost": f"cost per day out of service, {_PLAN_COST}",
        "ports": "ports it may call, separated by ';' (NULL: any)",
        "cargo_types": "cargo types it may carry, separated by ';' (NULL: any)",
        "laden_speed_kn": "planning speed laden, knots (NULL: design speed)",
        "ballast_speed_kn": "planning speed in ballast, knots (NULL: design speed)",
        "laden_draft_m": "draft laden, metres (fuel per NM from the performance model at this draft)",
        "ballast_draft_m": "draft in ballast, metres", "source_file": _NOON["source_file"]}),
    "vessel_availability_rejected": ("rows of availability files refused on import",
                                     {"imo": "IMO number of the vessel", **_REJECTED, "source_file": _NOON["source_file"]}),
    "contracts": ("cargo contracts to plan: cargo, weights, ports and the load window", {
        "code": "contract code", "cargo_type": "cargo type", "min_t": "minimum cargo weight, tonnes",
        "max_t": "maximum cargo weight, tonnes", "load_port": "port of loading (ports.port)",
        "discharge_port": "port of discharge (ports.port)", "early_utc": f"load window opens: earliest start of loading {UTC}",
        "late_utc": f"load window closes: latest start of loading {UTC}",
        "penalty": f"cost of leaving the contract unassigned (e.g. chartered out on the spot market), {_PLAN_COST}",
        "source_file": _NOON["source_file"]}),
    "contracts_rejected": ("rows of contracts files refused on import, with the reason",
                           {"code": "contract code", **_REJECTED, "source_file": _NOON["source_file"]}),
    "port_distances": ("sea distance between two ports: length of the routing graph's shortest sea route, reused by later plans", {
        "port_a": "first port (names in sorted order; the distance holds both ways)", "port_b": "second port",
        "lat_a": "latitude of port_a used, degrees north", "lon_a": "longitude of port_a used, degrees east",
        "lat_b": "latitude of port_b used, degrees north", "lon_b": "longitude of port_b used, degrees east",
        "dist_nm": "shortest sea route clear of land, nautical miles (NULL: no sea route, see reason)",
        "gc_nm": "great-circle distance, nautical miles", "reason": "why there is no sea route",
        "computed_at": f"when the distance was computed {UTC}"}),
    "fleet_plans": ("fleet operation plans: which vessel lifts which contract, one row per plan, with its cost items", {
        "plan_id": "plan id", "created_at": f"when the plan was made {UTC}", "as_of_utc": f"planning time {UTC}",
        "status": "active (its voyages are routed) | superseded (a newer plan replaced its unsailed voyages)",
        "superseded_at": f"when a newer plan replaced it {UTC}", "solver": "planner used (milp: HiGHS set partitioning)",
        "solve_status": "optimal (proven) | feasible (best found; gap says how far from optimal at most) | no plan",
        "gap": "proven relative optimality gap (0 when optimal)", "runtime_s": "planner run time, seconds",
        "n_contracts": "contracts planned", "n_assigned": "contracts given to a vessel",
        "n_unassigned": "contracts left (fleet_plan_unassigned says why)", "n_vessels_used": "vessels with at least one contract",
        "fuel_price": "fuel price per tonne the plan was costed at", "fuel_t": "fuel planned, tonnes (ballast and laden legs)",
        "fuel_cost": f"fuel cost, {_PLAN_COST}", "out_of_service_days": "days the used vessels spend in ballast or waiting",
        "out_of_service_cost": f"cost of those days, {_PLAN_COST}", "penalty_cost": f"penalties of the contracts left, {_PLAN_COST}",
        "total_cost": f"fuel + out of service + penalties, {_PLAN_COST}", "gantt_png": "picture of each vessel's schedule"}),
    "fleet_plan_legs": ("legs of each fleet plan, ballast and laden, with the voyage each became", {
        "plan_id": "plan (fleet_plans.plan_id)", "imo": "IMO number of the vessel", "seq": "leg number of the vessel, from 0",
        "kind": "ballast (to a load port or the end port) | laden (load port to discharge port)",
        "contract_code": "contract the leg serves (contracts.code; NULL for the last ballast to the end port)",
        "from_port": "port the leg leaves", "to_port": "port the leg reaches", "dist_nm": "sea distance, nautical miles",
        "depart_utc": f"planned departure {UTC}",
        "arrive_utc": f"required arrival {UTC}: laden, the discharge; ballast, the start of loading (the voyage's RTA)",
        "fuel_t": "fuel planned at the planning speed, tonnes", "lift_t": "cargo lifted, tonnes (0 in ballast)",
        "voyage_id": "voyage made of the leg (voyages.voyage_id)"}),
    "fleet_plan_unassigned": ("contracts a fleet plan leaves unassigned, and why", {
        "plan_id": "plan (fleet_plans.plan_id)", "contract_code": "contract (contracts.code)",
        "penalty": f"its penalty, {_PLAN_COST}", "reason": "why no vessel lifts it"}),
}
_INGEST = {
    "run_id": "ingest run that fetched the file",
    "source": "weather source: GSM (wind) | GWM (waves) | OSCAR (currents)",
    "cycle": f"forecast cycle the file was fetched for, its init time {UTC}",
    "file_name": "file name", "url": "where the file was fetched from", "bytes": "file size, bytes",
    "sha256": "SHA-256 of the file",
    "status": "ok (fetched) | skipped (already had) | missing (not found, or no answer in time) | corrupt (did not decode) "
              "| error (refused, e.g. no permission)",
    "error": "what went wrong", "started_at": f"fetch start {UTC}", "finished_at": f"fetch end {UTC}",
}
_CYCLES = {
    "cycle": f"forecast cycle, its init time {UTC}",
    "complete": "true when every expected file is in the weather cube",
    "n_files_expected": "files the cycle needs", "n_files_ok": "files fetched or already had",
    "missing": "what is missing, e.g. \"GSM FD0512; GWM 90-132 h\"",
    "written_at": f"when the status was written {UTC}",
}
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
    "limits_fuel_t": "fuel the engine-change limits cost, tonnes (plan minus the best plan on its route without them)",
    "unlimited_fuel_t": "fuel burnt in tonnes by the best engine plans on the same routes without engine-change limits",
    "discrete_baseline_fuel_t": "fuel burnt in tonnes on the discrete-rpm baseline (arrives early: overstates savings)",
    "savings_vs_discrete_pct": "fuel saved against the discrete-rpm baseline, percent (arrives early: overstated)",
}


def _view_of(base: dict, **extra: str) -> dict:
    return {**base, **extra}


TABLES: dict[str, tuple[str, dict[str, str]]] = {
    "schema_migrations": ("schema changes applied to this warehouse, by name",
                          {"name": "migration name", "applied_at": f"when it was applied {UTC}"}),
    "vessels": ("the fleet: one row per vessel", _VESSELS),
    "vessels_rejected": ("rows of vessels files refused on import",
                         {"imo": _VESSELS["imo"], **_REJECTED, "source_file": _NOON["source_file"]}),
    "noon_reports": ("noon reports: what each vessel sailed, burnt and met, per report", _NOON),
    "noon_reports_rejected": ("noon reports refused on import, with the reason", {**_NOON, **_REJECTED}),
    "hull_performance_monthly": ("speed loss against a clean hull per vessel and month (ISO 19030 spirit), rewritten at "
                                 "every refit", _HULL),
    "noon_reports_history": ("stored noon reports replaced by corrected ones or excluded for a period, as they were",
                             {**_NOON, "removed_at": f"when the report was replaced or excluded {UTC}",
                              "reason": "replaced by <file> | excluded: <the operator's reason>"}),
    "perf_models": ("fitted vessel performance models (speed and fuel), every version", _MODELS),
    "voyages": ("voyages to route: ports, departure and required arrival", _VOYAGES),
    "voyages_rejected": ("rows of voyages files refused on import",
                         {"voyage_id": _VOYAGES["voyage_id"], "imo": _VOYAGES["imo"], **_REJECTED,
                          "source_file": _NOON["source_file"]}),
    "bunker_logs": ("fuel bunkered: what, where, from whom, and what remained on board", {
        "imo": "IMO number of the vessel", "bill_no": "bunker delivery note number",
        "date_utc": f"delivery date {UTC}", "port": "port of delivery", "supplier": "supplier",
        "fuel_type": "fuel grade, upper case: HFO | LFO | MGO | MDO | DO | LNG | ...",
        "received_t": "fuel received, tonnes", "rob_t": "fuel of this grade remaining on board before receiving, tonnes",
        "source_file": _NOON["source_file"]}),
    "bunker_logs_rejected": ("rows of bunker-log files refused on import, with the reason and the raw row", {
        "imo": "IMO number of the vessel, when readable", "bill_no": "bunker delivery note number, as written",
        **_REJECTED, "source_file": _NOON["source_file"]}),
    "voyage_positions": ("positions of voyages at sea given by an operator; re-planning starts from the newest", {
        "voyage_id": _VOYAGES["voyage_id"], "ts_utc": f"time of the position {UTC}",
        "lat": "latitude, degrees north", "lon": "longitude, degrees east", "note": "who or what gave it",
        "entered_at": f"when it was entered {UTC}"}),
    "ingest_log": ("weather files fetched: one row per file and attempt", _INGEST),
    "cycles": ("weather forecast cycles: complete or what is missing", _CYCLES),
    "route_runs": ("fleet routing runs: one row per run", _RUNS),
    "routes": ("route plans: one row per run and voyage (fuel in tonnes, times UTC)", _ROUTES),
    "route_legs": ("legs of each route plan, with the weather met (speeds in knots, times UTC)", _LEGS),
    **_PLANNING,
}
VIEWS: dict[str, tuple[str, dict[str, str]]] = {
    "hull_performance": ("hull and propeller performance per vessel and month, with the trend", _view_of(
        {k: v for k, v in _HULL.items() if k != "computed_at"}, vessel_name=_VESSELS["name"],
        trend_pct_per_month="least-squares slope of the vessel's monthly speed loss, percent per month")),
    "latest_routes": ("the plan to sail per voyage: its newest plan, flagged when a newer attempt failed", _view_of(
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
        "model_version": _ROUTES["model_version"], "planned_fuel_t": "planned fuel burnt in tonnes",
        "planned_eta_utc": f"planned arrival {UTC}", "n_reports": "noon reports at sea on the voyage",
        "actual_fuel_t": "fuel burnt in tonnes, from the noon reports", "actual_hours": "hours steamed, from the noon reports",
        "actual_dist_nm": "distance sailed, nautical miles, from the noon reports",
        "actual_arrival_utc": f"the arrival: the first noon report within 10 NM of the destination, else the last report at "
                              f"sea before the next voyage (at most RTA + 30 days) {UTC}",
        "fuel_error_pct": "planned minus actual fuel, percent of actual",
        "arrival_error_h": "actual minus planned arrival, hours", "late_h": "actual arrival minus RTA, hours"}),
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
