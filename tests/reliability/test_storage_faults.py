"""Two ingests of one cycle at once, a full disk, and an analyst's DuckDB connection — against the real
flow, real Zarr and real DuckDB files (kills are in test_crash_recovery.py)."""

from __future__ import annotations

import errno
import json
import shutil
import subprocess
import sys
import threading
from pathlib import Path

import duckdb
import numpy as np
import pytest

from pipeline.sources.fetch import sha256_of
from storage import cube, ingest_log, warehouse
from storage.layout import DataLayout
from tests.http_mirror import serve
from tests.reliability.conftest import (CYCLE, N_FILES, assert_same_cube, file_urls, gsm_file, start_child,
                                       visible_cycles_equal_clean, warehouse_knows_cycle)

DEADLINE_S = 240.0


def test_two_ingests_of_one_cycle_at_once_agree(small_mirror, tmp_path, ingest, clean_cube, prefect_harness):
    """Two ingests of one data root never overlap: the second waits for the data root's job lock, then finds the
    cycle complete and skips it; one store, one cycle, every file fetched once."""
    root = tmp_path / "data"
    with serve(small_mirror) as (url, handler):
        procs = [start_child(root, url + "rish/", url + "oscar/", "--timeout", "60") for _ in range(2)]
        outs = [p.communicate(timeout=DEADLINE_S) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], [o[1][-3000:] for o in outs]
    first = gsm_file(small_mirror, 0).name
    assert handler.hits["/rish/2020/12/01/" + first] == 1  # fetched once: the second run did not overlap the first
    reports = [json.loads(o[0].strip().splitlines()[-1]) for o in outs]
    assert all(r["complete"] for r in reports), reports
    assert sorted(bool(r.get("skipped")) for r in reports) == [False, True], reports
    assert_same_cube(DataLayout(root).weather_cube, clean_cube)
    raw = sorted(p for p in DataLayout(root).raw.rglob("*") if p.is_file())
    assert len(raw) == N_FILES and not list(root.rglob("*.part"))
    for p in raw:  # every raw file is byte-identical to the mirror's
        assert sha256_of(p) == sha256_of(next(small_mirror.rglob(p.name))), p.name
    warehouse_knows_cycle(root)
    main = duckdb.connect(str(DataLayout(root).warehouse), read_only=True)
    n_main = main.execute("SELECT count(*), count(DISTINCT run_id) FROM ingest_log").fetchone()
    main.close()
    snap = duckdb.connect(str(DataLayout(root).warehouse_snapshot), read_only=True)
    n_snap = snap.execute("SELECT count(*), count(DISTINCT run_id) FROM ingest_log").fetchone()
    snap.close()
    assert n_main == n_snap == (N_FILES, 1)  # the snapshot is not older than the last write


def _fail_after(n_ok: int, real):
    count = {"n": 0}

    def put(path, value, exclusive=False):
        count["n"] += 1
        if count["n"] > n_ok:
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return real(path, value, exclusive=exclusive)

    return put


@pytest.mark.parametrize("n_ok", [0, 10, 75], ids=["at-creation", "in-template", "mid-region"])  # creation ≈ 45 writes, region 64
def test_disk_full_during_the_cube_write_is_a_clear_error_and_no_cycle_shows(n_ok, small_mirror, tmp_path, ingest, clean_cube, monkeypatch):
    import zarr.storage._local as zarr_local

    root = tmp_path / "data"
    with monkeypatch.context() as m:
        m.setattr(zarr_local, "_put", _fail_after(n_ok, zarr_local._put))
        with pytest.raises(Exception) as info:
            ingest(root, *file_urls(small_mirror))
    msg = str(info.value)
    assert "No space left on device" in msg and "weather.zarr" in msg and "re-run" in msg, msg
    store = DataLayout(root).weather_cube
    assert cube.complete_cycles(store) == [] and visible_cycles_equal_clean(store, clean_cube) == 0
    report = ingest(root, *file_urls(small_mirror))  # space freed
    assert report["complete"]
    assert_same_cube(store, clean_cube)


def test_disk_full_during_download_stops_at_once_with_a_clear_error(small_mirror, tmp_path, ingest, clean_cube, prefect_harness):
    """RLIMIT_FSIZE below a GRIB file's size: the kernel refuses the write (EFBIG) as a full disk would."""
    root = tmp_path / "data"
    proc = start_child(root, *file_urls(small_mirror), "--fsize-limit", "300000")
    out, err = proc.communicate(timeout=DEADLINE_S)
    assert proc.returncode != 0
    assert "cannot write" in err and "File too large" in err and "free space on the data root" in err, err[-3000:]
    assert str(DataLayout(root).raw) in err
    # downloads run concurrently: files that fit may have landed, but each one whole, and no `.part` is left
    sources = {p.name: p for p in small_mirror.rglob("*") if p.is_file()}
    landed = [p for p in DataLayout(root).raw.rglob("*") if p.is_file()]
    assert all(p.name in sources and p.read_bytes() == sources[p.name].read_bytes() for p in landed), landed
    assert len(landed) < len([n for n in sources if n != "index.html"])  # it stopped: not everything was fetched
    assert not DataLayout(root).weather_cube.exists()
    assert ingest(root, *file_urls(small_mirror))["complete"]
    assert_same_cube(DataLayout(root).weather_cube, clean_cube)


ANALYST = """
import sys, duckdb
con = duckdb.connect(sys.argv[1], read_only=True)
print(con.execute("SELECT count(*) FROM ingest_log").fetchone()[0], flush=True)
sys.stdin.readline()          # hold the connection until told to close
print(con.execute("SELECT count(*) FROM ingest_log").fetchone()[0], flush=True)
con.close()
"""


def _analyst(path: Path) -> tuple[subprocess.Popen, int]:
    p = subprocess.Popen([sys.executable, "-c", ANALYST, str(path)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    first = p.stdout.readline()
    assert first.strip().isdigit(), p.stderr.read()
    return p, int(first)


def _row(run_id: str) -> dict:
    now = ingest_log.utcnow()
    return {"run_id": run_id, "source": "GSM", "cycle": np.datetime64(CYCLE, "ns"), "file_name": f"{run_id}.bin", "url": "u",
            "bytes": 1, "sha256": "0", "status": "ok", "error": None, "started_at": now, "finished_at": now}


def test_analyst_on_the_main_file_blocks_writers_the_snapshot_does_not(clean_root, tmp_path):
    root = tmp_path / "data"
    shutil.copytree(clean_root, root)
    db, snap = DataLayout(root).warehouse, DataLayout(root).warehouse_snapshot
    # 1. an analyst holding the main file read-only: a writer gets a clear "busy" error...
    analyst, n0 = _analyst(db)
    with pytest.raises(warehouse.WarehouseBusyError, match="warehouse.snapshot.duckdb"):
        with warehouse.connect(db, wait_s=0.2):
            pass
    # ...and a writer that is allowed to wait finishes once the analyst closes
    done = threading.Event()
    writer = threading.Thread(target=lambda: (ingest_log.record_files(db, [_row("waited")]), done.set()))
    writer.start()
    analyst.stdin.write("\n")
    analyst.stdin.flush()
    out, err = analyst.communicate(timeout=60)
    writer.join(timeout=90)
    assert done.is_set() and analyst.returncode == 0, err
    assert int(out.strip()) == n0  # the analyst's view never changed under it
    # 2. an analyst on the snapshot never blocks the pipeline; new connections see new rows
    analyst, s0 = _analyst(snap)
    ingest_log.record_files(db, [_row("while-reading-snapshot")])
    analyst.stdin.write("\n")
    analyst.stdin.flush()
    out, _ = analyst.communicate(timeout=60)
    assert int(out.strip()) == s0  # an open snapshot connection keeps its consistent view
    con = duckdb.connect(str(snap), read_only=True)
    assert con.execute("SELECT count(*) FROM ingest_log").fetchone()[0] == s0 + 1
    con.close()
    # 3. while the pipeline holds the main file, an analyst cannot open it at all
    with warehouse.connect(db):
        p = subprocess.run([sys.executable, "-c", f"import duckdb; duckdb.connect({str(db)!r}, read_only=True)"],
                           capture_output=True, text=True, timeout=60)
    assert p.returncode != 0 and "lock" in p.stderr.lower()
