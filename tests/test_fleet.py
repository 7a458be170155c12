"""End to end: nightly (ingest → refit → route-fleet on a local dask cluster), exports, CLI, deployments."""

from __future__ import annotations

import json
import os
import signal
import threading
import time
from pathlib import Path

import duckdb
import pandas as pd
import pytest

from pipeline.synthetic.fleet import generate_fleet, write_fleet
from storage import route_store


@pytest.fixture(scope="module")
def fleet_root(tmp_path_factory, demo_mirror, prefect_harness):
    """A data root with a 4-vessel fleet (+ one voyage departing from land) after one nightly run."""
    from cli.fleet import _import_fleet
    from flows.fleet import nightly
    from storage import fleet_store

    root = tmp_path_factory.mktemp("fleet") / "data"
    root.mkdir()
    fl = generate_fleet("2020-12-01T00", n_vessels=4, days=200, seed=3)
    folder = root.parent / "fleet_csv"
    write_fleet(fl, folder)
    _import_fleet(folder, root)
    bad = fl.voyages.iloc[[0]].copy()
    bad["voyage_id"], bad["dep_name"], bad["dep_lat"], bad["dep_lon"] = "VLAND", "Tokyo city", 35.68, 139.76
    fleet_store.import_voyages(root / "warehouse.duckdb", bad)
    urls = {"rish_url": (demo_mirror / "rish").as_uri() + "/", "oscar_url": (demo_mirror / "oscar").as_uri() + "/"}
    first = nightly(date="2020-12-01", data_root=str(root), cycles="00", **urls)
    return root, fl, first, urls


def _q(root: Path, sql: str):
    with duckdb.connect(str(root / "warehouse.duckdb"), read_only=True) as con:
        return con.execute(sql).fetchdf()


def test_nightly_fills_the_tables_and_records_the_unroutable_voyage(fleet_root):
    root, fl, first, _ = fleet_root
    r = first["routing"]
    routes = _q(root, f"SELECT * FROM routes WHERE run_id = '{r['run_id']}'").set_index("voyage_id")
    assert set(routes.index) == set(fl.voyages.voyage_id) | {"VLAND"}
    assert routes.loc["VLAND", "status"] == "failed" and "on land" in routes.loc["VLAND", "reason"]
    late_id = fl.voyages.voyage_id.iloc[-1]  # the generator gives the last voyage an impossible RTA
    assert routes.loc[late_id, "status"] == "late" and "late" in routes.loc[late_id, "reason"]
    ok = routes[routes.status == "ok"]
    assert len(ok) >= 2
    assert (ok.fuel_t <= ok.baseline_fuel_t + 1e-9).all()  # never worse than the baseline it starts from
    assert (pd.to_datetime(ok.eta_utc) <= pd.to_datetime(ok.rta_utc)).all()
    legs = _q(root, f"SELECT voyage_id, count(*) n, sum(fuel_t) f FROM route_legs WHERE run_id = '{r['run_id']}' GROUP BY 1").set_index("voyage_id")
    for vid in ok.index:
        assert legs.loc[vid, "n"] == routes.loc[vid, "n_legs"]
        assert legs.loc[vid, "f"] == pytest.approx(routes.loc[vid, "fuel_t"], rel=1e-9)
    for table in ("routes", "route_legs"):
        assert (route_store.parquet_dir(root / "exports", table) / f"run_id={r['run_id']}" / "part-0.parquet").exists()
    assert Path(r["fleet_map"]).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    views = {v: len(_q(root, f"SELECT * FROM {v}")) for v in ("latest_routes", "fleet_savings", "model_quality", "ingest_health")}
    assert views["latest_routes"] == len(routes) and views["fleet_savings"] == 1 and views["model_quality"] == 8
    assert views["ingest_health"] == 1


def test_rtz_exports_validate_against_the_published_schema(fleet_root):
    from pipeline.export.rtz import validate_rtz

    root, fl, first, _ = fleet_root
    out = Path(first["routing"]["exports_dir"])
    files = sorted(out.glob("voyages/*/*.rtz"))
    assert len(files) == len(fl.voyages)  # every routed voyage, none for the failed one
    for f in files:
        validate_rtz(f.read_bytes())
    vid = fl.voyages.voyage_id.iloc[0]
    gj = json.loads((out / "voyages" / vid / f"{vid}.geojson").read_text())
    assert gj["type"] == "FeatureCollection"


def test_a_run_exports_the_operator_s_set_each_file_naming_its_run(fleet_root):
    """No BFOA convergence plot unless asked (JITROUTE_DEBUG_PLOTS); every GeoJSON route names the run that made it;
    the weather maps show the fleet's ocean at the cycle's valid time, not the globe."""
    from PIL import Image

    _root, fl, first, _ = fleet_root
    r = first["routing"]
    out = Path(r["exports_dir"])
    assert not list(out.rglob("*.convergence.png"))
    geojsons = sorted(out.glob("voyages/*/*.geojson"))
    assert len(geojsons) == len(fl.voyages)
    for f in geojsons:
        route = json.loads(f.read_text())["features"][0]["properties"]
        assert route["kind"] == "route" and route["run_id"] == r["run_id"], f
    (wind,) = out.glob("weather_wind_*.png")
    width, height = Image.open(wind).size
    assert height / width > 0.6  # the whole globe is a 2:1 strip (360 × 160 degrees); the fleet's box is not


def test_second_nightly_adds_a_run_but_no_ingest_or_fits(fleet_root):
    from flows.fleet import nightly

    root, fl, first, urls = fleet_root
    before = {t: len(_q(root, f"SELECT * FROM {t}")) for t in ("ingest_log", "perf_models", "noon_reports", "cycles")}
    second = nightly(date="2020-12-01", data_root=str(root), cycles="00", **urls)
    after = {t: len(_q(root, f"SELECT * FROM {t}")) for t in before}
    assert after == before
    assert second["ingest"][0]["skipped"] and second["models_changed"] == 0
    runs = _q(root, "SELECT run_id FROM route_runs")
    assert len(runs) == 2 and second["routing"]["run_id"] != first["routing"]["run_id"]


def test_route_cli_json_png_and_rtz(fleet_root, tmp_path):
    from typer.testing import CliRunner

    from cli.main import app
    from pipeline.export.rtz import validate_rtz

    root, fl, _, _ = fleet_root
    vid = fl.voyages.voyage_id.iloc[1]
    res = CliRunner().invoke(app, ["route", "--voyage", vid, "--data", str(root), "--json", "--png", str(tmp_path / "r.png"),
                                   "--rtz", str(tmp_path / "r.rtz"), "--solver", "bfoa", "--seed", "3"])
    assert res.exit_code == 0, res.output
    plan = json.loads(res.stdout[res.stdout.index("{"):])
    assert plan["status"] in ("ok", "late") and plan["solver"] == "bfoa" and plan["voyage_id"] == vid
    assert plan["fuel_t"] == pytest.approx(sum(g["fuel_t"] for g in plan["legs"]), rel=1e-6)
    assert plan["baseline_fuel_t"] >= plan["fuel_t"] - 1e-6
    assert (tmp_path / "r.png").read_bytes()[:4] == b"\x89PNG"
    validate_rtz((tmp_path / "r.rtz").read_bytes())


def test_route_cli_shows_the_plans_spread_across_the_cycles_it_has(fleet_root, monkeypatch):
    from typer.testing import CliRunner

    from cli.main import app

    monkeypatch.setenv("COLUMNS", "300")  # one line per sentence

    root, fl, _, _ = fleet_root
    vid = fl.voyages.voyage_id.iloc[1]
    res = CliRunner().invoke(app, ["route", "--voyage", vid, "--data", str(root), "--solver", "gc"])
    assert res.exit_code == 0, res.output
    # one complete cycle in this warehouse: a one-member ensemble, where the plan is on time as planned
    line = next(ln for ln in res.output.splitlines() if ln.startswith("uncertainty"))
    assert "across 1 forecast: on time 100 % (baseline 100 %)" in line, line
    assert "saving P10/P50/P90 0.0/0.0/0.0 %" in line  # the gc plan is the constant-speed voyage itself
    assert "within the forecast" in res.output  # the saving split of the route line
    res = CliRunner().invoke(app, ["route", "--voyage", vid, "--data", str(root), "--solver", "gc", "--ensemble", "0"])
    assert res.exit_code == 0 and "uncertainty" not in res.output


def test_route_cli_says_what_is_missing(tmp_path):
    from typer.testing import CliRunner

    from cli.main import app

    res = CliRunner().invoke(app, ["route", "--voyage", "V1", "--data", str(tmp_path / "empty")])
    assert res.exit_code == 2 and "jitroute demo" in res.output


def test_deployments_have_their_schedules_and_parameters():
    from deploy.serve import ServeError, build_deployments

    deps = {d.name: d for d in build_deployments(timezone="Europe/Oslo", nightly_cron="15 3 * * *", data_root="/srv/jit",
                                                 rish_url="http://127.0.0.1:9/rish/")}
    assert set(deps) == {"nightly", "ingest", "backfill"}
    cron = deps["nightly"].schedules[0].schedule
    assert cron.cron == "15 3 * * *" and cron.timezone == "Europe/Oslo"
    ingest = deps["ingest"].schedules[0].schedule  # anchored to publication (cycle hours + 5 h), not to serve's start
    assert ingest.cron == "0 5,11,17,23 * * *" and ingest.timezone == "UTC"
    assert "cycle" not in deps["ingest"].parameters  # default: the newest published cycle
    assert deps["backfill"].schedules == [] and deps["backfill"].parameters["route"] is False
    assert all(d.parameters["data_root"] == "/srv/jit" for d in deps.values())
    assert all(d.parameters["rish_url"] == "http://127.0.0.1:9/rish/" for d in deps.values())
    assert all(d.entrypoint.startswith("flows.") for d in deps.values())  # module path: any working directory
    cycles = deps["backfill"]._parameter_openapi_schema.properties["cycles"]
    assert {"type": "integer"} in cycles["anyOf"]  # `-p cycles=12` arrives as a JSON integer and is accepted
    with pytest.raises(ServeError, match="time zone"):
        build_deployments(timezone="Mars/Olympus")
    with pytest.raises(ServeError, match="cron"):
        build_deployments(nightly_cron="every night")


# Last in the module: it adds a route run to the shared data root.
def test_killed_worker_loses_no_voyage(fleet_root, monkeypatch):
    from distributed import Client, LocalCluster

    from flows.fleet import route_fleet

    root, fl, _, _ = fleet_root
    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None)
    client = Client(cluster)
    monkeypatch.setenv("JITROUTE_DASK_ADDRESS", cluster.scheduler_address)
    killed: list[int] = []
    stop = threading.Event()

    def kill_a_busy_worker():
        deadline = time.monotonic() + 240
        while not stop.is_set() and time.monotonic() < deadline:
            busy = [w for w, keys in client.processing().items() if keys]
            if busy:
                pid = client.run(os.getpid, workers=[busy[0]])[busy[0]]
                os.kill(pid, signal.SIGKILL)
                killed.append(pid)
                return
            stop.wait(0.02)

    killer = threading.Thread(target=kill_a_busy_worker, daemon=True)
    killer.start()
    try:
        summary = route_fleet(cycle="2020-12-01T00", data_root=str(root), solver="dp", exports=False)
    finally:
        stop.set()
        killer.join(10)
        client.close()
        cluster.close()
    assert killed, "no worker was busy long enough to be killed"
    with duckdb.connect(str(root / "warehouse.duckdb"), read_only=True) as con:
        rows = con.execute("SELECT voyage_id, status, reason FROM routes WHERE run_id = ?", [summary["run_id"]]).fetchall()
    ids = {r[0] for r in rows}
    assert ids == set(fl.voyages.voyage_id) | {"VLAND"}
    for vid, status, reason in rows:
        assert status in ("ok", "late") or vid == "VLAND" or "routing task lost" in (reason or ""), (vid, status, reason)


def test_batches_are_sized_from_the_cluster_and_capped():
    from flows.jobs import dask_pool

    assert dask_pool.voyages_per_batch(12, 2, None) == 2  # about three batches per worker thread
    assert dask_pool.voyages_per_batch(1000, 2, None) == dask_pool.MAX_VOYAGES_PER_BATCH  # not 167 held in a worker
    assert dask_pool.voyages_per_batch(1000, 2, 50) == 50  # an explicit setting wins
    jobs = list(range(40))
    batches = dask_pool.batches(jobs, 16, length_nm=lambda j: j)
    assert sorted(j for b in batches for j in b) == jobs and max(map(len, batches)) <= 16
    assert [b[0] for b in batches] == [39, 38, 37]  # the longest voyages dealt first, one to each batch


def test_a_routing_batch_stops_the_dask_workers_task_profiler():
    """The profiler of a `dask worker` (on by default) kept a profile per second of routing; the first batch stops it."""
    from distributed import Client, LocalCluster

    from flows.jobs.route_worker import route_batch, stop_task_profiler

    assert stop_task_profiler() is False  # not in a dask worker: nothing to do
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        def profiling(dask_worker):
            return sorted({"profile", "profile-cycle"} & set(dask_worker.periodic_callbacks))

        assert list(client.run(profiling).values()) == [["profile", "profile-cycle"]]  # dask's default
        assert client.submit(route_batch, [], None, pure=False).result() == []  # an empty batch still stops it
        assert list(client.run(profiling).values()) == [[]]
        assert client.submit(stop_task_profiler, pure=False).result() is False  # already off


def test_a_local_cluster_leaves_no_process_behind():
    """The local cluster's worker processes start multiprocessing's resource tracker in the routing process; left
    running, it outlived the command by a moment. Closing the cluster stops and reaps it."""
    from multiprocessing import resource_tracker

    from flows.jobs.dask_pool import dask_client

    with dask_client(None, 1) as client:
        assert client.submit(sum, [1, 2], pure=False).result() == 3
        tracker = resource_tracker._resource_tracker._pid
    assert tracker is not None  # the workers started it
    assert resource_tracker._resource_tracker._pid is None
    with pytest.raises(ChildProcessError):  # stopped and reaped: no such child any more
        os.waitpid(tracker, os.WNOHANG)


def test_a_failure_inside_the_cluster_is_recorded_before_the_cluster_closes():
    """A SIGTERM gives the run a few seconds to unwind; closing a local cluster can take most of them on a busy
    machine, so the failure's record (on_error) comes first, while the workers still run."""
    from flows.jobs.dask_pool import dask_client

    seen = []

    def on_error(exc):
        seen.append((type(exc).__name__, client.status, client.submit(sum, [2, 3], pure=False).result()))

    with pytest.raises(SystemExit):
        with dask_client(None, 1, on_error=on_error) as client:
            raise SystemExit(143)
    assert seen == [("SystemExit", "running", 5)]
    assert client.status == "closed"
