"""The product as it runs unattended: a real `prefect server start`, `jitroute serve` with a one-minute
nightly cron, and the server's scheduler (no manual trigger) starting the run that routes the fleet.

Then everything is stopped and no process of the test may be left behind.
"""

from __future__ import annotations

import json
import signal
import subprocess
from pathlib import Path

import duckdb
import httpx
import pytest

from tests.conftest import fleet_data_root, mirror_urls
from tests.processes import VENV_BIN, describe, free_port, kill_tagged, new_tag, poll, tagged_env, wait_until_gone

pytestmark = pytest.mark.slow


@pytest.fixture
def scheduled_root(tmp_path, demo_mirror):
    """A data root with one complete cycle (2020-12-01T00) and a 2-vessel fleet, prepared without Prefect."""
    return fleet_data_root(tmp_path, demo_mirror, n_vessels=2, days=120, seed=5, refit=False), mirror_urls(demo_mirror)


def _runs(api: str) -> list[dict]:
    """Flow runs that have finished (the scheduler also pre-creates many future SCHEDULED ones)."""
    done = {"flow_runs": {"state": {"type": {"any_": ["COMPLETED", "FAILED", "CRASHED", "CANCELLED"]}}}, "limit": 200}
    r = httpx.post(f"{api}/flow_runs/filter", json=done, timeout=10)
    r.raise_for_status()
    return r.json()


def test_the_scheduler_starts_the_nightly_and_nothing_is_left_running(scheduled_root, tmp_path):
    root, urls = scheduled_root
    tag = new_tag()
    port = free_port()
    api = f"http://127.0.0.1:{port}/api"
    home = tmp_path / "prefect_home"
    env = tagged_env(tag, PREFECT_HOME=str(home), PREFECT_LOGGING_LEVEL="INFO",
                     PREFECT_SERVER_SERVICES_SCHEDULER_LOOP_SECONDS="5", JITROUTE_DASK_WORKERS="1")
    server = serve = None
    logs = tmp_path / "logs"
    logs.mkdir()
    try:
        server = subprocess.Popen([str(VENV_BIN / "prefect"), "server", "start", "--host", "127.0.0.1", "--port", str(port)],
                                  env=env, stdout=open(logs / "server.log", "w"), stderr=subprocess.STDOUT,
                                  start_new_session=True)

        def healthy():
            try:
                return httpx.get(f"{api}/health", timeout=2).status_code == 200
            except httpx.HTTPError:
                assert server.poll() is None, (logs / "server.log").read_text()[-3000:]
                return False

        poll("the Prefect server", healthy, 120, 0.5)
        client_env = dict(env, PREFECT_API_URL=api)
        serve = subprocess.Popen([str(VENV_BIN / "jitroute"), "serve", "--nightly-cron", "* * * * *", "--data", str(root),
                                  "--rish-url", urls["rish_url"], "--oscar-url", urls["oscar_url"]],
                                 env=client_env, cwd=tmp_path, stdout=open(logs / "serve.log", "w"),
                                 stderr=subprocess.STDOUT, start_new_session=True)

        def completed_scheduled_nightly():
            assert serve.poll() is None, (logs / "serve.log").read_text()[-3000:]
            runs = [r for r in _runs(api) if r.get("auto_scheduled")]
            failed = [r for r in runs if r["state_type"] in ("FAILED", "CRASHED")]
            assert not failed, (json.dumps(failed, indent=1)[:2000], (logs / "serve.log").read_text()[-5000:])
            return [r for r in runs if r["state_type"] == "COMPLETED" and r["name"] and r.get("deployment_id")]

        done = poll("a scheduled nightly run to complete", completed_scheduled_nightly, 240, 2)
        deployments = {d["id"]: d["name"] for d in httpx.post(f"{api}/deployments/filter", json={}, timeout=10).json()}
        assert "nightly" in {deployments.get(r["deployment_id"]) for r in done}

        ls = subprocess.run([str(VENV_BIN / "prefect"), "deployment", "ls"], env=client_env, capture_output=True,
                            text=True, timeout=120)
        assert ls.returncode == 0, ls.stderr[-2000:]
        assert "nightly/nightly" in ls.stdout and "backfill/backfill" in ls.stdout
        fr = subprocess.run([str(VENV_BIN / "prefect"), "flow-run", "ls"], env=client_env, capture_output=True, text=True,
                            timeout=120)
        assert fr.returncode == 0, fr.stderr[-2000:]

        logs_api = httpx.post(f"{api}/logs/filter", json={"limit": 200, "sort": "TIMESTAMP_ASC"}, timeout=10).json()
        messages = [entry["message"] for entry in logs_api]
        assert any("routed 1/2" in m for m in messages), messages[:50]  # jitroute.* loggers reach the run's logs
        artifacts = httpx.post(f"{api}/artifacts/filter", json={"limit": 50}, timeout=10).json()
        keys = {(a["key"], a["type"]) for a in artifacts}
        assert ("nightly-summary", "markdown") in keys and ("nightly-summary-table", "table") in keys, keys
        summary_md = next(a["data"] for a in artifacts if a["key"] == "nightly-summary")
        assert "fleet_map.png" in summary_md and "2020-12-01T00" in summary_md

        # An operator's backfill with a bare number for the cycle hours (arrives as a JSON integer)
        bf = subprocess.run([str(VENV_BIN / "prefect"), "deployment", "run", "backfill/backfill", "-p", "start=2020-12-01",
                             "-p", "end=2020-12-01", "-p", "cycles=0", "--watch"], env=client_env, capture_output=True,
                            text=True, timeout=300)
        assert bf.returncode == 0 and "Completed" in bf.stdout, (bf.stdout[-2000:], bf.stderr[-2000:])

        with duckdb.connect(str(root / "warehouse.snapshot.duckdb"), read_only=True) as con:
            runs = con.execute("SELECT status, trigger, n_voyages, cycle FROM route_runs WHERE trigger = 'nightly'").fetchall()
        assert runs and runs[0][0] in ("ok", "partial") and runs[0][2] == 2, runs
        assert str(runs[0][3]).startswith("2020-12-01 00:00")
    finally:
        for proc in (serve, server):
            if proc is not None and proc.poll() is None:
                proc.send_signal(signal.SIGINT)
                try:
                    proc.wait(timeout=60)
                except subprocess.TimeoutExpired:
                    proc.kill()
        left = wait_until_gone(tag, 30)
        kill_tagged(tag)
    assert not left, f"processes left running after serve and the server stopped:\n{describe(left)}"
    assert "Can't evaluate bulk DML" not in (logs / "server.log").read_text()
