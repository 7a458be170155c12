"""bench/peer_wrt_io.py: the weather handed to the isochrone peer (52North WeatherRoutingTool) is jitroute's weather,
read back from the real netCDF file in WRT's layout, in the turned frame a dateline voyage is handed over in; WRT's
route file comes back to jitroute's longitudes with WRT's own fuel."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from pipeline.routing.weather_field import from_arrays

BENCH = Path(__file__).resolve().parents[1] / "bench"


@pytest.fixture(scope="module")
def wio():
    spec = importlib.util.spec_from_file_location("peer_wrt_io", BENCH / "peer_wrt_io.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _field(lon):
    """Weather on 3 latitudes × the given longitudes × 3 hourly times, every value telling where and when it is."""
    lat = np.array([30.0, 31.0, 32.0])
    times = np.datetime64("2021-01-10T00:00", "s") + np.arange(3) * np.timedelta64(1, "h")
    t, la, lo = np.meshgrid(np.arange(3.0), lat, lon, indexing="ij")
    return from_arrays(lat, lon, times, u10=lo / 10.0 + t, v10=-la / 10.0, swh=1.0 + t, mwd_deg=np.full(t.shape, 350.0),
                       uo=np.full(t.shape, 0.3), vo=-0.1 * (t + 1.0))


def test_a_box_across_the_dateline_is_turned_into_wrts_longitudes_and_one_that_is_not_stays(wio):
    assert wio.shift_deg(np.arange(25.0, 91.0)) == 0.0
    shift = wio.shift_deg(np.arange(130.0, 246.0))  # 130 E .. 114 W, numbered 0..360 east
    lon_f = np.arange(130.0, 246.0) - shift
    assert shift == 188.0 and lon_f.min() >= -180.0 and lon_f.max() <= 180.0
    assert wio.to_frame(-150.0, shift) == pytest.approx(22.0)  # 150 W = 210 E, 22° east of the turned meridian
    assert wio.to_frame(wio.to_frame(-150.0, shift), -shift) == pytest.approx(-150.0)


def test_the_weather_file_round_trips_in_wrts_layout(wio, tmp_path):
    lon = np.arange(176.0, 186.0)  # across the dateline
    field = _field(lon)
    shift = wio.shift_deg(lon)
    path = tmp_path / "weather.nc"
    wio.weather_dataset(field, shift).to_netcdf(path)
    ds = xr.open_dataset(path)
    assert ds.attrs["longitude_shift_deg"] == shift == 180.0
    np.testing.assert_allclose(ds.longitude.values, lon - 180.0)  # −4 .. 5
    assert ds["u-component_of_wind_height_above_ground"].dims == ("latitude", "longitude", "time",
                                                                  "height_above_ground")
    assert ds["utotal"].dims == ("latitude", "longitude", "time", "depth")
    # WRT's ship reads a point with .sel(nearest): the point 179 W (181 E) at 31 N, 02:00 is the field's
    at = ds.sel(latitude=31.0, longitude=float(wio.to_frame(-179.0, shift)), time=np.datetime64("2021-01-10T02:00"),
                method="nearest")
    assert float(at["u-component_of_wind_height_above_ground"].sel(height_above_ground=10.0)) == pytest.approx(18.1 + 2)
    assert float(at["v-component_of_wind_height_above_ground"].sel(height_above_ground=10.0)) == pytest.approx(-3.1)
    assert float(at["VHM0"]) == pytest.approx(3.0)
    assert float(at["VMDR"]) == pytest.approx(350.0, abs=1e-3)  # coming from, not turned by the frame
    assert float(at["vtotal"].sel(depth=wio.CURRENT_DEPTH_M)) == pytest.approx(-0.3)
    assert float(at["utotal"].sel(depth=wio.CURRENT_DEPTH_M)) == pytest.approx(0.3)
    depth = tmp_path / "depth.nc"
    wio.depth_dataset(field, shift).to_netcdf(depth)
    z = xr.open_dataset(depth)["z"]
    assert float(z.max()) == -wio.DEEP_WATER_M and z.shape == (3, lon.size)


def test_the_config_puts_the_ports_the_map_and_the_ship_where_jitroute_has_them(wio, tmp_path):
    from types import SimpleNamespace

    field = _field(np.arange(176.0, 186.0))
    problem = SimpleNamespace(dep=(30.5, 177.0), arr=(31.5, -176.0), depart_utc=np.datetime64("2021-01-10T00:00"))
    cfg = wio.wrt_config(problem, field, 181.0, 12.0, 50.0, tmp_path, route_steps=20)
    assert cfg["DEFAULT_ROUTE"] == pytest.approx([30.5, -4.0, 31.5, 3.0])
    assert cfg["DEFAULT_MAP"] == pytest.approx([30.0, -5.0, 32.0, 4.0])
    assert cfg["DEPARTURE_TIME"] == "2021-01-10T00:00Z"
    # one step burns the calm-water fuel of 50 NM at 12 kn: 1.5 t/h · (12/14)³ for 50/12 h
    assert cfg["DELTA_FUEL"] == pytest.approx(1500.0 * (12.0 / 14.0) ** 3 * 50.0 / 12.0)
    # the direct-power ship burns 1.5 t/h at 14 kn, its service point (75 % SMCR) at the given specific consumption
    assert 0.75 * cfg["BOAT_SMCR_POWER"] * cfg["BOAT_FUEL_RATE"] == pytest.approx(1.5e6)
    assert cfg["BOAT_SPEED"] * 3600.0 / 1852.0 == pytest.approx(12.0, rel=1e-4)


def test_wrts_route_file_comes_back_to_jitroutes_longitudes_with_its_own_fuel(wio, tmp_path):
    # as WRT's RouteParams.write_to_geojson writes it: Points [lon, lat], the step's start time and fuel rate
    feats = []
    for k, (lo, la, rate) in enumerate([(-4.0, 30.5, 0.8), (-2.0, 31.0, 0.6), (3.0, 31.5, -99)]):
        feats.append({"type": "Feature", "geometry": {"type": "Point", "coordinates": [lo, la]},
                      "properties": {"time": f"2021-01-10 {3 * k:02d}:00:00",
                                     "fuel_consumption": {"value": rate, "unit": "t/h"}}})
    path = tmp_path / "min_time_route.json"
    path.write_text(json.dumps({"type": "FeatureCollection", "features": feats}))
    lat, lon, fuel_t = wio.read_route(path, 181.0)
    np.testing.assert_allclose(lat, [30.5, 31.0, 31.5])
    np.testing.assert_allclose(lon, [177.0, 179.0, -176.0])
    assert fuel_t == pytest.approx(0.8 * 3 + 0.6 * 3)


@pytest.mark.slow  # builds a suite instance and loads the DP kernels: ~5 s on a busy machine
def test_the_dps_own_route_handed_over_as_waypoints_prices_at_the_stored_optimum(wio):
    """The evaluator WRT's route goes through: the suite's stored optimum of a small instance, its route given as
    waypoints (a graph of one node per line), gets the best setting per leg back at the stored cost."""
    from pipeline.routing.engine_limits import best_engine_plan
    from pipeline.routing.savings import solver_instance
    from pipeline.synthetic import routing_suite as suite

    spec = suite.BY_NAME["short-coastal"]
    problem, space, weather = suite.build(spec)
    rec = suite.read_optima(BENCH / "optima.json")[spec.name]
    nodes = np.asarray(rec["nodes"], np.int64)
    lines = np.arange(nodes.size)
    lat, lon = space.lat[lines, nodes], space.lon[lines, nodes]
    inst, _ = solver_instance(problem, space, weather)
    _, cost, _ = best_engine_plan(wio.route_instance(inst, lat, lon), np.zeros(nodes.size, np.int64))
    assert cost == pytest.approx(suite.plan_cost(problem, space, weather, nodes, rec["rpm_idx"]), rel=1e-9)
    assert cost == pytest.approx(rec["cost"], rel=1e-9)
    assert wio.legs_off_clearance(inst, lat, lon) == 0
    # a route straight over Honshu's coast breaks jitroute's clearance where the graph never would
    assert wio.legs_off_clearance(inst, np.array([34.8, 35.6, 33.3]), np.array([139.9, 137.5, 135.6])) >= 1
