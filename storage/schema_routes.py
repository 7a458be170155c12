"""Warehouse schema for fleet routing runs: runs, routes, legs (named migrations, applied in order).

Times are UTC TIMESTAMPs; fuel in tonnes, distances in NM, speeds in knots, directions in
degrees (wind/waves coming-from).
"""

from storage.warehouse import Migration

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
            status VARCHAR NOT NULL,           -- ok | late | infeasible | error
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
            beyond_forecast BOOLEAN,
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
]
