"""Stopping `jitroute serve` with SIGTERM (systemd, an operator) while a flow run is in flight: the run finishes and is
recorded Completed, the cycle it ingested is in the cube, no new run starts, and `serve` then exits on its own."""

from __future__ import annotations

import signal
import subprocess

import httpx
import pytest

from tests.conftest import mirror_urls
from tests.processes import VENV_BIN, describe, free_port, kill_tagged, new_tag, poll, tagged_env, wait_until_gone

pytestmark = pytest.mark.slow


def _run(api: str, run_id: str) -> dict:
    r = httpx.get(f"{api}/flow_runs/{run_id}", timeout=10)
    r.raise_for_status()
    return r.json()


def test_sigterm_lets_the_flow_run_in_flight_finish(demo_mirror, tmp_path):
    from storage import cube

    root = tmp_path / "data"
    urls = mirror_urls(demo_mirror)
    tag = new_tag()
    port = free_port()
    api = f"http://127.0.0.1:{port}/api"
    env = tagged_env(tag, PREFECT_HOME=str(tmp_path / "prefect_home"), PREFECT_LOGGING_LEVEL="INFO",
                     JITROUTE_DASK_WORKERS="1")
    logs = tmp_path / "logs"
    logs.mkdir()
    server = serve = None
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
        serve = subprocess.Popen([str(VENV_BIN / "jitroute"), "serve", "--data", str(root), "--rish-url", urls["rish_url"],
                                  "--oscar-url", urls["oscar_url"]], env=client_env, cwd=tmp_path,
                                 stdout=open(logs / "serve.log", "w"), stderr=subprocess.STDOUT, start_new_session=True)

        def deployed():
            assert serve.poll() is None, (logs / "serve.log").read_text()[-3000:]
            names = {d["name"] for d in httpx.post(f"{api}/deployments/filter", json={}, timeout=10).json()}
            return "backfill" in names

        poll("serve's deployments", deployed, 180, 1)
        r = subprocess.run([str(VENV_BIN / "prefect"), "deployment", "run", "backfill/backfill", "-p", "start=2020-12-01",
                            "-p", "end=2020-12-01", "-p", "cycles=0"], env=client_env, capture_output=True, text=True,
                           timeout=120)
        assert r.returncode == 0, r.stderr[-2000:]
        run_id = next(w for w in r.stdout.split() if w.count("-") == 4 and len(w) == 36)
        poll("the backfill to be running", lambda: _run(api, run_id)["state_type"] == "RUNNING", 300, 0.5)
        serve.send_signal(signal.SIGTERM)
        assert serve.wait(timeout=600) in (0, 143), (logs / "serve.log").read_text()[-3000:]
        state = _run(api, run_id)
        assert state["state_type"] == "COMPLETED", (state["state"], (logs / "serve.log").read_text()[-3000:])
        assert cube.complete_cycles(root / "cubes" / "weather.zarr")  # its work is stored
        assert "waiting up to" in (logs / "serve.log").read_text()
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
