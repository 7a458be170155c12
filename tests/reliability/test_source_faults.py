"""Faulty and hostile sources through the real ingest flow: HTTP errors, timeouts and resets, damaged
GRIB2/NetCDF files, unsafe names in an index, and redirects to other hosts (loopback HTTP only)."""

from __future__ import annotations

import logging
import os
import shutil

import eccodes
import netCDF4
import numpy as np

import flows.ingest
import flows.jobs.ingest
from pipeline.synthetic import weather
from pipeline.synthetic.grib_writer import jma_grid, write_gsm_file, write_gwm_file
from storage import cube, ingest_log
from storage.layout import DataLayout
from tests.http_mirror import serve
from tests.reliability.conftest import (CYCLE, N_FILES, assert_same_cube, day_dir, file_urls, gsm_file, gwm_file,
                                       ingest_log_rows, mirror_file, oscar_files, warehouse_knows_cycle)
from tests.reliability.ingest_child import load_settings_with

C = np.datetime64(CYCLE, "ns")


def _url_path(mirror, path) -> str:
    return "/" + str(path.relative_to(mirror))


def test_http_errors_timeouts_and_resets_are_retried_then_missing_and_a_rerun_completes(mirror, tmp_path, ingest, monkeypatch, clean_cube):
    monkeypatch.setattr(flows.jobs.ingest, "load_settings", load_settings_with(**{"sources.http_timeout_s": 0.5}))
    faults = {gsm_file(mirror, 6).name: "404", gsm_file(mirror, 12).name: "500", gwm_file(mirror).name: "stall",
              oscar_files(mirror)[1].name: "reset"}
    root = tmp_path / "data"
    with serve(mirror, faults) as (url, handler):
        report = ingest(root, url + "rish/", url + "oscar/")
    assert not report["complete"] and report["n_ok"] == 1
    for name in faults:
        assert any(name in m and m.endswith(": missing") for m in report["missing"]), (name, report["missing"])
    hits = {p.rsplit("/", 1)[-1]: n for p, n in handler.hits.items()}
    assert hits[gsm_file(mirror, 6).name] == 1  # 404: no retry
    assert hits[gsm_file(mirror, 12).name] == hits[gwm_file(mirror).name] == hits[oscar_files(mirror)[1].name] == 2  # 1 retry
    log = ingest_log_rows(root)
    assert log[gsm_file(mirror, 6).name] == ("missing", f"{url}rish/2020/12/01/{gsm_file(mirror, 6).name}: not found (HTTP 404)")
    assert "HTTP 500" in log[gsm_file(mirror, 12).name][1] and "after 2 attempts" in log[gsm_file(mirror, 12).name][1]
    assert "Timeout" in log[gwm_file(mirror).name][1]
    assert "ReadError" in log[oscar_files(mirror)[1].name][1] or "reset" in log[oscar_files(mirror)[1].name][1].lower()
    assert log[gsm_file(mirror, 0).name][0] == "ok"
    status = ingest_log.cycle_status(DataLayout(root).warehouse)
    assert not status.complete.iloc[0] and gsm_file(mirror, 12).name in status.missing.iloc[0]
    store = DataLayout(root).weather_cube
    assert cube.cycle_states(store) == {C: cube.STATE_INCOMPLETE} and cube.complete_cycles(store) == []
    ds = cube.open_cube(store).sel(cycle=C)
    assert np.isnan(ds.u10.sel(step=np.timedelta64(6, "h")).values).all() and np.isnan(ds.swh.values).all() and np.isnan(ds.uo.values).all()
    assert not np.isnan(ds.u10.sel(step=np.timedelta64(0, "h")).values).all()
    assert not list(root.rglob("*.part"))
    with serve(mirror) as (url, _):
        assert ingest(root, url + "rish/", url + "oscar/")["complete"]
    assert_same_cube(store, clean_cube)
    warehouse_knows_cycle(root)


def test_transient_faults_are_retried_and_leave_no_trace(mirror, tmp_path, ingest, monkeypatch, clean_cube):
    monkeypatch.setattr(flows.jobs.ingest, "load_settings", load_settings_with(**{"sources.http_timeout_s": 0.5}))
    faults = {gsm_file(mirror, 0).name: "500x1", gsm_file(mirror, 6).name: "resetx1", gwm_file(mirror).name: "stallx1"}
    root = tmp_path / "data"
    with serve(mirror, faults) as (url, handler):
        report = ingest(root, url + "rish/", url + "oscar/")
    assert report["complete"] and report["n_ok"] == N_FILES, report
    hits = {p.rsplit("/", 1)[-1]: n for p, n in handler.hits.items()}
    assert [hits[n] for n in faults] == [2, 2, 2]
    assert_same_cube(DataLayout(root).weather_cube, clean_cube)
    assert {s for s, _ in ingest_log_rows(root).values()} == {"ok"}


def test_an_unlisted_day_writes_nothing_and_says_so(mirror, tmp_path, ingest):
    root = tmp_path / "data"
    with serve(mirror, {"rish/2020/12/01/": "404"}) as (url, _):
        report = ingest(root, url + "rish/", url + "oscar/")
    assert not report["complete"] and report["n_expected"] == 0
    assert report["missing"] == [f"no GSM/GWM files listed at {url}rish/2020/12/01/"]
    assert not DataLayout(root).weather_cube.exists()


# --- damaged files ---------------------------------------------------------------------------------


def _rewrite_grib(path, edit) -> None:
    """Re-encode every message of a GRIB2 file through `edit(handle, values (nj, ni)) -> new values`."""
    out = path.with_name(path.name + ".new")
    with open(path, "rb") as fin, open(out, "wb") as fout:
        while (h := eccodes.codes_grib_new_from_file(fin)) is not None:
            vals = eccodes.codes_get_values(h).reshape(eccodes.codes_get(h, "Nj"), eccodes.codes_get(h, "Ni"))
            new = edit(h, vals)
            eccodes.codes_set_values(h, np.asarray(new, float).ravel())
            eccodes.codes_write(h, fout)
            eccodes.codes_release(h)
    os.replace(out, path)


def _regional(h, vals):
    """Cut the global grid to 50N..20N, 120E..160E (what a mislabelled regional product looks like)."""
    for key, v in (("Ni", 81), ("Nj", 61), ("latitudeOfFirstGridPointInDegrees", 50.0), ("latitudeOfLastGridPointInDegrees", 20.0),
                   ("longitudeOfFirstGridPointInDegrees", 120.0), ("longitudeOfLastGridPointInDegrees", 160.0)):
        eccodes.codes_set(h, key, v)
    return vals[80:141, 240:321]


def _rotated(h, vals):
    eccodes.codes_set(h, "gridDefinitionTemplateNumber", 1)  # rotated lat/lon
    return vals


def _gsm_without_v10(path) -> None:
    lat, lon = jma_grid(0.5)
    L, O = np.meshgrid(lat, lon, indexing="ij")
    u, _ = weather.wind_uv(weather.hours_since_epoch(C) + 12, L, O)
    write_gsm_file(path, C, 12, {"prmsl": 101000.0 + 0 * u, "u10": u})


def _gwm_without_period(path) -> None:
    lat, lon = jma_grid(0.5)
    L, O = np.meshgrid(lat, lon, indexing="ij")
    t = weather.hours_since_epoch(C)
    swh, mwd, _ = (np.stack(x) for x in zip(*(weather.waves(t + s, L, O) for s in (0, 6, 12))))
    write_gwm_file(path, C, [0, 6, 12], {"swh": swh, "mwd": mwd}, np.zeros(L.shape, bool))


def _oscar_with_odd_dims(path) -> None:
    with netCDF4.Dataset(path.with_name("tmp.nc"), "w") as nc:
        for d, n in (("t", 1), ("y", 4), ("x", 8)):
            nc.createDimension(d, n)
        t = nc.createVariable("t", "f8", ("t",))
        t.units = "days since 1992-10-05"
        t[:] = [10280.0]
        for name in ("u", "v"):
            nc.createVariable(name, "f4", ("t", "y", "x"))[:] = np.zeros((1, 4, 8))
    os.replace(path.with_name("tmp.nc"), path)


def _garbage(path) -> None:
    path.write_bytes(np.random.default_rng(7).bytes(path.stat().st_size))


def _truncate(path) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) * 6 // 10])


ROUNDS = [  # each round damages files of a fresh copy of the mirror: (file, damage, what the log must say)
    [("gsm0", _truncate, ""), ("gsm6", lambda p: _rewrite_grib(p, _regional), "wrong grid"),
     ("gsm12", _gsm_without_v10, "no v10 (10 m wind)"), ("gwm", _garbage, "no GRIB messages"),
     ("oscar", _oscar_with_odd_dims, "unexpected dimensions")],
    [("gsm0", lambda p: _rewrite_grib(p, _rotated), "unsupported grid 'rotated_ll'"),
     ("gwm", _gwm_without_period, "no mean wave period"), ("oscar", _garbage, "not a readable NetCDF")],
]


def test_damaged_files_are_quarantined_named_and_replaced_by_a_rerun(small_mirror, tmp_path, ingest, clean_cube):
    root = tmp_path / "data"
    for k, damages in enumerate(ROUNDS):
        mirror = tmp_path / f"mirror{k}"
        shutil.copytree(small_mirror, mirror)
        for key, damage, _ in damages:
            damage(mirror_file(mirror, key))
        report = ingest(root, *file_urls(mirror))
        names = [mirror_file(mirror, key).name for key, _, _ in damages]
        assert not report["complete"] and sorted(report["corrupt"]) == sorted(names), report
        log = ingest_log_rows(root)
        for (key, _, says), name in zip(damages, names):
            status, error = log[name]
            assert status == "corrupt" and error.startswith(name) and says in error and str(mirror) in error, (name, error)
        assert cube.complete_cycles(DataLayout(root).weather_cube) == []
        quarantined = [p.name.rsplit(".", 1)[0] for p in DataLayout(root).quarantine.rglob("*") if p.is_file()]
        assert set(names) <= set(quarantined)
        assert not (set(names) & {p.name for p in DataLayout(root).raw.rglob("*")})  # never decoded again
    report = ingest(root, *file_urls(small_mirror))
    assert report["complete"] and report["corrupt"] == []
    assert_same_cube(DataLayout(root).weather_cube, clean_cube)
    warehouse_knows_cycle(root)


# --- hostile listings and redirects ----------------------------------------------------------------


def test_unsafe_names_in_an_index_are_never_fetched_or_written(mirror, tmp_path, ingest, caplog):
    day = day_dir(mirror)
    bait = {  # listed name -> a real GRIB file placed where following the name would lead
        "../../../Z__C_RJTD_20201201000000_GSM_GPV_Rgl_FD0018_grib2.bin": mirror / "Z__C_RJTD_20201201000000_GSM_GPV_Rgl_FD0018_grib2.bin",
        "/Z__C_RJTD_20201201000000_GSM_GPV_Rgl_FD0024_grib2.bin": mirror / "Z__C_RJTD_20201201000000_GSM_GPV_Rgl_FD0024_grib2.bin",
        "..%2F..%2FZ__C_RJTD_20201201000000_GSM_GPV_Rgl_FD0030_grib2.bin": day.parent.parent / "Z__C_RJTD_20201201000000_GSM_GPV_Rgl_FD0030_grib2.bin",
        "sub/../../Z__C_RJTD_20201201000000_GSM_GPV_Rgl_FD0036_grib2.bin": day.parent / "Z__C_RJTD_20201201000000_GSM_GPV_Rgl_FD0036_grib2.bin",
        f"{day}/Z__C_RJTD_20201201000000_GSM_GPV_Rgl_FD0042_grib2.bin": None,
    }
    for target in filter(None, bait.values()):
        shutil.copy(gsm_file(mirror, 0), target)
    legit = sorted(p.name for p in day.glob("*.bin"))
    links = "".join(f'<a href="{h}">{h}</a>\n' for h in [*bait, *legit])
    (day / "index.html").write_text(f"<html><body>{links}</body></html>")
    oscar_index = (mirror / "oscar" / "index.html").read_text()
    (mirror / "oscar" / "index.html").write_text(oscar_index.replace("</table>", '<a href="../../oscar_vel10280.nc">x</a></table>'))
    before = {p for p in tmp_path.rglob("*")}
    root = tmp_path / "data"
    with serve(mirror) as (url, handler), caplog.at_level(logging.WARNING):
        report = ingest(root, url + "rish/", url + "oscar/")
    assert report["complete"] and report["n_ok"] == N_FILES
    requested = {path for path, _ in handler.requests}
    assert not requested & {_url_path(mirror, t) for t in filter(None, bait.values())}
    assert all(path.startswith(("/rish/2020/12/01/", "/oscar/")) for path in requested), requested
    new = {p for p in tmp_path.rglob("*")} - before
    assert all(root in p.parents or p == root for p in new), [p for p in new if root not in p.parents]
    assert sorted(p.name for p in DataLayout(root).raw.rglob("*.bin")) == legit
    warned = " ".join(r.getMessage() for r in caplog.records)
    assert all(f"ignored unsafe name {h.replace('%2F', '/')!r}" in warned for h in bait), warned


def test_redirect_to_another_host_is_refused_unless_allowed(mirror, tmp_path, ingest, monkeypatch, clean_cube):
    target = gsm_file(mirror, 6)
    with serve(mirror) as (other_url, other):
        other_port = other_url.rsplit(":", 1)[1].strip("/")
        elsewhere = f"http://localhost:{other_port}{_url_path(mirror, target)}"
        with serve(mirror, {target.name: f"redirect:{elsewhere}"}) as (url, _):
            root = tmp_path / "refused" / "data"
            report = ingest(root, url + "rish/", url + "oscar/")
            assert not report["complete"] and f"GSM {target.name}: error" in report["missing"]
            status, error = ingest_log_rows(root)[target.name]
            assert status == "error" and "redirect to another host 'localhost' refused" in error
            assert other.requests == []  # the other host was never contacted
            assert not (DataLayout(root).raw / "gsm" / "20201201" / target.name).exists()
            monkeypatch.setattr(flows.jobs.ingest, "load_settings", load_settings_with(**{"sources.allowed_redirect_hosts": ("localhost",)}))
            root = tmp_path / "allowed" / "data"
            assert ingest(root, url + "rish/", url + "oscar/")["complete"]
            assert [p for p, _ in other.requests] == [_url_path(mirror, target)]
    assert_same_cube(DataLayout(root).weather_cube, clean_cube)
