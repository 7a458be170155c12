"""The recovery copies of the warehouse cannot be destroyed: a damaged warehouse stops a writing command before
it writes, its snapshots stay as they were (and load), and the error names the newest good one."""

from __future__ import annotations

import hashlib
import re
import shutil
from pathlib import Path

import duckdb
import numpy as np
import pytest
from typer.testing import CliRunner

from cli.main import app
from pipeline.synthetic.fleet import generate_fleet, write_fleet
from storage import warehouse
from storage.layout import DataLayout


def _cli(*args: str) -> tuple[int, str]:
    result = CliRunner().invoke(app, list(args))
    if result.exception and not isinstance(result.exception, SystemExit):
        raise result.exception
    return result.exit_code, re.sub(r"\s+", " ", result.output)


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _counts(path: Path) -> dict[str, int]:
    con = duckdb.connect(str(path), read_only=True)
    try:
        return {t: con.execute(f'SELECT count(*) FROM "{t}"').fetchone()[0] for t in ("vessels", "voyages", "noon_reports")}
    finally:
        con.close()


@pytest.fixture(autouse=True)
def plain_cli(monkeypatch):
    monkeypatch.delenv("PREFECT_API_URL", raising=False)
    monkeypatch.setenv("COLUMNS", "400")


@pytest.fixture(scope="module")
def built_root(tmp_path_factory) -> Path:
    """A small fleet imported three times through the CLI (three writes: three snapshot generations)."""
    base = tmp_path_factory.mktemp("recovery")
    write_fleet(generate_fleet("2020-12-01T00", n_vessels=3, days=90, seed=3), base / "fleet")
    mp = pytest.MonkeyPatch()
    mp.delenv("PREFECT_API_URL", raising=False)
    try:
        for _ in range(3):
            code, out = _cli("fleet", "import", str(base / "fleet"), "--data", str(base / "data"))
            assert code == 0, out
    finally:
        mp.undo()
    return base


@pytest.fixture
def fleet_root(built_root, tmp_path) -> Path:
    shutil.copytree(built_root / "fleet", tmp_path / "fleet")
    shutil.copytree(built_root / "data", tmp_path / "data")
    return tmp_path / "data"


def _overwrite_64k(path: Path, offset: int) -> None:
    with open(path, "r+b") as fh:
        fh.seek(offset)
        fh.write(np.random.default_rng(11).bytes(64 * 1024))


def test_three_verified_generations_are_kept(fleet_root):
    db = DataLayout(fleet_root).warehouse
    gens = warehouse.snapshot_generations(db)
    assert [p.name for p in gens] == ["warehouse.snapshot.duckdb", "warehouse.snapshot.1.duckdb", "warehouse.snapshot.2.duckdb"]
    assert all(p.exists() and warehouse.check_file(p) is None for p in gens)
    assert not list(fleet_root.glob("*.tmp*"))
    assert _counts(gens[0]) == _counts(db)


def test_a_warehouse_with_64_kib_overwritten_stops_a_writing_command_and_every_snapshot_survives(fleet_root, tmp_path):
    db = DataLayout(fleet_root).warehouse
    gens = warehouse.snapshot_generations(db)
    before = {p: _digest(p) for p in gens}
    counts_before = _counts(gens[0])
    assert counts_before["noon_reports"] > 0
    # the middle of the file: table data in use (the header alone would fail at open, which was already caught)
    _overwrite_64k(db, db.stat().st_size // 2)
    damaged = _digest(db)

    code, out = _cli("fleet", "import", str(tmp_path / "fleet"), "--data", str(fleet_root))
    assert code == 2, out
    assert "Traceback" not in out
    assert f"warehouse {db} is damaged" in out and "nothing was written" in out, out
    assert f"newest good snapshot {gens[0]}" in out and f"cp {gens[0]} {db}" in out, out

    assert {p: _digest(p) for p in gens} == before  # no snapshot replaced by the damaged file
    assert _digest(db) == damaged  # nothing written to the damaged file either
    for p in gens:
        assert warehouse.check_file(p) is None
    assert _counts(gens[0]) == counts_before  # nothing lost: the newest snapshot holds every row

    # the advice works: the recovered warehouse takes writes again
    db.rename(db.with_name("warehouse.duckdb.damaged"))
    db.write_bytes(gens[0].read_bytes())
    code, out = _cli("fleet", "import", str(tmp_path / "fleet"), "--data", str(fleet_root))
    assert code == 0, out
    assert _counts(db) == counts_before


def test_the_error_names_an_older_snapshot_when_the_newest_is_damaged_too(fleet_root, tmp_path):
    db = DataLayout(fleet_root).warehouse
    gens = warehouse.snapshot_generations(db)
    _overwrite_64k(db, db.stat().st_size // 2)
    _overwrite_64k(gens[0], gens[0].stat().st_size // 2)
    code, out = _cli("noon", "import", str(tmp_path / "fleet" / "noon_reports.csv"), "--data", str(fleet_root))
    assert code == 2, out
    assert f"newest good snapshot {gens[1]}" in out, out


def test_a_copy_that_fails_the_check_is_never_published(tmp_path, monkeypatch):
    db = tmp_path / "w.duckdb"
    with warehouse.connect(db) as con:
        con.execute("INSERT INTO schema_migrations VALUES ('marker', now())")
    snap = warehouse.snapshot_path(db)
    before = _digest(snap)
    real_copy = warehouse.shutil.copyfile

    def torn_copy(src, dst):  # the copy gets damaged on its way (a bad disk block, a full disk)
        real_copy(src, dst)
        if Path(dst).name.startswith("w.snapshot.duckdb.tmp"):
            _overwrite_64k(Path(dst), Path(dst).stat().st_size // 2)

    monkeypatch.setattr(warehouse.shutil, "copyfile", torn_copy)
    with pytest.raises(warehouse.WarehouseCorruptError, match="snapshot copy of warehouse .* fails the check"):
        with warehouse.connect(db) as con:
            con.execute("INSERT INTO schema_migrations VALUES ('marker2', now())")
    assert _digest(snap) == before
    assert not list(tmp_path.glob("*.tmp*"))
