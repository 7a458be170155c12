"""Property-based tests (hypothesis) of the coordinate fixes in the OSCAR decoder, the NaN-aware regrid
with its longitude wrap, and the listing's name checks. Files are real NetCDF written with netCDF4."""

from __future__ import annotations

import html
import tempfile
from pathlib import Path

import netCDF4
import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pipeline.decode.oscar import decode_oscar
from pipeline.sources import rish
from pipeline.weather.regrid import bilinear
from storage import raw_store

SETTINGS = settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow])
coef = st.floats(-2.0, 2.0, allow_nan=False, width=32)


def _write_v1(path: Path, res: float, day: int, u_of, v_of) -> tuple[np.ndarray, np.ndarray]:
    """An OSCAR v1 file as distributed: (time, depth, latitude, longitude), latitude 80→-80, longitude 20→420
    (the band 380..420 repeats 20..60). `u_of(lat, raw_lon)` sees the raw longitude, so the two copies of
    the repeated band may differ. Returns the raw (lat, lon) axes."""
    lat = np.linspace(80.0, -80.0, int(round(160 / res)) + 1)
    lon = np.linspace(20.0, 420.0, int(round(400 / res)) + 1)
    L, O = np.meshgrid(lat, lon, indexing="ij")
    with netCDF4.Dataset(path, "w") as nc:
        for name, n in (("time", None), ("depth", 1), ("latitude", lat.size), ("longitude", lon.size)):
            nc.createDimension(name, n)
        t = nc.createVariable("time", "i4", ("time",))
        t.units = "day since 1992-10-05 00:00:00"
        t[:] = [day]
        nc.createVariable("depth", "f4", ("depth",))[:] = [15.0]
        nc.createVariable("latitude", "f8", ("latitude",))[:] = lat
        nc.createVariable("longitude", "f8", ("longitude",))[:] = lon
        for name, f in (("u", u_of), ("v", v_of)):
            nc.createVariable(name, "f4", ("time", "depth", "latitude", "longitude"), fill_value=np.float32(np.nan))[0, 0] = f(L, O)
    return lat, lon


@SETTINGS
@given(res=st.sampled_from([1 / 3, 0.5, 1.0, 2.0, 4.0, 5.0, 8.0, 10.0]), day=st.integers(0, 12000),
       a=coef, b=coef, c=coef, band_offset=st.floats(0.5, 4.0))
def test_oscar_v1_longitudes_fold_to_0_360_once_and_latitude_ascends(res, day, a, b, c, band_offset):
    def u_of(lat, raw_lon):  # the repeated copy (raw lon > 380) is marked by an offset
        return a + b * lat / 80 + c * np.cos(np.radians(raw_lon)) + np.where(raw_lon > 380 + 1e-6, band_offset, 0.0)

    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / f"oscar_vel{day}.nc"
        _write_v1(path, res, day, u_of, lambda lat, lon: b * lat / 80)
        ds = decode_oscar(path)
    n = int(round(360 / res))
    lon, lat = ds.lon.values, ds.lat.values
    assert ds.uo.dims == ("time", "lat", "lon") and ds.sizes["lon"] == n and ds.sizes["lat"] == int(round(160 / res)) + 1
    assert np.all(np.diff(lon) > 0) and lon[0] >= 0 and lon[-1] < 360 and np.allclose(np.diff(lon), res)
    assert np.all(np.diff(lat) > 0) and lat[0] == -80 and lat[-1] == 80
    assert ds.time.values[0] == np.datetime64("1992-10-05", "ns") + np.timedelta64(day, "D")
    # every folded longitude holds the first copy in file order: 20..380 as such, 0..20 from 360..380
    raw = np.where(lon >= 20 - 1e-6, lon, lon + 360)
    L, R = np.meshgrid(lat, raw, indexing="ij")
    np.testing.assert_allclose(ds.uo.values[0], u_of(L, R).astype(np.float32), atol=2e-6)
    np.testing.assert_allclose(ds.vo.values[0], (b * L / 80).astype(np.float32), atol=2e-6)


def _write_v2(path: Path, lat: np.ndarray, lon: np.ndarray, u: np.ndarray, lon_first: bool, day: float) -> None:
    """An OSCAR v2.0 file: dimensions `longitude`/`latitude`, coordinate variables `lon`/`lat` (not dimension
    names), _FillValue -999, time in days since 1990-01-01. `u` is (lat, lon)."""
    with netCDF4.Dataset(path, "w") as nc:
        nc.createDimension("time", 1)
        dims = ("longitude", "latitude") if lon_first else ("latitude", "longitude")
        nc.createDimension("longitude", lon.size)
        nc.createDimension("latitude", lat.size)
        t = nc.createVariable("time", "f8", ("time",))
        t.units = "days since 1990-01-01"
        t[:] = [day]
        nc.createVariable("lon", "f4", ("longitude",))[:] = lon
        nc.createVariable("lat", "f4", ("latitude",))[:] = lat
        data = u.T if lon_first else u
        for name in ("u", "v"):
            nc.createVariable(name, "f4", ("time", *dims), fill_value=np.float32(-999.0))[0] = data


@SETTINGS
@given(res=st.sampled_from([0.25, 0.5, 1.0, 2.5, 5.0]), lat_descending=st.booleans(), west_negative=st.booleans(),
       lon_first=st.booleans(), day=st.integers(0, 20000), a=coef, b=coef,
       fill_seed=st.integers(0, 2**32 - 1), fill_fraction=st.floats(0.0, 0.5))
def test_oscar_v2_name_mismatch_orientation_and_fill_are_fixed(res, lat_descending, west_negative, lon_first, day, a, b,
                                                               fill_seed, fill_fraction):
    lat = np.arange(-89.75, 89.75 + res / 2, res) if res == 0.25 else np.arange(-80.0, 80.0 + res / 2, res)
    lat = lat[::-1] if lat_descending else lat
    lon = np.arange(int(round(360 / res))) * res
    lon = np.where(lon >= 180, lon - 360, lon) if west_negative else lon
    L, O = np.meshgrid(lat, lon, indexing="ij")
    u = (a + b * np.sin(np.radians(L)) * np.cos(np.radians(O))).astype(np.float32)
    fill = np.random.default_rng(fill_seed).random(u.shape) < fill_fraction
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "oscar_currents_final_20201201.nc"
        _write_v2(path, lat, lon, np.where(fill, np.float32(-999.0), u), lon_first, float(day))
        ds = decode_oscar(path)
    assert ds.uo.dims == ("time", "lat", "lon")
    assert np.all(np.diff(ds.lat.values) > 0) and np.all(np.diff(ds.lon.values) > 0)
    assert ds.lon.values[0] >= 0 and ds.lon.values[-1] < 360 and ds.sizes["lon"] == lon.size
    assert ds.time.values[0] == np.datetime64("1990-01-01", "ns") + np.timedelta64(day, "D")
    # each input cell lands at its own (lat, lon mod 360), -999 became NaN and nothing else did
    picked = ds.uo.sel(lat=lat, lon=np.mod(lon, 360), method="nearest")
    np.testing.assert_allclose(picked.lat, lat, atol=1e-6)
    np.testing.assert_allclose(picked.lon, np.mod(lon, 360), atol=1e-6)
    got = picked.values[0]
    assert np.array_equal(np.isnan(got), fill)
    np.testing.assert_array_equal(got[~fill], u[~fill])


# --- regrid ----------------------------------------------------------------------------------------

grid_step = st.sampled_from([0.25, 0.5, 1.0, 1.5, 2.0, 5.0])


@SETTINGS
@given(dlat=grid_step, dlon=grid_step, lat0=st.floats(-80, 0), a=coef, b=coef, c=coef, d=coef, data=st.data())
def test_bilinear_reproduces_a_bilinear_field_exactly_inside_cells(dlat, dlon, lat0, a, b, c, d, data):
    src_lat = lat0 + dlat * np.arange(int(40 / dlat) + 1)
    src_lon = dlon * np.arange(int(round(360 / dlon)))
    La, Lo = np.meshgrid(src_lat, src_lon, indexing="ij")

    def f(lat, lon):  # bilinear in (lat, lon) inside every cell; kept O(1) so float32 error stays small
        x, y = (lat - lat0) / 40, lon / 360
        return a + b * x + c * y + d * x * y

    dst_lat = np.array(data.draw(st.lists(st.floats(src_lat[0], src_lat[-1]), min_size=1, max_size=8)))
    dst_lon = np.array(data.draw(st.lists(st.floats(0.0, src_lon[-1]), min_size=1, max_size=8)))  # not the wrap cell
    out = bilinear(f(La, Lo), src_lat, src_lon, dst_lat, dst_lon)
    T, O = np.meshgrid(dst_lat, dst_lon, indexing="ij")
    np.testing.assert_allclose(out, f(T, O), atol=5e-5)


@SETTINGS
@given(dlon=grid_step, nan_seed=st.integers(0, 2**32 - 1), nan_fraction=st.floats(0.0, 1.0), value=coef, data=st.data())
def test_bilinear_is_nan_only_where_every_corner_is_nan(dlon, nan_seed, nan_fraction, value, data):
    src_lat = np.arange(-10.0, 10.0 + 1e-9, 1.0)
    src_lon = dlon * np.arange(int(round(360 / dlon)))
    field = np.full((src_lat.size, src_lon.size), value, np.float32)
    nan = np.random.default_rng(nan_seed).random(field.shape) < nan_fraction
    field[nan] = np.nan
    # targets strictly inside cells (all four weights > 0), incl. the wrap cell between the last column and 360
    j = np.array(data.draw(st.lists(st.integers(0, src_lat.size - 2), min_size=1, max_size=6)))
    i = np.array(data.draw(st.lists(st.integers(0, src_lon.size - 1), min_size=1, max_size=6)))
    fy, fx = data.draw(st.floats(0.05, 0.95)), data.draw(st.floats(0.05, 0.95))
    out = bilinear(field, src_lat, src_lon, src_lat[j] + fy, src_lon[i] + fx * dlon)
    i1 = (i + 1) % src_lon.size
    all_nan = nan[j][:, i] & nan[j][:, i1] & nan[j + 1][:, i] & nan[j + 1][:, i1]
    assert np.array_equal(np.isnan(out), all_nan)
    np.testing.assert_allclose(out[~all_nan], value, rtol=1e-5, atol=1e-6)


@SETTINGS
@given(dlon=grid_step, k=st.integers(-3, 3), frac=st.floats(0.0, 1.0), seed=st.integers(0, 2**32 - 1))
def test_longitude_wraps_round_the_globe(dlon, k, frac, seed):
    src_lat = np.array([-1.0, 1.0])
    src_lon = dlon * np.arange(int(round(360 / dlon)))
    row = np.random.default_rng(seed).normal(size=src_lon.size).astype(np.float32)
    field = np.vstack([row, row])
    x = src_lon[-1] + frac * dlon  # in the cell between the last column and 360 (= the first column)
    expect = (1 - frac) * row[-1] + frac * row[0]
    out = bilinear(field, src_lat, src_lon, np.array([0.0]), np.array([x, x + 360.0 * k]))
    np.testing.assert_allclose(out[0], [expect, expect], rtol=1e-5, atol=1e-5)


# --- listing names ---------------------------------------------------------------------------------

href = st.text(alphabet=st.sampled_from(list("Z_C.RJTD0123456789abgrib/\\:%2F.-?#~ éx")), min_size=1, max_size=40)


@SETTINGS
@given(hrefs=st.lists(href, min_size=1, max_size=12))
def test_every_name_an_index_yields_stays_inside_the_raw_store(hrefs):
    page = "".join(f'<a href="{html.escape(h, quote=True)}">{html.escape(h)}</a>' for h in hrefs)
    names, rejected = rish.parse_index(page)
    raw = Path("/nonexistent/data/raw")
    for name in names:
        assert "/" not in name and "\\" not in name and ".." not in name
        p = raw_store.path_for(raw, "GSM", np.datetime64("2020-12-01"), name)
        assert p.parent == raw / "gsm" / "20201201" and p.name == name
    for r in rejected:
        try:
            raw_store.path_for(raw, "GSM", np.datetime64("2020-12-01"), r)
        except ValueError:
            continue  # refused twice over
        assert ":" in r  # only names with a colon: harmless on POSIX, refused by the listing all the same
