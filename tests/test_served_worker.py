"""deploy/prefect.yaml under a real process work-pool worker: the flow runs an API caller starts cannot steer the data
root, send the Earthdata token's fetch to their own host, or read a file of the flow host outside the data root's
inbox; the same deployment with the host's own values plans the fleet."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import duckdb
import pytest

from tests.http_mirror import serve
from tests.processes import VENV_BIN, describe, kill_tagged, new_tag, tagged_env, wait_until_gone
from tests.processes import prefect as run_prefect

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parent.parent


def _inbox_root(base: Path) -> Path:
    """The flow host's data root: a 4-vessel fleet imported, its planning files in the inbox."""
    from flows.jobs.refit import import_fleet_folder
    from pipeline.synthetic.contracts import write_demo_planning
    from pipeline.synthetic.fleet import generate_fleet, write_fleet

    root = base / "data"
    fl = generate_fleet("2020-12-01T00", n_vessels=4, days=30, seed=3)
    write_fleet(fl, base / "fleet")
    import_fleet_folder(str(base / "fleet"), data_root=str(root))
    files = write_demo_planning(fl.vessels, "2020-12-01T00", base / "plan", n_contracts=6, seed=4,
                                ports=("Busan", "Shanghai", "Qingdao", "Kaohsiung", "Keelung"))
    (root / "inbox").mkdir()
    for f in files.values():
        shutil.copy(f, root / "inbox")
    return root


def test_a_work_pool_worker_refuses_a_callers_data_root_urls_and_host_files(prefect_harness, tmp_path):
    from prefect.client.orchestration import get_client
    from prefect.settings import PREFECT_API_URL

    root = _inbox_root(tmp_path)
    theirs = tmp_path / "theirs"
    secret = tmp_path / "secret.csv"
    secret.write_text("code,cargo_type\nAWS_SECRET_ACCESS_KEY,hunter2\n")
    tag = new_tag()
    env = tagged_env(tag, PREFECT_API_URL=PREFECT_API_URL.value(), JITROUTE_HOME=str(REPO), JITROUTE_DATA=str(root),
                     JITROUTE_OBJECT_ROOT="", JITROUTE_DASK_ADDRESS="", JITROUTE_EARTHDATA_TOKEN="edl-secret-token")
    env.pop("JITROUTE_SERVED", None)  # a worker is no `jitroute serve`: the flows must know on their own

    def prefect(*args: str) -> str:
        return run_prefect(*args, env=env, cwd=REPO)

    prefect("work-pool", "create", "jitroute", "--type", "process", "--overwrite")
    prefect("deploy", "--all", "--prefect-file", str(REPO / "deploy" / "prefect.yaml"))
    with serve(tmp_path) as (listener, handler):
        asks = {"ingest": ("ingest-weather/ingest", {"cycle": "2020-12-01T00", "oscar_url": listener + "oscar/"}),
                "route": ("route-fleet/route-fleet", {"data_root": str(theirs)}),
                "plan-host-file": ("plan-fleet/plan-fleet", {"contracts": str(secret)}),
                "plan-escape": ("plan-fleet/plan-fleet", {"contracts": "contracts.csv", "ports": "../../secret.csv"}),
                "plan": ("plan-fleet/plan-fleet", {"contracts": "contracts.csv", "availability": "availability.csv",
                                                    "ports": "ports.csv", "as_of": "2020-12-01T00:00Z"})}
        with get_client(sync_client=True) as client:
            ids = {}
            for key, (name, params) in asks.items():
                dep = client.read_deployment_by_name(name)
                ids[key] = client.create_flow_run_from_deployment(dep.id, parameters=params).id
        worker = subprocess.run([str(VENV_BIN / "prefect"), "worker", "start", "--pool", "jitroute", "--run-once"],
                                cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900)
        try:
            assert worker.returncode == 0, (worker.stdout[-3000:], worker.stderr[-3000:])
            with get_client(sync_client=True) as client:
                states = {k: client.read_flow_run(i).state for k, i in ids.items()}
        finally:
            left = wait_until_gone(tag, 30)
            kill_tagged(tag)
        assert handler.requests == []  # the token's fetch never reached the caller's host
    assert not left, describe(left)
    shown = {k: (s.type.value, s.message) for k, s in states.items()}
    for key, says in (("ingest", "parameter oscar_url="), ("route", "parameter data_root="),
                      ("plan-host-file", "parameter contracts="), ("plan-escape", "parameter ports=")):
        assert states[key].is_failed() and says in states[key].message and "refused" in states[key].message, shown
    assert "served flow reads input files only under" in states["plan-escape"].message
    assert states["plan"].is_completed(), shown
    assert not theirs.exists()
    with duckdb.connect(str(root / "warehouse.duckdb"), read_only=True) as con:
        plans = con.execute("SELECT count(*), min(n_contracts) FROM fleet_plans").fetchone()
        leaked = con.execute("SELECT count(*) FROM contracts_rejected WHERE raw LIKE '%hunter2%'").fetchone()[0]
    assert plans == (1, 6) and leaked == 0
