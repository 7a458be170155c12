"""One definition per warehouse table (schemas/tables): the migrated warehouse, the Parquet files of a real run and
the rows the code builds all follow it."""

from __future__ import annotations

import duckdb
import pyarrow.parquet as pq
import pytest

from schemas.table import RowShapeError
from schemas.tables import TABLES
from schemas.tables.routes import ROUTE_LEGS, ROUTES
from storage import route_store, warehouse
from tests.conftest import fleet_data_root


def _migrated(tmp_path) -> duckdb.DuckDBPyConnection:
    db = tmp_path / "fresh.duckdb"
    with warehouse.connect(db):
        pass
    return duckdb.connect(str(db), read_only=True)


def test_a_fresh_warehouse_has_exactly_the_defined_tables_columns_types_and_keys(tmp_path):
    con = _migrated(tmp_path)
    tables = {r[0] for r in con.execute("SELECT table_name FROM information_schema.tables "
                                        "WHERE table_type = 'BASE TABLE'").fetchall()}
    assert tables == set(TABLES) - {ROUTE_LEGS.name}
    # route_legs is a view over one Parquet file per run (storage/route_history.py): the defined columns and types,
    # described; its key is kept by the writer (test_route_history)
    got = con.execute("SELECT column_name, data_type FROM information_schema.columns WHERE table_name = 'route_legs' "
                      "ORDER BY ordinal_position").fetchall()
    assert got == [(c.name, c.duckdb) for c in ROUTE_LEGS.columns]
    assert dict(con.execute("SELECT column_name, comment FROM duckdb_columns() WHERE table_name = 'route_legs'")
                .fetchall()) == ROUTE_LEGS.comments()
    for name, table in TABLES.items():
        if name == ROUTE_LEGS.name:
            continue
        got = con.execute("SELECT column_name, data_type, is_nullable = 'NO' FROM information_schema.columns "
                          "WHERE table_name = ? ORDER BY ordinal_position", [name]).fetchall()
        want = [(c.name, c.duckdb, c.not_null or c.name in table.primary_key) for c in table.columns]
        assert got == want, name
        constraints = con.execute("SELECT constraint_type, constraint_column_names FROM duckdb_constraints() "
                                  "WHERE table_name = ? AND constraint_type IN ('PRIMARY KEY', 'CHECK')", [name]).fetchall()
        assert [tuple(cols) for kind, cols in constraints if kind == "PRIMARY KEY"] == ([table.primary_key]
                                                                                      if table.primary_key else []), name
        assert {cols[0] for kind, cols in constraints if kind == "CHECK"} == {c.name for c in table.columns if c.allowed}
        comments = dict(con.execute("SELECT column_name, comment FROM duckdb_columns() WHERE table_name = ?",
                                    [name]).fetchall())
        assert comments == table.comments(), name
    con.close()


def test_the_generated_ddl_makes_the_same_table_as_the_migrations(tmp_path):
    """A new table or column is made from its definition: each definition's CREATE TABLE gives the columns, types and
    keys the migrations gave."""
    con = _migrated(tmp_path)
    fresh = duckdb.connect()
    query = ("SELECT column_name, data_type, is_nullable FROM information_schema.columns WHERE table_name = ? "
             "ORDER BY ordinal_position")
    for name, table in TABLES.items():
        fresh.execute(table.create_sql())
        if name == ROUTE_LEGS.name:  # a view in the warehouse: nullable columns (the key is kept by the writer)
            assert [r[:2] for r in fresh.execute(query, [name]).fetchall()] == [r[:2] for r in con.execute(query, [name]).fetchall()]
            continue
        assert fresh.execute(query, [name]).fetchall() == con.execute(query, [name]).fetchall(), name
    con.close()


def test_units_follow_the_column_names():
    suffixes = {"_kn": "kn", "_nm": "NM", "_t": "t", "_h": "h", "_m": "m", "_deg": "degree", "_pct": "%", "_utc": "UTC"}
    for table in TABLES.values():
        for c in table.columns:
            for suffix, unit in suffixes.items():
                if c.name.endswith(suffix):
                    assert c.unit == unit, (table.name, c.name, c.unit)
            if c.duckdb == "TIMESTAMP":
                assert c.unit == "UTC", (table.name, c.name)


def test_a_row_with_a_key_the_table_lacks_or_without_a_column_is_refused(tmp_path):
    leg = ROUTE_LEGS.empty_row(voyage_id="V1", leg=0)
    with pytest.raises(RowShapeError, match="wind_gust_kn not defined for route_legs"):
        ROUTE_LEGS.check_rows([leg, {**leg, "wind_gust_kn": 3.0}])
    short = dict(leg)
    del short["hours_without_wind"]
    with pytest.raises(RowShapeError, match="missing hours_without_wind"):
        ROUTE_LEGS.check_rows([short])
    db = tmp_path / "w.duckdb"
    route_store.begin_run(db, "r1", cycle="2020-12-01T00", solver="gc", trigger="manual", n_voyages=1)
    route = ROUTES.empty_row(voyage_id="V1", status="ok")
    with pytest.raises(RowShapeError):  # nothing of the run is stored, no Parquet written
        route_store.write_run_results(db, tmp_path / "exports", "r1", [route], [{**leg, "wind_gust_kn": 3.0}])
    with duckdb.connect(str(db), read_only=True) as con:
        assert con.execute("SELECT count(*) FROM routes").fetchone() == (0,)
    assert not (tmp_path / "exports").exists()


@pytest.mark.slow  # ingest, refit and a fleet run
def test_a_real_run_writes_parquet_with_exactly_the_defined_schemas(tmp_path, demo_mirror):
    from flows.jobs.fleet import route_fleet_job

    root = fleet_data_root(tmp_path, demo_mirror, n_vessels=2, days=150, seed=11, refit=True, at_sea=(0,))
    summary = route_fleet_job(cycle="2020-12-01T00", data_root=str(root), solver="gc", exports=False)
    exports = root / "exports"
    for table in (ROUTES, ROUTE_LEGS):
        path = route_store.parquet_dir(exports, table.name) / f"run_id={summary['run_id']}" / "part-0.parquet"
        assert pq.read_schema(path).remove_metadata() == table.arrow_schema(without=["run_id"]), table.name
    legs = pq.read_table(route_store.parquet_dir(exports, "route_legs")).to_pandas()
    assert len(legs) and legs["hours_without_wind"].notna().all() and legs["hours_beyond_forecast"].notna().all()
    with duckdb.connect(str(root / "warehouse.duckdb"), read_only=True) as con:
        n_stored = con.execute("SELECT count(*) FROM route_legs WHERE hours_before_cycle IS NOT NULL").fetchone()[0]
    assert n_stored == len(legs)
