"""The warehouse as analysts and BI tools meet it: described columns, constrained statuses, a snapshot older
DuckDB readers open, and an existing warehouse upgraded to all of it."""

import duckdb
import pytest

from storage import warehouse

CHECKED_MIGRATIONS = {"ingest_002_status_checks", "fleet_005_status_checks", "routes_006_status_checks"}


def _undescribed(con) -> list[tuple[str, str | None]]:
    return con.execute("""
        SELECT table_name, NULL FROM duckdb_tables() WHERE database_name = current_database() AND comment IS NULL
        UNION ALL SELECT view_name, NULL FROM duckdb_views()
            WHERE database_name = current_database() AND NOT internal AND comment IS NULL
        UNION ALL SELECT table_name, column_name FROM duckdb_columns()
            WHERE database_name = current_database() AND schema_name = 'main' AND comment IS NULL
        ORDER BY ALL""").fetchall()


def test_every_table_view_and_column_is_described_with_units(tmp_path):
    with warehouse.connect(tmp_path / "w.duckdb") as con:
        assert _undescribed(con) == []  # a column added without a description (schemas/tables, views in storage/schema_docs.py) fails here
        n = con.execute("SELECT count(*) FROM duckdb_columns() WHERE database_name = current_database() "
                        "AND schema_name = 'main'").fetchone()[0]
        comment = dict(con.execute("SELECT table_name || '.' || column_name, comment FROM duckdb_columns() "
                                   "WHERE database_name = current_database()").fetchall())
    assert n > 250
    assert "tonnes" in comment["routes.fuel_t"] and "hours" in comment["routes.hours"]
    assert "knots" in comment["route_legs.sog_kn"] and "UTC" in comment["route_legs.eta_utc"]
    assert "UTC" in comment["latest_routes.eta_utc"]


@pytest.mark.parametrize("table, columns, good, bad", [
    ("routes", "run_id, voyage_id, status", "'r', 'V1', 'late'", "'r', 'V2', 'done'"),
    ("route_runs", "run_id, started_at, status", "'r1', now(), 'partial'", "'r2', now(), 'aborted'"),
    ("ingest_log", "source, file_name, status", "'GSM', 'f', 'error'", "'GSM', 'f', 'OK'"),
    ("perf_models", "imo, version, fitted_at, form, target, status, active",
     "1, 1, now(), 'thesis', 'fuel', 'superseded', false", "1, 2, now(), 'thesis', 'fuel', 'draft', false"),
])
def test_a_status_the_code_never_writes_is_refused(tmp_path, table, columns, good, bad):
    with warehouse.connect(tmp_path / "w.duckdb") as con:
        con.execute(f"INSERT INTO {table} ({columns}) VALUES ({good})")
        with pytest.raises(duckdb.ConstraintException, match="CHECK"):
            con.execute(f"INSERT INTO {table} ({columns}) VALUES ({bad})")
        assert con.execute(f"SELECT count(*) FROM {table}").fetchone()[0] == 1


def test_an_existing_warehouse_upgrades_keeping_its_rows(tmp_path, monkeypatch):
    db = tmp_path / "w.duckdb"
    every = warehouse._all_migrations()
    first_checked = {m.name.split("_")[0]: m.name for m in every if m.name in CHECKED_MIGRATIONS}
    before = [m for m in every  # each schema's migrations from before its status checks (they apply in order)
              if m.name.split("_")[0] in first_checked and m.name < first_checked[m.name.split("_")[0]]]
    monkeypatch.setattr(warehouse, "_all_migrations", lambda: before)
    with warehouse.connect(db) as con:  # the warehouse as it was before statuses were checked and columns described
        con.execute("INSERT INTO route_runs (run_id, started_at, status) VALUES ('r1', now(), 'ok')")
        con.execute("INSERT INTO routes (run_id, voyage_id, status, beyond_forecast, fuel_t) VALUES ('r1', 'V1', 'ok', 3, 5.0)")
        con.execute("INSERT INTO ingest_log (source, file_name, status) VALUES ('GSM', 'f', 'skipped')")
        con.execute("INSERT INTO route_legs (run_id, voyage_id, leg, fuel_t) VALUES ('r1', 'V1', 0, 2.5), ('r1', 'V1', 1, 2.5)")
    monkeypatch.undo()
    with warehouse.connect(db) as con:
        applied = {r[0] for r in con.execute("SELECT name FROM schema_migrations").fetchall()}
        assert CHECKED_MIGRATIONS <= applied and any(n.startswith("docs_comments_") for n in applied)
        assert con.execute("SELECT voyage_id, n_legs_beyond_forecast, fuel_t FROM routes").fetchall() == [("V1", 3, 5.0)]
        assert con.execute("SELECT count(*) FROM ingest_log").fetchone()[0] == 1
        assert _undescribed(con) == []
        listed = {r[0] for r in con.execute("SELECT column_name FROM duckdb_columns() WHERE table_name = 'latest_routes'").fetchall()}
        assert {"n_legs_beyond_forecast", "forecast_flag", "newer_attempt_failed"} <= listed and "beyond_forecast" not in listed
        assert con.execute("SELECT n_legs_beyond_forecast FROM latest_routes").fetchall() == [(3,)]
        # the legs left the DuckDB file for one Parquet file per run, listed in route_leg_parts
        assert con.execute("SELECT table_type FROM information_schema.tables WHERE table_name = 'route_legs'").fetchone() == ("VIEW",)
        assert con.execute("SELECT run_id, leg, fuel_t FROM route_legs ORDER BY leg").fetchall() == [("r1", 0, 2.5), ("r1", 1, 2.5)]
        assert con.execute("SELECT run_id, file, n_rows FROM route_leg_parts").fetchall() == [("r1", "run_id=r1/part-0.parquet", 2)]
    assert (tmp_path / "w.history" / "route_legs" / "run_id=r1" / "part-0.parquet").exists()


@pytest.mark.parametrize("created_by", ["warehouse", "duckdb 2 default format"])
def test_the_snapshot_is_written_in_the_declared_storage_version_and_opens_read_only(tmp_path, created_by):
    db = tmp_path / "w.duckdb"
    if created_by != "warehouse":  # a warehouse made before it was created in the snapshot's format
        duckdb.connect(str(db)).close()
        assert warehouse.storage_version_number(db) != warehouse.SNAPSHOT_STORAGE_NUMBER
    with warehouse.connect(db) as con:
        con.execute("INSERT INTO route_runs (run_id, started_at, status) VALUES ('r1', now(), 'ok')")
        con.execute("INSERT INTO routes (run_id, voyage_id, status, fuel_t) VALUES ('r1', 'V1', 'ok', 5.0)")
    snap = warehouse.snapshot_path(db)
    # DuckDB file header: checksum (8 bytes), "DUCK", storage format number; 64 is read by DuckDB 0.10 to 1.1
    assert warehouse.storage_version_number(snap) == warehouse.SNAPSHOT_STORAGE_NUMBER == 64
    assert warehouse.SNAPSHOT_STORAGE_VERSION == "v1.1.0"
    assert not list(tmp_path.glob("*.tmp*"))
    with duckdb.connect(str(snap), read_only=True) as con:
        assert con.execute("SELECT voyage_id, fuel_t FROM latest_routes").fetchall() == [("V1", 5.0)]
        # 4 + fleet_plans.status and fleet_plan_legs.kind + plan_verification.coverage
        assert con.execute("SELECT count(*) FROM duckdb_constraints() WHERE constraint_type = 'CHECK'").fetchone()[0] == 7
        assert _undescribed(con) == []
