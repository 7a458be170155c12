"""Warehouse tables: fleet routing runs, their plans and legs."""

from schemas.table import Column, Table

ROUTE_RUNS = Table('route_runs', 'fleet routing runs: one row per run', (
    Column('run_id', 'VARCHAR', None, 'routing run id'),
    Column('started_at', 'TIMESTAMP', 'UTC', 'when the run started (UTC)', not_null=True),
    Column('finished_at', 'TIMESTAMP', 'UTC', 'when the run finished (UTC)'),
    Column('cycle', 'TIMESTAMP', 'UTC', 'weather forecast cycle routed on, its init time (UTC)'),
    Column('n_voyages', 'INTEGER', None, 'voyages in the run'),
    Column('n_ok', 'INTEGER', None, 'voyages with a plan (ok or late)'),
    Column('n_failed', 'INTEGER', None, 'voyages without a plan (infeasible or failed)'),
    Column('status', 'VARCHAR', None,
           'running | ok (every voyage planned) | partial (some) | failed (none, or the run died: reason)', not_null=True, allowed=('running', 'ok', 'partial', 'failed')),
    Column('solver', 'VARCHAR', None, 'routing solver used'),
    Column('trigger', 'VARCHAR', None, 'what started the run: nightly | backfill | manual'),
    Column('host', 'VARCHAR', None, 'host the run ran on'),
    Column('pid', 'INTEGER', None, 'process id of the run on its host'),
    Column('pid_started', 'VARCHAR', None,
           'start time of that process (clock ticks after boot), so a reused pid is not taken for it'),
    Column('reason', 'VARCHAR', None, 'why the run failed'),
    Column('n_export_failed', 'INTEGER', None, 'exports (RTZ, GeoJSON, PNG) that failed'),
    Column('export_errors', 'VARCHAR', None, 'one line per failed export: voyage, kind, error'),
    Column('nominal_utc', 'TIMESTAMP', 'UTC',
           "the run's nominal time (the nightly's scheduled time, or the newest cycle it targeted) (UTC)"),
    Column('cycle_age_h', 'DOUBLE', 'h', "hours from the routed cycle's init time to nominal_utc"),
), primary_key=('run_id',))

ROUTES = Table('routes', 'route plans: one row per run and voyage (fuel in tonnes, times UTC)', (
    Column('run_id', 'VARCHAR', None, 'routing run that made this plan (route_runs.run_id)'),
    Column('voyage_id', 'VARCHAR', None, 'voyage routed (voyages.voyage_id)'),
    Column('imo', 'BIGINT', None, 'IMO number of the vessel'),
    Column('solver', 'VARCHAR', None, 'routing solver used (e.g. bfoa, dp, astar)'),
    Column('objective', 'VARCHAR', None, 'what the solver minimised (e.g. jit: least fuel arriving by the RTA)'),
    Column('status', 'VARCHAR', None,
           'ok (on time) | late (arrives after the RTA) | infeasible (no route) | failed (not routed: reason)', not_null=True, allowed=('ok', 'late', 'infeasible', 'failed')),
    Column('reason', 'VARCHAR', None, 'why the plan is not ok, or notes on it'),
    Column('depart_utc', 'TIMESTAMP', 'UTC', 'planned departure (UTC)'),
    Column('eta_utc', 'TIMESTAMP', 'UTC', 'planned arrival (UTC)'),
    Column('rta_utc', 'TIMESTAMP', 'UTC', 'required time of arrival (UTC)'),
    Column('hours', 'DOUBLE', 'h', 'planned passage time, hours (waits at nodes included)'),
    Column('fuel_t', 'DOUBLE', 't', 'planned fuel burnt in tonnes (waits at nodes included)'),
    Column('baseline_fuel_t', 'DOUBLE', 't',
           'fuel burnt in tonnes on the baseline (great circle, constant speed) route'),
    Column('baseline_hours', 'DOUBLE', None, 'passage time of the baseline route, hours'),
    Column('savings_pct', 'DOUBLE', '%', 'fuel saved against the baseline, percent'),
    Column('distance_nm', 'DOUBLE', 'NM', 'planned distance, nautical miles'),
    Column('cost', 'DOUBLE', None, 'solver objective value (dimensionless)'),
    Column('model_version', 'INTEGER', None, 'performance model version used (perf_models.version)'),
    Column('cycle', 'TIMESTAMP', 'UTC', 'weather forecast cycle used, its init time (UTC)'),
    Column('seed', 'INTEGER', None, 'random seed of the solver'),
    Column('runtime_s', 'DOUBLE', 's', 'solver run time, seconds'),
    Column('n_legs', 'INTEGER', None, 'number of legs of the plan'),
    Column('n_legs_beyond_forecast', 'INTEGER', None,
           "number of legs sailed past the forecast horizon (in the region's mean wind and waves from near the beam)"),
    Column('forecast_flag', 'VARCHAR', None,
           "'beyond horizon', 'before cycle', 'weather missing' (a hole in the cube's wind, sailed as calm; the "
           'reason names the legs), comma separated, or empty when the voyage lies in the forecast'),
    Column('hours_beyond_forecast', 'DOUBLE', None, 'hours sailed past the last forecast step'),
    Column('hours_before_cycle', 'DOUBLE', None, "hours sailed before the forecast cycle's init time"),
    Column('honest_baseline_rpm', 'DOUBLE', 'rpm',
           "the one constant rpm (between the vessel's limits) at which the base route arrives at the RTA"),
    Column('honest_baseline_fuel_t', 'DOUBLE', 't',
           'fuel burnt in tonnes on the base route at honest_baseline_rpm, same weather and model'),
    Column('honest_baseline_hours', 'DOUBLE', None, 'passage time at honest_baseline_rpm, hours'),
    Column('profile_fuel_t', 'DOUBLE', 't', 'fuel burnt in tonnes by the best engine plan on the base route'),
    Column('savings_total_pct', 'DOUBLE', '%',
           'fuel saved against the honest baseline, percent (= speed profile + route)'),
    Column('savings_speed_profile_pct', 'DOUBLE', '%',
           'part of the saving from the speed profile (best engine plan on the base route), percent'),
    Column('savings_route_pct', 'DOUBLE', '%', 'part of the saving from the route, percent'),
    Column('min_engine_hold_h', 'DOUBLE', 'h', 'least hours each engine setting is held (engine-change limit), hours'),
    Column('engine_change_cost_t', 'DOUBLE', 't', 'cost of one engine change in the objective, tonnes of fuel'),
    Column('n_engine_changes', 'INTEGER', None, 'engine setting changes along the plan'),
    Column('unlimited_fuel_t', 'DOUBLE', 't',
           'fuel burnt in tonnes by the best engine plan on the same route without engine-change limits'),
    Column('limits_fuel_t', 'DOUBLE', 't',
           'what the engine-change limits cost, tonnes (fuel_t minus unlimited_fuel_t)'),
    Column('min_land_clearance_nm', 'DOUBLE', 'NM',
           'least distance to land along the plan outside its port approaches and outside the fairways of the '
           'passages it sails (a canal between its banks, a strait; and the approach radius at a fairway\'s ends, '
           'as at a port), nautical miles (to 0.1 NM, or to 4 % of it when that is more; 25 means at least 25)'),
    Column('start_kind', 'VARCHAR', None,
           'where the plan starts: port (the departure) | noon report | operator position | advanced along plan '
           '(an old report moved on along the previous plan)'),
    Column('start_lat', 'DOUBLE', 'degree_north', 'latitude the plan starts at, degrees north'),
    Column('start_lon', 'DOUBLE', 'degree_east', 'longitude the plan starts at, degrees east'),
    Column('start_utc', 'TIMESTAMP', 'UTC', 'time the plan starts at (UTC)'),
    Column('start_position_utc', 'TIMESTAMP', 'UTC',
           'time of the position report the plan starts from (UTC); empty from the port'),
    Column('start_advanced_h', 'DOUBLE', 'h',
           'hours an old position report was moved on along the previous plan (0: used as reported)'),
    Column('start_note', 'VARCHAR', None, 'how the start was chosen when the report was old or missing'),
    Column('voyage_fingerprint', 'VARCHAR', None,
           'digest of the voyage (vessel, ports, RTA, draft) the plan was made for; latest_routes.stale compares'
           ' it'),
    Column('fuel_beyond_forecast_t', 'DOUBLE', 't',
           "part of fuel_t burnt after the forecast's last valid time (sailed in the region's mean wind and waves from "
           'near the beam, no current: an assumption, not a forecast), tonnes'),
    Column('honest_baseline_fuel_beyond_forecast_t', 'DOUBLE', 't',
           "part of honest_baseline_fuel_t burnt after the forecast's last valid time, tonnes"),
    Column('savings_forecast_pct', 'DOUBLE', '%',
           "part of savings_total_pct burnt within the forecast's valid times: the saving the forecast backs, percent"),
    Column('savings_beyond_forecast_pct', 'DOUBLE', '%',
           "part of savings_total_pct burnt after the forecast's last valid time (an assumption, not a forecast), "
           'percent; savings_forecast_pct + savings_beyond_forecast_pct = savings_total_pct'),
    Column('ensemble_members', 'INTEGER', None,
           'forecast cycles the plan and its baseline were sailed through (the one routed on and the complete ones '
           'before it, valid at the same times); empty: not computed'),
    Column('p_on_time', 'DOUBLE', None,
           'share of those cycles in which the plan, sailed as made, arrives by the RTA (+ 0.5 h), 0..1'),
    Column('baseline_p_on_time', 'DOUBLE', None, 'the same share for the constant-speed baseline, 0..1'),
    Column('fuel_p10_t', 'DOUBLE', 't', "10th percentile of the plan's fuel over those cycles, tonnes"),
    Column('fuel_p50_t', 'DOUBLE', 't', "median of the plan's fuel over those cycles, tonnes"),
    Column('fuel_p90_t', 'DOUBLE', 't', "90th percentile of the plan's fuel over those cycles, tonnes"),
    Column('savings_p10_pct', 'DOUBLE', '%',
           '10th percentile over those cycles of the saving against the baseline sailed in the same cycle, percent'),
    Column('savings_p50_pct', 'DOUBLE', '%', 'median of that saving, percent'),
    Column('savings_p90_pct', 'DOUBLE', '%', '90th percentile of that saving, percent'),
    Column('baseline_lat_deg', 'DOUBLE[]', 'degree',
           "latitudes of the constant-speed baseline's waypoints (the base route), degrees north; empty: no baseline"),
    Column('baseline_lon_deg', 'DOUBLE[]', 'degree', "longitudes of the baseline's waypoints, degrees east"),
    Column('baseline_leg_rpm', 'DOUBLE[]', 'rpm',
           "engine speed of each leg of the baseline (one constant rpm), so it can be sailed again (plan_verification)"),
    Column('margin_cost_pct', 'DOUBLE', '%',
           'what aiming before the RTA (an arrival margin) costs: the constant-speed voyage arriving as early as the plan '
           'aims burns this much more than the one arriving at the RTA, percent of the latter\'s fuel; '
           'savings_total_pct (against the RTA baseline) = savings_speed_profile_pct + savings_route_pct − this; '
           '0: the plan aims at the RTA'),
), primary_key=('run_id', 'voyage_id'))

ROUTE_LEGS = Table('route_legs', 'legs of each route plan, with the weather met (speeds in knots, times UTC)', (
    Column('run_id', 'VARCHAR', None, 'routing run that made this plan (route_runs.run_id)'),
    Column('voyage_id', 'VARCHAR', None, 'voyage routed (voyages.voyage_id)'),
    Column('leg', 'INTEGER', None, 'leg number along the route, from 0'),
    Column('lat0', 'DOUBLE', 'degree_north', 'leg start latitude, degrees north'),
    Column('lon0', 'DOUBLE', 'degree_east', 'leg start longitude, degrees east'),
    Column('lat1', 'DOUBLE', 'degree_north', 'leg end latitude, degrees north'),
    Column('lon1', 'DOUBLE', 'degree_east', 'leg end longitude, degrees east'),
    Column('course_deg', 'DOUBLE', 'degree', 'course over ground, degrees true'),
    Column('dist_nm', 'DOUBLE', 'NM', 'leg distance, nautical miles'),
    Column('rpm', 'DOUBLE', 'rpm', 'main engine speed, revolutions per minute'),
    Column('stw_kn', 'DOUBLE', 'kn', 'speed through water, knots'),
    Column('sog_kn', 'DOUBLE', 'kn', 'speed over ground, knots'),
    Column('hours', 'DOUBLE', 'h', 'leg sailing time, hours (the wait before it is wait_h)'),
    Column('fuel_t', 'DOUBLE', 't', 'fuel burnt in tonnes sailing the leg (the wait before it is wait_fuel_t)'),
    Column('etd_utc', 'TIMESTAMP', 'UTC', 'leg start time (UTC), after any wait at its start node'),
    Column('eta_utc', 'TIMESTAMP', 'UTC', 'leg end time (UTC)'),
    Column('wind_kn', 'DOUBLE', 'kn', 'true wind speed on the leg, knots'),
    Column('wind_dir_deg', 'DOUBLE', 'degree', 'wind coming from, degrees true'),
    Column('hs_m', 'DOUBLE', 'm', 'significant wave height on the leg, metres'),
    Column('wave_dir_deg', 'DOUBLE', 'degree', 'waves coming from, degrees true'),
    Column('current_kn', 'DOUBLE', 'kn', 'current speed on the leg, knots'),
    Column('beyond_forecast', 'BOOLEAN', None,
           "true when the leg is sailed past the forecast horizon (in the region's mean wind and waves from near the beam)"),
    Column('hours_beyond_forecast', 'DOUBLE', 'h', "hours of the leg sailed past the forecast's last valid time"),
    Column('hours_before_cycle', 'DOUBLE', 'h', "hours of the leg sailed before the forecast cycle's init time"),
    Column('hours_without_wind', 'DOUBLE', 'h',
           "hours of the leg sailed where the cube's wind is missing (a hole, sailed as calm; the plan's reason names the leg)"),
    Column('wait_h', 'DOUBLE', 'h',
           'hours the ship waits (hove to) at the leg\'s start node before sailing it, e.g. for weather to pass; 0 for most '
           'plans; the route\'s hours include it'),
    Column('wait_fuel_t', 'DOUBLE', 't', 'fuel burnt in tonnes while waiting before the leg; the route\'s fuel_t includes it'),
    Column('fuel_beyond_forecast_t', 'DOUBLE', 't',
           "fuel burnt in tonnes after the forecast's last valid time, sailing the leg and waiting before it (the "
           "region's mean wind and waves from near the beam, no current: an assumption, not a forecast)"),
), primary_key=('run_id', 'voyage_id', 'leg'))

# the columns routing added to route_legs after they were first made (DDL from the definition above)
LEG_HOURS_ADDED = ('hours_beyond_forecast', 'hours_before_cycle', 'hours_without_wind')
# the columns splitting each plan's saving into what the forecast covers and what it does not
ROUTE_FORECAST_SPLIT_ADDED = ('fuel_beyond_forecast_t', 'honest_baseline_fuel_beyond_forecast_t',
                              'savings_forecast_pct', 'savings_beyond_forecast_pct')
# the plan's spread across a lagged ensemble of cycles (pipeline/routing/ensemble.py)
ROUTE_ENSEMBLE_ADDED = ('ensemble_members', 'p_on_time', 'baseline_p_on_time', 'fuel_p10_t', 'fuel_p50_t', 'fuel_p90_t',
                        'savings_p10_pct', 'savings_p50_pct', 'savings_p90_pct')

# what the plan's arrival margin costs, the saving being against the baseline arriving at the RTA itself
ROUTE_MARGIN_COST_ADDED = ('margin_cost_pct',)

# the baseline's track, so plan and baseline can be sailed again in the weather that came (plan_verification)
ROUTE_BASELINE_TRACK_ADDED = ('baseline_lat_deg', 'baseline_lon_deg', 'baseline_leg_rpm')

# What happened: each plan and its baseline re-sailed in the analysed weather of later cycles
# (pipeline/routing/verification.py, flows/jobs/verify.py)
PLAN_VERIFICATION = Table('plan_verification', 'plans re-sailed in the analysed weather of later cycles, with their '
                          'constant-speed baselines: realised fuel and arrival against the claim (one row per plan, '
                          'replaced as newer cycles arrive)', (
    Column('run_id', 'VARCHAR', None, 'routing run that made the plan (routes.run_id)'),
    Column('voyage_id', 'VARCHAR', None, 'voyage (routes.voyage_id)'),
    Column('plan_kind', 'VARCHAR', None,
           'where the plan starts: port (the whole voyage) or re-plan at sea (the rest of it, from routes.start_kind)'),
    Column('cycle', 'TIMESTAMP', 'UTC', 'forecast cycle the plan was made on (UTC)'),
    Column('cycles_used', 'VARCHAR', None,
           'cycles whose weather the plan was re-sailed in, oldest first, comma separated (YYYY-MM-DDTHH)'),
    Column('newest_cycle', 'TIMESTAMP', 'UTC', 'the newest of them (UTC)'),
    Column('analysis_lead_h', 'DOUBLE', 'h', "the longest lead counted as analysed weather, hours"),
    Column('analysed_until_utc', 'TIMESTAMP', 'UTC', 'the last analysed valid time (UTC)'),
    Column('hours_analysed', 'DOUBLE', 'h',
           "hours of the plan's realised passage in analysed weather (between two analysed valid times)"),
    Column('hours_total', 'DOUBLE', 'h', "hours of the plan's realised passage"),
    Column('coverage', 'VARCHAR', None,
           'verified (the whole passage analysed) | partly verified (the rest sailed in the newest forecast, or past it '
           'in its neutral weather)', not_null=True, allowed=('verified', 'partly verified')),
    Column('claimed_fuel_t', 'DOUBLE', 't', "the plan's fuel as planned (routes.fuel_t), tonnes"),
    Column('realised_fuel_t', 'DOUBLE', 't', "the plan's fuel re-sailed, tonnes"),
    Column('claimed_eta_utc', 'TIMESTAMP', 'UTC', 'arrival as planned (UTC)'),
    Column('realised_eta_utc', 'TIMESTAMP', 'UTC', 'arrival re-sailed (UTC)'),
    Column('realised_late_h', 'DOUBLE', 'h', 'hours the re-sailed arrival is after the RTA (negative: early)'),
    Column('claimed_baseline_fuel_t', 'DOUBLE', 't',
           "the constant-speed baseline's fuel in the plan's forecast (routes.honest_baseline_fuel_t), tonnes"),
    Column('realised_baseline_fuel_t', 'DOUBLE', 't', "the baseline's fuel re-sailed, tonnes; empty: no baseline stored"),
    Column('realised_baseline_eta_utc', 'TIMESTAMP', 'UTC', "the baseline's arrival re-sailed (UTC)"),
    Column('claimed_savings_pct', 'DOUBLE', '%', 'saving against the baseline as claimed (routes.savings_total_pct), percent'),
    Column('realised_savings_pct', 'DOUBLE', '%',
           'saving against the baseline, both re-sailed in the same weather, percent'),
    Column('verified_at', 'TIMESTAMP', 'UTC', 'when this row was computed (UTC)', not_null=True),
), primary_key=('run_id', 'voyage_id'))

# route_legs is kept in one Parquet file per run beside the warehouse (storage/route_history.py); this table lists
# the files of committed runs, so a file is part of the warehouse only once its run's rows are committed
ROUTE_LEG_PARTS = Table('route_leg_parts', 'the Parquet files holding the route_legs of each committed run, one per batch of voyages it stored', (
    Column('run_id', 'VARCHAR', None, 'routing run whose legs the file holds (route_runs.run_id)'),
    Column('file', 'VARCHAR', None, 'the file, relative to the route_legs folder beside the warehouse', not_null=True),
    Column('n_rows', 'BIGINT', None, 'legs in the file', not_null=True),
    Column('n_bytes', 'BIGINT', None, 'size of the file in bytes', not_null=True),
    Column('sha256', 'VARCHAR', None, 'SHA-256 of the file, hex, taken when it was written and read back', not_null=True),
    Column('written_at', 'TIMESTAMP', 'UTC', 'when the file was written (UTC)', not_null=True),
), primary_key=('run_id', 'file'))

TABLES = (ROUTE_RUNS, ROUTES, ROUTE_LEGS, ROUTE_LEG_PARTS, PLAN_VERIFICATION)
