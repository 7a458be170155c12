"""SIGTERM stops `jitroute ingest` (one download dripping for ever) and `jitroute refit` (waiting for the
warehouse) within a few seconds, as real subprocesses: exit code 143, no traceback, no `.part` file, nothing
half-written visible."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import duckdb
import pytest

from storage import cube
from storage.layout import DataLayout
from tests.http_mirror import serve
from tests.reliability.conftest import CYCLE, REPO, child_env, gsm_file

STOP_WITHIN_S = 8.0  # the grace period is 5 s; normally it is well under that


def _jitroute(*args: str, env_extra: dict | None = None) -> subprocess.Popen:
    env = child_env()
    env.update(env_extra or {})
    return subprocess.Popen([sys.executable, "-m", "cli.main", *args], cwd=REPO, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _stop(proc: subprocess.Popen) -> tuple[float, str, str]:
    t0 = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    try:
        out, err = proc.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
        pytest.fail(f"still running 60 s after SIGTERM:\n{err[-3000:]}")
    return time.monotonic() - t0, out, err


def test_sigterm_stops_an_ingest_with_a_dripping_download(mirror, tmp_path, prefect_harness):
    root = tmp_path / "data"
    drip = gsm_file(mirror, 6)
    with serve(mirror, {drip.name: "drip:0.05"}) as (url, handler):
        proc = _jitroute("ingest", "--cycle", CYCLE, "--data", str(root), "--rish-url", url + "rish/", "--oscar-url", url + "oscar/")
        try:
            assert handler.dripping.wait(120), "the download never started"
            took, out, err = _stop(proc)
        finally:
            proc.kill()
    assert proc.returncode == 143, (proc.returncode, err[-3000:])
    assert took < STOP_WITHIN_S, took
    assert "Traceback" not in err and "Traceback" not in out, err[-3000:]
    assert not list(root.rglob("*.part"))
    assert not (root / "raw" / "gsm" / "20201201" / drip.name).exists()
    store = DataLayout(root).weather_cube
    assert cube.cycle_states(store).get(cube.np.datetime64(CYCLE, "ns"), cube.STATE_HIDDEN) == cube.STATE_HIDDEN
    if DataLayout(root).warehouse.exists():
        con = duckdb.connect(str(DataLayout(root).warehouse), read_only=True)
        assert con.execute("SELECT count(*) FROM cycles WHERE complete").fetchone()[0] == 0
        con.close()


@pytest.fixture
def fleet_root(tmp_path, prefect_harness) -> Path:
    from typer.testing import CliRunner

    from cli.main import app
    from pipeline.synthetic.fleet import generate_fleet, write_fleet

    folder = tmp_path / "fleet"
    write_fleet(generate_fleet("2020-12-01T00", n_vessels=2, days=60, seed=4), folder)
    root = tmp_path / "data"
    result = CliRunner().invoke(app, ["fleet", "import", str(folder), "--data", str(root)])
    assert result.exit_code == 0, result.output
    return root


def test_sigterm_stops_a_refit_waiting_for_the_warehouse(fleet_root):
    db = fleet_root / "warehouse.duckdb"
    before = duckdb.connect(str(db), read_only=True)
    n_models = before.execute("SELECT count(*) FROM perf_models").fetchone()[0]
    before.close()
    holder = duckdb.connect(str(db))  # an analyst's write connection: the refit waits for it (up to 60 s)
    try:
        proc = _jitroute("refit", "--data", str(fleet_root), env_extra={"PREFECT_LOGGING_LEVEL": "INFO"})
        try:
            for line in proc.stderr:  # Prefect announces the flow run once the refit has really started
                if "refit-performance" in line:
                    break
            else:
                pytest.fail(f"refit ended before it started: {proc.wait()}")
            took, out, err = _stop(proc)
        finally:
            proc.kill()
    finally:
        holder.close()
    assert proc.returncode == 143, (proc.returncode, err[-3000:])
    assert took < STOP_WITHIN_S, took
    assert "Traceback" not in err, err[-3000:]
    con = duckdb.connect(str(db), read_only=True)
    assert con.execute("SELECT count(*) FROM perf_models").fetchone()[0] == n_models
    con.close()
