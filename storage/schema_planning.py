"""Warehouse schema for fleet operation planning: ports, vessel availability, cargo contracts (+ refused rows),
sea distances between ports, fleet plans and their legs, and the plan that made each voyage.

Units: nautical miles, tonnes, hours; costs in the currency of the fuel price (e.g. USD); times UTC.
"""

from storage.migration import Migration

MIGRATIONS: list[Migration] = [
    Migration(
        "planning_001_tables",
        """
        CREATE TABLE ports (
            port VARCHAR PRIMARY KEY,
            lat DOUBLE NOT NULL,
            lon DOUBLE NOT NULL,
            source_file VARCHAR
        );
        CREATE TABLE ports_rejected (port VARCHAR, raw VARCHAR, reason VARCHAR NOT NULL, source_file VARCHAR,
                                     rejected_at TIMESTAMP);
        CREATE TABLE vessel_availability (
            imo BIGINT PRIMARY KEY,
            from_utc TIMESTAMP NOT NULL,
            from_port VARCHAR NOT NULL,
            until_utc TIMESTAMP,
            until_port VARCHAR,
            port_hours DOUBLE,
            daily_cost DOUBLE,
            ports VARCHAR,                    -- ';'-separated, NULL: any
            cargo_types VARCHAR,              -- ';'-separated, NULL: any
            laden_speed_kn DOUBLE,
            ballast_speed_kn DOUBLE,
            laden_draft_m DOUBLE,
            ballast_draft_m DOUBLE,
            source_file VARCHAR
        );
        CREATE TABLE vessel_availability_rejected (imo BIGINT, raw VARCHAR, reason VARCHAR NOT NULL,
                                                   source_file VARCHAR, rejected_at TIMESTAMP);
        CREATE TABLE contracts (
            code VARCHAR PRIMARY KEY,
            cargo_type VARCHAR NOT NULL,
            min_t DOUBLE NOT NULL,
            max_t DOUBLE NOT NULL,
            load_port VARCHAR NOT NULL,
            discharge_port VARCHAR NOT NULL,
            early_utc TIMESTAMP NOT NULL,
            late_utc TIMESTAMP NOT NULL,
            penalty DOUBLE,
            source_file VARCHAR
        );
        CREATE TABLE contracts_rejected (code VARCHAR, raw VARCHAR, reason VARCHAR NOT NULL, source_file VARCHAR,
                                         rejected_at TIMESTAMP);
        CREATE TABLE port_distances (
            port_a VARCHAR NOT NULL,          -- the two names in sorted order; the distance holds both ways
            port_b VARCHAR NOT NULL,
            lat_a DOUBLE, lon_a DOUBLE, lat_b DOUBLE, lon_b DOUBLE,
            dist_nm DOUBLE,                   -- NULL: no sea route
            gc_nm DOUBLE,
            reason VARCHAR,
            computed_at TIMESTAMP,
            PRIMARY KEY (port_a, port_b)
        );
        CREATE TABLE fleet_plans (
            plan_id VARCHAR PRIMARY KEY,
            created_at TIMESTAMP NOT NULL,
            as_of_utc TIMESTAMP NOT NULL,
            status VARCHAR NOT NULL CHECK (status IN ('active', 'superseded')),
            superseded_at TIMESTAMP,
            solver VARCHAR,
            solve_status VARCHAR,
            gap DOUBLE,
            runtime_s DOUBLE,
            n_contracts INTEGER,
            n_assigned INTEGER,
            n_unassigned INTEGER,
            n_vessels_used INTEGER,
            fuel_price DOUBLE,
            fuel_t DOUBLE,
            fuel_cost DOUBLE,
            out_of_service_days DOUBLE,
            out_of_service_cost DOUBLE,
            penalty_cost DOUBLE,
            total_cost DOUBLE,
            gantt_png VARCHAR
        );
        CREATE TABLE fleet_plan_legs (
            plan_id VARCHAR NOT NULL,
            imo BIGINT NOT NULL,
            seq INTEGER NOT NULL,
            kind VARCHAR NOT NULL CHECK (kind IN ('ballast', 'laden')),
            contract_code VARCHAR,
            from_port VARCHAR NOT NULL,
            to_port VARCHAR NOT NULL,
            dist_nm DOUBLE,
            depart_utc TIMESTAMP NOT NULL,
            arrive_utc TIMESTAMP NOT NULL,
            fuel_t DOUBLE,
            lift_t DOUBLE,
            voyage_id VARCHAR,
            PRIMARY KEY (plan_id, imo, seq)
        );
        CREATE TABLE fleet_plan_unassigned (
            plan_id VARCHAR NOT NULL,
            contract_code VARCHAR NOT NULL,
            penalty DOUBLE,
            reason VARCHAR NOT NULL,
            PRIMARY KEY (plan_id, contract_code)
        );
        ALTER TABLE voyages ADD COLUMN plan_id VARCHAR;
        """,
    ),
    Migration(
        "planning_002_distances_along_sea_routes",
        """
        DELETE FROM port_distances;  -- the node-line graph's distances: computed again along the global sea routes
        ALTER TABLE port_distances ADD COLUMN passages VARCHAR;
        ALTER TABLE port_distances ADD COLUMN canal_nm DOUBLE;
        ALTER TABLE port_distances ADD COLUMN canal_h DOUBLE;
        """,
    ),
    Migration(
        "planning_003_search_stopped_by",
        """
        ALTER TABLE fleet_plans ADD COLUMN stopped_by VARCHAR;  -- what ended the planner's search (effort, safety cap)
        """,
    ),
]
