"""route_legs lives in one Parquet file per run beside the warehouse (storage/route_history.py): the DuckDB file, which
every write checks whole and copies to the snapshot, does not hold the legs; a file joins the view only with its run's
commit, is never replaced once committed, and a missing or changed one is found."""

from __future__ import annotations

import hashlib
import shutil

import duckdb
import pytest

from storage import route_history, route_store, warehouse
from storage.layout import DataLayout
from tests.test_route_store import _leg, _route


def _write_run(db, run_id, n_voyages=2, n_legs=3):
    route_store.begin_run(db, run_id, cycle="2020-12-01T00", solver="bfoa", trigger="manual", n_voyages=n_voyages)
    routes = [_route(f"V{v}", "ok", 90.0, 100.0) for v in range(n_voyages)]
    legs = [_leg(f"V{v}", k) for v in range(n_voyages) for k in range(n_legs)]
    return route_store.write_run_results(db, db.parent / "exports", run_id, routes, legs)


def _sha(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _read(path, sql):
    con = duckdb.connect(str(path), read_only=True)
    try:
        return con.execute(sql).fetchall()
    finally:
        con.close()


@pytest.mark.slow
def test_the_legs_are_one_file_per_run_beside_the_warehouse_and_not_in_the_duckdb_file(tmp_path):
    db = tmp_path / "w.duckdb"
    _write_run(db, "r1")
    _write_run(db, "r2", n_voyages=3, n_legs=4)
    folder = route_history.history_dir(db)
    assert folder == tmp_path / "w.history" / "route_legs"
    assert sorted(p.parent.name for p in folder.glob("run_id=r*/part-0.parquet")) == ["run_id=r1", "run_id=r2"]
    snap = warehouse.snapshot_path(db)
    for path in (db, snap):  # the analysts' snapshot shows them as the warehouse does
        assert _read(path, "SELECT table_type FROM information_schema.tables WHERE table_name = 'route_legs'") == [("VIEW",)]
        assert _read(path, "SELECT run_id, count(*), sum(fuel_t) FROM route_legs GROUP BY 1 ORDER BY 1") == [
            ("r1", 6, 24.0), ("r2", 12, 48.0)]
        assert _read(path, "SELECT run_id, n_rows FROM route_leg_parts ORDER BY 1") == [("r1", 6), ("r2", 12)]
    # times as the warehouse holds them (naive UTC), and the plan's legs in latest_routes' join
    assert _read(db, "SELECT etd_utc, eta_utc FROM route_legs WHERE run_id = 'r1' AND voyage_id = 'V0' AND leg = 0")[0][1].minute == 36
    assert route_store.current_plan_legs(db, ["V2"])["V2"][0]["lat0"] == 35.0
    # the check of every write reads only the DuckDB file: its tables hold no leg
    assert "route_legs" not in {r[0] for r in _read(db, "SELECT table_name FROM duckdb_tables()")}


@pytest.mark.slow
def test_a_file_of_a_run_that_never_committed_is_not_shown_and_is_replaced_by_its_run(tmp_path):
    db = tmp_path / "w.duckdb"
    _write_run(db, "r1")
    folder = route_history.history_dir(db)
    con = duckdb.connect(str(db))
    try:  # a run killed after writing its file, before its commit
        route_history.write_part(con, folder, "r9", "SELECT * REPLACE ('r9' AS run_id) FROM route_legs WHERE run_id = 'r1'")
    finally:
        con.close()
    assert (folder / "run_id=r9" / "part-0.parquet").exists()
    assert _read(db, "SELECT DISTINCT run_id FROM route_legs") == [("r1",)]
    with warehouse.connect(db):  # a writer finds nothing wrong: an unlisted file is no part of the warehouse
        pass
    _write_run(db, "r9", n_voyages=1, n_legs=2)
    assert _read(db, "SELECT run_id, count(*) FROM route_legs GROUP BY 1 ORDER BY 1") == [("r1", 6), ("r9", 2)]


def test_a_committed_runs_file_is_never_replaced_and_repeated_legs_are_refused(tmp_path):
    db = tmp_path / "w.duckdb"
    _write_run(db, "r1")
    part = route_history.history_dir(db) / "run_id=r1" / "part-0.parquet"
    before = _sha(part)
    with pytest.raises(duckdb.ConstraintException, match="r1"):
        route_store.write_run_results(db, tmp_path / "exports", "r1", [_route("V0", "ok", 1.0, 2.0)], [])
    assert _sha(part) == before
    assert _read(db, "SELECT count(*) FROM route_legs")[0][0] == 6
    route_store.begin_run(db, "r2", cycle="2020-12-01T00", solver="bfoa", trigger="manual", n_voyages=1)
    with pytest.raises(ValueError, match=r"1 repeated \(voyage_id, leg\)"):
        route_store.write_run_results(db, tmp_path / "exports", "r2", [_route("V0", "ok", 1.0, 2.0)],
                                      [_leg("V0", 0), _leg("V0", 0)])
    assert not (route_history.history_dir(db) / "run_id=r2").exists()
    assert _read(db, "SELECT count(*) FROM routes WHERE run_id = 'r2'")[0][0] == 0


@pytest.mark.slow
def test_an_older_snapshot_shows_the_legs_of_its_own_runs_only(tmp_path):
    db = tmp_path / "w.duckdb"
    _write_run(db, "r1")
    old = tmp_path / "kept.snapshot.duckdb"
    shutil.copyfile(warehouse.snapshot_path(db), old)
    _write_run(db, "r2")
    assert _read(old, "SELECT DISTINCT run_id FROM route_legs") == [("r1",)]
    assert _read(warehouse.snapshot_path(db), "SELECT DISTINCT run_id FROM route_legs ORDER BY 1") == [("r1",), ("r2",)]
    # recovering the warehouse from the older snapshot: r2's file is unlisted, and r2 can be written again
    shutil.copyfile(old, db)
    _write_run(db, "r2", n_voyages=1, n_legs=1)
    assert _read(db, "SELECT run_id, count(*) FROM route_legs GROUP BY 1 ORDER BY 1") == [("r1", 6), ("r2", 1)]


@pytest.mark.parametrize("damage", ["deleted", "truncated"])
@pytest.mark.slow
def test_a_missing_or_truncated_legs_file_stops_every_writer_naming_it(tmp_path, damage):
    db = tmp_path / "warehouse.duckdb"  # the data layout's name: its check runs below
    _write_run(db, "r1")
    _write_run(db, "r2")
    part = route_history.history_dir(db) / "run_id=r1" / "part-0.parquet"
    if damage == "deleted":
        part.unlink()
    else:
        part.write_bytes(part.read_bytes()[:-100])
    snap_before = _sha(warehouse.snapshot_path(db))
    with pytest.raises(route_history.HistoryDamagedError, match=f"the legs file {part} of run r1 "):
        with warehouse.connect(db) as con:
            con.execute("INSERT INTO route_runs (run_id, started_at, status) VALUES ('x', now(), 'ok')")
    with pytest.raises(warehouse.WarehouseCorruptError, match="nothing was written"):
        DataLayout(tmp_path).ensure()  # what every job calls before it writes anything
    assert _sha(warehouse.snapshot_path(db)) == snap_before
    assert _read(db, "SELECT count(*) FROM route_runs WHERE run_id = 'x'")[0][0] == 0


def test_the_digest_check_finds_a_changed_byte_the_size_check_cannot(tmp_path):
    db = tmp_path / "w.duckdb"
    _write_run(db, "r1")
    _write_run(db, "r2")
    part = route_history.history_dir(db) / "run_id=r2" / "part-0.parquet"
    with warehouse.connect(db, write=False) as con:
        assert route_history.check_digests(con) == []
    data = bytearray(part.read_bytes())
    data[len(data) // 2] ^= 0xFF
    part.write_bytes(bytes(data))
    with warehouse.connect(db, write=False) as con:
        problems = route_history.check_digests(con)
    assert len(problems) == 1 and f"{part} of run r2 differs" in problems[0]


def test_a_moved_data_root_gets_its_view_at_the_new_place_on_the_next_write(tmp_path):
    _write_run(tmp_path / "a" / "w.duckdb", "r1")
    shutil.move(tmp_path / "a", tmp_path / "b")
    db = tmp_path / "b" / "w.duckdb"
    with warehouse.connect(db):
        pass
    assert _read(db, "SELECT count(*) FROM route_legs")[0][0] == 6
    assert str(tmp_path / "b" / "w.history") in _read(db, "SELECT sql FROM duckdb_views() WHERE view_name = 'route_legs'")[0][0]


def test_a_write_leaves_a_current_view_and_its_columns_file_alone(tmp_path):
    """The view is made again only when its folder or columns changed, not on every write (each remake rewrites the
    columns file and changes the catalog the snapshot copies)."""
    db = tmp_path / "w.duckdb"
    _write_run(db, "r1")
    columns = route_history._columns_file(route_history.history_dir(db))
    view = _read(db, "SELECT sql FROM duckdb_views() WHERE view_name = 'route_legs'")
    with warehouse.connect(db) as con:
        assert route_history._view_is_current(con, route_history.history_dir(db))
    stamp = columns.stat().st_mtime_ns
    with warehouse.connect(db):
        pass
    assert columns.stat().st_mtime_ns == stamp and list(columns.parent.iterdir()) == [columns]
    assert _read(db, "SELECT sql FROM duckdb_views() WHERE view_name = 'route_legs'") == view
    assert _read(db, "SELECT count(*) FROM route_legs")[0][0] == 6


def test_warehouse_check_reads_every_legs_file_and_names_the_changed_one(tmp_path):
    from typer.testing import CliRunner

    from cli.main import app

    db = tmp_path / "warehouse.duckdb"
    _write_run(db, "r1")
    result = CliRunner().invoke(app, ["warehouse", "check", "--data", str(tmp_path)])
    assert result.exit_code == 0 and "1 legs files" in result.output, result.output
    part = route_history.history_dir(db) / "run_id=r1" / "part-0.parquet"
    data = bytearray(part.read_bytes())
    data[10] ^= 0xFF
    part.write_bytes(bytes(data))
    result = CliRunner().invoke(app, ["warehouse", "check", "--data", str(tmp_path)])
    assert result.exit_code == 1 and "run r1 differs" in " ".join(result.output.split()), result.output
