"""The product as it runs unattended: a real `prefect server start`, `jitroute serve` with a one-minute
nightly cron, and the server's scheduler (no manual trigger) starting the nightly. The mirror holds only
2020-12-01, so the scheduled nightly (today's cycles) refuses to route on weather years old and ends Failed naming
the cycle and its age; the same deployment run for 2020-12-01 routes the fleet, re-planning its ship at sea from
its noon report. The operator's runs (that nightly and a backfill) are started while the scheduler waits for the
minute; the data root's job lock runs the three one after another.

Then everything is stopped and no process of the test may be left behind.
"""

from __future__ import annotations

import json
from datetime import datetime, timezone
import subprocess

import duckdb
import httpx
import pytest

from tests.conftest import fleet_data_root, mirror_urls
from tests.processes import VENV_BIN, poll, prefect_server_and_serve

pytestmark = pytest.mark.slow


@pytest.fixture
def scheduled_root(tmp_path, demo_mirror):
    """A data root with one complete cycle (2020-12-01T00) and a 2-vessel fleet (the first voyage at sea), prepared
    without Prefect."""
    return (fleet_data_root(tmp_path, demo_mirror, n_vessels=2, days=120, seed=5, refit=False, at_sea=(0,)),
            mirror_urls(demo_mirror))


def _runs(api: str) -> list[dict]:
    """Flow runs that have finished (the scheduler also pre-creates many future SCHEDULED ones)."""
    done = {"flow_runs": {"state": {"type": {"any_": ["COMPLETED", "FAILED", "CRASHED", "CANCELLED"]}}}, "limit": 200}
    r = httpx.post(f"{api}/flow_runs/filter", json=done, timeout=10)
    r.raise_for_status()
    return r.json()


def test_the_scheduler_starts_the_nightly_and_nothing_is_left_running(scheduled_root, tmp_path):
    root, urls = scheduled_root
    with prefect_server_and_serve(tmp_path, ["--nightly-cron", "* * * * *", "--data", str(root), "--rish-url",
                                             urls["rish_url"], "--oscar-url", urls["oscar_url"]],
                                  PREFECT_SERVER_SERVICES_SCHEDULER_LOOP_SECONDS="5", PREFECT_RUNNER_POLL_FREQUENCY="1",
                                  JITROUTE_DASK_WORKERS="1") as served:
        api, client_env = served.api, served.env

        # An operator's runs while the scheduler waits for the minute: the nightly for the mirror's day, which routes
        # the fleet, the ship at sea from its noon report, and a backfill with a bare number for the cycle hours (it
        # arrives as a JSON integer). The data root's job lock queues them and the scheduled nightly one by one.
        def deployed():
            assert served.serve.poll() is None, served.log("serve")
            found = httpx.post(f"{api}/deployments/filter", json={}, timeout=10).json()
            return {d["id"]: d["name"] for d in found} if {"nightly", "backfill"} <= {d["name"] for d in found} else None

        deployments = poll("serve to register its deployments", deployed, 120, 0.5)
        since = datetime.now(timezone.utc).isoformat()  # the logs of these runs and later ones
        watch = [str(VENV_BIN / "prefect"), "deployment", "run", "--watch", "--watch-interval", "1"]
        night = subprocess.Popen([*watch, "nightly/nightly", "-p", "date=2020-12-01", "-p", "cycles=0"], env=client_env,
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        bf = subprocess.Popen([*watch, "backfill/backfill", "-p", "start=2020-12-01", "-p", "end=2020-12-01", "-p",
                               "cycles=0"], env=client_env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)

        def refused_scheduled_nightly():
            assert served.serve.poll() is None, served.log("serve")
            runs = [r for r in _runs(api) if r.get("auto_scheduled") and r.get("deployment_id")]
            ended = [r for r in runs if r["state_type"] in ("COMPLETED", "FAILED", "CRASHED")]
            assert all(r["state_type"] == "FAILED" for r in ended), json.dumps(ended, indent=1)[:3000]
            return ended

        done = poll("a scheduled nightly run to end", refused_scheduled_nightly, 300, 1)
        assert "nightly" in {deployments.get(r["deployment_id"]) for r in done}
        message = done[0]["state"]["message"]  # weather too old: cycle 2020-12-01T00 is 52000 h old at …
        assert "weather too old" in message and "2020-12-01T00" in message and "h old at" in message, message

        for name, proc in (("nightly", night), ("backfill", bf)):
            out, err = proc.communicate(timeout=600)
            assert proc.returncode == 0 and "Completed" in out, (name, out[-2000:], err[-2000:])

        ls = subprocess.run([str(VENV_BIN / "prefect"), "deployment", "ls"], env=client_env, capture_output=True,
                            text=True, timeout=120)
        assert ls.returncode == 0, ls.stderr[-2000:]
        assert "nightly/nightly" in ls.stdout and "backfill/backfill" in ls.stdout
        fr = subprocess.run([str(VENV_BIN / "prefect"), "flow-run", "ls"], env=client_env, capture_output=True, text=True,
                            timeout=120)
        assert fr.returncode == 0, fr.stderr[-2000:]

        logs_api = httpx.post(f"{api}/logs/filter", json={"logs": {"timestamp": {"after_": since}}, "limit": 200,
                                                          "sort": "TIMESTAMP_ASC"}, timeout=10).json()
        messages = [entry["message"] for entry in logs_api]
        assert any("routed 1/2" in m for m in messages), messages[:50]  # jitroute.* loggers reach the run's logs
        assert any("(1 from port, 1 at sea re-planned)" in m for m in messages), messages[:50]
        artifacts = httpx.post(f"{api}/artifacts/filter", json={"limit": 50}, timeout=10).json()
        keys = {(a["key"], a["type"]) for a in artifacts}
        assert ("nightly-summary", "markdown") in keys and ("nightly-summary-table", "table") in keys, keys
        summaries = [a["data"] for a in artifacts if a["key"] == "nightly-summary"]
        assert any("fleet_map.png" in md and "2020-12-01T00" in md for md in summaries), summaries
        assert any(": Failed" in md and "**Routing refused:** weather too old" in md for md in summaries), summaries

        with duckdb.connect(str(root / "warehouse.snapshot.duckdb"), read_only=True) as con:
            runs = con.execute("SELECT status, n_voyages, cycle, cycle_age_h, reason FROM route_runs "
                               "WHERE trigger = 'nightly' ORDER BY started_at").fetchall()
            starts = dict(con.execute("SELECT voyage_id, start_kind FROM latest_routes").fetchall())
        routed = [r for r in runs if r[0] in ("ok", "partial")]
        assert routed and routed[0][1] == 2 and str(routed[0][2]).startswith("2020-12-01 00:00") and routed[0][3] == 0.0
        assert any(r[0] == "failed" and "weather too old" in r[4] for r in runs), runs
        assert starts == {"V20001": "noon report", "V20002": "port"}
    assert "Can't evaluate bulk DML" not in (served.logs / "server.log").read_text()
