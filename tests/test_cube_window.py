"""A voyage reads only its window of a cube cycle; cycles are published through consolidated metadata with a
content version; the cube may live on S3 (moto's server on loopback)."""

from __future__ import annotations

import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from pipeline.routing import weather_field as wf
from pipeline.routing.problem import lon_span_deg
from storage import cube, cube_window

CYCLE = np.datetime64("2020-12-01T00", "ns")
CYCLE2 = np.datetime64("2020-12-01T06", "ns")
LAT = np.arange(-80.0, 80.01, 2.0)
LON = np.arange(0.0, 360.0, 2.0)
STEPS = np.arange(0, 49, 6)


def cycle_ds(cycle=CYCLE, wind_ms: float = 0.0) -> xr.Dataset:
    """A global cycle whose every value differs (so a wrong cell or step shows), plus `wind_ms` of east wind."""
    t, la, lo = np.meshgrid(STEPS, LAT, LON, indexing="ij")
    smooth = np.sin(np.radians(lo)) * np.cos(np.radians(la)) + 0.01 * t + 0.001 * la
    dims = ("step", "lat", "lon")
    data = {v: (dims, (smooth * (k + 1) + (wind_ms if v == "u10" else 0.0)).astype(np.float32))
            for k, v in enumerate(cube.DATA_VARS)}
    data["mwd"] = (dims, ((lo + 10 * t) % 360.0).astype(np.float32))
    data["current_age_h"] = (("step",), np.zeros(STEPS.size, np.float32))
    return xr.Dataset(data, coords={"cycle": cycle, "step": STEPS, "lat": LAT, "lon": LON})


@pytest.fixture
def store(tmp_path):
    path = tmp_path / "cubes" / "weather.zarr"
    cube.write_cycle(path, cycle_ds(), complete=True)
    return path


@pytest.fixture(scope="module")
def read_only_store(tmp_path_factory):
    """`store` written once for the tests that only read it."""
    path = tmp_path_factory.mktemp("cube") / "cubes" / "weather.zarr"
    cube.write_cycle(path, cycle_ds(), complete=True)
    return path


def window(store, box_lat, box_lon, t_from="2020-12-01T13", t_to="2020-12-02T05", **kw) -> wf.WeatherField:
    win = cube_window.read_window(store, CYCLE, valid_utc=(np.datetime64(t_from), np.datetime64(t_to)),
                                  lat_deg=box_lat, lon_deg=box_lon, variables=wf.CUBE_VARIABLES, **kw)
    return wf.from_window(win)


@pytest.mark.parametrize("box_lat, box_lon", [((10, 30), (140, 160)),  # open ocean
                                               ((20, 50), (170, 200)),  # across 180°
                                               ((-10, 10), (350, 375))])  # across 0°, the grid's seam
@pytest.mark.slow
def test_a_window_samples_like_the_whole_cycle_inside_its_box(read_only_store, box_lat, box_lon):
    whole = wf.from_cycle(cube.load_cycle(read_only_store, CYCLE), CYCLE)
    part = window(read_only_store, box_lat, box_lon)
    assert part.values.size < whole.values.size / 10 and not part.grid.wraps
    assert part.t_ref == whole.t_ref  # times count from the cycle in both
    rng = np.random.default_rng(1)
    a, b = np.zeros(7, np.float32), np.zeros(7, np.float32)
    for _ in range(300):
        lat, lon = rng.uniform(*box_lat), (rng.uniform(*box_lon) + 180.0) % 360.0 - 180.0
        t_h = rng.uniform(13.0, 29.0)
        assert wf.sample_nb(whole.kernel, t_h, lat, lon, a) == wf.sample_nb(part.kernel, t_h, lat, lon, b)
        np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-6, err_msg=f"at {lat:.2f}, {lon:.2f}, {t_h:.1f} h")


def test_a_window_holds_the_steps_bracketing_its_times_clipped_to_the_cycle(read_only_store):
    assert list(window(read_only_store, (0, 10), (0, 10)).times_h) == [12, 18, 24, 30]  # 13 h .. 29 h
    late = window(read_only_store, (0, 10), (0, 10), t_from="2020-12-02T10", t_to="2020-12-09T00")
    assert list(late.times_h) == [30, 36, 42, 48]  # the cycle's last step stays the horizon
    after = window(read_only_store, (0, 10), (0, 10), t_from="2020-12-05T00", t_to="2020-12-09T00")
    assert list(after.times_h) == [48]


def test_a_window_across_the_seam_has_continuous_longitudes(read_only_store):
    part = window(read_only_store, (-10, 10), (350, 375))
    g = part.grid
    assert g.lon0 < 350 and g.lon0 + g.dlon * (g.nlon - 1) > 375
    lon = g.lon0 + g.dlon * np.arange(g.nlon)
    u10 = part.values[wf.U10, 0, 0]
    expected = cycle_ds()["u10"].isel(step=2).sel(lat=part.grid.lat0).sel(lon=lon % 360.0).values
    np.testing.assert_array_equal(u10, expected)


def test_lon_span_is_the_shortest_arc():
    assert lon_span_deg([140.0, 150.0, 145.0]) == (140.0, 150.0)
    assert lon_span_deg([175.0, -175.0, 179.0]) == (175.0, 185.0)
    assert lon_span_deg([-5.0, 5.0]) == (355.0, 365.0)


@pytest.mark.slow
def test_a_plain_reader_sees_only_published_cycles_without_a_warning(store):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert xr.open_zarr(store).sizes["cycle"] == 1
    loc = cube.locate(store)
    with cube.writer_lock(None, loc):  # a writer between its append and its publication
        index = cube._append_hidden(loc, cube._template(cycle_ds(CYCLE2), CYCLE2))
        cube._write_region(loc, index, cycle_ds(CYCLE2))
        cube._set_state(loc, index, cube.STATE_COMPLETE)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            assert list(xr.open_zarr(store)["cycle"].values) == [CYCLE]
        assert CYCLE2 not in cube.cycle_versions(store)
        cube._publish(loc, CYCLE2)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert list(xr.open_zarr(store)["cycle"].values) == [CYCLE, CYCLE2]
    assert set(cube.cycle_versions(store)) == {CYCLE, CYCLE2}


def _route(store, version):
    from flows.jobs.route_worker import route_one
    from pipeline.performance.model import reference_model
    from pipeline.routing.job import RouteJob, RoutingOptions

    voyage = {"voyage_id": "VREINGEST", "imo": 1, "dep_lat": 34.0, "dep_lon": 141.0, "arr_lat": 30.0,
              "arr_lon": 147.0, "depart_utc": np.datetime64("2020-12-01T02"), "rta_utc": np.datetime64("2020-12-02T18"),
              "rpm_options": [70, 85, 100]}
    job = RouteJob(voyage=voyage, vessel={"rpm_max": 100}, model=reference_model(14.0, 100.0, 1.5).to_json(),
                   run_id="r1", cycle=str(CYCLE)[:19], exports=False, options=RoutingOptions(n_lines=6, n_points=7),
                   cycle_version=version)
    return route_one(job, str(store))["legs"]


@pytest.mark.slow  # a cycle written again and a voyage routed on it, end to end
def test_a_worker_routes_on_the_new_values_after_a_re_ingest(store):
    v1 = cube.cycle_versions(store)[CYCLE]
    calm_legs = _route(store, v1)
    cube.write_cycle(store, cycle_ds(wind_ms=15.0), complete=True)  # the same cycle, re-ingested
    v2 = cube.cycle_versions(store)[CYCLE]
    assert v2 > v1
    assert _route(store, v1)[0]["wind_kn"] == calm_legs[0]["wind_kn"]  # same version: the cached window
    windy_legs = _route(store, v2)
    assert windy_legs[0]["wind_kn"] > calm_legs[0]["wind_kn"] + 10  # the run that read v2 meets the new wind


@pytest.mark.slow  # a child process that routes
def test_a_worker_routes_from_the_cube_without_pandas_xarray_or_duckdb(store):
    """What keeps a dask worker small: routing a voyage (exports off) imports none of the big table libraries."""
    code = (f"import sys; sys.path.insert(0, {str(Path(__file__).parents[1])!r})\n"
            "import numpy as np\n"
            "from flows.jobs.route_worker import route_one\n"
            "from pipeline.performance.model import reference_model\n"
            "from pipeline.routing.job import RouteJob, RoutingOptions\n"
            "voyage = {'voyage_id': 'VSMALL', 'imo': 1, 'dep_lat': 34.0, 'dep_lon': 141.0, 'arr_lat': 30.0,\n"
            "          'arr_lon': 147.0, 'depart_utc': np.datetime64('2020-12-01T02'),\n"
            "          'rta_utc': np.datetime64('2020-12-02T18'), 'rpm_options': [70, 85, 100]}\n"
            "job = RouteJob(voyage=voyage, vessel={'rpm_max': 100}, model=reference_model(14.0, 100.0, 1.5).to_json(),\n"
            f"               run_id='r1', cycle={str(CYCLE)[:19]!r}, exports=False,\n"
            "               options=RoutingOptions(n_lines=6, n_points=7))\n"
            f"row = route_one(job, {str(store)!r})['route']\n"
            "print(row['status'], sorted({m.split('.')[0] for m in sys.modules} & {'pandas', 'xarray', 'pyarrow', 'duckdb'}))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "ok []", out


# --- the cube on S3 -----------------------------------------------------------------------------------------------


@pytest.fixture
def s3_options(s3_endpoint):
    """fsspec options for the suite's S3 server (conftest.s3_endpoint, bucket `jitroute`)."""
    return {"endpoint_url": s3_endpoint["AWS_ENDPOINT_URL"], "key": s3_endpoint["AWS_ACCESS_KEY_ID"],
            "secret": s3_endpoint["AWS_SECRET_ACCESS_KEY"]}


@pytest.mark.slow  # an S3 server
def test_the_cube_on_s3_is_written_read_by_window_and_published_for_plain_readers(s3_options, store, tmp_path):
    url, locks = "s3://jitroute/root/cubes/weather.zarr", tmp_path / "locks"
    with pytest.raises(cube.CubeError, match="lock_dir"):
        cube.write_cycle(url, cycle_ds(), complete=True, storage_options=s3_options)
    cube.write_cycle(url, cycle_ds(), complete=True, lock_dir=locks, storage_options=s3_options)
    assert (locks / "weather.zarr.lock").exists()
    before = cube_window.CHUNK_CACHE.fetched_bytes
    on_s3 = window(url, (20, 50), (170, 200), storage_options=s3_options)
    fetched = cube_window.CHUNK_CACHE.fetched_bytes
    assert fetched > before  # the chunks came from S3 through the cache
    window(url, (25, 45), (175, 195), storage_options=s3_options)  # a second voyage in the same chunks: no GET of a chunk
    assert cube_window.CHUNK_CACHE.fetched_bytes == fetched
    local = window(store, (20, 50), (170, 200))
    np.testing.assert_array_equal(on_s3.values, local.values)
    assert on_s3.grid == local.grid

    loc = cube.locate(url, s3_options)
    with cube.writer_lock(locks, loc):  # a second cycle appended and written, not yet published
        index = cube._append_hidden(loc, cube._template(cycle_ds(CYCLE2), CYCLE2))
        cube._write_region(loc, index, cycle_ds(CYCLE2))
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            assert list(xr.open_zarr(url, storage_options=s3_options)["cycle"].values) == [CYCLE]
        assert cube.cycle_states(url, storage_options=s3_options) == {CYCLE: cube.STATE_COMPLETE,
                                                                       CYCLE2: cube.STATE_HIDDEN}
        cube._set_state(loc, index, cube.STATE_COMPLETE)
        cube._publish(loc, CYCLE2)
    assert list(xr.open_zarr(url, storage_options=s3_options)["cycle"].values) == [CYCLE, CYCLE2]


# --- the chunk cache, constant-time opening, retention ----------------------------------------------------------


def _chunk_files_bytes(store: Path, rows: slice, cols: slice, variables=wf.CUBE_VARIABLES) -> int:
    """Bytes on disk of the chunk files of cycle row 0 that hold grid rows `rows` × columns `cols`."""
    clat, clon = cube.spatial_chunks(LAT.size, LON.size)
    return sum((store / v / "c" / "0" / "0" / str(j) / str(k)).stat().st_size for v in variables
               for j in range(rows.start // clat, (rows.stop - 1) // clat + 1)
               for k in range(cols.start // clon, (cols.stop - 1) // clon + 1))


@pytest.mark.slow
def test_a_second_voyage_in_the_same_window_fetches_no_chunk_again(store):
    cache = cube_window.CHUNK_CACHE
    cache.clear()
    first = window(store, (10, 30), (140, 160))
    rows = slice(int(np.searchsorted(LAT, first.grid.lat0)), int(np.searchsorted(LAT, first.grid.lat0)) + first.grid.nlat)
    col0 = int(np.searchsorted(LON, first.grid.lon0))
    assert cache.fetched_bytes == _chunk_files_bytes(store, rows, slice(col0, col0 + first.grid.nlon)) > 0
    fetched, n = cache.fetched_bytes, cache.fetched_chunks
    again = window(store, (12, 28), (142, 158))  # another voyage inside the same chunks, its own published view
    assert (cache.fetched_bytes, cache.fetched_chunks) == (fetched, n) and cache.hit_chunks >= n
    np.testing.assert_array_equal(again.values, window(store, (12, 28), (142, 158)).values)
    cube.write_cycle(store, cycle_ds(wind_ms=15.0), complete=True)  # re-ingested: a new content version
    windy = window(store, (12, 28), (142, 158))
    assert cache.fetched_bytes > fetched  # its chunks are fetched afresh …
    assert windy.values[wf.U10].mean() > again.values[wf.U10].mean() + 14  # … and give the new values
    assert cache.fetched_bytes <= fetched + sum(f.stat().st_size for v in wf.CUBE_VARIABLES
                                                for f in (store / v / "c" / "0").rglob("*") if f.is_file())


def test_the_cache_keeps_to_its_byte_bound():
    cache = cube_window.ChunkCache(max_bytes=250)
    for k in range(5):
        cache.put(k, bytes(100))
    assert cache.held_bytes == 200 and cache.get(0) is None and cache.get(4) == bytes(100)
    assert cache.fetched_bytes == 500 and cache.distinct_bytes == 500
    cache.put(0, bytes(100))  # dropped, then fetched again: counted as fetched twice, once as distinct
    assert cache.stats()["fetched_bytes"] == 600 and cache.stats()["distinct_bytes"] == 500


@pytest.mark.slow
def test_opening_the_newest_cycle_reads_no_chunk_of_the_cycle_coordinate(store):
    cube.write_cycle(store, cycle_ds(CYCLE2), complete=True)
    for f in (store / "cycle" / "c").rglob("*"):  # were any read, opening would fail
        if f.is_file():
            f.unlink()
    assert cube_window.newest_complete_cycle(store) == CYCLE2
    pub = cube_window.open_published(store)
    assert pub.rows == {CYCLE: 0, CYCLE2: 1}
    w = cube_window.read_window(store, CYCLE2, valid_utc=(np.datetime64("2020-12-01T13"), np.datetime64("2020-12-02T05")),
                                lat_deg=(10, 30), lon_deg=(140, 160), published=pub)
    assert w.cycle == CYCLE2 and w.data["u10"].size > 0


@pytest.mark.slow
def test_retention_retires_old_cycles_and_frees_their_chunks(store):
    day2 = CYCLE + np.timedelta64(1, "D")
    for c in (CYCLE2, day2):
        cube.write_cycle(store, cycle_ds(c), complete=True)
    assert cube.retire_cycles(store, keep_days=0.9) == [CYCLE]  # 06 UTC is 18 h before the newest: kept
    assert not (store / "u10" / "c" / "0").exists() and (store / "u10" / "c" / "1").exists()
    assert set(cube.cycle_versions(store)) == {CYCLE2, day2} and cube.complete_cycles(store) == [CYCLE2, day2]
    assert set(cube_window.open_published(store).rows) == {CYCLE2, day2}
    with pytest.raises(KeyError, match="not in the cube"):
        window(store, (10, 30), (140, 160))
    assert xr.open_zarr(store).sizes["cycle"] == 3  # a plain reader still lists the row (all NaN)
    assert cube.retire_cycles(store, keep_days=0.9) == []  # nothing more to retire
    cube.write_cycle(store, cycle_ds(), complete=True)  # ingested again: back in its row
    assert window(store, (10, 30), (140, 160)).values.size > 0 and cube.retire_cycles(store, keep_days=2) == []


@pytest.mark.slow
def test_cube_retire_takes_its_retention_from_the_option_or_the_setting(tmp_path, monkeypatch):
    from typer.testing import CliRunner

    from cli.main import app
    from flows.settings import SettingsError, load_settings

    store = tmp_path / "data" / "cubes" / "weather.zarr"
    for c in (CYCLE, CYCLE2):
        cube.write_cycle(store, cycle_ds(c), complete=True)
    monkeypatch.delenv("JITROUTE_CUBE_RETENTION_DAYS", raising=False)
    res = CliRunner().invoke(app, ["cube", "retire", "--data", str(tmp_path / "data")])
    assert res.exit_code == 2 and "--keep-days" in res.output
    monkeypatch.setenv("JITROUTE_CUBE_RETENTION_DAYS", "0.1")  # 2.4 h: the 00 UTC cycle is 6 h older than the newest
    assert load_settings().cube_retention_days == 0.1
    res = CliRunner().invoke(app, ["cube", "retire", "--data", str(tmp_path / "data")])
    assert res.exit_code == 0 and "retired 1 cycle(s)" in res.output and "2020-12-01T00" in res.output, res.output
    assert cube.complete_cycles(store) == [CYCLE2]
    monkeypatch.setenv("JITROUTE_CUBE_RETENTION_DAYS", "a week")
    with pytest.raises(SettingsError, match="JITROUTE_CUBE_RETENTION_DAYS"):
        load_settings()


def test_every_s3_filesystem_of_a_process_shares_one_botocore_session():
    import pickle

    from storage.cube_location import fs_options, shared_s3_session

    cube_opts = fs_options("s3://bucket/cubes/weather.zarr", {"key": "k"})
    export_opts = fs_options("s3a://bucket/exports", {})
    assert cube_opts["session"] is export_opts["session"] is shared_s3_session() and cube_opts["key"] == "k"
    assert pickle.loads(pickle.dumps(cube_opts))["session"] is shared_s3_session()  # sent elsewhere: that process's
    assert "session" not in fs_options("/data/cubes/weather.zarr", {}) and "session" not in fs_options("gs://b/x", {})
