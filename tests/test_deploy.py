"""deploy/prefect.yaml, as far as one machine allows: it parses, its entrypoints are the flows, its schedules are
the ones `jitroute serve` uses, and `prefect deploy --all` registers every deployment on a throw-away server."""

from __future__ import annotations

import importlib
from pathlib import Path

import pytest
import yaml

from tests.processes import new_tag, tagged_env
from tests.processes import prefect as run_prefect

REPO = Path(__file__).resolve().parent.parent
PREFECT_YAML = REPO / "deploy" / "prefect.yaml"
HOST_ENV = {"JITROUTE_HOME": "/srv/jitroute/app", "JITROUTE_DATA": "/srv/jitroute/data",
            "JITROUTE_OBJECT_ROOT": "s3://fleet-bucket/jitroute", "JITROUTE_DASK_ADDRESS": "tcp://scheduler-host:8786"}


def _deployments() -> dict[str, dict]:
    return {d["name"]: d for d in yaml.safe_load(PREFECT_YAML.read_text())["deployments"]}


def test_prefect_yaml_entrypoints_are_the_flows_and_schedules_match_serve():
    from prefect import Flow

    from deploy.serve import NIGHTLY_CRON
    from flows.settings import load_settings
    from pipeline.sources.cycles import publication_cron

    deps = _deployments()
    assert set(deps) == {"nightly", "ingest", "backfill", "route-fleet", "plan-fleet"}
    for name, d in deps.items():
        path, attr = d["entrypoint"].split(":")
        assert (REPO / path).is_file(), d["entrypoint"]
        fl = getattr(importlib.import_module(path.removesuffix(".py").replace("/", ".")), attr)
        assert isinstance(fl, Flow), (name, fl)
        assert d["work_pool"]["name"] == "jitroute"
        assert set(d["work_pool"]["job_variables"]["env"]) == {"JITROUTE_DATA", "JITROUTE_OBJECT_ROOT",
                                                               "JITROUTE_DASK_ADDRESS"}
    s = load_settings()
    assert deps["nightly"]["schedules"][0]["cron"] == NIGHTLY_CRON
    assert deps["ingest"]["schedules"][0]["cron"] == publication_cron(s.sources.cycles_utc, s.sources.publish_delay_h)


@pytest.mark.slow
def test_prefect_deploy_all_registers_every_deployment_with_the_hosts_settings(prefect_harness):
    from prefect.settings import PREFECT_API_URL

    env = tagged_env(new_tag(), PREFECT_API_URL=PREFECT_API_URL.value(), **HOST_ENV)

    def prefect(*args: str) -> str:
        return run_prefect(*args, env=env, cwd=REPO)

    prefect("work-pool", "create", "jitroute", "--type", "process", "--overwrite")
    prefect("deploy", "--all", "--prefect-file", str(PREFECT_YAML))

    from prefect.client.orchestration import get_client

    with get_client(sync_client=True) as client:
        registered = {d.name: d for d in client.read_deployments()}
    assert set(registered) >= set(_deployments())
    nightly = registered["nightly"]
    assert nightly.entrypoint == "flows/fleet.py:nightly" and nightly.work_pool_name == "jitroute"
    assert nightly.job_variables["env"] == {k: v for k, v in HOST_ENV.items() if k != "JITROUTE_HOME"}
    assert nightly.pull_steps[0]["prefect.deployments.steps.set_working_directory"]["directory"] == HOST_ENV["JITROUTE_HOME"]
    assert [s.schedule.cron for s in nightly.schedules] == ["30 2 * * *"]
