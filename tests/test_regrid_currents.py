import numpy as np
import pytest
import xarray as xr

from pipeline.weather.currents import currents_at
from pipeline.weather.grid import routing_grid
from pipeline.weather.regrid import bilinear, regrid


def test_routing_grid_defaults():
    lat, lon = routing_grid()
    assert lat[0] == -80 and lat[-1] == 80 and lat.size == 321
    assert lon[0] == 0 and lon[-1] == 359.5 and lon.size == 720


def test_bilinear_is_exact_on_a_linear_field_and_wraps_longitude():
    src_lat = np.arange(-10.0, 10.5, 1.0)
    src_lon = np.arange(0.0, 360.0, 1.0)
    L, O = np.meshgrid(src_lat, src_lon, indexing="ij")
    field = 2.0 * L + np.cos(np.radians(O))
    dst_lat = np.array([-9.25, 0.5, 3.75])
    dst_lon = np.array([0.25, 120.5, 359.5])
    out = bilinear(field, src_lat, src_lon, dst_lat, dst_lon)
    # linear in lat exactly; in lon bilinear between neighbours (359 and 0 at 359.5)
    expect_lon = {0.25: 0.75 * np.cos(0) + 0.25 * np.cos(np.radians(1)), 120.5: 0.5 * (np.cos(np.radians(120)) + np.cos(np.radians(121))),
                  359.5: 0.5 * (np.cos(np.radians(359)) + 1.0)}
    for i, la in enumerate(dst_lat):
        for j, lo in enumerate(dst_lon):
            assert out[i, j] == pytest.approx(2 * la + expect_lon[lo], abs=1e-5)


def test_bilinear_ignores_nan_corners_and_keeps_all_land_nan():
    src_lat = np.array([0.0, 1.0])
    src_lon = np.arange(0.0, 360.0, 1.0)
    f = np.ones((2, 360))
    f[0, 0] = np.nan
    f[:, 10:12] = np.nan
    out = bilinear(f, src_lat, src_lon, np.array([0.5]), np.array([0.5, 10.5, 20.0]))
    assert out[0, 0] == pytest.approx(1.0)  # three valid corners
    assert np.isnan(out[0, 1])  # all four corners land
    assert out[0, 2] == pytest.approx(1.0)


def test_regrid_directions_through_components():
    ds = xr.Dataset({"mwd": (("lat", "lon"), np.array([[350.0, 10.0], [350.0, 10.0]]))},
                    coords={"lat": [0.0, 1.0], "lon": [0.0, 1.0]})
    out = regrid(ds, np.array([0.5]), np.array([0.5]))
    assert float(out.mwd[0, 0]) == pytest.approx(0.0, abs=1e-4) or float(out.mwd[0, 0]) == pytest.approx(360.0, abs=1e-4)


def test_currents_latest_analysis_at_or_before_valid_time():
    t = np.array(["2020-11-26", "2020-12-01"], dtype="datetime64[ns]")
    oscar = xr.Dataset({"uo": (("time", "lat", "lon"), np.array([1.0, 2.0])[:, None, None] * np.ones((2, 2, 2))),
                        "vo": (("time", "lat", "lon"), np.zeros((2, 2, 2)))},
                       coords={"time": t, "lat": [0.0, 1.0], "lon": [0.0, 1.0]})
    vt = np.array(["2020-11-25T00", "2020-11-30T18", "2020-12-01T00", "2020-12-03T06"], dtype="datetime64[ns]")
    out = currents_at(oscar, vt)
    assert np.isnan(out.uo.values[0]).all() and np.isnan(out.current_age_h.values[0])
    assert out.uo.values[1, 0, 0] == 1.0 and out.current_age_h.values[1] == pytest.approx(4 * 24 + 18)
    assert out.uo.values[2, 0, 0] == 2.0 and out.current_age_h.values[2] == 0
    assert out.current_age_h.values[3] == pytest.approx(54)


def test_regrid_onto_the_same_grid_is_the_identity_and_twice_equals_once():
    lat, lon = routing_grid(1.0, -10.0, 10.0)
    src_lat, src_lon = np.arange(-90.0, 90.5, 0.5), np.arange(0.0, 360.0, 0.5)
    rng = np.random.default_rng(3)
    ds = xr.Dataset({"swh": (("lat", "lon"), rng.random((src_lat.size, src_lon.size)).astype(np.float32)),
                     "mwd": (("lat", "lon"), (rng.random((src_lat.size, src_lon.size)) * 360).astype(np.float32))},
                    coords={"lat": src_lat, "lon": src_lon})
    once = regrid(ds, lat, lon)
    assert once["swh"].shape == (lat.size, lon.size)
    twice = regrid(once, lat, lon)  # the ingest regrids in its decode workers, then assembles
    for v in ("swh", "mwd"):
        np.testing.assert_array_equal(twice[v].values, once[v].values)
        np.testing.assert_array_equal(once[v].values, ds[v].sel(lat=lat, lon=lon).values)
