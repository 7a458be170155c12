"""The command line as users run it: subprocesses of the installed `jitroute`, on a busy machine, killed
mid-run, with bad input; checked for lost voyages, half-published exports and processes left behind."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import duckdb
import pytest

from tests.conftest import fleet_data_root
from tests.processes import VENV_BIN, describe, jitroute, kill_tagged, new_tag, tagged_env, wait_until_gone


@pytest.fixture(scope="module")
def routed_root(tmp_path_factory, demo_mirror) -> Path:
    """A data root with the 2020-12-01T00 cycle, a 3-vessel fleet and fitted models; made with plain jobs (no Prefect)."""
    return fleet_data_root(tmp_path_factory.mktemp("operable"), demo_mirror, n_vessels=3, days=150, seed=11, refit=True)


def _copy(root: Path, dest: Path) -> Path:
    shutil.copytree(root, dest, ignore=shutil.ignore_patterns("locks", "exports"))
    return dest


def _sql(root: Path, query: str):
    with duckdb.connect(str(root / "warehouse.duckdb"), read_only=True) as con:
        return con.execute(query).fetchall()


@pytest.mark.parametrize("args, says", [
    (["route", "--from", "35.3,139.8", "--to", "13.45,144.55", "--depart", "2020-13-01T13", "--rta", "2020-12-05T12",
      "--imo", "9140607"], "--depart '2020-13-01T13' is not a UTC time"),
    (["route", "--from", "139.8,35.3", "--to", "13.45,144.55", "--depart", "2020-12-01T13", "--rta", "2020-12-05T12",
      "--imo", "9140607"], "did you give LON,LAT"),
    (["backfill", "--start", "2020-12-01", "--end", "2020-1203"], "cannot read end '2020-1203'"),
    (["nightly", "--date", "2020-12-1x"], "cannot read date '2020-12-1x'"),
    (["ingest", "--cycle", "2020-12-01T25"], "cannot read cycle"),
    (["refit", "--imo", "1234567"], "vessel(s) 1234567 not in"),
    (["route-fleet", "--cycle", "2019-01-01T00"], "not in the cube"),
    (["noon", "import", "no-such-file.csv"], "no such file"),
])
def test_bad_input_gets_one_line_and_exit_2(routed_root, args, says):
    r = jitroute(*args, "--data", str(routed_root), env=tagged_env(new_tag()), timeout_s=120)
    assert r.returncode == 2, (r.stdout, r.stderr)
    assert "Traceback" not in r.stderr + r.stdout
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:") and says in lines[0], r.stderr


def test_tables_are_not_cut_when_output_is_not_a_terminal(routed_root):
    r = jitroute("refit", "--data", str(routed_root), env=tagged_env(new_tag()), timeout_s=120)
    assert r.returncode == 0, r.stderr
    widest = max(len(line) for line in r.stdout.splitlines())
    assert widest > 100 and "…" not in r.stdout, r.stdout  # rich would cut to 80 columns with "…"


def test_interactive_commands_import_no_prefect_without_an_api(routed_root, tmp_path):
    """No configured Prefect API: the quick commands run as plain functions (no temporary server)."""
    root = _copy(routed_root, tmp_path / "data")
    code = (
        "import sys\n"
        "from cli.main import app\n"
        "for argv in (['refit', '--data', sys.argv[1]], ['route', '--voyage', 'V20001', '--data', sys.argv[1], '--calm',"
        " '--solver', 'gc']):\n"
        "    try:\n"
        "        app(argv)\n"
        "    except SystemExit as e:\n"
        "        assert e.code in (0, None), (argv, e.code)\n"
        "print('PREFECT_IMPORTED' if 'prefect' in sys.modules else 'NO_PREFECT')\n"
    )
    env = tagged_env(new_tag(), PREFECT_HOME=str(tmp_path / "no_prefect_home"))
    r = subprocess.run([sys.executable, "-c", code, str(root)], env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    assert r.stdout.strip().endswith("NO_PREFECT"), r.stdout[-2000:]


def test_with_a_prefect_api_a_command_is_recorded_as_a_flow_run(routed_root, tmp_path, prefect_harness):
    import prefect.settings
    from prefect.client.orchestration import get_client
    from prefect.client.schemas.filters import FlowFilter, FlowFilterName

    root = _copy(routed_root, tmp_path / "data")
    api = str(prefect.settings.PREFECT_API_URL.value())
    r = jitroute("refit", "--data", str(root), env=tagged_env(new_tag(), PREFECT_API_URL=api), timeout_s=300)
    assert r.returncode == 0, r.stderr[-3000:]
    with get_client(sync_client=True) as client:
        runs = client.read_flow_runs(flow_filter=FlowFilter(name=FlowFilterName(any_=["refit-performance"])))
    assert any(run.state_type.value == "COMPLETED" for run in runs)


def test_route_fleet_on_a_busy_machine_loses_no_voyage_and_leaves_no_process(routed_root, tmp_path):
    root = _copy(routed_root, tmp_path / "data")
    busy_tag, tag = new_tag(), new_tag()
    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"], env=tagged_env(busy_tag)) for _ in range(2)]
    try:
        r = jitroute("route-fleet", "--data", str(root), env=tagged_env(tag, JITROUTE_DASK_WORKERS="2"), timeout_s=600)
    finally:
        for h in hogs:
            h.kill()
            h.wait()
    assert r.returncode == 0, r.stderr[-3000:]
    rows = _sql(root, "SELECT voyage_id, status, reason FROM routes")
    assert len(rows) == 3
    assert all(status in ("ok", "late") for _v, status, _r in rows), rows
    assert not [line for line in r.stderr.splitlines() if "Traceback" in line or "already in use" in line
                or "leaked semaphore" in line or "still alive" in line], r.stderr[-3000:]
    left = wait_until_gone(tag, 30)
    kill_tagged(tag)
    assert not left, describe(left)


def test_a_killed_run_is_marked_failed_by_the_next_command_and_publishes_nothing(routed_root, tmp_path):
    root = _copy(routed_root, tmp_path / "data")
    tag = new_tag()
    proc = subprocess.Popen([str(VENV_BIN / "jitroute"), "route-fleet", "--data", str(root)],
                            env=tagged_env(tag, JITROUTE_DASK_WORKERS="1"), stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, start_new_session=True)
    staged = None
    deadline = time.monotonic() + 240
    for line in proc.stdout:  # kill it once the first voyage's exports are staged
        runs = root / "exports" / "runs"
        staged = next(iter(runs.glob(".staging-*")), None) if runs.exists() else None
        if staged is not None and any(staged.iterdir()) or "routed 1/" in line:
            break
        assert time.monotonic() < deadline, "route-fleet never routed a voyage"
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    kill_tagged(tag)
    run_id, status = _sql(root, "SELECT run_id, status FROM route_runs")[0]
    assert status == "running"  # nobody has looked yet
    # the batches stored before the kill are kept, each voyage once, with exactly their legs (a legs file written
    # for a batch that never committed is not shown)
    n, distinct, n_legs = _sql(root, "SELECT count(*), count(DISTINCT voyage_id), coalesce(sum(n_legs), 0) FROM routes")[0]
    assert n == distinct <= 3
    assert _sql(root, "SELECT count(*) FROM route_legs")[0][0] == n_legs
    r = jitroute("route-fleet", "--data", str(root), "--voyage", "V20001", "--solver", "gc",
                 env=tagged_env(tag, JITROUTE_DASK_WORKERS="1"), timeout_s=300)
    assert r.returncode == 0, r.stderr[-3000:]
    status, reason = _sql(root, f"SELECT status, reason FROM route_runs WHERE run_id = '{run_id}'")[0]
    assert status == "failed" and "process died" in reason and "pid" in reason
    runs = root / "exports" / "runs"
    assert not (runs / run_id).exists() and not list(runs.glob(".staging-*"))
    published = [p.name for p in runs.iterdir()]
    assert len(published) == 1 and (runs / published[0] / "voyages" / "V20001" / "V20001.rtz").exists()
    left = wait_until_gone(tag, 30)
    kill_tagged(tag)
    assert not left, describe(left)


def test_a_run_that_fails_after_some_batches_keeps_them_once_and_publishes_nothing(routed_root, tmp_path, monkeypatch):
    """Each batch is stored as it finishes; the run then fails (the store of the shortest voyage's batch, routed
    last, raises): the batches stored before stay, each voyage once, in the tables and the Parquet exports; the run
    is failed and publishes no files; storing a stored batch again adds nothing."""
    import pandas as pd

    from flows.jobs.fleet import route_fleet_job
    from storage import route_store

    import flows.jobs.fleet as fleet

    root = _copy(routed_root, tmp_path / "data")
    monkeypatch.setenv("JITROUTE_DASK_WORKERS", "1")
    settings = fleet.load_settings  # every batch stored as soon as it finishes
    monkeypatch.setattr(fleet, "load_settings", lambda **kw: settings(**kw, **{"routing.store_every_s": 0.0}))
    last = _sql(root, "SELECT voyage_id FROM voyages ORDER BY (arr_lat - dep_lat)^2 + (arr_lon - dep_lon)^2 LIMIT 1")[0][0]
    real, calls = route_store.write_batch, []

    def store_then_fail_on_the_last(*args):
        if last in {r["voyage_id"] for r in args[3]}:
            raise OSError(f"disk gone while storing {last}")
        calls.append((args, real(*args)))
        return calls[-1][1]

    monkeypatch.setattr(route_store, "write_batch", store_then_fail_on_the_last)
    with pytest.raises(OSError, match="disk gone"):
        route_fleet_job(cycle="2020-12-01T00", data_root=str(root), solver="gc", batch_size=1)
    stored = sorted(v for _args, ids in calls for v in ids)
    assert stored and last not in stored and len(set(stored)) == len(stored)
    run_id, status, reason = _sql(root, "SELECT run_id, status, reason FROM route_runs")[0]
    assert status == "failed" and "disk gone" in reason
    assert sorted(v for (v,) in _sql(root, "SELECT voyage_id FROM routes")) == stored
    n_legs = _sql(root, "SELECT sum(n_legs) FROM routes")[0][0]
    assert n_legs > 0 and _sql(root, "SELECT count(*) FROM route_legs")[0][0] == n_legs
    parts = sorted(route_store.parquet_dir(root / "exports", "routes").glob(f"run_id={run_id}/*.parquet"))
    assert [p.name for p in parts] == [f"part-{k}.parquet" for k in range(len(calls))]
    assert sorted(pd.concat([pd.read_parquet(p) for p in parts])["voyage_id"]) == stored
    runs = root / "exports" / "runs"
    assert not (runs / run_id).exists() and not list(runs.glob(".staging-*"))
    # the first batch stored again (a retried step): nothing added, no new file
    assert real(*calls[0][0]) == []
    assert sorted(v for (v,) in _sql(root, "SELECT voyage_id FROM routes")) == stored
    assert _sql(root, "SELECT count(*) FROM route_legs")[0][0] == n_legs
    assert len(list(parts[0].parent.glob("*.parquet"))) == len(calls)


def test_a_failed_export_is_counted_and_the_others_still_written(routed_root, tmp_path, monkeypatch):
    from flows.jobs.fleet import route_fleet_job

    root = _copy(routed_root, tmp_path / "data")
    monkeypatch.setenv("JITROUTE_RTZ_SCHEMAS", str(tmp_path / "no_schemas_here"))  # every RTZ export fails (workers inherit it)
    monkeypatch.setenv("JITROUTE_DASK_WORKERS", "1")
    summary = route_fleet_job(cycle="2020-12-01T00", data_root=str(root), solver="gc")
    rows = _sql(root, "SELECT voyage_id, status, reason FROM routes")
    assert {s for _v, s, _r in rows} <= {"ok", "late"}
    assert not any("export" in (reason or "") for _v, _s, reason in rows)  # the route stands; its reason is about the route
    assert len(summary["export_failures"]) == 3 and all(": rtz: " in e for e in summary["export_failures"])
    out = Path(summary["exports_dir"])
    assert not list(out.glob("voyages/*/*.rtz"))
    assert len(list(out.glob("voyages/*/*.geojson"))) == 3 and len(list(out.glob("voyages/V*/V*.png"))) >= 3
    assert _sql(root, "SELECT n_export_failed FROM fleet_savings")[0][0] == 3


def test_serve_without_a_reachable_prefect_api_refuses_in_one_line(tmp_path):
    from tests.processes import free_port

    home = tmp_path / "prefect_home"  # no profile: no API configured
    for extra in ({}, {"PREFECT_API_URL": f"http://127.0.0.1:{free_port()}/api"}):
        r = jitroute("serve", env=tagged_env(new_tag(), PREFECT_HOME=str(home), **extra), timeout_s=120)
        lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
        assert r.returncode == 2 and len(lines) == 1, r.stderr
        assert "prefect server start" in lines[0] and "PREFECT_API_URL" in lines[0]


def test_a_second_job_on_the_same_data_root_waits_and_says_for_whom(tmp_path):
    from storage.run_lock import job_lock

    holder = subprocess.Popen([sys.executable, "-c",
                               "import sys, time\n"
                               "from storage.run_lock import job_lock\n"
                               "with job_lock(sys.argv[1], 'nightly (2020-12-01T00)'):\n"
                               "    print('HELD', flush=True); sys.stdin.readline()\n", str(tmp_path / "locks")],
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "HELD"
        said = []
        with pytest.raises(TimeoutError, match=r"nightly \(2020-12-01T00\) \(host .*, pid \d+"):
            with job_lock(tmp_path / "locks", "ingest 2020-12-01T06", say=said.append, poll_s=0.05, wait_s=0.5):
                pass
        assert len(said) == 1 and said[0].startswith("waiting for nightly (2020-12-01T00)")
    finally:
        holder.communicate("\n", timeout=30)
    with job_lock(tmp_path / "locks", "ingest 2020-12-01T06", wait_s=5):  # free again once the holder ends
        with job_lock(tmp_path / "locks", "the nightly's own ingest", wait_s=0):  # re-entrant within a process
            pass


def test_weather_map_command_draws_a_step_and_refuses_what_does_not_exist(routed_root, tmp_path):
    env = tagged_env(new_tag())
    r = jitroute("weather", "map", "--var", "wind", "--step", "24", "--out", str(tmp_path / "w.png"), "--data",
                 str(routed_root), env=env, timeout_s=180)
    assert r.returncode == 0, r.stderr[-2000:]
    assert (tmp_path / "w.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    for args, says in ((["--var", "rain"], "is not one of wind, waves, currents"), (["--step", "7"], "has no step 7 h"),
                       (["--cycle", "2019-01-01T00"], "is not in the cube")):
        r = jitroute("weather", "map", *args, "--data", str(routed_root), env=env, timeout_s=180)
        assert r.returncode == 2 and says in r.stderr and "Traceback" not in r.stderr, r.stderr


def test_sigterm_stops_route_fleet_cleanly_and_leaves_no_process(routed_root, tmp_path):
    root = _copy(routed_root, tmp_path / "data")
    tag = new_tag()
    proc = subprocess.Popen([str(VENV_BIN / "jitroute"), "route-fleet", "--data", str(root), "--batch-size", "1"],
                            env=tagged_env(tag, JITROUTE_DASK_WORKERS="1"), stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    for line in proc.stdout:  # stop it once it is routing
        if "routed 1/" in line:
            break
    t0 = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    out, _ = proc.communicate(timeout=60)
    assert proc.returncode == 143, out[-3000:]
    assert time.monotonic() - t0 < 15, "route-fleet took too long to stop after SIGTERM"
    left = wait_until_gone(tag, 20)
    kill_tagged(tag)
    assert not left, describe(left)
    status, reason = _sql(root, "SELECT status, reason FROM route_runs")[0]
    assert status == "failed" and reason, (status, reason)
    assert _sql(root, "SELECT count(*) FROM routes")[0][0] == 0  # all or nothing
    runs = root / "exports" / "runs"
    assert not runs.exists() or not any(runs.iterdir()), list(runs.iterdir())


def test_a_run_s_weather_maps_leave_the_chunk_cache_to_the_voyages(routed_root):
    """The run's weather maps are drawn in a routing worker: their read of the whole grid bypasses the worker's
    chunk cache, which a voyage's window read fills."""
    import numpy as np

    from flows.jobs import weather_maps
    from storage import cube_window

    store, cycle = routed_root / "cubes" / "weather.zarr", np.datetime64("2020-12-01T00", "ns")
    before = cube_window.CHUNK_CACHE.stats()["fetched_bytes"]
    maps = weather_maps.run_maps_png(store, cycle)
    assert set(maps) == {"waves", "wind"} and all(png[:8] == b"\x89PNG\r\n\x1a\n" for png in maps.values())
    assert cube_window.CHUNK_CACHE.stats()["fetched_bytes"] == before
    weather_maps.step_fields(store, cycle, 0, stride=2)  # the same read through the cache
    assert cube_window.CHUNK_CACHE.stats()["fetched_bytes"] > before
