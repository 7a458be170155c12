"""Warehouse tables: fleet (vessels, noon reports, performance models, voyages, bunker logs)."""

from dataclasses import replace

from schemas.table import Column, Table

VESSELS = Table('vessels', 'the fleet: one row per vessel', (
    Column('imo', 'BIGINT', None, 'IMO number of the vessel'),
    Column('name', 'VARCHAR', None, 'vessel name', not_null=True),
    Column('type', 'VARCHAR', None, 'vessel type'),
    Column('dwt', 'DOUBLE', 't', 'deadweight, tonnes'),
    Column('design_speed_kn', 'DOUBLE', 'kn', 'design speed, knots'),
    Column('mcr_kw', 'DOUBLE', 'kW', 'maximum continuous rating, kW'),
    Column('rpm_max', 'DOUBLE', 'rpm', 'maximum main engine speed, revolutions per minute'),
    Column('design_fuel_tph', 'DOUBLE', 't/h', 'design fuel consumption, tonnes per hour'),
    Column('barred_rpm', 'VARCHAR', 'rpm', 'barred main engine speed ranges that must not be held, as low-high rpm '
           'separated by ";" (e.g. 52-60); empty: none'),
), primary_key=('imo',))

# the columns of a noon report, shared by the stored, the refused and the replaced reports
NOON_COLUMNS = (
    Column('imo', 'BIGINT', None, 'IMO number of the vessel', not_null=True),
    Column('ts_utc', 'TIMESTAMP', 'UTC', 'time of the noon report (UTC)', not_null=True),
    Column('lat', 'DOUBLE', 'degree_north', 'latitude at report time, degrees north'),
    Column('lon', 'DOUBLE', 'degree_east', 'longitude at report time, degrees east'),
    Column('rpm', 'DOUBLE', 'rpm', 'mean main engine speed since the last report, revolutions per minute'),
    Column('draft_m', 'DOUBLE', 'm', 'mean draft, metres'),
    Column('trim_m', 'DOUBLE', 'm', 'trim (aft minus fore draft), metres'),
    Column('stw_kn', 'DOUBLE', 'kn', 'mean speed through water since the last report, knots'),
    Column('sog_kn', 'DOUBLE', 'kn', 'mean speed over ground since the last report, knots'),
    Column('dist_nm', 'DOUBLE', 'NM', 'distance sailed since the last report, nautical miles'),
    Column('hours', 'DOUBLE', 'h', 'hours steamed since the last report'),
    Column('fuel_t', 'DOUBLE', 't', 'fuel burnt since the last report, tonnes (all grades)'),
    Column('fuel_hfo_t', 'DOUBLE', 't', 'heavy fuel oil burnt since the last report, tonnes'),
    Column('fuel_mgo_t', 'DOUBLE', 't', 'marine gas oil burnt since the last report, tonnes'),
    Column('wind_kn', 'DOUBLE', 'kn', 'true wind speed, knots'),
    Column('wind_dir_rel_deg', 'DOUBLE', 'degree',
           'wind coming from, degrees relative to the bow (0 head, 180 following)'),
    Column('wave_m', 'DOUBLE', 'm', 'significant wave height, metres'),
    Column('wave_dir_rel_deg', 'DOUBLE', 'degree',
           'waves coming from, degrees relative to the bow (0 head, 180 following)'),
    Column('current_kn', 'DOUBLE', 'kn', 'current speed, knots'),
    Column('current_dir_rel_deg', 'DOUBLE', 'degree', 'current setting towards, degrees relative to the bow'),
    Column('months_since_drydock', 'DOUBLE', 'month', 'months since the last dry-docking (hull fouling)'),
    Column('source_file', 'VARCHAR', None, 'file the row was imported from'),
)
# what every table of refused rows keeps besides the readable keys
RAW = Column('raw', 'VARCHAR', None, 'the row as it came in')
REASON = Column('reason', 'VARCHAR', None, 'why the row was refused', not_null=True)
SOURCE_FILE = NOON_COLUMNS[-1]
REJECTED_AT = Column('rejected_at', 'TIMESTAMP', 'UTC', 'when the row was refused (UTC)')

VESSELS_REJECTED = Table('vessels_rejected', 'rows of vessels files refused on import', (
    Column('imo', 'BIGINT', None, 'IMO number of the vessel'),
    RAW,
    REASON,
    SOURCE_FILE,
    REJECTED_AT,
))

NOON_REPORTS = Table('noon_reports', 'noon reports: what each vessel sailed, burnt and met, per report', NOON_COLUMNS,
                     primary_key=('imo', 'ts_utc'))

NOON_REPORTS_REJECTED = Table(
    'noon_reports_rejected', 'noon reports refused on import, with the reason',
    (*(replace(c, not_null=False) for c in NOON_COLUMNS), RAW, REASON, REJECTED_AT))

NOON_REPORTS_HISTORY = Table(
    'noon_reports_history', 'stored noon reports replaced by corrected ones or excluded for a period, as they were', (
        *NOON_COLUMNS,
        Column('removed_at', 'TIMESTAMP', 'UTC', 'when the report was replaced or excluded (UTC)', not_null=True),
        Column('reason', 'VARCHAR', None, "replaced by <file> | excluded: <the operator's reason>", not_null=True),
    ))

PERF_MODELS = Table('perf_models', 'fitted vessel performance models (speed and fuel), every version', (
    Column('imo', 'BIGINT', None, 'IMO number of the vessel'),
    Column('version', 'INTEGER', None, 'model version, per vessel and target'),
    Column('fitted_at', 'TIMESTAMP', 'UTC', 'when the model was fitted (UTC)', not_null=True),
    Column('form', 'VARCHAR', None, 'model form: thesis | physical | mlp', not_null=True),
    Column('target', 'VARCHAR', None, 'what the model predicts: speed (knots through water) | fuel (tonnes per hour)'),
    Column('coefficients', 'VARCHAR', None, 'JSON {regressor: value}'),
    Column('n_rows', 'INTEGER', None, 'noon reports fitted on'),
    Column('r2', 'DOUBLE', None, 'coefficient of determination on the fitted rows'),
    Column('rmse', 'DOUBLE', None,
           'root mean square error on the fitted rows (knots for speed, tonnes per hour for fuel)'),
    Column('cv_rmse', 'DOUBLE', None, 'cross-validated root mean square error (units of the target)'),
    Column('status', 'VARCHAR', None,
           'active | rejected (failed validation: reason) | superseded (a newer model is active)', not_null=True, allowed=('active', 'rejected', 'superseded')),
    Column('reason', 'VARCHAR', None, 'why the model was activated or rejected'),
    Column('active', 'BOOLEAN', None, 'true for the model routing uses', not_null=True),
    Column('months_dd', 'DOUBLE', 'month', 'months since dry-docking the model was fitted at'),
    Column('holdout_rmse', 'DOUBLE', None,
           'root mean square error on the newest reports, fitted without them (units of the target)'),
    Column('n_holdout', 'INTEGER', None, 'newest reports held out for holdout_rmse'),
    Column('data_hash', 'VARCHAR', None,
           'digest of the rows, form and fit settings (the same inputs give the same model)'),
    Column('data_to_utc', 'TIMESTAMP', 'UTC', 'newest report the coefficients were fitted on (UTC)'),
    Column('flag', 'VARCHAR', None, 'why new reports contradict this active model'),
    Column('envelope', 'VARCHAR', None,
           'JSON of the conditions fitted on: rpm and draft_m [least, largest], largest wind_kn and hs_m; '
           'routing clips rpm settings to it and evaluates the model inside it'),
    Column('gate', 'VARCHAR', None,
           "the gate the refit applied: 'default' or the settings that differed (jitroute refit --gate "
           'NAME=VALUE)'),
), primary_key=('imo', 'version', 'target'))

HULL_PERFORMANCE_MONTHLY = Table(
    'hull_performance_monthly',
    'speed loss against a clean hull per vessel and month (ISO 19030 spirit), rewritten at every refit', (
    Column('imo', 'BIGINT', None, 'IMO number of the vessel'),
    Column('month', 'DATE', None, 'calendar month (its first day, UTC)'),
    Column('n_reports', 'INTEGER', None, 'noon reports of the month with a reference speed', not_null=True),
    Column('speed_loss_pct', 'DOUBLE', '%',
           "median speed loss over the month's reports, percent: 100·(1 − measured STW / the active model's STW "
           "with a clean hull in the report's conditions)"),
    Column('flag', 'BOOLEAN', None,
           'speed loss above the threshold (settings.performance.hull_flag_pct, 5 % by default)', not_null=True),
    Column('model_version', 'INTEGER', None, 'version of the active model used as the reference'),
    Column('computed_at', 'TIMESTAMP', 'UTC', 'when the month was computed (UTC)', not_null=True),
), primary_key=('imo', 'month'))

VOYAGES = Table('voyages', 'voyages to route: ports, departure and required arrival', (
    Column('voyage_id', 'VARCHAR', None, 'voyage id'),
    Column('imo', 'BIGINT', None, 'IMO number of the vessel', not_null=True),
    Column('dep_name', 'VARCHAR', None, 'departure port'),
    Column('dep_lat', 'DOUBLE', 'degree_north', 'departure latitude, degrees north'),
    Column('dep_lon', 'DOUBLE', 'degree_east', 'departure longitude, degrees east'),
    Column('arr_name', 'VARCHAR', None, 'arrival port'),
    Column('arr_lat', 'DOUBLE', 'degree_north', 'arrival latitude, degrees north'),
    Column('arr_lon', 'DOUBLE', 'degree_east', 'arrival longitude, degrees east'),
    Column('depart_utc', 'TIMESTAMP', 'UTC', 'departure time (UTC)', not_null=True),
    Column('rta_utc', 'TIMESTAMP', 'UTC', 'required time of arrival (UTC)', not_null=True),
    Column('draft_m', 'DOUBLE', 'm', 'draft, metres'),
    Column('trim_m', 'DOUBLE', 'm', 'trim (aft minus fore draft), metres'),
    Column('rpm_options', 'DOUBLE[]', 'rpm', 'main engine speeds the solver may choose, revolutions per minute'),
    Column('max_hs_m', 'DOUBLE', 'm', 'highest significant wave height allowed, metres'),
    Column('max_wind_kn', 'DOUBLE', 'kn', 'highest wind allowed, knots'),
    Column('status', 'VARCHAR', None, 'voyage status from the voyages file (planned voyages are routed)'),
    Column('plan_id', 'VARCHAR', None,
           'fleet plan that made this voyage (fleet_plans.plan_id); NULL for voyages from a voyages file'),
), primary_key=('voyage_id',))

VOYAGES_REJECTED = Table('voyages_rejected', 'rows of voyages files refused on import', (
    Column('voyage_id', 'VARCHAR', None, 'voyage id'),
    Column('imo', 'BIGINT', None, 'IMO number of the vessel'),
    RAW,
    REASON,
    SOURCE_FILE,
    REJECTED_AT,
))

VOYAGE_POSITIONS = Table(
    'voyage_positions',
    'positions of voyages at sea given by an operator; re-planning starts from the newest', (
    Column('voyage_id', 'VARCHAR', None, 'voyage id'),
    Column('ts_utc', 'TIMESTAMP', 'UTC', 'time of the position (UTC)'),
    Column('lat', 'DOUBLE', 'degree_north', 'latitude, degrees north', not_null=True),
    Column('lon', 'DOUBLE', 'degree_east', 'longitude, degrees east', not_null=True),
    Column('note', 'VARCHAR', None, 'who or what gave it'),
    Column('entered_at', 'TIMESTAMP', 'UTC', 'when it was entered (UTC)'),
), primary_key=('voyage_id', 'ts_utc'))

BUNKER_LOGS = Table('bunker_logs', 'fuel bunkered: what, where, from whom, and what remained on board', (
    Column('imo', 'BIGINT', None, 'IMO number of the vessel'),
    Column('bill_no', 'VARCHAR', None, 'bunker delivery note number'),
    Column('date_utc', 'TIMESTAMP', 'UTC', 'delivery date (UTC)', not_null=True),
    Column('port', 'VARCHAR', None, 'port of delivery'),
    Column('supplier', 'VARCHAR', None, 'supplier'),
    Column('fuel_type', 'VARCHAR', None, 'fuel grade, upper case: HFO | LFO | MGO | MDO | DO | LNG | ...'),
    Column('received_t', 'DOUBLE', 't', 'fuel received, tonnes', not_null=True),
    Column('rob_t', 'DOUBLE', 't', 'fuel of this grade remaining on board before receiving, tonnes'),
    SOURCE_FILE,
), primary_key=('imo', 'bill_no', 'fuel_type'))

BUNKER_LOGS_REJECTED = Table(
    'bunker_logs_rejected',
    'rows of bunker-log files refused on import, with the reason and the raw row', (
    Column('imo', 'BIGINT', None, 'IMO number of the vessel, when readable'),
    Column('bill_no', 'VARCHAR', None, 'bunker delivery note number, as written'),
    RAW,
    REASON,
    SOURCE_FILE,
    REJECTED_AT,
))

TABLES = (VESSELS, VESSELS_REJECTED, NOON_REPORTS, NOON_REPORTS_REJECTED, NOON_REPORTS_HISTORY, PERF_MODELS, HULL_PERFORMANCE_MONTHLY, VOYAGES, VOYAGES_REJECTED, VOYAGE_POSITIONS, BUNKER_LOGS, BUNKER_LOGS_REJECTED,)
