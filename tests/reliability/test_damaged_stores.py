"""Stores damaged on disk, found and repaired: a real Zarr cube missing its `zarr.json` or holding a corrupt
chunk, a corrupt `warehouse.duckdb`; and `latest_routes` when a newer routing attempt failed."""

from __future__ import annotations

import logging
import os
import re
import shutil
import subprocess
import sys

import duckdb
import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from cli.main import app
from schemas.tables.routes import ROUTES
from storage import cube, route_store
from storage.layout import DataLayout
from storage.cube_location import CorruptChunkError
from tests.reliability.conftest import CYCLE, REPO, assert_same_cube, child_env, file_urls

C = np.datetime64(CYCLE, "ns")


@pytest.fixture(autouse=True)
def quiet(monkeypatch):
    monkeypatch.setenv("COLUMNS", "400")
    monkeypatch.setattr(logging, "raiseExceptions", False)


def _cli(*args: str) -> tuple[int, str]:
    result = CliRunner().invoke(app, list(args))
    if result.exception and not isinstance(result.exception, SystemExit):
        raise result.exception
    return result.exit_code, re.sub(r"\s+", " ", result.output)


@pytest.fixture
def root(clean_root, tmp_path):
    dst = tmp_path / "data"
    shutil.copytree(clean_root, dst)
    return dst


def test_a_deleted_zarr_json_is_named_moved_aside_and_rebuilt(root, small_mirror, ingest, clean_cube):
    store = DataLayout(root).weather_cube
    (store / "zarr.json").unlink()
    # an ingest no longer fails on a rename with advice about disk space, nor leaves weather.zarr.creating
    with pytest.raises(cube.CubeError, match=r"the store is damaged \(weather.zarr/zarr.json is missing\).*jitroute cube repair"):
        ingest(root, *file_urls(small_mirror), force=True)
    assert not store.with_name("weather.zarr.creating").exists()
    with pytest.raises(cube.CubeError, match="weather.zarr/zarr.json is missing"):
        cube.open_cube(store)
    code, out = _cli("cube", "check", "--data", str(root))
    assert code == 1 and "damaged: weather.zarr/zarr.json is missing" in out and "jitroute cube repair" in out, out
    rish, oscar = file_urls(small_mirror)
    code, out = _cli("cube", "repair", "--data", str(root), "--rish-url", rish, "--oscar-url", oscar)
    assert code == 0 and "moved the damaged store aside" in out and f"re-ingested {CYCLE}: complete" in out, out
    aside = [p for p in store.parent.iterdir() if p.name.startswith("weather.zarr.damaged-")]
    assert len(aside) == 1 and (aside[0] / "u10").is_dir()  # kept for inspection
    assert_same_cube(store, clean_cube)
    code, out = _cli("cube", "check", "--data", str(root))
    assert code == 0 and "ok:" in out, out


def _spoil_chunk(store, var="u10", key="0/0/1/1"):
    chunk = store / var / "c" / key
    assert chunk.is_file()
    data = bytearray(chunk.read_bytes())
    data[len(data) // 2:] = np.random.default_rng(3).bytes(len(data) - len(data) // 2)
    chunk.write_bytes(bytes(data))
    return chunk


def _chunk_key(store, var, *, lat, lon, cycle_index=0):
    """The key (`i/0/j/k`) of the chunk of `var` holding the point."""
    import zarr

    arr = zarr.open_array(str(store / var), mode="r")
    grid = xr.open_zarr(store, consolidated=False)
    j = int(np.argmin(np.abs(grid["lat"].values - lat))) // arr.chunks[2]
    k = int(np.argmin(np.abs(grid["lon"].values - lon))) // arr.chunks[3]
    return f"{cycle_index}/0/{j}/{k}"


def test_a_corrupt_chunk_is_named_with_its_cycle_and_the_re_ingest_that_fixes_it(root, small_mirror, ingest, clean_cube):
    store = DataLayout(root).weather_cube
    chunk = _spoil_chunk(store)
    with pytest.raises(CorruptChunkError) as exc:
        cube.load_cycle(store, C)
    msg = str(exc.value)
    assert msg.startswith(f"cube chunk {chunk} of cycle {CYCLE} is corrupt"), msg
    assert msg.endswith(f"run `jitroute ingest --cycle {CYCLE} --force`"), msg
    code, out = _cli("cube", "check", "--data", str(root))
    assert code == 1 and f"corrupt chunk: {chunk} (u10, cycle {CYCLE})" in out, out
    assert ingest(root, *file_urls(small_mirror), force=True)["complete"]  # the advice works
    assert_same_cube(store, clean_cube)


def test_cube_repair_hides_a_cycle_with_a_corrupt_chunk_and_re_ingests_it(root, small_mirror, fast_settings, prefect_harness,
                                                                        clean_cube):
    store = DataLayout(root).weather_cube
    _spoil_chunk(store, "swh", "0/0/2/0")
    code, out = _cli("cube", "repair", "--data", str(root), "--no-rebuild")
    assert code == 0 and f"hid 1 cycle(s) with corrupt chunks: {CYCLE}" in out and f"jitroute ingest --cycle {CYCLE} --force" in out
    assert cube.complete_cycles(store) == [] and cube.open_cube(store).sizes["cycle"] == 0  # readers no longer meet it
    rish, oscar = file_urls(small_mirror)
    code, out = _cli("cube", "repair", "--data", str(root), "--rish-url", rish, "--oscar-url", oscar)
    assert code == 0 and f"re-ingested {CYCLE}: complete" in out, out  # still found while hidden, rebuilt now
    assert_same_cube(store, clean_cube)


def _corrupt_blocks(path):
    data = bytearray(path.read_bytes())
    for k in range(4096, len(data), 7):
        data[k] ^= 0xFF
    path.write_bytes(bytes(data))


@pytest.mark.parametrize("damage", ["garbage", "blocks"])
def test_a_corrupt_warehouse_gives_one_line_naming_the_file_and_the_snapshot(root, damage, prefect_harness):
    db = DataLayout(root).warehouse
    if damage == "garbage":
        db.write_bytes(np.random.default_rng(5).bytes(db.stat().st_size))
    else:
        _corrupt_blocks(db)
    proc = subprocess.run([sys.executable, "-m", "cli.main", "refit", "--data", str(root)], cwd=REPO, env=child_env(),
                          capture_output=True, text=True, timeout=300)
    err = [line for line in proc.stderr.splitlines() if line.startswith("error:")]
    assert proc.returncode == 2, proc.stderr[-3000:]
    assert "Traceback" not in proc.stderr and "Traceback" not in proc.stdout, proc.stderr[-3000:]
    assert len(err) == 1 and f"warehouse {db} is damaged" in err[0], proc.stderr[-3000:]
    assert f"cp {DataLayout(root).warehouse_snapshot} {db}" in err[0]
    os.replace(db, db.with_name("warehouse.duckdb.damaged"))  # the advice works
    shutil.copyfile(DataLayout(root).warehouse_snapshot, db)
    con = duckdb.connect(str(db), read_only=True)
    assert con.execute("SELECT count(*) FROM cycles WHERE complete").fetchone()[0] == 1
    con.close()


# --- latest_routes -------------------------------------------------------------------------------------------------


def _row(vid, status, fuel, reason=None):
    return ROUTES.empty_row(**{"voyage_id": vid, "imo": 9140607, "solver": "bfoa", "objective": "jit", "status": status, "reason": reason,
            "depart_utc": "2020-12-01T06:00Z", "eta_utc": "2020-12-03T06:00Z" if fuel else None, "rta_utc": "2020-12-03T06:00Z",
            "hours": 48.0 if fuel else None, "fuel_t": fuel, "baseline_fuel_t": 100.0 if fuel else None, "cycle": "2020-12-01T00Z",
            "seed": 1, "n_legs": 2 if fuel else 0, "n_legs_beyond_forecast": 0})


def test_latest_routes_keeps_the_last_good_plan_and_flags_a_later_failure(tmp_path):
    db = tmp_path / "w.duckdb"
    runs = [("r1", [_row("V1", "ok", 90.0), _row("V2", "ok", 80.0), _row("V3", "failed", None, "on land")]),
            ("r2", [_row("V1", "late", 95.0, "late by 2.0 h"), _row("V2", "failed", None, "no weather: cycle missing")]),
            ("r3", [_row("V1", "infeasible", None, "no route at sea within the limits"), _row("V3", "failed", None, "still on land")])]
    for run_id, rows in runs:
        route_store.begin_run(db, run_id, cycle="2020-12-01T00", solver="bfoa", trigger="manual", n_voyages=len(rows))
        route_store.write_run_results(db, tmp_path / "exports", run_id, rows, [])
    con = duckdb.connect(str(db), read_only=True)
    got = {r[0]: r[1:] for r in con.execute(
        "SELECT voyage_id, run_id, status, fuel_t, newer_attempt_failed, newer_attempt_run_id, newer_attempt_status, "
        "newer_attempt_reason FROM latest_routes ORDER BY voyage_id").fetchall()}
    con.close()
    assert got == {
        "V1": ("r2", "late", 95.0, True, "r3", "infeasible", "no route at sea within the limits"),  # a late plan is a plan
        "V2": ("r1", "ok", 80.0, True, "r2", "failed", "no weather: cycle missing"),
        "V3": ("r3", "failed", None, False, None, None, None),  # never planned: its newest attempt, not flagged
    }


def test_a_plain_ingest_re_ingests_a_complete_cycle_whose_chunk_is_corrupt(root, small_mirror, ingest, clean_cube):
    store = DataLayout(root).weather_cube
    _spoil_chunk(store, "v10", "0/0/0/2")
    report = ingest(root, *file_urls(small_mirror))  # no --force: "complete" is not taken on trust
    assert report["complete"] and not report.get("skipped"), report
    assert_same_cube(store, clean_cube)
    assert ingest(root, *file_urls(small_mirror))["skipped"]  # whole again: the next run skips it


def test_routing_on_a_corrupt_chunk_fails_the_voyage_with_the_chunk_and_the_fix(root):
    from flows.jobs.route_worker import route_one, window_field
    from pipeline.routing.job import RouteJob, RoutingOptions

    store = DataLayout(root).weather_cube
    _spoil_chunk(store, "u10", _chunk_key(store, "u10", lat=32.0, lon=142.0))  # under the voyage: its window reads it
    window_field.cache_clear()
    voyage = {"voyage_id": "VCHUNK", "imo": 1, "dep_lat": 34.0, "dep_lon": 140.0, "arr_lat": 30.0, "arr_lon": 145.0,
              "depart_utc": np.datetime64("2020-12-01T02"), "rta_utc": np.datetime64("2020-12-02T12"), "rpm_options": [70, 80]}
    from tests.reliability.test_routing_faults import MODEL

    res = route_one(RouteJob(voyage=voyage, vessel={"rpm_max": 100}, model=MODEL.to_json(), run_id="r1",
                             cycle=str(C)[:19], exports=False, options=RoutingOptions(n_lines=6, n_points=7)), str(store))
    row = res["route"]
    assert row["status"] == "failed" and "unexpected" not in row["reason"], row["reason"]
    assert f"of cycle {CYCLE} is corrupt" in row["reason"] and f"jitroute ingest --cycle {CYCLE} --force" in row["reason"]
