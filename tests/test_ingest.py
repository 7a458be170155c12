"""End-to-end ingest through the real flow: HTTP mirror on 127.0.0.1 → raw store → Zarr cube."""

import shutil
import subprocess
import sys
import threading
from pathlib import Path

import duckdb
import numpy as np
import pytest
import xarray as xr

from flows.ingest import ingest_weather
from pipeline.synthetic import weather
from schemas import cube_variables
from storage import cube
from storage.layout import DataLayout
from tests.http_mirror import serve

CYCLE = "2020-12-01T00"
T0 = weather.hours_since_epoch(np.datetime64(CYCLE))


def _ingest(root, mirror_url_rish, mirror_url_oscar, **kw):
    return ingest_weather(CYCLE, data_root=str(root), rish_url=mirror_url_rish, oscar_url=mirror_url_oscar, **kw)


@pytest.fixture(scope="module")
def ingested(demo_mirror, tmp_path_factory, prefect_harness):
    root = tmp_path_factory.mktemp("ingested") / "data"
    with serve(demo_mirror) as (url, _):
        report = _ingest(root, url + "rish/", url + "oscar/")
    return root, report


def test_http_ingest_matches_the_analytic_fields(ingested):
    root, report = ingested
    assert report["complete"] and report["n_ok"] == report["n_expected"] == 23 + 2 + 2
    ds = cube.load_cycle(DataLayout(root).weather_cube, CYCLE)
    for step, lat, lon in [(0, 35.0, 160.0), (36, -20.0, 75.5), (132, 45.5, 200.0)]:
        u, v = weather.wind_uv(T0 + step, lat, lon)
        swh, mwd, mwp = weather.waves(T0 + step, lat, lon)
        p = ds.sel(step=np.timedelta64(step, "h"), lat=lat, lon=lon)
        assert float(p.u10) == pytest.approx(float(u), abs=0.01)
        assert float(p.v10) == pytest.approx(float(v), abs=0.01)
        assert float(p.swh) == pytest.approx(float(swh), abs=0.01)
        assert float(p.mwp) == pytest.approx(float(mwp), abs=0.01)
    # currents: the OSCAR grid is 1/3°, the cube 0.5°: bilinear error on a smooth jet is small
    cu, cv = weather.currents_uv(T0, 33.0, 135.0)
    assert float(ds.uo.sel(step=np.timedelta64(0, "h"), lat=33.0, lon=135.0)) == pytest.approx(float(cu), abs=0.05)
    assert np.isnan(float(ds.swh.sel(step=np.timedelta64(0, "h"), lat=36.0, lon=138.5)))  # land
    assert not list(Path(root).rglob("*.idx"))


def test_ingest_log_records_every_file(ingested):
    root, _ = ingested
    con = duckdb.connect(str(DataLayout(root).warehouse_snapshot), read_only=True)
    rows = con.execute("SELECT source, status, count(*), min(bytes), count(DISTINCT sha256) FROM ingest_log GROUP BY ALL ORDER BY 1").fetchall()
    assert [(r[0], r[1], r[2]) for r in rows] == [("GSM", "ok", 23), ("GWM", "ok", 2), ("OSCAR", "ok", 2)]
    assert all(r[3] > 1000 and r[4] == r[2] for r in rows)
    assert con.execute("SELECT complete FROM cycles").fetchall() == [(True,)]


def test_second_ingest_is_skipped_and_forced_reingest_is_identical(ingested, demo_mirror):
    root, _ = ingested
    store = DataLayout(root).weather_cube
    before = xr.open_zarr(store, consolidated=False).load()
    version = cube.cycle_versions(store)[np.datetime64(CYCLE, "ns")]
    again = _ingest(root, f"file://{demo_mirror}/rish/", f"file://{demo_mirror}/oscar/")
    assert again["skipped"]
    assert cube.cycle_versions(store)[np.datetime64(CYCLE, "ns")] == version  # a skipped ingest publishes nothing
    forced = _ingest(root, f"file://{demo_mirror}/rish/", f"file://{demo_mirror}/oscar/", force=True)
    assert forced["complete"]
    after = xr.open_zarr(store, consolidated=False).load()
    assert after.sizes["cycle"] == 1
    assert cube.cycle_versions(store)[np.datetime64(CYCLE, "ns")] > version  # re-written: readers must read it again
    for ds in (before, after):
        ds.attrs.pop("cycle_versions")
    xr.testing.assert_identical(before, after)  # file:// gives the same cube as http://


def test_missing_and_corrupt_files_make_an_incomplete_cycle_then_a_rerun_repairs_it(demo_mirror, tmp_path, prefect_harness):
    mirror = tmp_path / "mirror"
    shutil.copytree(demo_mirror, mirror)
    day = mirror / "rish" / "2020" / "12" / "01"
    gsm36 = day / "Z__C_RJTD_20201201000000_GSM_GPV_Rgl_FD0112_grib2.bin"
    good = gsm36.read_bytes()
    gsm36.write_bytes(good[:100] + b"\x00garbage" * 50)
    root = tmp_path / "data"
    with serve(mirror, {"Z__C_RJTD_20201201000000_GSM_GPV_Rgl_FD0200_grib2.bin": "404"}) as (url, _):
        r = _ingest(root, url + "rish/", url + "oscar/")
        assert not r["complete"]
        assert r["corrupt"] == [gsm36.name]
        store = DataLayout(root).weather_cube
        assert cube.complete_cycles(store) == []
        ds = cube.open_cube(store).sel(cycle=np.datetime64(CYCLE, "ns"))
        assert np.isnan(ds.u10.sel(step=np.timedelta64(36, "h")).values).all() and np.isnan(ds.u10.sel(step=np.timedelta64(48, "h")).values).all()
        assert not np.isnan(ds.u10.sel(step=np.timedelta64(42, "h")).values).all()
        assert len(list((root / "quarantine" / "gsm").iterdir())) == 1
        con = duckdb.connect(str(DataLayout(root).warehouse_snapshot), read_only=True)
        statuses = dict(con.execute("SELECT file_name, status FROM ingest_log").fetchall())
        con.close()
        assert statuses[gsm36.name] == "corrupt" and statuses["Z__C_RJTD_20201201000000_GSM_GPV_Rgl_FD0200_grib2.bin"] == "missing"
    gsm36.write_bytes(good)
    with serve(mirror) as (url, _):
        assert _ingest(root, url + "rish/", url + "oscar/")["complete"]
    assert cube.complete_cycles(DataLayout(root).weather_cube) == [np.datetime64(CYCLE, "ns")]


KILL_SCRIPT = """
import os, signal, sys
import numpy as np, xarray as xr
from storage import cube
src, dst, lock, where = sys.argv[1:5]
ds = xr.open_zarr(src, consolidated=False).isel(cycle=0).load()
ds = ds.assign_coords(cycle=np.datetime64("2020-12-01T12", "ns"))
if where == "before-state":
    real = cube._set_state
    def killer(path, index, state):
        if state != cube.STATE_HIDDEN:
            os.kill(os.getpid(), signal.SIGKILL)
        real(path, index, state)
    cube._set_state = killer
elif where == "mid-region":
    import zarr
    real_set = zarr.Array.__setitem__
    count = {"n": 0}
    def killer(self, key, value):
        count["n"] += 1
        if count["n"] == 3:
            os.kill(os.getpid(), signal.SIGKILL)
        return real_set(self, key, value)
    zarr.Array.__setitem__ = killer
    cube.zarr.Array.__setitem__ = killer
cube.write_cycle(dst, ds, complete=True)
"""


@pytest.mark.parametrize("where", ["before-state", "mid-region"])
def test_killed_writer_leaves_no_partial_cycle_and_rerun_repairs(ingested, tmp_path, where):
    root, _ = ingested
    src = DataLayout(root).weather_cube
    dst = tmp_path / "cube.zarr"
    shutil.copytree(src, dst)
    script = tmp_path / "kill.py"
    script.write_text(KILL_SCRIPT)
    proc = subprocess.run([sys.executable, str(script), str(src), str(dst), "", where],
                          cwd=Path(__file__).resolve().parents[1], capture_output=True, text=True)
    assert proc.returncode == -9, proc.stderr
    assert cube.complete_cycles(dst) == [np.datetime64(CYCLE, "ns")]  # the killed cycle is not visible
    assert cube.open_cube(dst).sizes["cycle"] == 1
    proc = subprocess.run([sys.executable, str(script), str(src), str(dst), "", "none"],
                          cwd=Path(__file__).resolve().parents[1], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    ds = cube.open_cube(dst).load()
    assert ds.sizes["cycle"] == 2
    np.testing.assert_array_equal(ds.u10.isel(cycle=0).values, ds.u10.isel(cycle=1).values)


def test_concurrent_writes_of_one_cycle_are_serialised(ingested, tmp_path):
    root, _ = ingested
    ds = cube.load_cycle(DataLayout(root).weather_cube, CYCLE)
    dst = tmp_path / "c.zarr"
    errors = []

    def write():
        try:
            cube.write_cycle(dst, ds, complete=True)
        except Exception as exc:  # collected and asserted below
            errors.append(exc)

    threads = [threading.Thread(target=write) for _ in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
    out = cube.open_cube(dst)
    assert out.sizes["cycle"] == 1 and cube.complete_cycles(dst) == [np.datetime64(CYCLE, "ns")]
    np.testing.assert_array_equal(out.swh.isel(cycle=0).values, ds.swh.values)


def test_ingested_cube_is_cf(ingested):
    """cf-xarray finds the CF roles of the cube's coordinates by their attributes alone."""
    import cf_xarray  # noqa: F401  (registers the .cf accessor)

    root, _ = ingested
    ds = cube.open_cube(DataLayout(root).weather_cube)
    assert ds.cf["forecast_reference_time"].name == "cycle" and ds.cf["forecast_period"].name == "step"
    assert ds.cf["latitude"].name == "lat" and ds.cf["longitude"].name == "lon"
    assert ds.cf.axes == {"X": ["lon"], "Y": ["lat"], "T": ["valid_time"]}
    assert ds.cf["time"].dims == ("cycle", "step")
    np.testing.assert_array_equal(ds.cf["time"].values, ds.cycle.values[:, None] + ds.step.values[None, :])
    # the step axis has room for the 00/12 UTC cycles' leads to 264 h; the demo cycle lists leads to 132 h only
    assert ds.step.values[-1] == np.timedelta64(264, "h") and ds.step.encoding["units"] == "hours"
    assert bool(ds.u10.sel(step=np.timedelta64(144, "h")).isnull().all())
    assert ds.current_age_h.attrs["units"] == "h"
    flags = ds.cycle_state.attrs["flag_values"]  # Zarr keeps attributes as JSON: typed again by the variable's dtype
    assert cube_variables.attrs("cycle_state")["flag_values"].dtype == ds.cycle_state.dtype == np.int8
    np.testing.assert_array_equal(np.asarray(flags, ds.cycle_state.dtype), flags)
    assert bool((ds.cycle_state.cf == "complete").all())
    for c in ("cycle", "step", "valid_time", "lat", "lon"):
        assert "_FillValue" not in ds[c].encoding and "_FillValue" not in ds[c].attrs, c


def _write_as_before_valid_time(path, cycle_ds):
    """A one-cycle store in the layout written before `valid_time` existed: step as plain int32 hours with
    units, lat/lon with a NaN fill value, flag_values as text."""
    old = cycle_ds.drop_vars("current_age_h").expand_dims(cycle=[cycle_ds.cycle.values])
    old = old.assign(current_age_h=cycle_ds.current_age_h.expand_dims(cycle=1).astype(np.float32),
                     cycle_state=("cycle", np.array([cube.STATE_COMPLETE], np.int8),
                                  {"flag_values": "0 1 2", "flag_meanings": "hidden complete incomplete"}))
    old = old.assign_coords(step=("step", cycle_ds.step.values.astype(np.int32), {"units": "hours", "long_name": "lead time"}))
    steps, shape = cycle_ds.sizes["step"], (cycle_ds.sizes["lat"], cycle_ds.sizes["lon"])
    old.to_zarr(path, mode="w", consolidated=False, zarr_format=3,
                encoding={"cycle": dict(cube.CYCLE_ENCODING)} | {v: {"chunks": (1, steps, *cube.spatial_chunks(*shape))} for v in cube.DATA_VARS})


def test_a_store_written_before_valid_time_opens_and_is_upgraded_by_the_next_write(tmp_path):
    lat, lon, steps = np.arange(-1.0, 1.5, 0.5), np.arange(0.0, 2.0, 0.5), np.array([0, 6, 12], np.int32)
    first, second = np.datetime64("2020-12-01T00", "ns"), np.datetime64("2020-12-01T12", "ns")

    def cycle_ds(c, value):
        data = {v: (("step", "lat", "lon"), np.full((3, lat.size, lon.size), value + i, np.float32))
                for i, v in enumerate(cube.DATA_VARS)}
        return xr.Dataset(data | {"current_age_h": ("step", np.array([1.0, 7.0, 13.0], np.float32))},
                          coords={"step": steps, "lat": lat, "lon": lon, "cycle": c})

    store = tmp_path / "cube.zarr"
    _write_as_before_valid_time(store, cycle_ds(first, 1.0))
    old = cube.open_cube(store)  # read as it is: step in plain hours
    assert list(cube_variables.step_hours(old.step.values)) == [0, 6, 12] and "valid_time" not in old
    cube.write_cycle(store, cycle_ds(second, 10.0), complete=True)
    ds = cube.open_cube(store).load()
    assert list(ds.cycle.values) == [first, second]
    np.testing.assert_array_equal(ds.step.values, steps.astype("timedelta64[h]").astype("timedelta64[ns]"))
    np.testing.assert_array_equal(ds.valid_time.values, ds.cycle.values[:, None] + ds.step.values[None, :])
    assert float(ds.u10.isel(cycle=0).max()) == 1.0 and float(ds.vo.isel(cycle=1).min()) == 16.0  # data kept
    assert ds.lat.attrs["axis"] == "Y" and "_FillValue" not in ds.lat.encoding
    assert ds.cycle_state.attrs["flag_values"] == [0, 1, 2] and ds.cycle.attrs["standard_name"] == "forecast_reference_time"
