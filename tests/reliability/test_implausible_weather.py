"""Implausible or mislabelled weather through the real ingest flow: each damaged file is `corrupt` with its
reason, the cycle is incomplete (never routed as complete), and a re-ingest of the good files gives the clean
cube — nothing lost. OSCAR in cm/s that says so is converted, not refused."""

from __future__ import annotations

import shutil

import eccodes
import netCDF4
import numpy as np

from pipeline.synthetic import weather
from pipeline.synthetic.grib_writer import jma_grid, write_gsm_file, write_gwm_file
from storage import cube
from storage.layout import DataLayout
from tests.reliability.conftest import (CYCLE, N_FILES, assert_same_cube, file_urls, ingest_log_rows,
                                       mirror_file, oscar_files)
from tests.reliability.test_source_faults import _rewrite_grib

C = np.datetime64(CYCLE, "ns")


def _wind(lead_h):
    lat, lon = jma_grid(0.5)
    L, O = np.meshgrid(lat, lon, indexing="ij")
    return weather.wind_uv(weather.hours_since_epoch(C) + lead_h, L, O)


def _km_per_h(path) -> None:
    _rewrite_grib(path, lambda h, vals: vals * 3.6 if eccodes.codes_get(h, "discipline") == 0 else vals)


def _dated_2019(path) -> None:
    def edit(h, vals):
        eccodes.codes_set(h, "dataDate", 20190101)
        return vals
    _rewrite_grib(path, edit)


def _second_u10(path) -> None:
    u, _ = _wind(12)
    extra = write_gsm_file(path.with_name("extra.bin"), C, 12, {"u10": u + 40.0})
    path.write_bytes(path.read_bytes() + extra.read_bytes())
    extra.unlink()


def _regional_60n_to_0(path) -> None:
    def edit(h, vals):
        for key, v in (("Nj", 121), ("latitudeOfFirstGridPointInDegrees", 60.0), ("latitudeOfLastGridPointInDegrees", 0.0)):
            eccodes.codes_set(h, key, v)
        return vals[60:181]
    _rewrite_grib(path, edit)


def _inf_box(path) -> None:
    u, v = _wind(0)
    lat, lon = jma_grid(0.5)
    box = np.ix_((lat >= 10) & (lat <= 36), (lon >= 135) & (lon <= 150))
    u[box], v[box] = np.inf, np.nan
    write_gsm_file(path, C, 0, {"u10": u, "v10": v}, packing="grid_ieee")


def _huge_grid(path) -> None:
    lat, lon = jma_grid(0.1)
    const = np.full((lat.size, lon.size), 5.0)
    write_gsm_file(path, C, 6, {"u10": const, "v10": const}, res_deg=0.1)


def _gwm_lead_18(path) -> None:
    lat, lon = jma_grid(0.5)
    L, O = np.meshgrid(lat, lon, indexing="ij")
    t = weather.hours_since_epoch(C)
    swh, mwd, mwp = (np.stack(x) for x in zip(*(weather.waves(t + s, L, O) for s in (0, 6, 18))))
    write_gwm_file(path, C, [0, 6, 18], {"swh": swh, "mwd": mwd, "mwp": mwp}, np.zeros(L.shape, bool))


def _oscar_units(units: str, scale: float):
    def damage(path) -> None:
        with netCDF4.Dataset(path, "a") as nc:
            for name in ("u", "v"):
                nc[name][:] = nc[name][:] * scale
                nc[name].units = units
    return damage


ROUNDS = [  # (file, damage, what the log must say)
    [("gsm0", _km_per_h, "of u10 outside the plausible -75..75 m s-1"),
     ("gsm6", _dated_2019, "reference time 2019-01-01T00:00 in the file, 2020-12-01T00:00 in its name"),
     ("gsm12", _second_u10, "two u10 fields at lead 12 h"),
     ("gwm", _regional_60n_to_0, "wrong grid: latitudes 0..60"),
     ("oscar", _oscar_units("knots", 1.0), "u is in 'knots'")],
    [("gsm0", _inf_box, "missing or non-finite value(s) of u10 (lat 10..36, lon 135..150)"),
     ("gsm6", _huge_grid, "3600×1801 points declared"),
     ("gwm", _gwm_lead_18, "lead 18 h in the file, 0..12 h in its name"),
     ("oscar", _oscar_units("m/s", 100.0), "of uo outside the plausible -10..10 m s-1")],
]


def test_implausible_and_mislabelled_files_are_corrupt_and_a_clean_rerun_loses_nothing(small_mirror, tmp_path, ingest,
                                                                                        clean_cube):
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
            assert status == "corrupt" and error.startswith(name) and says in error, (name, error)
        assert sum(status == "corrupt" for status, _ in log.values()) == len(names)
        assert cube.complete_cycles(DataLayout(root).weather_cube) == []
    report = ingest(root, *file_urls(small_mirror))
    assert report["complete"] and report["corrupt"] == []
    log = ingest_log_rows(root)
    assert len(log) >= N_FILES and all(status in ("ok", "skipped") for status, _ in log.values()), log
    assert_same_cube(DataLayout(root).weather_cube, clean_cube)


def test_oscar_in_cm_per_s_that_says_so_is_converted(small_mirror, tmp_path, ingest, clean_cube):
    mirror = tmp_path / "mirror"
    shutil.copytree(small_mirror, mirror)
    for path in oscar_files(mirror):
        _oscar_units("cm/s", 100.0)(path)
    root = tmp_path / "data"
    report = ingest(root, *file_urls(mirror))
    assert report["complete"] and report["corrupt"] == [], report
    got = cube.open_cube(DataLayout(root).weather_cube).sel(cycle=C)
    for name in ("uo", "vo"):
        want = clean_cube[name].sel(cycle=C).values
        assert np.nanmax(np.abs(want)) > 0.1
        np.testing.assert_allclose(got[name].values, want, atol=1e-5)
