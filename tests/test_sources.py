"""RISH/OSCAR listing and the fetcher, over a real HTTP server on 127.0.0.1."""

import numpy as np
import pytest

from pipeline.sources import oscar, rish
from pipeline.sources.fetch import FetchOptions, fetch, sha256_of
from tests.http_mirror import serve

FAST = FetchOptions(timeout_s=5, retries=2, backoff_s=0.01)


def test_names_are_recognised_and_others_ignored():
    f = rish.parse_name("Z__C_RJTD_20201201120000_GSM_GPV_Rgl_FD0112_grib2.bin")
    assert (f.model, f.first_lead_h, f.cycle) == ("GSM", 36, np.datetime64("2020-12-01T12", "ns"))
    g = rish.parse_name("Z__C_RJTD_20201201000000_GWM_GPV_Rgl_Gll0p25deg_FD0318-0512_grib2.bin")
    assert (g.model, g.first_lead_h, g.last_lead_h, g.res_deg) == ("GWM", 90, 132, 0.25)
    assert rish.parse_name("Z__C_RJTD_20201201000000_MSM_GPV_Rjp_Lsurf_FH00-15_grib2.bin") is None
    assert rish.parse_name("README.txt") is None


def test_index_rejects_paths_and_parent_links():
    page = """<a href="../">Parent</a><a href="sub/">sub</a>
    <a href="Z__C_RJTD_20201201000000_GSM_GPV_Rgl_FD0000_grib2.bin">ok</a>
    <a href="../../etc/passwd">x</a><a href="/abs/Z__C_RJTD_20201201000000_GSM_GPV_Rgl_FD0006_grib2.bin">y</a>
    <a href="..%2F..%2Fevil.bin">z</a><a href="http://elsewhere/a.bin">w</a>"""
    names, rejected = rish.parse_index(page)
    assert names == ["Z__C_RJTD_20201201000000_GSM_GPV_Rgl_FD0000_grib2.bin"]
    assert len(rejected) == 4


def test_coverage_and_resolution_preference():
    files = [rish.parse_name(n) for n in (
        "Z__C_RJTD_20201201000000_GSM_GPV_Rgl_FD0000_grib2.bin",
        "Z__C_RJTD_20201201000000_GWM_GPV_Rgl_Gll0p5deg_FD0000-0312_grib2.bin",
        "Z__C_RJTD_20201201000000_GWM_GPV_Rgl_Gll0p25deg_FD0000-0312_grib2.bin",
    )]
    kept = rish.prefer_resolution(files)
    assert [f.res_deg for f in kept if f.model == "GWM"] == [0.25]
    gaps = rish.coverage(kept, [0, 6, 84, 90])
    assert gaps == {"GSM": [6, 84, 90], "GWM": [90]}


def test_oscar_window_takes_latest_before_and_prefers_final():
    names = ["oscar_vel10280.nc", "oscar_vel10285.nc", "oscar_vel10290.nc", "oscar_currents_nrt_20201205.nc",
             "oscar_currents_final_20201205.nc", "junk.nc"]
    t = lambda n: np.datetime64("1992-10-05", "D") + np.timedelta64(n, "D")
    chosen = oscar.files_for_window(names, np.datetime64(t(10287), "ns"), np.datetime64(t(10292), "ns"))
    assert [f.name for f in chosen] == ["oscar_vel10285.nc", "oscar_currents_final_20201205.nc", "oscar_vel10290.nc"]


@pytest.mark.slow
def test_fetch_retries_5xx_then_succeeds_with_checksum(tmp_path):
    (tmp_path / "srv").mkdir()
    (tmp_path / "srv" / "a.bin").write_bytes(b"x" * 5000)
    with serve(tmp_path / "srv", {"a.bin": "500x2"}) as (url, handler):
        r = fetch(url + "a.bin", tmp_path / "out" / "a.bin", FAST)
    assert r.status == "ok" and r.bytes == 5000 and r.sha256 == sha256_of(tmp_path / "out" / "a.bin")
    assert handler.hits["/a.bin"] == 3
    again = fetch(url + "a.bin", tmp_path / "out" / "a.bin", FAST, expected_sha256=r.sha256)
    assert again.status == "skipped"


@pytest.mark.slow
def test_fetch_404_is_missing_at_once_and_truncation_never_lands(tmp_path):
    (tmp_path / "srv").mkdir()
    (tmp_path / "srv" / "t.bin").write_bytes(b"y" * 100_000)
    with serve(tmp_path / "srv", {"t.bin": "truncate"}) as (url, handler):
        missing = fetch(url + "nope.bin", tmp_path / "out" / "nope.bin", FAST)
        cut = fetch(url + "t.bin", tmp_path / "out" / "t.bin", FAST)
    assert missing.status == "missing" and handler.hits["/nope.bin"] == 1
    assert cut.status == "missing" and "t.bin" in cut.error
    assert not (tmp_path / "out" / "t.bin").exists() and not list((tmp_path / "out").glob("*.part"))


@pytest.mark.slow
def test_redirect_to_another_host_is_refused(tmp_path):
    (tmp_path / "srv").mkdir()
    with serve(tmp_path / "srv", {"r.bin": "redirect:http://localhost:9/r.bin"}) as (url, _):
        r = fetch(url + "r.bin", tmp_path / "out" / "r.bin", FAST)
        allowed = fetch(url + "r.bin", tmp_path / "out" / "r.bin", FetchOptions(timeout_s=2, retries=0, backoff_s=0.01, allowed_redirect_hosts=("localhost",)))
    assert r.status == "error" and "refused" in r.error
    assert allowed.status == "missing"  # followed, then nothing listens on port 9


def test_file_urls_work_like_http(tmp_path):
    (tmp_path / "a.bin").write_bytes(b"abc")
    r = fetch(f"file://{tmp_path}/a.bin", tmp_path / "out" / "a.bin", FAST)
    assert r.status == "ok" and (tmp_path / "out" / "a.bin").read_bytes() == b"abc"
    assert fetch(f"file://{tmp_path}/b.bin", tmp_path / "out" / "b.bin", FAST).status == "missing"


def test_every_cube_variable_comes_from_exactly_one_registered_source():
    from pipeline.sources.registry import SOURCES
    from schemas.cube_variables import DATA_VARS

    provided = [v for src in SOURCES for v in src.variables]
    assert sorted(provided) == sorted(DATA_VARS)
    assert [s.name for s in SOURCES if s.primary] == ["GSM", "GWM"] and [s.name for s in SOURCES if s.needs_token] == ["OSCAR"]
