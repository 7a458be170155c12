"""The warehouse as analysts and BI tools meet it: described columns, constrained statuses, a snapshot older
DuckDB readers open, and an existing warehouse upgraded to all of it."""

import re

import duckdb
import pytest

from storage import warehouse
from storage.route_history import history_dir

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
@pytest.mark.slow
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


def _same_sql(sql: str, db) -> str:
    """A view's SQL as DuckDB prints it, made comparable between warehouses: the folder of the warehouse's own legs
    files named alike, and each EXCLUDE list (a set, printed in no fixed order) sorted."""
    sql = sql.replace(str(history_dir(db)), "<legs folder>")
    return re.sub(r"EXCLUDE \(([^()]*)\)", lambda m: "EXCLUDE (" + ", ".join(sorted(m[1].split(", "))) + ")", sql)


def _schema(db) -> dict:
    """Everything the migrations make in the warehouse `db`: tables, columns (type, default, comment), views (the
    folder of its own legs files named alike), constraints, indexes, the recorded migration names and the rows of
    every table."""
    with duckdb.connect(str(db), read_only=True) as con:
        q = lambda sql: sorted(con.execute(sql).fetchall(), key=repr)  # noqa: E731
        tables = [t for (t,) in q("SELECT table_name FROM duckdb_tables() WHERE database_name = current_database()")]
        return {
            "tables": q("SELECT table_name, comment FROM duckdb_tables() WHERE database_name = current_database()"),
            "columns": q("SELECT table_name, column_name, column_index, data_type, column_default, is_nullable, comment "
                         "FROM duckdb_columns() WHERE database_name = current_database()"),
            "views": [(name, _same_sql(sql, db), comment) for name, sql, comment in
                      q("SELECT view_name, sql, comment FROM duckdb_views() WHERE database_name = current_database() "
                        "AND NOT internal")],
            "constraints": q("SELECT table_name, constraint_type, constraint_text FROM duckdb_constraints() "
                             "WHERE database_name = current_database()"),
            "indexes": q("SELECT table_name, index_name, sql FROM duckdb_indexes() WHERE database_name = current_database()"),
            "migrations": q("SELECT name FROM schema_migrations"),
            "rows": {t: q(f'SELECT * EXCLUDE (applied_at) FROM "{t}"') if t == "schema_migrations"
                     else q(f'SELECT * FROM "{t}"') for t in tables},
        }


@pytest.mark.slow
def test_a_new_warehouse_copied_from_the_template_is_the_one_migrated_from_scratch(tmp_path, monkeypatch):
    """The tests' new warehouses are copies of one migrated once (warehouse.use_templates, tests/conftest.py): the copy
    holds what every migration run on an empty file gives, in the snapshot's storage format, and a list of migrations
    that differs gets its own template rather than a copy of another's."""
    monkeypatch.setattr(warehouse, "_TEMPLATE_FOLDER", None)
    warehouse.use_templates(tmp_path / "templates")
    with warehouse.connect(tmp_path / "copied.duckdb"):
        pass
    [template] = (tmp_path / "templates").glob("migrated-*.duckdb")
    with warehouse.connect(tmp_path / "copied_again.duckdb"):
        pass
    assert list((tmp_path / "templates").glob("migrated-*.duckdb")) == [template]  # made once, copied since
    warehouse.use_templates(None)
    with warehouse.connect(tmp_path / "scratch.duckdb"):
        pass
    scratch = _schema(tmp_path / "scratch.duckdb")
    assert len(scratch["migrations"]) == len(warehouse._all_migrations()) and len(scratch["tables"]) > 10
    assert _schema(tmp_path / "copied.duckdb") == scratch == _schema(tmp_path / "copied_again.duckdb")
    assert warehouse.storage_version_number(tmp_path / "copied.duckdb") == warehouse.SNAPSHOT_STORAGE_NUMBER
    assert warehouse.snapshot_path(tmp_path / "copied.duckdb").exists()

    warehouse.use_templates(tmp_path / "templates")
    fewer = warehouse._all_migrations()[:3]
    monkeypatch.setattr(warehouse, "_all_migrations", lambda: fewer)
    with warehouse.connect(tmp_path / "fewer.duckdb") as con:
        assert {r[0] for r in con.execute("SELECT name FROM schema_migrations").fetchall()} == {m.name for m in fewer}
    assert len(list((tmp_path / "templates").glob("migrated-*.duckdb"))) == 2
    assert not list(tmp_path.rglob("*.tmp*"))


@pytest.mark.slow
def test_an_existing_warehouse_is_never_replaced_by_the_template(tmp_path, monkeypatch):
    monkeypatch.setattr(warehouse, "_TEMPLATE_FOLDER", None)
    warehouse.use_templates(tmp_path / "templates")
    db = tmp_path / "w.duckdb"
    with warehouse.connect(db) as con:
        con.execute("INSERT INTO route_runs (run_id, started_at, status) VALUES ('r1', now(), 'ok')")
    with warehouse.connect(db) as con:
        assert con.execute("SELECT run_id FROM route_runs").fetchall() == [("r1",)]
    warehouse._from_template(db)  # as if another process had created it between the check and the copy
    with warehouse.connect(db, write=False) as con:
        assert con.execute("SELECT run_id FROM route_runs").fetchall() == [("r1",)]


def test_threads_creating_the_same_new_warehouse_leave_one_whole_copy(tmp_path, monkeypatch):
    """Each thread copies the template to its own temporary file and links it in place: the first link wins, no
    thread's copy is written over while another thread links it."""
    from concurrent.futures import ThreadPoolExecutor

    monkeypatch.setattr(warehouse, "_TEMPLATE_FOLDER", None)
    warehouse.use_templates(tmp_path / "templates")
    db = tmp_path / "w.duckdb"
    with ThreadPoolExecutor(4) as pool:
        list(pool.map(lambda _: warehouse._from_template(db), range(16)))
    [template] = (tmp_path / "templates").glob("migrated-*.duckdb")
    assert db.read_bytes() == template.read_bytes() and warehouse.check_file(db) is None
    assert not list(tmp_path.glob("*.tmp*"))
