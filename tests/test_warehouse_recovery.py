"""The recovery copies of the warehouse cannot be destroyed: a damaged warehouse stops a writing command before
it writes, its snapshots stay as they were (and load), and the error names the newest good one."""

from __future__ import annotations

import hashlib
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import duckdb
import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from cli.main import app
from pipeline.synthetic.fleet import generate_fleet, write_fleet
from storage import warehouse
from storage.layout import DataLayout

REPO = Path(__file__).resolve().parents[1]


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
    monkeypatch.setattr(warehouse, "SNAPSHOT_MIN_AGE_S", 0.0)  # every write makes a generation (seconds apart here)


@pytest.fixture(scope="module")
def built_root(tmp_path_factory) -> Path:
    """A small fleet imported three times through the CLI (three writes: three snapshot generations)."""
    base = tmp_path_factory.mktemp("recovery")
    write_fleet(generate_fleet("2020-12-01T00", n_vessels=3, days=90, seed=3), base / "fleet")
    mp = pytest.MonkeyPatch()
    mp.delenv("PREFECT_API_URL", raising=False)
    mp.setattr(warehouse, "SNAPSHOT_MIN_AGE_S", 0.0)
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


def _damage_data_in_use(path: Path) -> None:
    """Overwrite 64 KiB of `path` where it holds data in use: from the middle of the file on, the first 64 KiB
    whose loss the check sees (a block that is free after the writes so far would be no damage at all)."""
    original = path.read_bytes()
    size = len(original)
    for offset in list(range(size // 2, size - 64 * 1024, 64 * 1024)) + list(range(12 * 1024, size // 2, 64 * 1024)):
        _overwrite_64k(path, offset)
        if warehouse.check_file(path) is not None:
            return
        path.write_bytes(original)
    raise AssertionError(f"no 64 KiB of {path} holds data the check reads")


def test_three_verified_generations_are_kept(fleet_root):
    db = DataLayout(fleet_root).warehouse
    gens = warehouse.snapshot_generations(db)
    assert [p.name for p in gens] == ["warehouse.snapshot.duckdb", "warehouse.snapshot.1.duckdb", "warehouse.snapshot.2.duckdb"]
    assert all(p.exists() and warehouse.check_file(p) is None for p in gens)
    assert not list(fleet_root.glob("*.tmp*"))
    assert _counts(gens[0]) == _counts(db)


def test_writes_within_minutes_refresh_the_newest_snapshot_and_keep_the_older_generations(fleet_root, tmp_path,
                                                                                         monkeypatch):
    monkeypatch.setattr(warehouse, "SNAPSHOT_MIN_AGE_S", 600.0)
    db = DataLayout(fleet_root).warehouse
    gens = warehouse.snapshot_generations(db)
    older = {p: _digest(p) for p in gens[1:]}
    noon = pd.read_csv(tmp_path / "fleet" / "noon_reports.csv")
    noon["ts_utc"] = pd.to_datetime(noon["ts_utc"]) + pd.Timedelta(days=200)
    noon.to_csv(tmp_path / "later.csv", index=False)
    code, out = _cli("noon", "import", str(tmp_path / "later.csv"), "--data", str(fleet_root))
    assert code == 0, out
    assert {p: _digest(p) for p in gens[1:]} == older  # the same command's writes did not push them out
    assert _counts(gens[0]) == _counts(db) and _counts(gens[0])["noon_reports"] > _counts(gens[1])["noon_reports"]


def test_a_warehouse_with_64_kib_overwritten_stops_a_writing_command_and_every_snapshot_survives(fleet_root, tmp_path):
    db = DataLayout(fleet_root).warehouse
    gens = warehouse.snapshot_generations(db)
    before = {p: _digest(p) for p in gens}
    counts_before = _counts(gens[0])
    assert counts_before["noon_reports"] > 0
    # table data in use (the header alone would fail at open, which was already caught)
    _damage_data_in_use(db)
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
    _damage_data_in_use(db)
    _damage_data_in_use(gens[0])
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


def _immutable(path: Path, on: bool) -> bool:
    return subprocess.run(["chattr", "+i" if on else "-i", str(path)], capture_output=True).returncode == 0


def test_an_immutable_warehouse_is_named_as_unwritable_not_as_busy(fleet_root, tmp_path):
    db = DataLayout(fleet_root).warehouse
    if shutil.which("chattr") is None or not _immutable(db, True):
        pytest.skip("machine capability: `chattr +i` is missing or refused here (it needs root and a file system with "
                    "the immutable flag, such as ext4 or xfs)")
    try:
        before = _digest(db)
        code, out = _cli("noon", "import", str(tmp_path / "fleet" / "noon_reports.csv"), "--data", str(fleet_root))
    finally:
        _immutable(db, False)
    assert code == 2, out
    assert f"warehouse {db} cannot be written (" in out and "Operation not permitted" in out and "chattr -i" in out, out
    assert "held by another process" not in out and "Traceback" not in out
    assert _digest(db) == before


def test_a_full_disk_during_an_import_is_one_line_and_loses_nothing(fleet_root, tmp_path):
    """The file-size limit (RLIMIT_FSIZE: EFBIG, as a full disk) set to the warehouse's size: the import's rows are
    committed to the write-ahead log, then the checkpoint into the warehouse or the snapshot copy cannot be written
    (which one depends on how the checkpoint lays out its blocks): one line either way, and nothing lost."""
    db = DataLayout(fleet_root).warehouse
    gens = warehouse.snapshot_generations(db)
    counts = _counts(db)
    digests = {p: _digest(p) for p in gens}
    noon = pd.read_csv(tmp_path / "fleet" / "noon_reports.csv")
    noon["ts_utc"] = pd.to_datetime(noon["ts_utc"]) + pd.Timedelta(days=400)  # new reports, so the import must write
    noon = noon[pd.to_datetime(noon["ts_utc"]) < pd.Timestamp.now("UTC")]
    assert len(noon) > 100
    noon.to_csv(tmp_path / "new_noon.csv", index=False)
    control = tmp_path / "control"  # the same import with room: what the warehouse must hold afterwards
    shutil.copytree(fleet_root, control)
    code, out = _cli("noon", "import", str(tmp_path / "new_noon.csv"), "--data", str(control))
    assert code == 0, out
    expected = _counts(DataLayout(control).warehouse)
    assert expected["noon_reports"] > counts["noon_reports"]
    limit = db.stat().st_size
    script = ("import resource, signal, sys\n"
              "signal.signal(signal.SIGXFSZ, signal.SIG_IGN)\n"
              f"resource.setrlimit(resource.RLIMIT_FSIZE, ({limit}, {limit}))\n"
              "from cli.main import main\n"
              f"sys.argv = ['jitroute', 'noon', 'import', {str(tmp_path / 'new_noon.csv')!r}, '--data', {str(fleet_root)!r}]\n"
              "main()\n")
    env = {k: v for k, v in os.environ.items() if k != "PREFECT_API_URL"} | {"COLUMNS": "400"}
    proc = subprocess.run([sys.executable, "-c", script], cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    err = [line for line in proc.stderr.splitlines() if line.startswith("error:")]
    assert proc.returncode == 2, proc.stderr[-3000:]
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
    assert len(err) == 1 and "File too large" in err[0] and "free space" in err[0], proc.stderr[-3000:]
    assert (f"no space to write warehouse {db} (" in err[0]
            or f"warehouse {db} holds this command's writes and the snapshots are as they were" in err[0]), err[0]
    assert {p: _digest(p) for p in gens} == digests  # the recovery copies untouched
    assert not list(fleet_root.glob("*.tmp*"))  # no partial copy left
    assert warehouse.check_file(db) is None
    assert _counts(db) == expected  # nothing lost: every committed row is there
    # with room again, the next write publishes a snapshot holding everything
    code, out = _cli("noon", "import", str(tmp_path / "new_noon.csv"), "--data", str(fleet_root))
    assert code == 0, out
    assert _counts(gens[0]) == _counts(db) and all(warehouse.check_file(p) is None for p in gens)
