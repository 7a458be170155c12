"""A hostile HTTP server on 127.0.0.1 (slow drip, endless body, a 5 GB announced length, redirect loops), an
unreachable OSCAR listing, and files whose fields are all fill: each ends as a named `missing`/`corrupt`
file or an incomplete cycle, never as a hung ingest, a full disk or a "complete" cycle without data."""

from __future__ import annotations

import os
import shutil
import time

import eccodes
import netCDF4
import numpy as np
import pytest

import flows.ingest
import flows.jobs.ingest
from pipeline.sources.fetch import FetchOptions, fetch, read_text
from storage import cube
from storage.layout import DataLayout
from tests.http_mirror import serve
from tests.reliability.conftest import CYCLE, file_urls, gsm_file, gwm_file, ingest_log_rows, oscar_files
from tests.reliability.ingest_child import load_settings_with

C = np.datetime64(CYCLE, "ns")
QUICK = dict(timeout_s=2.0, retries=2, backoff_s=0.01)


def _url(base: str, mirror, path) -> str:
    return base + str(path.relative_to(mirror))


# --- fetch() against the hostile server -------------------------------------------------------------------------


def test_a_slow_drip_fails_the_minimum_rate_and_is_missing_with_the_reason(mirror, tmp_path):
    target = gsm_file(mirror, 6)
    opts = FetchOptions(**QUICK, min_rate_bps=1000.0, rate_window_s=0.3, deadline_s=60.0)
    with serve(mirror, {target.name: "drip:0.02"}) as (url, handler):
        t0 = time.monotonic()
        res = fetch(_url(url, mirror, target), tmp_path / "out" / target.name, opts)
        took = time.monotonic() - t0
    assert res.status == "missing" and "too slow" in res.error and "below the minimum of 1000 B/s" in res.error, res
    assert "after 3 attempts" in res.error and handler.hits[f"/{target.relative_to(mirror)}"] == 3
    assert took < 10, took  # three windows of 0.3 s, not the hours a 1-byte drip of this file would take
    assert not list((tmp_path / "out").iterdir())


def test_a_drip_fast_enough_for_the_rate_still_meets_the_total_deadline(mirror, tmp_path):
    target = gsm_file(mirror, 6)
    opts = FetchOptions(**QUICK, min_rate_bps=1.0, rate_window_s=0.2, deadline_s=1.0)
    with serve(mirror, {target.name: "drip:0.01"}) as (url, handler):
        t0 = time.monotonic()
        res = fetch(_url(url, mirror, target), tmp_path / "out" / target.name, opts)
        took = time.monotonic() - t0
    assert res.status == "missing" and "not complete within the deadline of 1 s" in res.error, res
    assert handler.hits[f"/{target.relative_to(mirror)}"] == 1 and took < 5  # no retry past the deadline
    assert not list((tmp_path / "out").iterdir())


def test_a_huge_announced_length_is_refused_before_writing_anything(mirror, tmp_path):
    target = gsm_file(mirror, 6)
    with serve(mirror, {target.name: "huge"}) as (url, handler):
        res = fetch(_url(url, mirror, target), tmp_path / "out" / target.name, FetchOptions(**QUICK, max_bytes=64 << 20))
    assert res.status == "missing" and "announces 5000000000 bytes, above the cap of 67108864 bytes" in res.error, res
    assert handler.hits[f"/{target.relative_to(mirror)}"] == 1  # refused, not retried
    assert not list((tmp_path / "out").iterdir())


def test_an_endless_body_is_stopped_at_the_cap(mirror, tmp_path):
    target = gsm_file(mirror, 6)
    with serve(mirror, {target.name: "endless"}) as (url, handler):
        res = fetch(_url(url, mirror, target), tmp_path / "out" / target.name, FetchOptions(**QUICK, max_bytes=2 << 20))
    assert res.status == "missing" and "grew past the cap of 2097152 bytes" in res.error, res
    assert handler.hits[f"/{target.relative_to(mirror)}"] == 1
    assert not list((tmp_path / "out").iterdir())


def test_a_local_file_above_the_cap_is_refused_too(mirror, tmp_path):
    target = gsm_file(mirror, 6)
    res = fetch(target.as_uri(), tmp_path / "out" / target.name, FetchOptions(**QUICK, max_bytes=1000))
    assert res.status == "missing" and f"announces {target.stat().st_size} bytes, above the cap of 1000" in res.error


@pytest.mark.parametrize("fault, says", [("endless", "grew past the cap of 1048576 bytes for this index page"),
                                         ("huge", "announces 5000000000 bytes, above the cap of 1048576 bytes for this index page"),
                                         ("redirect-loop", "too many redirects")])
def test_index_pages_are_capped_and_loops_end(mirror, fault, says):
    with serve(mirror, {"rish/2020/12/01/": fault}) as (url, handler):
        with pytest.raises(ConnectionError, match=says):
            read_text(url + "rish/2020/12/01/", FetchOptions(**QUICK, max_index_bytes=1 << 20))
    assert sum(handler.hits.values()) <= 6


def test_a_redirect_loop_on_a_file_ends_as_an_error(mirror, tmp_path):
    target = gsm_file(mirror, 6)
    with serve(mirror, {target.name: "redirect-loop"}) as (url, handler):
        res = fetch(_url(url, mirror, target), tmp_path / target.name, FetchOptions(**QUICK))
    assert res.status == "error" and "too many redirects" in res.error
    assert handler.hits[f"/{target.relative_to(mirror)}"] == 5


# --- through the ingest flow --------------------------------------------------------------------------------------


def test_ingest_with_a_dripping_and_an_endless_file_ends_with_both_missing(mirror, tmp_path, ingest, monkeypatch):
    monkeypatch.setattr(flows.jobs.ingest, "load_settings", load_settings_with(**{
        "sources.http_deadline_s": 3.0, "sources.http_min_rate_bps": 2000.0, "sources.http_rate_window_s": 0.5,
        "sources.gwm_max_bytes": 4 << 20}))
    drip, endless = gsm_file(mirror, 12), gwm_file(mirror)
    root = tmp_path / "data"
    t0 = time.monotonic()
    with serve(mirror, {drip.name: "drip:0.02", endless.name: "endless"}) as (url, _):
        report = ingest(root, url + "rish/", url + "oscar/")
    assert time.monotonic() - t0 < 60
    assert not report["complete"] and report["n_ok"] == 3, report
    log = ingest_log_rows(root)
    assert log[drip.name][0] == "missing" and "too slow" in log[drip.name][1], log[drip.name]
    assert log[endless.name][0] == "missing" and "grew past the cap of 4194304 bytes" in log[endless.name][1]
    assert not list(root.rglob("*.part"))
    assert cube.cycle_states(DataLayout(root).weather_cube) == {C: cube.STATE_INCOMPLETE}


def test_an_unreachable_oscar_listing_still_ingests_wind_and_waves(mirror, tmp_path, ingest, clean_cube):
    root = tmp_path / "data"
    with serve(mirror, {"oscar/": "500"}) as (url, _):
        report = ingest(root, url + "rish/", url + "oscar/")
    assert not report["complete"] and report["n_ok"] == 4, report
    assert any(m.startswith("OSCAR listing unreachable") and "HTTP 500" in m for m in report["missing"]), report["missing"]
    store = DataLayout(root).weather_cube
    assert cube.cycle_states(store) == {C: cube.STATE_INCOMPLETE}
    got = cube.open_cube(store).sel(cycle=C).load()
    for v in ("u10", "v10", "swh", "mwd", "mwp"):
        np.testing.assert_array_equal(got[v].values, clean_cube[v].isel(cycle=0).values)
    assert np.isnan(got.uo.values).all()
    from storage import ingest_log

    status = ingest_log.cycle_status(DataLayout(root).warehouse)
    assert not status.complete.iloc[0] and "OSCAR listing unreachable" in status.missing.iloc[0]


# --- files with no valid values -------------------------------------------------------------------------------------


def _all_missing_grib(path) -> None:
    """Every value of every message marked missing in the bitmap."""
    out = path.with_name(path.name + ".new")
    with open(path, "rb") as fin, open(out, "wb") as fout:
        while (h := eccodes.codes_grib_new_from_file(fin)) is not None:
            n = eccodes.codes_get(h, "numberOfDataPoints")
            eccodes.codes_set(h, "bitmapPresent", 1)
            miss = eccodes.codes_get_double(h, "missingValue")
            eccodes.codes_set_values(h, np.full(n, miss))
            eccodes.codes_write(h, fout)
            eccodes.codes_release(h)
    os.replace(out, path)


def _all_fill_oscar(path) -> None:
    with netCDF4.Dataset(path, "a") as nc:
        for name in ("u", "v"):
            var = nc.variables[name]
            var[:] = np.full(var.shape, np.nan, np.float32)  # the v1 fill value


def test_all_fill_files_are_corrupt_with_no_valid_values(small_mirror, tmp_path, ingest):
    mirror = tmp_path / "mirror"
    shutil.copytree(small_mirror, mirror)
    gsm, osc = gsm_file(mirror, 6), oscar_files(mirror)[1]
    _all_missing_grib(gsm)
    _all_fill_oscar(osc)
    root = tmp_path / "data"
    report = ingest(root, *file_urls(mirror))
    assert not report["complete"] and sorted(report["corrupt"]) == sorted([gsm.name, osc.name]), report
    log = ingest_log_rows(root)
    assert log[gsm.name][0] == "corrupt" and "no valid values in u10" in log[gsm.name][1], log[gsm.name]
    assert log[osc.name][0] == "corrupt" and "no valid values in u" in log[osc.name][1], log[osc.name]
    assert cube.complete_cycles(DataLayout(root).weather_cube) == []
