"""Stopping `jitroute serve` with SIGTERM (systemd, an operator) while a flow run is in flight: the run finishes and is
recorded Completed, the cycle it ingested is in the cube, no new run starts, and `serve` then exits on its own."""

from __future__ import annotations

import signal
import subprocess

import httpx
import pytest

from tests.conftest import mirror_urls
from tests.processes import VENV_BIN, poll, prefect_server_and_serve

pytestmark = pytest.mark.slow


def _run(api: str, run_id: str) -> dict:
    r = httpx.get(f"{api}/flow_runs/{run_id}", timeout=10)
    r.raise_for_status()
    return r.json()


def test_sigterm_lets_the_flow_run_in_flight_finish(demo_mirror, tmp_path):
    from storage import cube

    root = tmp_path / "data"
    urls = mirror_urls(demo_mirror)
    with prefect_server_and_serve(tmp_path, ["--data", str(root), "--rish-url", urls["rish_url"],
                                             "--oscar-url", urls["oscar_url"]], JITROUTE_DASK_WORKERS="1") as served:
        api = served.api

        def deployed():
            assert served.serve.poll() is None, served.log("serve")
            names = {d["name"] for d in httpx.post(f"{api}/deployments/filter", json={}, timeout=10).json()}
            return "backfill" in names

        poll("serve's deployments", deployed, 180, 1)
        r = subprocess.run([str(VENV_BIN / "prefect"), "deployment", "run", "backfill/backfill", "-p", "start=2020-12-01",
                            "-p", "end=2020-12-01", "-p", "cycles=0"], env=served.env, capture_output=True, text=True,
                           timeout=120)
        assert r.returncode == 0, r.stderr[-2000:]
        run_id = next(w for w in r.stdout.split() if w.count("-") == 4 and len(w) == 36)
        poll("the backfill to be running", lambda: _run(api, run_id)["state_type"] == "RUNNING", 300, 0.5)
        served.serve.send_signal(signal.SIGTERM)
        assert served.serve.wait(timeout=600) in (0, 143), served.log("serve")
        state = _run(api, run_id)
        assert state["state_type"] == "COMPLETED", (state["state"], served.log("serve"))
        assert cube.complete_cycles(root / "cubes" / "weather.zarr")  # its work is stored
        assert "waiting up to" in (served.logs / "serve.log").read_text()
