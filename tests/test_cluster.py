"""The fleet on a real cluster: an S3 server on loopback (moto) holding the weather cube and the exports, a
`dask scheduler` and two `dask worker` processes started in another folder without the data root, `jitroute
route-fleet`, and one worker SIGKILLed mid-run. Nothing may be lost: every voyage has its row, every routed voyage
its files in the bucket under a published run (manifest written last)."""

from __future__ import annotations

import json
import os
import signal
import subprocess

import duckdb
import pytest

from tests.conftest import fleet_data_root
from tests.processes import VENV_BIN, describe, kill_tagged, new_tag, poll, tagged_env, wait_until_gone

pytestmark = pytest.mark.slow

N_VESSELS = 4
OBJECT_ROOT = "s3://jitroute/fleet"


def test_a_killed_worker_loses_no_voyage_and_the_exports_land_in_the_bucket(tmp_path, demo_mirror, s3_endpoint,
                                                                             dask_cluster, monkeypatch):
    import s3fs
    from distributed import Client

    def batch_progress(dask_scheduler):  # runs on the scheduler (defined here so it is pickled by value)
        """Routing tasks finished so far, and the workers busy with one now (address → pid)."""
        prefix = dask_scheduler.task_prefixes.get("route_batch")
        counts = prefix.state_counts if prefix else {}
        busy = {ws.address: ws.pid for ws in dask_scheduler.workers.values()
                if any(ts.prefix.name == "route_batch" for ts in ws.processing)}
        return {"done": counts.get("memory", 0), "busy": busy, "workers": len(dask_scheduler.workers)}

    address, procs = dask_cluster
    for k, v in {"JITROUTE_OBJECT_ROOT": OBJECT_ROOT, **s3_endpoint}.items():
        monkeypatch.setenv(k, v)
    root = fleet_data_root(tmp_path, demo_mirror, n_vessels=N_VESSELS, days=60, seed=11, refit=True)
    s3 = s3fs.S3FileSystem(endpoint_url=s3_endpoint["AWS_ENDPOINT_URL"], key="testing", secret="testing")
    bucket_root = OBJECT_ROOT.removeprefix("s3://")
    assert s3.exists(f"{bucket_root}/cubes/weather.zarr/zarr.json")  # the ingest wrote the cube to the bucket
    assert not (root / "cubes" / "weather.zarr").exists()  # and nothing of it to the data root
    tag = new_tag()
    env = tagged_env(tag, JITROUTE_DASK_ADDRESS=address)  # the object root and S3 endpoint from monkeypatch
    with Client(address, timeout="30s") as client:
        client.wait_for_workers(2, timeout=60)
        pids = {procs[name].pid for name in ("worker1", "worker2")}
        assert set(client.run(os.getpid).values()) == pids
        run = subprocess.Popen([str(VENV_BIN / "jitroute"), "route-fleet", "--data", str(root), "--batch-size", "1",
                                "--solver", "gc"],
                               env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                               start_new_session=True)
        try:
            def some_done_one_busy():
                assert run.poll() is None, run.communicate()[0][-4000:]
                p = client.run_on_scheduler(batch_progress)
                assert p["done"] < N_VESSELS, "every voyage was routed before a worker could be killed"
                return p if p["done"] >= 1 and p["busy"] else None

            at_kill = poll("a routed voyage while others are being routed", some_done_one_busy, 120, 0.05)
            victim = next(iter(at_kill["busy"].values()))
            assert victim in pids
            os.kill(victim, signal.SIGKILL)
            out, _ = run.communicate(timeout=180)
        finally:
            if run.poll() is None:
                os.killpg(run.pid, signal.SIGKILL)
                run.wait()
        after = client.run_on_scheduler(batch_progress)
    left = wait_until_gone(tag, 30)
    kill_tagged(tag)
    assert not left, describe(left)
    assert run.returncode == 0, out[-4000:]
    assert after["workers"] == 1, after  # the killed one stayed dead: the other routed what it had been given

    with duckdb.connect(str(root / "warehouse.duckdb"), read_only=True) as con:
        (run_id,), = con.execute("SELECT run_id FROM route_runs WHERE status = 'ok'").fetchall()
        rows = con.execute("SELECT voyage_id, status, reason FROM routes WHERE run_id = ?", [run_id]).fetchall()
    assert len(rows) == N_VESSELS and len({v for v, _s, _r in rows}) == N_VESSELS, rows
    assert {s for _v, s, _r in rows} <= {"ok", "late"}, rows  # none "failed: routing task lost"
    assert sum(s == "ok" for _v, s, _r in rows) >= N_VESSELS - 1, rows

    s3.invalidate_cache()
    run_prefix = f"{bucket_root}/exports/runs/{run_id}"
    objects = {p[len(run_prefix) + 1:]: info["size"] for p, info in s3.find(run_prefix, detail=True).items()}
    manifest = json.loads(s3.cat_file(f"{run_prefix}/_SUCCESS"))
    assert {f["name"]: f["bytes"] for f in manifest["files"]} == {n: b for n, b in objects.items() if n != "_SUCCESS"}
    for voyage_id, _status, _reason in rows:
        for ending in (".rtz", ".geojson", ".png"):
            assert objects.get(f"voyages/{voyage_id}/{voyage_id}{ending}", 0) > 0, (voyage_id, ending, sorted(objects))
    assert objects.get("fleet_map.png", 0) > 0
    assert not s3.find(f"{bucket_root}/exports/runs/.staging-{run_id}")
    assert not (root / "exports" / "runs").exists()  # nothing of the run's exports on the local data root
    assert f"exports: {OBJECT_ROOT}/exports/runs/{run_id}" in out
