"""Warehouse schema for the fleet: vessels, noon reports (+ rejected), performance models, voyages.

Units: knots, nautical miles, metres, hours, tonnes; times UTC. Relative directions
(`*_dir_rel_deg`) are where wind/waves come FROM relative to the bow: 0 head, 180 following.
"""

from storage.migration import Migration

NOON_COLUMNS = """
    imo BIGINT NOT NULL,
    ts_utc TIMESTAMP NOT NULL,
    lat DOUBLE, lon DOUBLE,
    rpm DOUBLE, draft_m DOUBLE, trim_m DOUBLE,
    stw_kn DOUBLE, sog_kn DOUBLE, dist_nm DOUBLE, hours DOUBLE,
    fuel_t DOUBLE, fuel_hfo_t DOUBLE, fuel_mgo_t DOUBLE,
    wind_kn DOUBLE, wind_dir_rel_deg DOUBLE, wave_m DOUBLE, wave_dir_rel_deg DOUBLE,
    current_kn DOUBLE, current_dir_rel_deg DOUBLE,
    months_since_drydock DOUBLE,
    source_file VARCHAR
"""

MIGRATIONS: list[Migration] = [
    Migration(
        "fleet_001_tables",
        f"""
        CREATE TABLE vessels (
            imo BIGINT PRIMARY KEY,
            name VARCHAR NOT NULL,
            type VARCHAR,
            dwt DOUBLE,
            design_speed_kn DOUBLE,
            mcr_kw DOUBLE,
            rpm_max DOUBLE,
            design_fuel_tph DOUBLE
        );
        CREATE TABLE noon_reports ({NOON_COLUMNS}, PRIMARY KEY (imo, ts_utc));
        CREATE TABLE noon_reports_rejected ({NOON_COLUMNS}, raw VARCHAR, reason VARCHAR NOT NULL, rejected_at TIMESTAMP);
        CREATE TABLE perf_models (
            imo BIGINT NOT NULL,
            version INTEGER NOT NULL,
            fitted_at TIMESTAMP NOT NULL,
            form VARCHAR NOT NULL,            -- thesis | physical | fuzzy
            target VARCHAR NOT NULL,          -- speed | fuel
            coefficients VARCHAR,             -- JSON {{regressor: value}}
            n_rows INTEGER,
            r2 DOUBLE,
            rmse DOUBLE,
            cv_rmse DOUBLE,
            status VARCHAR NOT NULL,          -- active | rejected | superseded
            reason VARCHAR,
            active BOOLEAN NOT NULL,
            months_dd DOUBLE,
            PRIMARY KEY (imo, version, target)
        );
        CREATE TABLE voyages (
            voyage_id VARCHAR PRIMARY KEY,
            imo BIGINT NOT NULL,
            dep_name VARCHAR, dep_lat DOUBLE, dep_lon DOUBLE,
            arr_name VARCHAR, arr_lat DOUBLE, arr_lon DOUBLE,
            depart_utc TIMESTAMP NOT NULL,
            rta_utc TIMESTAMP NOT NULL,
            draft_m DOUBLE, trim_m DOUBLE,
            rpm_options DOUBLE[],
            max_hs_m DOUBLE,
            max_wind_kn DOUBLE,
            status VARCHAR DEFAULT 'planned'
        );
        """,
    ),
    Migration(
        "fleet_002_rejected_keys_nullable",
        # a row rejected for a bad timestamp or IMO has none to store; it is kept with its raw text
        """
        ALTER TABLE noon_reports_rejected ALTER COLUMN imo DROP NOT NULL;
        ALTER TABLE noon_reports_rejected ALTER COLUMN ts_utc DROP NOT NULL;
        """,
    ),
    Migration(
        "fleet_003_rejected_vessels_voyages",
        # rows of vessels.csv / voyages.csv refused on import, with the reason and the row as it came in
        """
        CREATE TABLE vessels_rejected (imo BIGINT, raw VARCHAR, reason VARCHAR NOT NULL, source_file VARCHAR,
                                       rejected_at TIMESTAMP);
        CREATE TABLE voyages_rejected (voyage_id VARCHAR, imo BIGINT, raw VARCHAR, reason VARCHAR NOT NULL,
                                       source_file VARCHAR, rejected_at TIMESTAMP);
        """,
    ),
    Migration(
        "fleet_003_model_validation",
        # a model is scored on reports it was not fitted on; the rows it was fitted on are identified
        # (data_hash: the same rows and form give the same model, stored once); a contradiction between
        # new reports and the active model is flagged on it
        """
        ALTER TABLE perf_models ADD COLUMN holdout_rmse DOUBLE;   -- RMSE on the newest reports, fitted without them
        ALTER TABLE perf_models ADD COLUMN n_holdout INTEGER;
        ALTER TABLE perf_models ADD COLUMN data_hash VARCHAR;     -- digest of the rows, form and fit settings
        ALTER TABLE perf_models ADD COLUMN data_to_utc TIMESTAMP; -- newest report the coefficients were fitted on
        ALTER TABLE perf_models ADD COLUMN flag VARCHAR;          -- why new reports contradict this (active) model
        """,
    ),
    Migration(
        "fleet_004_bunker_logs",
        # what was bunkered, where and from whom, and what remained on board (the thesis's Bunker Logs)
        """
        CREATE TABLE bunker_logs (
            imo BIGINT NOT NULL,
            bill_no VARCHAR NOT NULL,         -- the bunker delivery note
            date_utc TIMESTAMP NOT NULL,
            port VARCHAR,
            supplier VARCHAR,
            fuel_type VARCHAR NOT NULL,       -- HFO | LFO | MGO | MDO | DO | LNG | ... (upper case)
            received_t DOUBLE NOT NULL,       -- tonnes received
            rob_t DOUBLE,                     -- tonnes of this fuel remaining on board before receiving
            source_file VARCHAR,
            PRIMARY KEY (imo, bill_no, fuel_type)
        );
        """,
    ),
    Migration(
        "fleet_005_status_checks",
        # a model's status limited to the values the code writes (DuckDB adds a CHECK only with CREATE TABLE: rebuilt)
        """
        CREATE TABLE perf_models_new (
            imo BIGINT NOT NULL,
            version INTEGER NOT NULL,
            fitted_at TIMESTAMP NOT NULL,
            form VARCHAR NOT NULL,
            target VARCHAR NOT NULL,
            coefficients VARCHAR,
            n_rows INTEGER,
            r2 DOUBLE,
            rmse DOUBLE,
            cv_rmse DOUBLE,
            status VARCHAR NOT NULL CHECK (status IN ('active', 'rejected', 'superseded')),
            reason VARCHAR,
            active BOOLEAN NOT NULL,
            months_dd DOUBLE,
            holdout_rmse DOUBLE,
            n_holdout INTEGER,
            data_hash VARCHAR,
            data_to_utc TIMESTAMP,
            flag VARCHAR,
            PRIMARY KEY (imo, version, target)
        );
        INSERT INTO perf_models_new SELECT imo, version, fitted_at, form, target, coefficients, n_rows, r2, rmse, cv_rmse,
            status, reason, active, months_dd, holdout_rmse, n_holdout, data_hash, data_to_utc, flag FROM perf_models;
        DROP TABLE perf_models;
        ALTER TABLE perf_models_new RENAME TO perf_models;
        """,
    ),
    Migration(
        "fleet_006_bunker_logs_rejected",
        # bunker-log rows refused on import, kept with the reason and their raw text (as for noon reports)
        """
        CREATE TABLE bunker_logs_rejected (imo BIGINT, bill_no VARCHAR, raw VARCHAR, reason VARCHAR NOT NULL,
                                           source_file VARCHAR, rejected_at TIMESTAMP);
        """,
    ),
    Migration(
        "fleet_007_model_envelope_gate",
        # the conditions a model was fitted on (routing clips rpm settings and guards the inputs to them) and the
        # gate its refit applied ('default' or the settings that differed)
        """
        ALTER TABLE perf_models ADD COLUMN envelope VARCHAR;  -- JSON {rpm: [lo, hi], draft_m: [lo, hi], wind_kn, hs_m, ...}
        ALTER TABLE perf_models ADD COLUMN gate VARCHAR;      -- 'default' or the gate settings that differed
        """,
    ),
    Migration(
        "fleet_008_noon_history",
        # stored reports replaced by corrected ones, or excluded for a period, are kept here with why and when
        f"""
        CREATE TABLE noon_reports_history ({NOON_COLUMNS}, removed_at TIMESTAMP NOT NULL, reason VARCHAR NOT NULL);
        """,
    ),
    Migration(
        "fleet_009_hull_performance",
        # speed loss against a clean hull per vessel and month (pipeline.performance.hull), rewritten at every refit
        """
        CREATE TABLE hull_performance_monthly (
            imo BIGINT NOT NULL,
            month DATE NOT NULL,
            n_reports INTEGER NOT NULL,
            speed_loss_pct DOUBLE,
            flag BOOLEAN NOT NULL,
            model_version INTEGER,
            computed_at TIMESTAMP NOT NULL,
            PRIMARY KEY (imo, month)
        );
        CREATE VIEW hull_performance AS
        SELECT h.imo, v.name AS vessel_name, h.month, h.n_reports, h.speed_loss_pct, h.flag, h.model_version,
               regr_slope(h.speed_loss_pct, year(h.month) * 12 + month(h.month)) OVER (PARTITION BY h.imo)
                   AS trend_pct_per_month
        FROM hull_performance_monthly h LEFT JOIN vessels v USING (imo);
        """,
    ),
    Migration(
        "fleet_010_voyage_positions",
        # positions of voyages at sea given by an operator (`jitroute position add`): re-planning starts from the
        # newest of these and the vessel's noon reports
        """
        CREATE TABLE IF NOT EXISTS voyage_positions (
            voyage_id VARCHAR NOT NULL,
            ts_utc TIMESTAMP NOT NULL,
            lat DOUBLE NOT NULL,
            lon DOUBLE NOT NULL,
            note VARCHAR,
            entered_at TIMESTAMP,
            PRIMARY KEY (voyage_id, ts_utc)
        );
        """,
    ),
    Migration(
        "fleet_011_vessel_barred_rpm",
        # an engine's barred speed ranges, never chosen by the continuous speed refinement (routing)
        "ALTER TABLE vessels ADD COLUMN IF NOT EXISTS barred_rpm VARCHAR;",
    ),
]
