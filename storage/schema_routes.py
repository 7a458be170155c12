"""Warehouse schema for fleet routing runs: runs, routes, legs (named migrations, applied in order).

Times are UTC TIMESTAMPs; fuel in tonnes, distances in NM, speeds in knots, directions in
degrees (wind/waves coming-from).
"""

import hashlib

from schemas.tables.routes import (LEG_HOURS_ADDED, PLAN_VERIFICATION, ROUTE_BASELINE_TRACK_ADDED, ROUTE_ENSEMBLE_ADDED,
                                   ROUTE_FORECAST_SPLIT_ADDED, ROUTE_MARGIN_COST_ADDED, ROUTE_LEG_PARTS, ROUTE_LEGS, ROUTES)
from storage.migration import Migration

# What a plan depends on of its voyage (vessel, ports, RTA, draft), as one digest: routing stores it with each plan
# (storage.fleet_store.voyage_fingerprints) and latest_routes compares it with the voyage of today, so a plan made
# for an RTA, port, vessel or draft since changed shows as `stale`. One expression for both, over a voyages row `v`.
VOYAGE_FINGERPRINT_SQL = (
    "md5(concat_ws('|', v.imo, v.dep_name, v.dep_lat, v.dep_lon, v.arr_name, v.arr_lat, v.arr_lon, "
    "strftime(v.rta_utc, '%Y-%m-%dT%H:%M:%S'), v.draft_m))")

# The view of the plan to sail per voyage. A view made with `r.*` keeps the columns routes had when it was made,
# so it is made again after every migration (views_migration) and always lists the routes columns of today.
LATEST_ROUTES_VIEW = """
        CREATE OR REPLACE VIEW latest_routes AS
        WITH attempts AS (
            SELECT r.*, u.started_at AS run_started_at, r.status IN ('ok', 'late') AS has_plan,
                   row_number() OVER (PARTITION BY r.voyage_id ORDER BY u.started_at DESC, r.run_id DESC) AS newest_rank
            FROM routes r JOIN route_runs u USING (run_id)
        ),
        newest AS (SELECT * FROM attempts WHERE newest_rank = 1),
        shown AS (  -- the newest attempt with a plan; a voyage never planned shows its newest attempt
            SELECT * FROM attempts
            QUALIFY row_number() OVER (PARTITION BY voyage_id ORDER BY has_plan DESC, run_started_at DESC, run_id DESC) = 1
        )
        SELECT s.* EXCLUDE (run_started_at, has_plan, newest_rank), v.dep_name, v.arr_name, x.name AS vessel_name,
               n.run_id <> s.run_id AS newer_attempt_failed,
               CASE WHEN n.run_id <> s.run_id THEN n.run_id END AS newer_attempt_run_id,
               CASE WHEN n.run_id <> s.run_id THEN n.status END AS newer_attempt_status,
               CASE WHEN n.run_id <> s.run_id THEN n.reason END AS newer_attempt_reason,
               CASE WHEN n.run_id <> s.run_id THEN n.run_started_at END AS newer_attempt_at,
               CASE WHEN s.status NOT IN ('ok', 'late') OR s.voyage_fingerprint IS NULL OR v.voyage_id IS NULL THEN false
                    ELSE s.voyage_fingerprint <> """ + VOYAGE_FINGERPRINT_SQL + """ END AS stale,
               CASE WHEN s.status NOT IN ('ok', 'late') OR s.voyage_fingerprint IS NULL OR v.voyage_id IS NULL
                         OR s.voyage_fingerprint = """ + VOYAGE_FINGERPRINT_SQL + """ THEN NULL
                    ELSE concat_ws(', ', CASE WHEN v.rta_utc IS DISTINCT FROM s.rta_utc THEN 'RTA changed' END,
                                   CASE WHEN v.imo IS DISTINCT FROM s.imo THEN 'vessel changed' END,
                                   'voyage changed since the plan was made (RTA, ports, vessel or draft): re-plan it') END
                   AS stale_reason
        FROM shown s
        JOIN newest n USING (voyage_id)
        LEFT JOIN voyages v USING (voyage_id)
        LEFT JOIN vessels x ON x.imo = s.imo
        -- a voyage a fleet re-plan replaced (deleted) has no plan to sail any more
        WHERE v.voyage_id IS NOT NULL
           OR s.voyage_id NOT IN (SELECT voyage_id FROM fleet_plan_legs WHERE voyage_id IS NOT NULL);
"""


# latest_routes as migration routes_006 made it (before the plan-start and staleness columns existed)
_LATEST_ROUTES_VIEW_006 = """
        CREATE OR REPLACE VIEW latest_routes AS
        WITH attempts AS (
            SELECT r.*, u.started_at AS run_started_at, r.status IN ('ok', 'late') AS has_plan,
                   row_number() OVER (PARTITION BY r.voyage_id ORDER BY u.started_at DESC, r.run_id DESC) AS newest_rank
            FROM routes r JOIN route_runs u USING (run_id)
        ),
        newest AS (SELECT * FROM attempts WHERE newest_rank = 1),
        shown AS (  -- the newest attempt with a plan; a voyage never planned shows its newest attempt
            SELECT * FROM attempts
            QUALIFY row_number() OVER (PARTITION BY voyage_id ORDER BY has_plan DESC, run_started_at DESC, run_id DESC) = 1
        )
        SELECT s.* EXCLUDE (run_started_at, has_plan, newest_rank), v.dep_name, v.arr_name, x.name AS vessel_name,
               n.run_id <> s.run_id AS newer_attempt_failed,
               CASE WHEN n.run_id <> s.run_id THEN n.run_id END AS newer_attempt_run_id,
               CASE WHEN n.run_id <> s.run_id THEN n.status END AS newer_attempt_status,
               CASE WHEN n.run_id <> s.run_id THEN n.reason END AS newer_attempt_reason,
               CASE WHEN n.run_id <> s.run_id THEN n.run_started_at END AS newer_attempt_at
        FROM shown s
        JOIN newest n USING (voyage_id)
        LEFT JOIN voyages v USING (voyage_id)
        LEFT JOIN vessels x ON x.imo = s.imo;
"""


# fleet_savings with each run's saving split by when the fuel is burnt (savings.py): within the forecast's valid
# times (backed by the forecast) and after its last one (the neutral weather past the horizon, an assumption). The
# split sums run over the voyages that have it (plans made before it existed do not).
_SPLIT = "r.savings_forecast_pct IS NOT NULL"
FLEET_SAVINGS_VIEW_013 = f"""
        CREATE OR REPLACE VIEW fleet_savings AS
        SELECT u.run_id, u.started_at, u.cycle, u.trigger, u.status AS run_status, count(*) AS n_voyages,
               count(*) FILTER (WHERE r.status = 'ok') AS n_on_time,
               count(*) FILTER (WHERE r.status = 'late') AS n_late,
               count(*) FILTER (WHERE r.status = 'infeasible') AS n_infeasible,
               count(*) FILTER (WHERE r.status = 'failed') AS n_failed,
               count(*) FILTER (WHERE r.status IN ('infeasible', 'failed')) AS n_not_routed,
               coalesce(u.n_export_failed, 0) AS n_export_failed,
               count(*) FILTER (WHERE r.savings_total_pct IS NOT NULL) AS n_compared,
               sum(r.fuel_t) FILTER (WHERE r.savings_total_pct IS NOT NULL) AS fuel_t,
               sum(r.honest_baseline_fuel_t) FILTER (WHERE r.savings_total_pct IS NOT NULL) AS honest_baseline_fuel_t,
               sum(r.profile_fuel_t) FILTER (WHERE r.savings_total_pct IS NOT NULL) AS profile_fuel_t,
               100 * (1 - sum(r.fuel_t) FILTER (WHERE r.savings_total_pct IS NOT NULL)
                        / nullif(sum(r.honest_baseline_fuel_t) FILTER (WHERE r.savings_total_pct IS NOT NULL), 0))
                   AS savings_total_pct,
               100 * (1 - sum(r.profile_fuel_t) FILTER (WHERE r.savings_total_pct IS NOT NULL)
                        / nullif(sum(r.honest_baseline_fuel_t) FILTER (WHERE r.savings_total_pct IS NOT NULL), 0))
                   AS savings_speed_profile_pct,
               100 * (sum(r.profile_fuel_t) FILTER (WHERE r.savings_total_pct IS NOT NULL)
                      - sum(r.fuel_t) FILTER (WHERE r.savings_total_pct IS NOT NULL))
                   / nullif(sum(r.honest_baseline_fuel_t) FILTER (WHERE r.savings_total_pct IS NOT NULL), 0)
                   AS savings_route_pct,
               count(*) FILTER (WHERE r.forecast_flag LIKE '%beyond horizon%') AS n_beyond_horizon,
               count(*) FILTER (WHERE {_SPLIT}) AS n_split,
               sum(r.fuel_beyond_forecast_t) FILTER (WHERE {_SPLIT}) AS fuel_beyond_forecast_t,
               sum(r.honest_baseline_fuel_beyond_forecast_t) FILTER (WHERE {_SPLIT})
                   AS honest_baseline_fuel_beyond_forecast_t,
               100 * ((sum(r.honest_baseline_fuel_t) FILTER (WHERE {_SPLIT})
                       - sum(r.honest_baseline_fuel_beyond_forecast_t) FILTER (WHERE {_SPLIT}))
                      - (sum(r.fuel_t) FILTER (WHERE {_SPLIT}) - sum(r.fuel_beyond_forecast_t) FILTER (WHERE {_SPLIT})))
                   / nullif(sum(r.honest_baseline_fuel_t) FILTER (WHERE {_SPLIT}), 0) AS savings_forecast_pct,
               100 * (sum(r.honest_baseline_fuel_beyond_forecast_t) FILTER (WHERE {_SPLIT})
                      - sum(r.fuel_beyond_forecast_t) FILTER (WHERE {_SPLIT}))
                   / nullif(sum(r.honest_baseline_fuel_t) FILTER (WHERE {_SPLIT}), 0) AS savings_beyond_forecast_pct,
               sum(r.limits_fuel_t) AS limits_fuel_t,
               sum(r.unlimited_fuel_t) FILTER (WHERE r.limits_fuel_t IS NOT NULL) AS unlimited_fuel_t,
               sum(r.baseline_fuel_t) FILTER (WHERE r.fuel_t IS NOT NULL) AS discrete_baseline_fuel_t,
               100 * (1 - sum(r.fuel_t) FILTER (WHERE r.baseline_fuel_t IS NOT NULL)
                        / nullif(sum(r.baseline_fuel_t) FILTER (WHERE r.fuel_t IS NOT NULL), 0)) AS savings_vs_discrete_pct
        FROM route_runs u JOIN routes r USING (run_id)
        GROUP BY ALL;
"""


# fleet_savings with each run's spread (routes.savings_p10/p50/p90_pct fuel-weighted by the baseline's fuel, as
# savings_total_pct is, and the mean P(on time)) and what its plans realised in the analysed weather of later cycles
# (plan_verification): the claim over the same verified voyages beside the realised saving, like with like
_SPREAD = "r.savings_p10_pct IS NOT NULL AND r.honest_baseline_fuel_t > 0"
_VERIFIED = "v.realised_baseline_fuel_t > 0 AND r.honest_baseline_fuel_t > 0"


def _weighted(col: str) -> str:
    return (f"sum(r.{col} * r.honest_baseline_fuel_t) FILTER (WHERE {_SPREAD}) "
            f"/ nullif(sum(r.honest_baseline_fuel_t) FILTER (WHERE {_SPREAD}), 0)")


_FLEET_SAVINGS_ADDED_016 = f"""
               count(*) FILTER (WHERE r.p_on_time IS NOT NULL) AS n_ensemble,
               avg(r.p_on_time) AS p_on_time,
               {_weighted('savings_p10_pct')} AS savings_p10_pct,
               {_weighted('savings_p50_pct')} AS savings_p50_pct,
               {_weighted('savings_p90_pct')} AS savings_p90_pct,
               count(v.run_id) AS n_verified,
               count(*) FILTER (WHERE v.coverage = 'verified') AS n_verified_whole,
               sum(v.hours_analysed) AS verified_hours_analysed,
               sum(v.hours_total) AS verified_hours_total,
               count(*) FILTER (WHERE {_VERIFIED}) AS n_verified_compared,
               sum(r.fuel_t) FILTER (WHERE {_VERIFIED}) AS verified_claimed_fuel_t,
               sum(v.realised_fuel_t) FILTER (WHERE {_VERIFIED}) AS realised_fuel_t,
               sum(v.realised_baseline_fuel_t) FILTER (WHERE {_VERIFIED}) AS realised_baseline_fuel_t,
               100 * (1 - sum(r.fuel_t) FILTER (WHERE {_VERIFIED})
                        / nullif(sum(r.honest_baseline_fuel_t) FILTER (WHERE {_VERIFIED}), 0)) AS verified_claimed_savings_pct,
               100 * (1 - sum(v.realised_fuel_t) FILTER (WHERE {_VERIFIED})
                        / nullif(sum(v.realised_baseline_fuel_t) FILTER (WHERE {_VERIFIED}), 0)) AS realised_savings_pct,
               count(*) FILTER (WHERE v.realised_late_h <= 0.5) AS n_realised_on_time,
"""
FLEET_SAVINGS_VIEW_016 = (FLEET_SAVINGS_VIEW_013
                          .replace("               sum(r.limits_fuel_t) AS limits_fuel_t,",
                                   _FLEET_SAVINGS_ADDED_016.strip("\n") + "\n               sum(r.limits_fuel_t) AS limits_fuel_t,")
                          .replace("FROM route_runs u JOIN routes r USING (run_id)",
                                   "FROM route_runs u JOIN routes r USING (run_id)\n"
                                   "        LEFT JOIN plan_verification v USING (run_id, voyage_id)"))
assert FLEET_SAVINGS_VIEW_016.count("plan_verification") == 1 and "n_verified_whole" in FLEET_SAVINGS_VIEW_016

# fleet_savings with what the runs' arrival margins cost (routes.margin_cost_pct, fuel-weighted by the honest
# baseline's fuel over the compared voyages, as savings_total_pct, which already counts it; 0 for a plan aiming at
# the RTA and for rows stored before the column)
_COMPARED = "r.savings_total_pct IS NOT NULL"
FLEET_SAVINGS_VIEW_020 = FLEET_SAVINGS_VIEW_016.replace(
    "               sum(r.limits_fuel_t) AS limits_fuel_t,",
    f"               sum(coalesce(r.margin_cost_pct, 0) * r.honest_baseline_fuel_t) FILTER (WHERE {_COMPARED})\n"
    f"                   / nullif(sum(r.honest_baseline_fuel_t) FILTER (WHERE {_COMPARED}), 0) AS margin_cost_pct,\n"
    "               sum(r.limits_fuel_t) AS limits_fuel_t,", 1)
assert FLEET_SAVINGS_VIEW_020.count("AS margin_cost_pct") == 1


ARRIVAL_NM = 10.0  # a noon report this close to the destination is the arrival (plan against actual)

# plan against actual, like with like (migration routes_014). A plan made at sea (a re-plan: latest_routes.start_kind
# other than port) covers the voyage from its start only, so the actual side is counted from that start too: reports
# after it, the first one pro rata for the hours it covers after the start. A voyage has ended at its arrival report
# (within ARRIVAL_NM of the destination) or, without positions, when the vessel's next voyage has departed and
# reported; a ship still at sea has no arrival, and its errors are empty (its last report is not the arrival).
VOYAGE_PERFORMANCE_VIEW_014 = f"""
        CREATE OR REPLACE VIEW voyage_performance AS
        WITH bounds AS (
            SELECT voyage_id, imo, depart_utc, rta_utc, arr_lat, arr_lon,
                   lead(depart_utc) OVER (PARTITION BY imo ORDER BY depart_utc) AS next_depart_utc,
                   least(coalesce(lead(depart_utc) OVER (PARTITION BY imo ORDER BY depart_utc), rta_utc + INTERVAL 30 DAY),
                         rta_utc + INTERVAL 30 DAY) AS bound_utc
            FROM voyages),
        arrivals AS (
            SELECT b.voyage_id, min(n.ts_utc) AS arrived_utc
            FROM bounds b JOIN noon_reports n ON n.imo = b.imo AND n.ts_utc > b.depart_utc AND n.ts_utc <= b.bound_utc
            WHERE n.lat IS NOT NULL AND n.lon IS NOT NULL AND b.arr_lat IS NOT NULL AND b.arr_lon IS NOT NULL
              AND 2 * 3440.065 * asin(sqrt(pow(sin(radians(n.lat - b.arr_lat) / 2), 2)
                    + cos(radians(n.lat)) * cos(radians(b.arr_lat)) * pow(sin(radians(n.lon - b.arr_lon) / 2), 2)))
                  <= {ARRIVAL_NM}
            GROUP BY b.voyage_id),
        last_reports AS (SELECT imo, max(ts_utc) AS last_utc FROM noon_reports GROUP BY imo),
        windows AS (
            SELECT b.voyage_id, b.imo, b.depart_utc, coalesce(a.arrived_utc, b.bound_utc) AS window_end_utc,
                   a.arrived_utc,
                   a.arrived_utc IS NOT NULL OR (b.next_depart_utc IS NOT NULL AND l.last_utc >= b.next_depart_utc) AS ended,
                   CASE WHEN coalesce(p.start_kind, 'port') <> 'port' AND p.start_utc > b.depart_utc THEN p.start_utc
                        ELSE b.depart_utc END AS compared_from_utc,
                   coalesce(p.start_kind, 'port') <> 'port' AND p.start_utc > b.depart_utc AS from_replan
            FROM bounds b LEFT JOIN arrivals a USING (voyage_id) LEFT JOIN last_reports l USING (imo)
            LEFT JOIN latest_routes p USING (voyage_id)),
        shares AS (  -- each report's share after compared_from_utc (a re-plan's first report covers hours before it)
            SELECT w.voyage_id, n.ts_utc, n.fuel_t, n.hours, n.dist_nm,
                   CASE WHEN w.from_replan AND n.hours > 0
                        THEN least(1.0, date_diff('second', w.compared_from_utc, n.ts_utc) / 3600.0 / n.hours)
                        ELSE 1.0 END AS share
            FROM windows w JOIN noon_reports n
              ON n.imo = w.imo AND n.ts_utc > w.compared_from_utc AND n.ts_utc <= w.window_end_utc
            WHERE coalesce(n.dist_nm, 0) > 0 OR coalesce(n.stw_kn, 0) > 0.5),  -- at sea
        sailed AS (
            SELECT voyage_id, count(*) AS n_reports, sum(fuel_t * share) AS actual_fuel_t, sum(hours * share) AS actual_hours,
                   sum(dist_nm * share) AS actual_dist_nm, max(ts_utc) AS last_report_utc
            FROM shares GROUP BY voyage_id)
        SELECT v.voyage_id, v.imo, s.name AS vessel_name, v.dep_name, v.arr_name, v.depart_utc, v.rta_utc,
               p.run_id, p.status AS plan_status, p.model_version, coalesce(p.start_kind, 'port') AS plan_start_kind,
               w.compared_from_utc, p.fuel_t AS planned_fuel_t, p.eta_utc AS planned_eta_utc,
               a.n_reports, a.actual_fuel_t, a.actual_hours, a.actual_dist_nm, w.ended AS arrived, a.last_report_utc,
               CASE WHEN w.ended THEN coalesce(w.arrived_utc, a.last_report_utc) END AS actual_arrival_utc,
               CASE WHEN w.ended THEN 100 * (p.fuel_t - a.actual_fuel_t) / nullif(a.actual_fuel_t, 0) END AS fuel_error_pct,
               CASE WHEN w.ended THEN date_diff('second', p.eta_utc, coalesce(w.arrived_utc, a.last_report_utc)) / 3600.0
                    END AS arrival_error_h,
               CASE WHEN w.ended THEN date_diff('second', v.rta_utc, coalesce(w.arrived_utc, a.last_report_utc)) / 3600.0
                    END AS late_h
        FROM voyages v
        LEFT JOIN vessels s USING (imo)
        LEFT JOIN latest_routes p USING (voyage_id)
        LEFT JOIN windows w USING (voyage_id)
        LEFT JOIN sailed a USING (voyage_id);
"""


MIGRATIONS: list[Migration] = [
    Migration(
        "routes_001_tables",
        """
        CREATE TABLE route_runs (
            run_id VARCHAR PRIMARY KEY,
            started_at TIMESTAMP NOT NULL,
            finished_at TIMESTAMP,
            cycle TIMESTAMP,
            n_voyages INTEGER,
            n_ok INTEGER,
            n_failed INTEGER,
            status VARCHAR NOT NULL,           -- running | ok | partial | failed
            solver VARCHAR,
            trigger VARCHAR                    -- nightly | backfill | manual
        );
        CREATE TABLE routes (
            run_id VARCHAR NOT NULL,
            voyage_id VARCHAR NOT NULL,
            imo BIGINT,
            solver VARCHAR,
            objective VARCHAR,
            status VARCHAR NOT NULL,           -- ok | late | infeasible | failed
            reason VARCHAR,
            depart_utc TIMESTAMP,
            eta_utc TIMESTAMP,
            rta_utc TIMESTAMP,
            hours DOUBLE,
            fuel_t DOUBLE,
            baseline_fuel_t DOUBLE,
            baseline_hours DOUBLE,
            savings_pct DOUBLE,
            distance_nm DOUBLE,
            cost DOUBLE,
            model_version INTEGER,
            cycle TIMESTAMP,
            seed INTEGER,
            runtime_s DOUBLE,
            n_legs INTEGER,
            beyond_forecast INTEGER,           -- legs sailed past the forecast horizon (last step persisted)
            PRIMARY KEY (run_id, voyage_id)
        );
        CREATE TABLE route_legs (
            run_id VARCHAR NOT NULL,
            voyage_id VARCHAR NOT NULL,
            leg INTEGER NOT NULL,
            lat0 DOUBLE, lon0 DOUBLE, lat1 DOUBLE, lon1 DOUBLE,
            course_deg DOUBLE,
            dist_nm DOUBLE,
            rpm DOUBLE,
            stw_kn DOUBLE,
            sog_kn DOUBLE,
            hours DOUBLE,
            fuel_t DOUBLE,
            etd_utc TIMESTAMP,
            eta_utc TIMESTAMP,
            wind_kn DOUBLE,
            wind_dir_deg DOUBLE,
            hs_m DOUBLE,
            wave_dir_deg DOUBLE,
            current_kn DOUBLE,
            beyond_forecast BOOLEAN,
            PRIMARY KEY (run_id, voyage_id, leg)
        );
        """,
    ),
    Migration(
        "routes_002_analyst_views",
        """
        -- the newest routing of every voyage
        CREATE VIEW latest_routes AS
        SELECT r.*, v.dep_name, v.arr_name, s.name AS vessel_name
        FROM routes r
        JOIN route_runs u USING (run_id)
        LEFT JOIN voyages v USING (voyage_id)
        LEFT JOIN vessels s ON s.imo = r.imo
        QUALIFY row_number() OVER (PARTITION BY r.voyage_id ORDER BY u.started_at DESC) = 1;

        -- fuel and savings per run (only voyages routed with a baseline count towards savings)
        CREATE VIEW fleet_savings AS
        SELECT u.run_id, u.started_at, u.cycle, u.trigger, count(*) AS n_voyages,
               count(*) FILTER (WHERE r.status = 'ok') AS n_on_time,
               count(*) FILTER (WHERE r.status = 'late') AS n_late,
               count(*) FILTER (WHERE r.status IN ('infeasible', 'failed')) AS n_not_routed,
               sum(r.fuel_t) FILTER (WHERE r.baseline_fuel_t IS NOT NULL) AS fuel_t,
               sum(r.baseline_fuel_t) FILTER (WHERE r.fuel_t IS NOT NULL) AS baseline_fuel_t,
               100 * (1 - sum(r.fuel_t) FILTER (WHERE r.baseline_fuel_t IS NOT NULL)
                        / nullif(sum(r.baseline_fuel_t) FILTER (WHERE r.fuel_t IS NOT NULL), 0)) AS savings_pct
        FROM route_runs u JOIN routes r USING (run_id)
        GROUP BY ALL;

        -- active model fit quality per vessel and target
        CREATE VIEW model_quality AS
        SELECT m.imo, s.name AS vessel_name, m.target, m.form, m.version, m.fitted_at, m.n_rows, m.r2, m.rmse,
               m.cv_rmse, (SELECT count(*) FROM noon_reports n WHERE n.imo = m.imo) AS n_reports,
               (SELECT count(*) FROM noon_reports_rejected x WHERE x.imo = m.imo) AS n_rejected
        FROM perf_models m LEFT JOIN vessels s ON s.imo = m.imo
        WHERE m.active;

        -- per cycle: completeness and what the files did
        CREATE VIEW ingest_health AS
        SELECT c.cycle, c.complete, c.n_files_expected, c.n_files_ok, c.missing, c.written_at,
               count(l.file_name) FILTER (WHERE l.status = 'ok') AS files_downloaded,
               count(l.file_name) FILTER (WHERE l.status = 'skipped') AS files_skipped,
               count(l.file_name) FILTER (WHERE l.status = 'missing') AS files_missing,
               count(l.file_name) FILTER (WHERE l.status = 'corrupt') AS files_corrupt
        FROM cycles c LEFT JOIN ingest_log l ON l.cycle = c.cycle
        GROUP BY ALL;
        """,
    ),
    Migration(
        "routes_003_latest_good_plan",
        # the newest attempt may have failed (no weather, a lost worker): the plan to sail is then still the
        # newest successful one, flagged, with the failure's reason beside it
        """
        CREATE OR REPLACE VIEW latest_routes AS
        WITH attempts AS (
            SELECT r.*, u.started_at AS run_started_at, r.status IN ('ok', 'late') AS has_plan,
                   row_number() OVER (PARTITION BY r.voyage_id ORDER BY u.started_at DESC, r.run_id DESC) AS newest_rank
            FROM routes r JOIN route_runs u USING (run_id)
        ),
        newest AS (SELECT * FROM attempts WHERE newest_rank = 1),
        shown AS (  -- the newest attempt with a plan; a voyage never planned shows its newest attempt
            SELECT * FROM attempts
            QUALIFY row_number() OVER (PARTITION BY voyage_id ORDER BY has_plan DESC, run_started_at DESC, run_id DESC) = 1
        )
        SELECT s.* EXCLUDE (run_started_at, has_plan, newest_rank), v.dep_name, v.arr_name, x.name AS vessel_name,
               n.run_id <> s.run_id AS newer_attempt_failed,
               CASE WHEN n.run_id <> s.run_id THEN n.run_id END AS newer_attempt_run_id,
               CASE WHEN n.run_id <> s.run_id THEN n.status END AS newer_attempt_status,
               CASE WHEN n.run_id <> s.run_id THEN n.reason END AS newer_attempt_reason,
               CASE WHEN n.run_id <> s.run_id THEN n.run_started_at END AS newer_attempt_at
        FROM shown s
        JOIN newest n USING (voyage_id)
        LEFT JOIN voyages v USING (voyage_id)
        LEFT JOIN vessels x ON x.imo = s.imo;
        """,
    ),
    Migration(
        "routes_004_run_owner_and_exports",
        """
        -- who runs it (a run whose process died is marked failed by the next writer), why a run failed,
        -- and exports that failed (each export stands alone; the voyage's route is kept)
        ALTER TABLE route_runs ADD COLUMN IF NOT EXISTS host VARCHAR;
        ALTER TABLE route_runs ADD COLUMN IF NOT EXISTS pid INTEGER;
        ALTER TABLE route_runs ADD COLUMN IF NOT EXISTS pid_started VARCHAR;    -- the process's start time, so a reused PID is not taken for it
        ALTER TABLE route_runs ADD COLUMN IF NOT EXISTS reason VARCHAR;
        ALTER TABLE route_runs ADD COLUMN IF NOT EXISTS n_export_failed INTEGER;
        ALTER TABLE route_runs ADD COLUMN IF NOT EXISTS export_errors VARCHAR;  -- one line per failed export: voyage, kind, error

        -- fuel and savings per run (only voyages routed with a baseline count towards savings);
        -- n_on_time + n_late + n_infeasible + n_failed = n_voyages
        CREATE OR REPLACE VIEW fleet_savings AS
        SELECT u.run_id, u.started_at, u.cycle, u.trigger, u.status AS run_status, count(*) AS n_voyages,
               count(*) FILTER (WHERE r.status = 'ok') AS n_on_time,
               count(*) FILTER (WHERE r.status = 'late') AS n_late,
               count(*) FILTER (WHERE r.status = 'infeasible') AS n_infeasible,
               count(*) FILTER (WHERE r.status = 'failed') AS n_failed,
               count(*) FILTER (WHERE r.status IN ('infeasible', 'failed')) AS n_not_routed,
               coalesce(u.n_export_failed, 0) AS n_export_failed,
               sum(r.fuel_t) FILTER (WHERE r.baseline_fuel_t IS NOT NULL) AS fuel_t,
               sum(r.baseline_fuel_t) FILTER (WHERE r.fuel_t IS NOT NULL) AS baseline_fuel_t,
               100 * (1 - sum(r.fuel_t) FILTER (WHERE r.baseline_fuel_t IS NOT NULL)
                        / nullif(sum(r.baseline_fuel_t) FILTER (WHERE r.fuel_t IS NOT NULL), 0)) AS savings_pct
        FROM route_runs u JOIN routes r USING (run_id)
        GROUP BY ALL;
        """,
    ),
    Migration(
        "routes_003_model_quality_validation",
        # model quality shows the held-out score and any flag raised by new reports
        """
        CREATE OR REPLACE VIEW model_quality AS
        SELECT m.imo, s.name AS vessel_name, m.target, m.form, m.version, m.fitted_at, m.n_rows, m.r2, m.rmse,
               m.cv_rmse, m.n_holdout, m.holdout_rmse, m.data_to_utc, m.flag,
               (SELECT count(*) FROM noon_reports n WHERE n.imo = m.imo) AS n_reports,
               (SELECT count(*) FROM noon_reports_rejected x WHERE x.imo = m.imo) AS n_rejected
        FROM perf_models m LEFT JOIN vessels s ON s.imo = m.imo
        WHERE m.active;
        """,
    ),
    Migration(
        "routes_004_voyage_performance",
        # plan against actual: each voyage's newest plan beside what its noon reports show. A voyage's
        # reports are its vessel's reports at sea after departure, up to the next voyage's departure (at most
        # RTA + 3 days); the last of them stands for the arrival.
        """
        CREATE VIEW voyage_performance AS
        WITH windows AS (
            SELECT voyage_id, imo, depart_utc, rta_utc,
                   least(coalesce(lead(depart_utc) OVER (PARTITION BY imo ORDER BY depart_utc), rta_utc + INTERVAL 3 DAY),
                         rta_utc + INTERVAL 3 DAY) AS window_end_utc
            FROM voyages),
        sailed AS (
            SELECT w.voyage_id, count(*) AS n_reports, sum(n.fuel_t) AS actual_fuel_t, sum(n.hours) AS actual_hours,
                   sum(n.dist_nm) AS actual_dist_nm, max(n.ts_utc) AS actual_arrival_utc
            FROM windows w JOIN noon_reports n ON n.imo = w.imo AND n.ts_utc > w.depart_utc AND n.ts_utc <= w.window_end_utc
            WHERE coalesce(n.dist_nm, 0) > 0 OR coalesce(n.stw_kn, 0) > 0.5  -- at sea
            GROUP BY w.voyage_id)
        SELECT v.voyage_id, v.imo, s.name AS vessel_name, v.dep_name, v.arr_name, v.depart_utc, v.rta_utc,
               p.run_id, p.status AS plan_status, p.model_version, p.fuel_t AS planned_fuel_t, p.eta_utc AS planned_eta_utc,
               a.n_reports, a.actual_fuel_t, a.actual_hours, a.actual_dist_nm, a.actual_arrival_utc,
               100 * (p.fuel_t - a.actual_fuel_t) / nullif(a.actual_fuel_t, 0) AS fuel_error_pct,
               date_diff('second', p.eta_utc, a.actual_arrival_utc) / 3600.0 AS arrival_error_h,
               date_diff('second', v.rta_utc, a.actual_arrival_utc) / 3600.0 AS late_h
        FROM voyages v
        LEFT JOIN vessels s USING (imo)
        LEFT JOIN latest_routes p USING (voyage_id)
        LEFT JOIN sailed a USING (voyage_id);
        """,
    ),
    Migration(
        "routes_005_forecast_horizon",
        """
        -- a plan that sails past the cycle's last forecast step (the last step persisted) or departs before the
        -- cycle is not silently ok: which of the two, and for how many hours
        ALTER TABLE routes ADD COLUMN IF NOT EXISTS forecast_flag VARCHAR;         -- 'beyond horizon' | 'before cycle' | both
        ALTER TABLE routes ADD COLUMN IF NOT EXISTS hours_beyond_forecast DOUBLE;  -- hours sailed past the last forecast step
        ALTER TABLE routes ADD COLUMN IF NOT EXISTS hours_before_cycle DOUBLE;     -- hours sailed before the cycle's init time
        """,
    ),
    Migration(
        "routes_006_status_checks",
        # statuses limited to the values the code writes (DuckDB adds a CHECK only with CREATE TABLE, so the two
        # tables are rebuilt); the route's count of legs past the horizon gets its own name, n_legs_beyond_forecast,
        # apart from the legs' boolean beyond_forecast; latest_routes is made again so its columns follow
        """
        CREATE TABLE route_runs_new (
            run_id VARCHAR PRIMARY KEY,
            started_at TIMESTAMP NOT NULL,
            finished_at TIMESTAMP,
            cycle TIMESTAMP,
            n_voyages INTEGER,
            n_ok INTEGER,
            n_failed INTEGER,
            status VARCHAR NOT NULL CHECK (status IN ('running', 'ok', 'partial', 'failed')),
            solver VARCHAR,
            trigger VARCHAR,
            host VARCHAR,
            pid INTEGER,
            pid_started VARCHAR,
            reason VARCHAR,
            n_export_failed INTEGER,
            export_errors VARCHAR
        );
        INSERT INTO route_runs_new SELECT run_id, started_at, finished_at, cycle, n_voyages, n_ok, n_failed, status, solver,
            trigger, host, pid, pid_started, reason, n_export_failed, export_errors FROM route_runs;
        DROP TABLE route_runs;
        ALTER TABLE route_runs_new RENAME TO route_runs;

        CREATE TABLE routes_new (
            run_id VARCHAR NOT NULL,
            voyage_id VARCHAR NOT NULL,
            imo BIGINT,
            solver VARCHAR,
            objective VARCHAR,
            status VARCHAR NOT NULL CHECK (status IN ('ok', 'late', 'infeasible', 'failed')),
            reason VARCHAR,
            depart_utc TIMESTAMP,
            eta_utc TIMESTAMP,
            rta_utc TIMESTAMP,
            hours DOUBLE,
            fuel_t DOUBLE,
            baseline_fuel_t DOUBLE,
            baseline_hours DOUBLE,
            savings_pct DOUBLE,
            distance_nm DOUBLE,
            cost DOUBLE,
            model_version INTEGER,
            cycle TIMESTAMP,
            seed INTEGER,
            runtime_s DOUBLE,
            n_legs INTEGER,
            n_legs_beyond_forecast INTEGER,
            forecast_flag VARCHAR,
            hours_beyond_forecast DOUBLE,
            hours_before_cycle DOUBLE,
            PRIMARY KEY (run_id, voyage_id)
        );
        INSERT INTO routes_new SELECT run_id, voyage_id, imo, solver, objective, status, reason, depart_utc, eta_utc, rta_utc,
            hours, fuel_t, baseline_fuel_t, baseline_hours, savings_pct, distance_nm, cost, model_version, cycle, seed,
            runtime_s, n_legs, beyond_forecast, forecast_flag, hours_beyond_forecast, hours_before_cycle FROM routes;
        DROP TABLE routes;
        ALTER TABLE routes_new RENAME TO routes;

        """ + _LATEST_ROUTES_VIEW_006 + """
        """,
    ),
    Migration(
        "routes_007_honest_savings_and_engine_limits",
        """
        -- savings against the honest baseline: the base route at the one constant rpm (between the vessel's
        -- limits) that arrives at the RTA, in the same weather and model; split into what the best engine plan on
        -- the base route saves (speed profile) and what the route adds (route); total = speed profile + route.
        -- baseline_fuel_t / savings_pct stay the discrete-rpm baseline, which usually arrives hours early.
        ALTER TABLE routes ADD COLUMN IF NOT EXISTS honest_baseline_rpm DOUBLE;
        ALTER TABLE routes ADD COLUMN IF NOT EXISTS honest_baseline_fuel_t DOUBLE;
        ALTER TABLE routes ADD COLUMN IF NOT EXISTS honest_baseline_hours DOUBLE;
        ALTER TABLE routes ADD COLUMN IF NOT EXISTS profile_fuel_t DOUBLE;            -- best engine plan on the base route
        ALTER TABLE routes ADD COLUMN IF NOT EXISTS savings_total_pct DOUBLE;
        ALTER TABLE routes ADD COLUMN IF NOT EXISTS savings_speed_profile_pct DOUBLE;
        ALTER TABLE routes ADD COLUMN IF NOT EXISTS savings_route_pct DOUBLE;
        -- engine-change limits the plan obeys, and what they cost: fuel_t − unlimited_fuel_t (the solver's plan on
        -- the same route without them)
        ALTER TABLE routes ADD COLUMN IF NOT EXISTS min_engine_hold_h DOUBLE;
        ALTER TABLE routes ADD COLUMN IF NOT EXISTS engine_change_cost_t DOUBLE;
        ALTER TABLE routes ADD COLUMN IF NOT EXISTS n_engine_changes INTEGER;
        ALTER TABLE routes ADD COLUMN IF NOT EXISTS unlimited_fuel_t DOUBLE;
        ALTER TABLE routes ADD COLUMN IF NOT EXISTS limits_fuel_t DOUBLE;

        -- per run: the honest savings are fuel-weighted over the voyages that have them (sums, not an average of
        -- percentages); the discrete-rpm figure is kept as savings_vs_discrete_pct
        CREATE OR REPLACE VIEW fleet_savings AS
        SELECT u.run_id, u.started_at, u.cycle, u.trigger, u.status AS run_status, count(*) AS n_voyages,
               count(*) FILTER (WHERE r.status = 'ok') AS n_on_time,
               count(*) FILTER (WHERE r.status = 'late') AS n_late,
               count(*) FILTER (WHERE r.status = 'infeasible') AS n_infeasible,
               count(*) FILTER (WHERE r.status = 'failed') AS n_failed,
               count(*) FILTER (WHERE r.status IN ('infeasible', 'failed')) AS n_not_routed,
               coalesce(u.n_export_failed, 0) AS n_export_failed,
               count(*) FILTER (WHERE r.savings_total_pct IS NOT NULL) AS n_compared,
               sum(r.fuel_t) FILTER (WHERE r.savings_total_pct IS NOT NULL) AS fuel_t,
               sum(r.honest_baseline_fuel_t) FILTER (WHERE r.savings_total_pct IS NOT NULL) AS honest_baseline_fuel_t,
               sum(r.profile_fuel_t) FILTER (WHERE r.savings_total_pct IS NOT NULL) AS profile_fuel_t,
               100 * (1 - sum(r.fuel_t) FILTER (WHERE r.savings_total_pct IS NOT NULL)
                        / nullif(sum(r.honest_baseline_fuel_t) FILTER (WHERE r.savings_total_pct IS NOT NULL), 0))
                   AS savings_total_pct,
               100 * (1 - sum(r.profile_fuel_t) FILTER (WHERE r.savings_total_pct IS NOT NULL)
                        / nullif(sum(r.honest_baseline_fuel_t) FILTER (WHERE r.savings_total_pct IS NOT NULL), 0))
                   AS savings_speed_profile_pct,
               100 * (sum(r.profile_fuel_t) FILTER (WHERE r.savings_total_pct IS NOT NULL)
                      - sum(r.fuel_t) FILTER (WHERE r.savings_total_pct IS NOT NULL))
                   / nullif(sum(r.honest_baseline_fuel_t) FILTER (WHERE r.savings_total_pct IS NOT NULL), 0)
                   AS savings_route_pct,
               sum(r.limits_fuel_t) AS limits_fuel_t,
               sum(r.unlimited_fuel_t) FILTER (WHERE r.limits_fuel_t IS NOT NULL) AS unlimited_fuel_t,
               sum(r.baseline_fuel_t) FILTER (WHERE r.fuel_t IS NOT NULL) AS discrete_baseline_fuel_t,
               100 * (1 - sum(r.fuel_t) FILTER (WHERE r.baseline_fuel_t IS NOT NULL)
                        / nullif(sum(r.baseline_fuel_t) FILTER (WHERE r.fuel_t IS NOT NULL), 0)) AS savings_vs_discrete_pct
        FROM route_runs u JOIN routes r USING (run_id)
        GROUP BY ALL;
        """,
    ),
    Migration(
        "routes_008_land_clearance",
        """
        -- least distance to land (NM) along the plan outside its port approaches, sampled at 0.1 NM
        -- (25 means at least 25 NM); empty when there is no plan
        ALTER TABLE routes ADD COLUMN IF NOT EXISTS min_land_clearance_nm DOUBLE;
        """,
    ),
    Migration(
        "routes_voyage_performance_ends_at_arrival",
        # plan against actual ends a voyage at its arrival: the first report after departure within ARRIVAL_NM of
        # the destination; reports after it (shifting to the berth, port stays) are not sea time. Without such a
        # report (no positions), up to the next voyage's departure, at most RTA + 30 days (a late voyage is no
        # longer cut at RTA + 3 days).
        f"""
        CREATE OR REPLACE VIEW voyage_performance AS
        WITH bounds AS (
            SELECT voyage_id, imo, depart_utc, rta_utc, arr_lat, arr_lon,
                   least(coalesce(lead(depart_utc) OVER (PARTITION BY imo ORDER BY depart_utc), rta_utc + INTERVAL 30 DAY),
                         rta_utc + INTERVAL 30 DAY) AS bound_utc
            FROM voyages),
        arrivals AS (
            SELECT b.voyage_id, min(n.ts_utc) AS arrived_utc
            FROM bounds b JOIN noon_reports n ON n.imo = b.imo AND n.ts_utc > b.depart_utc AND n.ts_utc <= b.bound_utc
            WHERE n.lat IS NOT NULL AND n.lon IS NOT NULL AND b.arr_lat IS NOT NULL AND b.arr_lon IS NOT NULL
              AND 2 * 3440.065 * asin(sqrt(pow(sin(radians(n.lat - b.arr_lat) / 2), 2)
                    + cos(radians(n.lat)) * cos(radians(b.arr_lat)) * pow(sin(radians(n.lon - b.arr_lon) / 2), 2)))
                  <= {ARRIVAL_NM}
            GROUP BY b.voyage_id),
        windows AS (
            SELECT b.voyage_id, b.imo, b.depart_utc, coalesce(a.arrived_utc, b.bound_utc) AS window_end_utc
            FROM bounds b LEFT JOIN arrivals a USING (voyage_id)),
        sailed AS (
            SELECT w.voyage_id, count(*) AS n_reports, sum(n.fuel_t) AS actual_fuel_t, sum(n.hours) AS actual_hours,
                   sum(n.dist_nm) AS actual_dist_nm, max(n.ts_utc) AS actual_arrival_utc
            FROM windows w JOIN noon_reports n ON n.imo = w.imo AND n.ts_utc > w.depart_utc AND n.ts_utc <= w.window_end_utc
            WHERE coalesce(n.dist_nm, 0) > 0 OR coalesce(n.stw_kn, 0) > 0.5  -- at sea
            GROUP BY w.voyage_id)
        SELECT v.voyage_id, v.imo, s.name AS vessel_name, v.dep_name, v.arr_name, v.depart_utc, v.rta_utc,
               p.run_id, p.status AS plan_status, p.model_version, p.fuel_t AS planned_fuel_t, p.eta_utc AS planned_eta_utc,
               a.n_reports, a.actual_fuel_t, a.actual_hours, a.actual_dist_nm, a.actual_arrival_utc,
               100 * (p.fuel_t - a.actual_fuel_t) / nullif(a.actual_fuel_t, 0) AS fuel_error_pct,
               date_diff('second', p.eta_utc, a.actual_arrival_utc) / 3600.0 AS arrival_error_h,
               date_diff('second', v.rta_utc, a.actual_arrival_utc) / 3600.0 AS late_h
        FROM voyages v
        LEFT JOIN vessels s USING (imo)
        LEFT JOIN latest_routes p USING (voyage_id)
        LEFT JOIN sailed a USING (voyage_id);
        """,
    ),
    Migration(
        "routes_009_plan_start_and_cycle_age",
        """
        -- where a plan starts: the departure port, or a position at sea (a noon report, an operator's position, or
        -- an old report advanced along the current plan), and what of the voyage it was made for
        ALTER TABLE routes ADD COLUMN IF NOT EXISTS start_kind VARCHAR;
        ALTER TABLE routes ADD COLUMN IF NOT EXISTS start_lat DOUBLE;
        ALTER TABLE routes ADD COLUMN IF NOT EXISTS start_lon DOUBLE;
        ALTER TABLE routes ADD COLUMN IF NOT EXISTS start_utc TIMESTAMP;
        ALTER TABLE routes ADD COLUMN IF NOT EXISTS start_position_utc TIMESTAMP;
        ALTER TABLE routes ADD COLUMN IF NOT EXISTS start_advanced_h DOUBLE;
        ALTER TABLE routes ADD COLUMN IF NOT EXISTS start_note VARCHAR;
        ALTER TABLE routes ADD COLUMN IF NOT EXISTS voyage_fingerprint VARCHAR;
        -- how old the routed cycle was at the run's nominal time
        ALTER TABLE route_runs ADD COLUMN IF NOT EXISTS nominal_utc TIMESTAMP;
        ALTER TABLE route_runs ADD COLUMN IF NOT EXISTS cycle_age_h DOUBLE;
        """,
    ),
    # what each leg sailed past the forecast, before the cycle, and through a hole in the wind (the plan's totals
    # and flags are made of these; they were dropped from the stored legs)
    Migration("routes_010_leg_forecast_hours", ROUTE_LEGS.add_columns_sql(*LEG_HOURS_ADDED)),
    # the legs leave the DuckDB file for one Parquet file per run (storage/route_history.py moves the rows and makes
    # route_legs a view over the files listed here). From here on route_legs is a view: a new column of it needs
    # only its definition (schemas/tables/routes.py), never an ALTER TABLE here.
    Migration("routes_011_leg_parts", ROUTE_LEG_PARTS.create_sql()),
    # a run stores its voyages batch by batch as they finish, each batch's legs one more file of the run: the key
    # becomes (run_id, file)
    Migration("routes_012_leg_parts_per_batch", f"""
        {ROUTE_LEG_PARTS.create_sql().replace(ROUTE_LEG_PARTS.name, ROUTE_LEG_PARTS.name + '_new', 1)}
        INSERT INTO route_leg_parts_new SELECT run_id, file, n_rows, n_bytes, sha256, written_at FROM route_leg_parts;
        DROP TABLE route_leg_parts;
        ALTER TABLE route_leg_parts_new RENAME TO route_leg_parts;
        """),
    # each plan's saving split into what the forecast covers and what it does not (past the last valid time plans
    # sail in neutral weather, engine.leg), and fleet_savings with the split
    Migration("routes_013_savings_forecast_split",
              ROUTES.add_columns_sql(*ROUTE_FORECAST_SPLIT_ADDED) + "\n" + FLEET_SAVINGS_VIEW_013),
    # plan against actual like with like: a re-plan from its start, a ship at sea without an arrival
    Migration("routes_014_voyage_performance_like_with_like", VOYAGE_PERFORMANCE_VIEW_014),
    # each plan's spread across a lagged ensemble of cycles
    Migration("routes_015_plan_ensemble_spread", ROUTES.add_columns_sql(*ROUTE_ENSEMBLE_ADDED)),
    # what happened: plans and their baselines re-sailed in the analysed weather of later cycles (the baseline's
    # track kept with each plan for it), and fleet_savings with the spread and the realised saving
    Migration("routes_016_plan_verification",
              "\n".join([ROUTES.add_columns_sql(*ROUTE_BASELINE_TRACK_ADDED), PLAN_VERIFICATION.create_sql(),
                         FLEET_SAVINGS_VIEW_016])),
    # a plan aiming before the RTA claims its saving against the baseline arriving at the RTA, and says what the
    # margin costs
    Migration("routes_019_margin_cost", ROUTES.add_columns_sql(*ROUTE_MARGIN_COST_ADDED)),
    # fleet_savings says what the run's arrival margins cost
    Migration("routes_020_fleet_margin_cost", FLEET_SAVINGS_VIEW_020),
]


def views_migration(after: list[str]) -> Migration:
    """The migration making `latest_routes` again, named anew whenever its text or the migrations `after` change."""
    digest = hashlib.sha256("\n".join([LATEST_ROUTES_VIEW, *after]).encode()).hexdigest()[:12]
    return Migration(f"routes_views_{digest}", LATEST_ROUTES_VIEW)
