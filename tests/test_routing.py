"""Routing engine: geodesy, the leg kernel, objectives and the solvers on analytic weather and real coasts.

Every expected value is computed here by hand (or by an independent formula in this file), not taken
from the code under test. Fault handling (land ports, past RTA, fenced destinations, blocking weather,
NaN holes, weather outside the area) lives in tests/reliability/test_routing_faults.py.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from pipeline.performance.model import reference_model
from pipeline.routing import geodesy as geo
from pipeline.routing.engine import leg as lk
from pipeline.routing import weather_field as wf
from pipeline.routing.objectives import LATE_STEP_T, objective, route_cost_nb
from pipeline.routing.problem import Instance
from pipeline.routing.search_space import build_search_space
from pipeline.routing.sphere import gc_points
from pipeline.routing.solve import BfoaParams, RoutingProblem, _evaluate, solver_instance
from routing_cases import solve, wavy
from tests import land_reference as globe

MODEL = reference_model(14.0, 100.0, 1.5)  # STW = 0.14·rpm kn, fuel = 1.5·(rpm/100)³ t/h in calm water
FAST = BfoaParams(n_bacteria=8, n_chemo=6, n_cycles=8)
MEDIUM = BfoaParams(n_bacteria=12, n_chemo=8, n_cycles=15)
R_NM = 3440.065
KN_PER_MS = 1.943844
T0 = "2020-12-01T06"


def haversine_nm(lat1, lon1, lat2, lon2):
    """Independent great-circle distance (numpy, radius 3440.065 NM)."""
    p1, p2, dl = np.radians(lat1), np.radians(lat2), np.radians(lon2 - lon1)
    a = np.sin((p2 - p1) / 2) ** 2 + np.cos(p1) * np.cos(p2) * np.sin(dl / 2) ** 2
    return 2 * R_NM * np.arcsin(np.sqrt(a))


def unit(lat, lon):
    p, l = np.radians(lat), np.radians(lon)
    return np.array([np.cos(p) * np.cos(l), np.cos(p) * np.sin(l), np.sin(p)])


def problem(dep, arr, hours, **kw):
    base = dict(dep=dep, arr=arr, depart_utc=T0, rta_utc=np.datetime64(T0) + np.timedelta64(int(hours * 60), "m"),
                model=MODEL, rpm_options=(70, 85, 100), n_lines=10, n_points=11, voyage_id="VTEST")
    base.update(kw)
    return RoutingProblem(**base)


def field(fn, lat=(10.0, 50.0), lon=(180.0, 250.0), step=0.5, hours=400):
    """A static field on a regular grid from fn(LAT, LON) → {var: 2-D array}; unset variables are zero."""
    la = np.arange(lat[0], lat[1] + 1e-9, step)
    lo = np.arange(lon[0], lon[1] + 1e-9, step)
    LA, LO = np.meshgrid(la, lo, indexing="ij")
    t0 = np.datetime64("2020-12-01T00")
    times = np.array([t0, t0 + np.timedelta64(hours, "h")])
    shape = (2,) + LA.shape
    kw = {k: np.zeros(shape) for k in ("u10", "v10", "swh", "mwd_deg", "uo", "vo")}
    for k, v in fn(LA, LO).items():
        kw[k] = np.broadcast_to(v, shape).copy()
    return wf.from_arrays(la, lo, times, **kw)


def node_offsets(plan, space):
    """Where each plan waypoint lies on its line, in nodes from the centre: a whole number on one of the graph's
    nodes, a fraction between two (a plan refined on a finer graph, refine_graph.py)."""
    offs = [0.0]  # the ports: every node of their lines is the port itself
    for i, (la, lo) in enumerate(plan.waypoints[1:-1], start=1):
        d = haversine_nm(la, lo, space.lat[i], space.lon[i])
        j = int(np.argmin(d))
        if d[j] < 1e-6:
            offs.append(float(j - space.centre))
            continue
        k = j + 1 if j + 1 < len(d) and (j == 0 or d[j + 1] < d[j - 1]) else j - 1
        assert d[j] + d[k] == pytest.approx(haversine_nm(space.lat[i, j], space.lon[i, j], space.lat[i, k],
                                                         space.lon[i, k]), abs=1e-3), f"waypoint {i} is off line {i}"
        offs.append(j + (k - j) * d[j] / (d[j] + d[k]) - space.centre)
    return np.round(np.array(offs + [0.0]), 3)


def vp(max_hs=None, max_wind=None, step_h=1.0):
    return lk.vessel(MODEL, draft_m=10.0, trim_m=0.0, max_hs_m=max_hs, max_wind_kn=max_wind, max_step_h=step_h)


# ---------------------------------------------------------------------------------------------- geodesy


def test_great_circle_distances_bearings_and_points_by_hand():
    one_deg = R_NM * math.radians(1.0)  # 60.04 NM on this sphere, 60 NM by the nautical-mile definition
    assert geo.gc_distance_nm(10.0, 20.0, 11.0, 20.0) == pytest.approx(one_deg, rel=1e-12)
    assert geo.gc_distance_nm(10.0, 20.0, 11.0, 20.0) == pytest.approx(60.0, rel=1e-3)
    assert geo.gc_distance_nm(0.0, 0.0, 0.0, 90.0) == pytest.approx(5400.0, rel=1e-3)
    assert geo.gc_distance_nm(0.0, 0.0, 90.0, 0.0) == pytest.approx(R_NM * math.pi / 2, rel=1e-12)
    assert geo.gc_distance_nm(0.0, 179.5, 0.0, -179.5) == pytest.approx(one_deg, rel=1e-9)  # across the dateline
    assert geo.gc_distance_nm(0.0, 10.0, 0.0, 370.0) == pytest.approx(0.0, abs=1e-6)  # 0..360 input
    # bearings: east, north, west, south, and 45° from (0,0) towards (45N, 90E) (y = x = √½ by hand)
    assert geo.gc_bearing_deg(0.0, 0.0, 0.0, 10.0) == pytest.approx(90.0)
    assert geo.gc_bearing_deg(0.0, 0.0, 10.0, 0.0) == pytest.approx(0.0)
    assert geo.gc_bearing_deg(0.0, 10.0, 0.0, 0.0) == pytest.approx(270.0)
    assert geo.gc_bearing_deg(10.0, 0.0, 0.0, 0.0) == pytest.approx(180.0)
    assert geo.gc_bearing_deg(0.0, 0.0, 45.0, 90.0) == pytest.approx(45.0)
    assert geo.gc_bearing_deg(0.0, 170.0, 0.0, -170.0) == pytest.approx(90.0)  # east across the dateline
    # intermediate points: equator midpoint, midpoint over the pole, and a dateline midpoint
    assert geo.gc_interpolate(0.0, 0.0, 0.0, 90.0, 0.5) == pytest.approx((0.0, 45.0), abs=1e-9)
    la, lo = geo.gc_interpolate(60.0, 0.0, 60.0, 180.0, 0.5)
    assert la == pytest.approx(90.0, abs=1e-6)
    la, lo = geo.gc_interpolate(0.0, 170.0, 0.0, -170.0, 0.5)
    assert la == pytest.approx(0.0, abs=1e-9) and abs(abs(lo) - 180.0) < 1e-9
    # an oblique case against slerp of unit vectors, and destination() as the inverse of distance + bearing
    p, q = (35.4, 139.7), (33.7, -118.3)
    d = geo.gc_distance_nm(*p, *q) / R_NM
    for f in (0.1, 0.37, 0.8):
        want = (np.sin((1 - f) * d) * unit(*p) + np.sin(f * d) * unit(*q)) / np.sin(d)
        assert unit(*geo.gc_interpolate(*p, *q, f)) == pytest.approx(want, abs=1e-9)
        la, lo = geo.gc_interpolate(*p, *q, f)
        assert geo.gc_distance_nm(*p, la, lo) == pytest.approx(f * d * R_NM, rel=1e-9)
    la, lo = geo.destination(*p, geo.gc_bearing_deg(*p, *q), geo.gc_distance_nm(*p, *q))
    assert geo.gc_distance_nm(la, lo, *q) < 1e-6
    assert geo.destination(0.0, 0.0, 90.0, R_NM * math.pi / 2) == pytest.approx((0.0, 90.0), abs=1e-9)  # a quarter east


def test_a_chord_steps_through_the_same_points_and_courses_as_the_formulas():
    # the leg kernel and the clearance checks step along a precomputed Chord: bit for bit what gc_interpolate and
    # gc_bearing_deg give, so routes, costs and the recorded solver results do not move with the speed-up
    rng = np.random.default_rng(7)
    for _ in range(2000):
        lat0, lat1 = rng.uniform(-80.0, 80.0, 2)
        lon0, lon1 = rng.uniform(-180.0, 360.0, 2)
        if rng.uniform() < 0.05:
            lat1, lon1 = lat0, lon0  # a zero-length chord
        chord = geo.chord(lat0, lon0, lat1, lon1)
        for f in (0.0, rng.uniform(), 1.0):
            point = geo.chord_point(chord, f)
            assert point == geo.gc_interpolate(lat0, lon0, lat1, lon1, f)
            assert geo.chord_course_deg(chord, *point) == geo.gc_bearing_deg(*point, lat1, lon1)


def test_numpys_great_circle_points_are_the_kernels_points():
    # the maps draw legs with sphere.gc_points (numpy: the picture process never loads numba); the same points as
    # gc_interpolate, across the dateline, for zero-length legs and at both ends
    rng = np.random.default_rng(11)
    lat0, lat1 = rng.uniform(-80.0, 80.0, (2, 3000))
    lon0, lon1 = rng.uniform(-180.0, 360.0, (2, 3000))
    lat1[:100], lon1[:100] = lat0[:100], lon0[:100]
    frac = np.concatenate([[0.0, 1.0], rng.uniform(0.0, 1.0, 2998)])
    got_lat, got_lon = gc_points(lat0, lon0, lat1, lon1, frac)
    want = np.array([geo.gc_interpolate(*args) for args in zip(lat0, lon0, lat1, lon1, frac)])
    np.testing.assert_allclose(got_lat, want[:, 0], rtol=0, atol=1e-12)
    np.testing.assert_allclose((got_lon - want[:, 1] + 180.0) % 360.0 - 180.0, 0.0, atol=1e-12)
    assert np.all((got_lon >= -180.0) & (got_lon < 180.0))
    # broadcast as the maps ask: a column of legs by a row of fractions
    lat, lon = gc_points(lat0[:5, None], lon0[:5, None], lat1[:5, None], lon1[:5, None], np.linspace(0.0, 1.0, 9))
    assert lat.shape == lon.shape == (5, 9)
    np.testing.assert_allclose(lat[:, 0], lat0[:5], atol=1e-12)


def test_yokohama_to_long_beach_stays_in_the_north_pacific():
    p, q = (35.4, 139.7), (33.7, -118.3)
    dist = geo.gc_distance_nm(*p, *q)
    assert dist == pytest.approx(haversine_nm(*p, *q), rel=1e-9)
    assert 4700.0 < dist < 4900.0  # ≈ 4,780 NM on this sphere
    pts = [geo.gc_interpolate(*p, *q, f) for f in np.linspace(0.0, 1.0, 201)]
    lats = np.array([a for a, _ in pts])
    lons = np.array([b for _, b in pts])
    assert np.all((lons >= 139.0) | (lons <= -118.0)), "the base route must cross the dateline, never 0°"
    # the arc's highest latitude is its vertex, by Clairaut: cos(lat_v) = cos(lat_0)·sin(course_0)
    vertex = math.degrees(math.acos(math.cos(math.radians(p[0])) * math.sin(math.radians(geo.gc_bearing_deg(*p, *q)))))
    assert lats.max() == pytest.approx(vertex, abs=0.01) and 47.0 < vertex < 48.0 and lats.min() >= 33.7 - 1e-9
    # consecutive points are ~24 NM apart (no jump round the world)
    steps = haversine_nm(lats[:-1], lons[:-1], lats[1:], lons[1:])
    assert steps == pytest.approx(dist / 200, rel=1e-6)
    space = build_search_space(p, q, n_lines=20, n_points=5, check_land=False)
    c = space.centre
    assert np.all((space.lon[:, c] >= 139.7 - 1e-9) | (space.lon[:, c] <= -118.3 + 1e-9))  # the base route itself
    assert np.all(np.abs(space.lon) > 100.0)  # lines ±956 NM wide, all still about the Pacific, none near 0°
    gaps = haversine_nm(space.lat[:-1, c], space.lon[:-1, c], space.lat[1:, c], space.lon[1:, c])
    assert gaps == pytest.approx(dist / 21, rel=1e-6)
    assert space.base_distance_nm == pytest.approx(dist)


def test_rhumb_line_is_never_shorter_than_the_great_circle():
    rng = np.random.default_rng(7)
    for _ in range(200):
        la1, la2 = rng.uniform(-70, 70, 2)
        lo1, lo2 = rng.uniform(-180, 180, 2)
        assert geo.rhumb_distance_nm(la1, lo1, la2, lo2) >= geo.gc_distance_nm(la1, lo1, la2, lo2) - 1e-6
    # equal on the equator and on a meridian; known values by hand elsewhere
    assert geo.rhumb_distance_nm(0.0, 10.0, 0.0, 40.0) == pytest.approx(30 * R_NM * math.radians(1), rel=1e-9)
    assert geo.rhumb_distance_nm(10.0, 20.0, 40.0, 20.0) == pytest.approx(30 * R_NM * math.radians(1), rel=1e-9)
    along_parallel = 20 * R_NM * math.radians(1) * math.cos(math.radians(35.0))  # 20° of longitude at 35° N
    assert geo.rhumb_distance_nm(35.0, 170.0, 35.0, -170.0) == pytest.approx(along_parallel, rel=1e-9)
    assert geo.rhumb_distance_nm(35.4, 139.7, 33.7, -118.3) > geo.gc_distance_nm(35.4, 139.7, 33.7, -118.3) + 200.0
    # a rhumb line holds its course: the bearing from any point on it to the end is the initial bearing
    b0 = geo.rhumb_bearing_deg(10.0, -30.0, 50.0, 20.0)
    for f in (0.25, 0.5, 0.75):
        la, lo = geo.rhumb_interpolate(10.0, -30.0, 50.0, 20.0, f)
        assert geo.rhumb_bearing_deg(la, lo, 50.0, 20.0) == pytest.approx(b0, abs=1e-6)
        assert geo.rhumb_distance_nm(10.0, -30.0, la, lo) == pytest.approx(f * geo.rhumb_distance_nm(10.0, -30.0, 50.0, 20.0), rel=1e-6)
    assert geo.rhumb_interpolate(0.0, 170.0, 0.0, -170.0, 0.25) == pytest.approx((0.0, 175.0), abs=1e-9)


# ---------------------------------------------------------------------------------------------- leg kernel


def test_calm_leg_takes_distance_over_stw_and_burns_rate_times_hours():
    calm = wf.uniform("2020-12-01T00", 200)
    for rpm in (70.0, 85.0, 100.0):
        stw = 14.0 * rpm / 100.0  # by hand from the reference model
        rate = 1.5 * (rpm / 100.0) ** 3
        assert float(MODEL.stw_kn(rpm, 10.0, 0.0)) == pytest.approx(stw)
        assert float(MODEL.fuel_tph(rpm, 10.0, 0.0)) == pytest.approx(rate)
        for (a, b) in (((0.0, 150.0), (0.0, 152.5)), ((30.0, -160.0), (33.0, -150.0)), ((40.0, 178.0), (41.0, -177.0))):
            dist = haversine_nm(*a, *b)
            out = lk.sail_leg(*a, *b, 6.0, rpm, vp(), calm)
            assert out[lk.CODE] == lk.OK and out[lk.BEYOND] == 0
            assert out[lk.H] == pytest.approx(dist / stw, rel=1e-9)
            assert out[lk.FUEL] == pytest.approx(rate * dist / stw, rel=1e-9)
            assert out[lk.STW_KN] == pytest.approx(stw) and out[lk.SOG_KN] == pytest.approx(stw)


def test_currents_wind_and_waves_act_along_the_course():
    leg = (0.0, 150.0, 0.0, 152.0)  # due east along the equator
    dist = haversine_nm(*leg)
    stw, rate = 11.9, 1.5 * 0.85**3  # 85 rpm
    for c in (0.5, 1.0, 2.0):
        for sign in (1.0, -1.0):  # +: following (setting east), −: head current
            f = wf.uniform("2020-12-01T00", 200, current_ms=(sign * c, 0.0))
            out = lk.sail_leg(*leg, 0.0, 85.0, vp(), f)
            sog = stw + sign * c * KN_PER_MS
            assert out[lk.SOG_KN] == pytest.approx(sog, rel=1e-9)
            assert out[lk.STW_KN] == pytest.approx(stw, rel=1e-9)
            assert out[lk.H] == pytest.approx(dist / sog, rel=1e-9)
            assert out[lk.FUEL] == pytest.approx(rate * dist / sog, rel=1e-9)
            assert out[lk.CUR_ALONG_KN] == pytest.approx(sign * c * KN_PER_MS, rel=1e-9)
    # a cross current (setting north) adds nothing along an eastward course
    f = wf.uniform("2020-12-01T00", 200, current_ms=(0.0, 1.5))
    assert lk.sail_leg(*leg, 0.0, 85.0, vp(), f)[lk.SOG_KN] == pytest.approx(stw)
    # 30 kn head wind (blowing towards the west, so coming FROM ahead) costs 1 kn and 0.0002·900 t/h
    f = wf.uniform("2020-12-01T00", 200, wind_ms=(-30.0 / KN_PER_MS, 0.0))
    out = lk.sail_leg(*leg, 0.0, 85.0, vp(), f)
    assert out[lk.STW_KN] == pytest.approx(stw - 1.0, rel=1e-6)  # the field stores float32
    assert out[lk.FUEL] == pytest.approx((rate + 0.18) * dist / (stw - 1.0), rel=1e-6)
    assert out[lk.WIND_KN] == pytest.approx(30.0, rel=1e-6)
    # 4 m head seas (coming from 090°) cost 1.5 kn and 0.01·16 t/h; following seas 0.14 of that (Kwon's shape)
    f = wf.uniform("2020-12-01T00", 200, swh_m=4.0, wave_from_deg=90.0)
    out = lk.sail_leg(*leg, 0.0, 85.0, vp(), f)
    assert out[lk.STW_KN] == pytest.approx(stw - 1.5, rel=1e-6)
    assert out[lk.FUEL] == pytest.approx((rate + 0.16) * dist / (stw - 1.5), rel=1e-6)
    f = wf.uniform("2020-12-01T00", 200, swh_m=4.0, wave_from_deg=270.0)
    out = lk.sail_leg(*leg, 0.0, 85.0, vp(), f)
    assert out[lk.STW_KN] == pytest.approx(stw - 0.14 * 1.5, rel=1e-6)
    assert out[lk.FUEL] == pytest.approx((rate + 0.14 * 0.16) * dist / (stw - 0.14 * 1.5), rel=1e-6)
    # limits: Hs 4 m against a 3.5 m limit, 30 kn wind against 25 kn, a head current the ship cannot stem
    f = wf.uniform("2020-12-01T00", 200, swh_m=4.0, wave_from_deg=90.0)
    assert lk.sail_leg(*leg, 0.0, 85.0, vp(max_hs=3.5), f)[lk.CODE] == lk.WAVE_LIMIT
    f = wf.uniform("2020-12-01T00", 200, wind_ms=(-30.0 / KN_PER_MS, 0.0))
    assert lk.sail_leg(*leg, 0.0, 85.0, vp(max_wind=25.0), f)[lk.CODE] == lk.WIND_LIMIT
    f = wf.uniform("2020-12-01T00", 200, current_ms=(-6.0, 0.0))  # 11.66 kn against 11.9 kn: SOG 0.24 < 0.5
    assert lk.sail_leg(*leg, 0.0, 85.0, vp(), f)[lk.CODE] == lk.NO_HEADWAY


def test_weather_sampling_interpolates_time_space_and_direction():
    # unequal valid-time intervals (0, 10, 30 h) with a current growing 0.1 m/s per hour; u10 = latitude;
    # waves from 350° then from 010° (the mean direction is north, not south)
    lat, lon = np.array([10.0, 20.0]), np.array([150.0, 160.0])
    t0 = np.datetime64("2020-12-01T00")
    times = t0 + np.array([0, 10, 30]).astype("timedelta64[h]")
    ramp = np.array([0.0, 1.0, 3.0])[:, None, None] * np.ones((3, 2, 2))
    u10 = np.broadcast_to(lat[None, :, None], (3, 2, 2))
    mwd = np.broadcast_to(np.array([350.0, 10.0, 10.0])[:, None, None], (3, 2, 2))
    f = wf.from_arrays(lat, lon, times, u10=u10, v10=np.zeros((3, 2, 2)), swh=ramp, mwd_deg=mwd, uo=ramp, vo=ramp)
    out = np.empty(wf.N_VARS)
    for t_h, want in ((0.0, 0.0), (5.0, 0.5), (10.0, 1.0), (20.0, 2.0), (27.0, 2.7)):
        assert not wf.sample_nb(f.kernel, t_h, 12.5, 155.0, out)
        assert out[wf.UO] == pytest.approx(want, abs=1e-6) and out[wf.SWH] == pytest.approx(want, abs=1e-6)
        assert out[wf.U10] == pytest.approx(12.5, abs=1e-5)
    wf.sample_nb(f.kernel, 5.0, 15.0, 151.0, out)
    assert math.degrees(math.atan2(out[wf.WAVE_X], out[wf.WAVE_Y])) == pytest.approx(0.0, abs=1e-4)
    assert wf.sample_nb(f.kernel, 40.0, 15.0, 151.0, out)  # past the horizon: flagged, persisted
    assert out[wf.UO] == pytest.approx(3.0)
    # stored per grid point (the sampling layout), offered variable by variable as before; latitudes given
    # north to south are stored south to north, and sample the same
    assert f.cells.shape == (2, 2, 3, wf.N_VARS) and f.cells.flags.c_contiguous and f.cells.dtype == np.float32
    np.testing.assert_array_equal(f.values[wf.U10], u10)
    np.testing.assert_array_equal(f.values[wf.SWH], ramp)
    flipped = wf.from_arrays(lat[::-1], lon, times, u10=u10[:, ::-1], v10=np.zeros((3, 2, 2)), swh=ramp,
                             mwd_deg=mwd, uo=ramp, vo=ramp)
    np.testing.assert_array_equal(flipped.cells, f.cells)


@pytest.mark.slow
def test_compiled_leg_equals_the_pure_python_twin():
    fld = field(wavy(3))
    rng = np.random.default_rng(11)
    for _ in range(6):
        lat0, lon0 = rng.uniform(15, 45), rng.uniform(-175, -115)
        lat1, lon1 = geo.destination(lat0, lon0, rng.uniform(0, 360), rng.uniform(20, 200))
        rpm, t0 = rng.uniform(60, 100), rng.uniform(0, 300)
        v = vp(step_h=rng.choice([0.25, 1.0]))
        fast = lk.sail_leg(lat0, lon0, lat1, lon1, t0, rpm, v, fld)
        slow = lk.sail_leg_python(lat0, lon0, lat1, lon1, t0, rpm, v, fld)
        assert fast[lk.CODE] == lk.OK and fast[lk.H] > 0
        np.testing.assert_allclose(fast, slow, rtol=1e-9, atol=1e-12)


def test_splitting_a_leg_does_not_change_its_hours():
    # constant course (equator) in a static uniform field with wind, waves and current: exact
    f = wf.uniform("2020-12-01T00", 200, wind_ms=(4.0, -3.0), swh_m=3.0, wave_from_deg=60.0, current_ms=(-0.7, 0.3))
    whole = lk.sail_leg(0.0, 150.0, 0.0, 153.0, 0.0, 85.0, vp(), f)
    a = lk.sail_leg(0.0, 150.0, 0.0, 151.1, 0.0, 85.0, vp(), f)
    b = lk.sail_leg(0.0, 151.1, 0.0, 153.0, a[lk.H], 85.0, vp(), f)
    assert a[lk.H] + b[lk.H] == pytest.approx(whole[lk.H], rel=1e-12)
    assert a[lk.FUEL] + b[lk.FUEL] == pytest.approx(whole[lk.FUEL], rel=1e-12)
    # an oblique leg in a static non-uniform field, with fine steps: equal up to the step discretisation
    fld = field(wavy(5))
    p, q = (25.0, -170.0), (31.0, -160.0)
    m = geo.gc_interpolate(*p, *q, 0.4)
    v = vp(step_h=0.05)
    whole = lk.sail_leg(*p, *q, 0.0, 85.0, v, fld)
    a = lk.sail_leg(*p, *m, 0.0, 85.0, v, fld)
    b = lk.sail_leg(*m, *q, a[lk.H], 85.0, v, fld)
    assert a[lk.H] + b[lk.H] == pytest.approx(whole[lk.H], rel=1e-5)
    assert a[lk.FUEL] + b[lk.FUEL] == pytest.approx(whole[lk.FUEL], rel=1e-5)


# ---------------------------------------------------------------------------------------------- solvers


def test_calm_sea_route_is_the_great_circle():
    dep, arr = (30.0, -160.0), (35.0, -130.0)
    pr = problem(dep, arr, 144)
    space = pr.search_space()
    calm = wf.uniform("2020-12-01T00", 400)
    for solver in ("dp", "bfoa"):
        plan = solve(pr, calm, solver=solver, seed=3, params=FAST, space=space)
        assert plan.status == "ok", plan.reason
        assert np.all(node_offsets(plan, space) == 0), solver
        assert plan.distance_nm == pytest.approx(haversine_nm(*dep, *arr), rel=1e-9)
        assert plan.hours <= pr.t_req_h + 1e-9
        for g in plan.legs:  # every leg in calm water: dist/stw hours at its rpm, rate × hours fuel
            stw, rate = 0.14 * g["rpm"], 1.5 * (g["rpm"] / 100) ** 3
            assert g["hours"] == pytest.approx(g["dist_nm"] / stw, rel=1e-9)
            assert g["fuel_t"] == pytest.approx(rate * g["hours"], rel=1e-9)
        # in calm water the constant speed that arrives at the RTA is the best plan (fuel per NM is convex in
        # speed): the plan is that voyage, at the one rpm between the settings that uses all the slack to the RTA
        assert plan.fuel_t == pytest.approx(plan.baseline.fuel_t, rel=1e-9) and abs(plan.savings_pct) < 1e-7
        assert pr.t_req_h - 1e-2 <= plan.baseline.hours <= pr.t_req_h + 1e-9
        assert plan.baseline.legs[0]["rpm"] not in pr.rpm_options


STORM_DEP, STORM_ARR = (30.0, -160.0), (35.0, -130.0)


def storm_field(hs_storm):
    mlat, mlon = geo.gc_interpolate(*STORM_DEP, *STORM_ARR, 0.5)

    def fn(LA, LO):
        inside = haversine_nm(LA, LO, mlat, mlon) < 200.0
        return dict(swh=np.where(inside, hs_storm, 1.0), mwd_deg=np.full(LA.shape, 90.0))
    return field(fn)


def test_storm_on_the_great_circle_is_avoided():
    storm = storm_field(8.0)
    pr = problem(STORM_DEP, STORM_ARR, 144)
    space = pr.search_space()
    base = solve(pr, storm, solver="gc", space=space)
    assert base.status == "ok" and max(g["hs_m"] for g in base.legs) > 7.0  # the baseline ploughs through it
    for solver, params in (("dp", None), ("bfoa", MEDIUM)):
        plan = solve(pr, storm, solver=solver, seed=1, params=params, space=space)
        assert plan.status == "ok", plan.reason
        offs = node_offsets(plan, space)
        mid = space.n_lines // 2
        assert np.all(np.abs(offs[mid - 1:mid + 3]) >= 3), (solver, offs)  # ≥ 185 NM off the great circle mid-route
        assert max(g["hs_m"] for g in plan.legs) < 1.5
        assert plan.baseline.fuel_t == pytest.approx(base.fuel_t)
        assert plan.savings_pct > 20.0, (solver, plan.savings_pct)
        assert plan.fuel_t < base.fuel_t and plan.hours <= pr.t_req_h + 1e-9
    # with a 6 m wave limit the great circle is impossible and the solvers still find a way round
    pr6 = problem(STORM_DEP, STORM_ARR, 144, max_hs_m=6.0)
    gc = solve(pr6, storm, solver="gc", space=space)
    assert gc.status == "infeasible" and "wave height" in gc.reason
    for solver in ("dp", "bfoa"):
        plan = solve(pr6, storm, solver=solver, seed=1, params=FAST, space=space)
        assert plan.status == "ok" and max(g["hs_m"] for g in plan.legs) < 6.0


def test_opposing_current_band_is_avoided():
    dep, arr = (0.0, -145.0), (0.0, -115.0)  # due east along the equator
    band = field(lambda LA, LO: dict(uo=np.where(np.abs(LA) < 1.5, -1.5, 0.0)), lat=(-12.0, 12.0), lon=(200.0, 250.0))
    pr = problem(dep, arr, 192)
    space = pr.search_space()
    for solver, params in (("dp", None), ("bfoa", FAST)):
        plan = solve(pr, band, solver=solver, seed=2, params=params, space=space)
        assert plan.status == "ok", plan.reason
        lats = np.array([la for la, _ in plan.waypoints])
        assert np.all(np.abs(lats[2:-2]) > 1.5), (solver, lats)  # out of the band for the middle of the voyage
        head = [g["current_kn"] for g in plan.legs[2:-2]]
        assert max(head) < 0.5
        assert plan.baseline.status == "ok" and plan.baseline.legs[5]["current_kn"] == pytest.approx(1.5 * KN_PER_MS, rel=1e-3)
        assert plan.fuel_t < plan.baseline.fuel_t and plan.savings_pct > 5.0, (solver, plan.savings_pct)


def test_impossible_rta_gives_the_least_late_plan():
    dep, arr = (30.0, -160.0), (35.0, -130.0)
    dist = haversine_nm(*dep, *arr)
    fastest_h = dist / 14.0
    pr = problem(dep, arr, 0.8 * fastest_h)
    calm = wf.uniform("2020-12-01T00", 400)
    for solver in ("dp", "bfoa", "astar", "gc"):
        plan = solve(pr, calm, solver=solver, seed=1, params=FAST)
        assert plan.status == "late", solver
        assert "RTA" in plan.reason and "late" in plan.reason
        assert all(g["rpm"] == 100.0 for g in plan.legs), solver
        assert plan.hours >= pr.t_req_h
        assert plan.hours == pytest.approx(fastest_h, rel=1e-9), solver  # the great circle at full speed
        assert f"{plan.hours - pr.t_req_h:.1f} h late" in plan.reason


@pytest.mark.parametrize("name, dep, arr, kw", [
    # Nojima-zaki → Kii Channel: the great circle crosses the Izu islands and the Kii peninsula
    # (16 lines: with 12, no node of the last line is both 2 NM clear of the Kii coast and in reach of the arrival)
    ("japan", (34.85, 139.85), (33.9, 135.0), dict(n_lines=16, n_points=15, d_point_nm=12.0)),
    # Singapore Strait, east entrance → west of Sentosa, among the southern islands (the fairway passes them
    # closer than the default 2 NM clearance)
    ("singapore", (1.25, 104.5), (1.15, 103.55), dict(n_lines=12, n_points=15, d_point_nm=1.0, land_clearance_nm=0.5)),
])
def test_routes_stay_at_sea_along_real_coasts(name, dep, arr, kw):
    def at_sea_everywhere(lat0, lon0, lat1, lon1, step_nm):
        n = max(2, int(math.ceil(haversine_nm(lat0, lon0, lat1, lon1) / step_nm)))
        pts = np.array([geo.gc_interpolate(lat0, lon0, lat1, lon1, k / n) for k in range(n + 1)])
        return bool(np.all(globe.is_ocean(pts[:, 0], pts[:, 1])))

    assert not at_sea_everywhere(*dep, *arr, 0.5), "the straight line must cross land for this test to mean anything"
    pr = problem(dep, arr, 30, **kw)
    space = pr.search_space()
    calm = wf.uniform("2020-12-01T00", 400)
    for solver in ("dp", "bfoa", "gc"):
        plan = solve(pr, calm, solver=solver, seed=1, params=FAST, space=space)
        assert plan.status == "ok", (name, solver, plan.reason)
        step = 0.1 if name == "singapore" else 1.0
        for g in plan.legs:
            assert at_sea_everywhere(g["lat0"], g["lon0"], g["lat1"], g["lon1"], step), (name, solver, g["leg"])
        assert plan.distance_nm > haversine_nm(*dep, *arr)  # it went round


def test_dateline_crossing_routes_like_the_great_circle():
    dep, arr = (35.0, 160.0), (35.0, -160.0)
    gc_nm = haversine_nm(*dep, *arr)
    assert gc_nm == pytest.approx(1953.7, abs=1.0)
    pr = problem(dep, arr, 168)
    calm = wf.uniform("2020-12-01T00", 400)
    for solver in ("dp", "bfoa"):
        plan = solve(pr, calm, solver=solver, seed=1, params=FAST)
        assert plan.status == "ok", plan.reason
        assert plan.distance_nm == pytest.approx(gc_nm, rel=0.005)
        assert max(g["dist_nm"] for g in plan.legs) < 300.0
        lons = np.array([lo for _, lo in plan.waypoints])
        assert np.all(np.abs(lons) >= 155.0)  # never round by 0°
        assert (lons > 0).any() and (lons < 0).any()
        assert plan.hours <= pr.t_req_h


def test_bfoa_engine_reset_keeps_arrival_inside_the_rta():
    """The RTA-aimed engine settings and the engine re-set after a route move (calm water: leg hours are exactly
    distance / STW, so hand formulas check them)."""
    from pipeline.routing.engine import timing as engine_timing

    dep, arr = (30.0, -160.0), (35.0, -130.0)
    dist = haversine_nm(*dep, *arr)
    hours = dist / (0.14 * 77.5)  # between the 70 and 85 rpm passages: a mix of both is needed
    pr = problem(dep, arr, hours, n_lines=10, n_points=11)
    space = pr.search_space()
    calm = wf.uniform("2020-12-01T00", 400)
    inst = Instance.build(pr, space, calm)
    voyage = (inst.graph, inst.vessel, inst.wx, inst.objective)
    L2 = space.lat.shape[0]
    s = engine_timing.scratch(L2)
    ct = s.ct
    rpm = np.empty(L2 - 1, np.int64)
    gc = space.base_route()
    for seed in range(1, 6):
        q = engine_timing.aim_engine_nb(lk.Voyage(*voyage), gc.copy(), rpm, s, np.random.default_rng(seed))
        t_arr = ct[-1] - inst.t_dep_h
        assert pr.t_req_h - pr.window_h <= t_arr <= pr.t_req_h + 1e-9, (seed, t_arr)
        assert {0, 1} <= set(rpm.tolist())  # a mix of the two settings that bracket the RTA
        assert q == pytest.approx(_evaluate(inst, gc, rpm)[0], rel=1e-12)
        # cheaper than holding the listed setting that meets the RTA (85 rpm), dearer than the exact constant speed
        assert q < _evaluate(inst, gc, np.full(L2 - 1, 1))[0]
        assert q > solve(pr, calm, solver="gc", space=space).cost
    # a detour (two nodes off for four lines) makes the same settings late; the re-set speeds legs up to be on time
    detour = gc.copy()
    detour[3:9] += np.array([1, 2, 2, 2, 2, 1])
    late_cost, late_h, _, _ = _evaluate(inst, detour, rpm)
    assert late_h > pr.t_req_h and late_cost > LATE_STEP_T
    s2 = engine_timing.scratch(L2)
    lk.sail_route_nb(detour, rpm, 0, *voyage, s2.ct, s2.cf)
    rpm2 = rpm.copy()
    q2 = engine_timing.retime_nb(lk.Voyage(*voyage), detour, rpm2, 0, late_cost, np.inf, s2,
                                 np.random.default_rng(1))
    assert s2.ct[-1] - inst.t_dep_h <= pr.t_req_h + 1e-9
    assert q2 < LATE_STEP_T and q2 == pytest.approx(_evaluate(inst, detour, rpm2)[0], rel=1e-12)
    assert np.all(rpm2 >= rpm) and rpm2.sum() > rpm.sum()  # legs only sped up
    # with a bar below any on-time plan the re-set gives up instead of sailing (jit objective)
    rpm3 = rpm.copy()
    lk.sail_route_nb(detour, rpm3, 0, *voyage, s2.ct, s2.cf)
    assert engine_timing.retime_nb(lk.Voyage(*voyage), detour, rpm3, 0, late_cost, 1.0, s2,
                                   np.random.default_rng(1)) == math.inf


def test_bfoa_is_reproducible_by_seed():
    fld = field(wavy(2))
    pr = problem((30.0, -160.0), (33.0, -145.0), 90, n_lines=8, n_points=9)
    space = pr.search_space()
    runs = {s: [solve(pr, fld, solver="bfoa", seed=s, params=FAST, space=space) for _ in range(2)] for s in (1, 2, 3, 4)}
    for s, (a, b) in runs.items():
        assert a.waypoints == b.waypoints and [g["rpm"] for g in a.legs] == [g["rpm"] for g in b.legs]
        assert a.cost == b.cost and a.n_evals == b.n_evals
        np.testing.assert_array_equal(a.history, b.history)
    # the seed is actually used: the searches differ between seeds (results may coincide)
    assert len({(r[0].n_evals, tuple(r[0].history)) for r in runs.values()}) > 1


DP_CASES = [  # (dep, arr, hours to the RTA, rpm options, weather seed, objective)
    ((30.0, -160.0), (33.0, -145.0), 90, (70, 85, 100), 0, "jit"),
    ((25.0, -150.0), (20.0, -138.0), 80, (75, 100), 1, "jit"),
    ((40.0, -170.0), (38.0, -155.0), 96, (70, 85, 100), 2, "jit"),
    ((35.0, -140.0), (28.0, -132.0), 64, (80, 100), 3, "thesis"),
]


def test_dp_is_never_beaten_and_bfoa_comes_close():
    for dep, arr, hours, rpms, wseed, obj in DP_CASES:
        fld = field(wavy(wseed))
        pr = problem(dep, arr, hours, rpm_options=rpms, objective=obj, n_lines=6, n_points=9)
        space = pr.search_space()
        dp = solve(pr, fld, solver="dp", space=space)
        assert dp.status == "ok", dp.reason
        gaps = []
        for seed in (1, 2, 3):
            b = solve(pr, fld, solver="bfoa", seed=seed, params=MEDIUM, space=space)
            assert b.status == "ok"
            assert dp.cost <= b.cost * (1 + 1e-3), (dep, seed, dp.cost, b.cost)  # only DP's time bucket may lose a little
            gaps.append(b.cost / dp.cost - 1.0)
        assert np.median(gaps) <= 0.02, (dep, gaps)
        assert dp.cost <= solve(pr, fld, solver="gc", space=space).cost * (1 + 1e-3)


def test_astar_arrives_by_the_rta_on_the_least_fuel_it_can():
    """A* alone arrives early at high rpm; with the engine plan per swept route it meets the RTA inside the window,
    never beats the exact DP, and is far cheaper than the fastest plan on its route."""
    from pipeline.routing.astar import AstarOptions

    fld = field(wavy(2))
    pr = problem((30.0, -160.0), (33.0, -145.0), 72, n_lines=8, n_points=9)
    space = pr.search_space()
    dp = solve(pr, fld, solver="dp", space=space)
    time_only = solve(pr, fld, solver="astar", space=space, options=AstarOptions(alphas=(0.0,)))
    full = solve(pr, fld, solver="astar", space=space)
    for plan in (time_only, full):
        assert plan.status == "ok" and plan.reason is None, plan.reason  # no "arrives … before the window"
        assert pr.t_req_h - pr.window_h <= plan.hours <= pr.t_req_h + 1e-9
        assert plan.cost >= dp.cost - 1e-9
        assert max(g["rpm"] for g in plan.legs) < 100.0  # slowed where it can, not 100 rpm throughout
    assert full.cost <= time_only.cost
    # every leg at full speed on the same route: what the α = 0 search alone used to sail
    fastest = _evaluate(Instance.build(pr, space, fld), np.array([space.centre] * 10),
                        np.full(9, 2))
    assert fastest[1] < pr.t_req_h - pr.window_h and time_only.fuel_t < 0.8 * fastest[2]


@pytest.mark.slow
def test_dp_equals_exhaustive_search_on_a_tiny_graph():
    for wseed, obj, rpms in ((7, "jit", (70, 85, 100)), (8, "thesis", (75, 100))):
        fld = field(wavy(wseed))
        pr = problem((32.0, -150.0), (29.0, -142.0), 40, rpm_options=rpms, objective=obj, n_lines=3, n_points=5,
                     max_shift=2)
        space = pr.search_space()
        dp = solve(pr, fld, solver="dp", space=space, continuous=False)  # over the settings, as enumerated here
        smooth = solve(pr, fld, solver="dp", space=space)  # the product's: speeds then refined continuously
        inst, _ = solver_instance(pr, space, fld)  # listed settings + the constant-speed rpm
        inst.f_target = dp.baseline.fuel_t  # as solve() sets it
        best = math.inf
        for mid in itertools.product(range(5), repeat=3):
            nodes = np.array((2, *mid, 2))
            for rr in itertools.product(range(len(inst.rpm_options)), repeat=4):
                best = min(best, _evaluate(inst, nodes, np.array(rr))[0])
        assert math.isfinite(best)
        assert dp.cost == pytest.approx(best, rel=1e-3), obj
        assert dp.cost >= best - 1e-9
        assert smooth.cost <= dp.cost + 1e-9 and smooth.hours <= pr.t_req_h + 1e-9  # refining never costs more


# ---------------------------------------------------------------------------------------------- objectives


def test_thesis_quality_function_as_published():
    T_req, F_t = 100.0, 50.0

    def q(hours, fuel):
        o = objective("thesis", t_dep_h=0.0, max_hours=1e3, t_req_h=T_req, window_h=6.0, f_target=F_t)
        return route_cost_nb(o, hours, fuel)

    assert q(100.0, 40.0) == pytest.approx(1.0 + 9999.9)  # T = T_req counts as late
    assert q(120.0, 10.0) == pytest.approx(1.2 + 9999.9)  # late: fuel ignored
    assert q(150.0, 0.0) > q(120.0, 80.0)
    assert q(85.0, 50.0) == pytest.approx(0.85 + 3.0)  # T = 0.85·T_req: the lower branch
    assert q(60.0, 25.0) == pytest.approx(0.85 + 1.5)  # fast: time ignored
    assert q(10.0, 25.0) == q(60.0, 25.0)
    assert q(90.0, 50.0) == pytest.approx(0.90 + 3.0)
    assert q(99.9, 20.0) == pytest.approx(0.999 + 1.2)


def test_jit_objective_ranks_on_time_before_late_and_penalises_early_mildly():
    T_req, W, early, late = 100.0, 6.0, 0.2, 1.0e4

    def q(hours, fuel):
        o = objective("jit", t_dep_h=0.0, max_hours=1e3, t_req_h=T_req, window_h=W, early_t_per_h=early,
                      late_t_per_h=late)
        return route_cost_nb(o, hours, fuel)

    # inside the window [RTA − 6 h, RTA]: just the fuel
    for h in (94.0, 97.0, 100.0):
        assert q(h, 42.0) == pytest.approx(42.0)
    # late: fuel + 1000 t + 1e4 t per hour late
    assert q(100.5, 42.0) == pytest.approx(42.0 + LATE_STEP_T + 5000.0)
    assert q(100.01, 0.0) > q(100.0, LATE_STEP_T - 1.0)  # an on-time plan beats a late one burning up to 1000 t less
    for late_h in (1e-3, 0.1, 5.0):
        for f_late in (0.0, 100.0):
            assert q(T_req + late_h, f_late) > q(T_req, f_late + 500.0)
    assert q(101.0, 100.0) < q(102.0, 0.0)  # among late plans the least late wins
    # early: 0.2 t per hour before the window, far less than the lateness penalty
    assert q(90.0, 42.0) == pytest.approx(42.0 + 0.2 * 4.0)
    assert q(50.0, 42.0) == pytest.approx(42.0 + 0.2 * 44.0)
    assert q(90.0, 40.0) < q(94.0, 42.0)  # arriving early still pays when it saves more fuel than the penalty
    assert q(90.0, 41.5) > q(94.0, 41.0)


def test_honest_baseline_and_savings_split_in_calm_water():
    """In calm water the honest baseline holds rpm = distance / (0.14 · hours to the RTA) and burns
    1.5·(rpm/100)³ t/h for exactly those hours; a constant speed is then the cheapest way to arrive on time
    (fuel per mile grows with speed), so the discrete-rpm plans save nothing against it and the route adds
    nothing either (the great circle is shortest)."""
    from pipeline.routing.savings import savings_split

    dep, arr = (30.0, -160.0), (35.0, -130.0)
    dist = haversine_nm(*dep, *arr)
    hours = dist / (0.14 * 77.5)
    pr = problem(dep, arr, hours, n_lines=10, n_points=11)
    space = pr.search_space()
    calm = wf.uniform("2020-12-01T00", 400)
    plan = solve(pr, calm, solver="dp", space=space)
    split = savings_split(pr, calm, plan, space)
    rpm = dist / (0.14 * pr.t_req_h)  # ≈ 77.5 (the RTA is whole minutes)
    assert split.baseline_rpm == pytest.approx(rpm, rel=1e-5)
    assert split.baseline_hours == pytest.approx(pr.t_req_h, abs=2e-3) and split.baseline_hours <= pr.t_req_h
    assert split.baseline_fuel_t == pytest.approx(1.5 * (rpm / 100) ** 3 * pr.t_req_h, rel=1e-4)
    assert split.speed_profile_pct == pytest.approx(0.0, abs=1e-9)  # nothing beats the one exact speed
    assert split.route_pct == pytest.approx(0.0, abs=1e-9)  # the DP's plan is on the great circle
    assert split.total_pct == pytest.approx(split.speed_profile_pct + split.route_pct)
    assert plan.savings_pct == pytest.approx(split.total_pct, abs=1e-9)  # its baseline is the constant speed


def _bfoa_start(pr, fld, params, seed=1):
    """The initial swarm of the BFOA on a voyage: (swarm, instance, knobs)."""
    from pipeline.routing.engine import timing as engine_timing
    from pipeline.routing.engine import swarm
    from pipeline.routing.baseline import baseline

    inst = Instance.build(pr, pr.search_space(), fld)
    base = baseline(inst)
    L2, P = inst.graph.lat.shape
    k = params.knobs(L2 - 2, P, inst.graph.max_shift)
    sw, s, wk = swarm.swarm(k.n_bacteria, L2), engine_timing.scratch(L2), swarm.work(L2)
    no_branches = np.empty((0, L2), np.int64)
    run = swarm.SwarmRun(inst.voyage, s, k, wk)
    swarm.init_swarm_nb(sw, base.nodes, base.rpm_idx, no_branches, run, np.random.default_rng(seed))
    return sw, inst, k


def test_bfoa_offset_routes_start_feasible_where_the_baseline_is_not():
    """Behind a storm above the wave limit the baseline (bacterium 0) cannot be sailed; the offset routes, spread
    from one side of the graph to the other, give the swarm feasible starts on both sides of it."""
    pr6 = problem(STORM_DEP, STORM_ARR, 144, max_hs_m=6.0)
    sw, inst, k = _bfoa_start(pr6, storm_field(8.0), FAST)
    c = inst.graph.lat.shape[1] // 2
    assert sw.cost[0] == math.inf and k.n_offset == FAST.n_bacteria - 1
    for i, edge in ((1, -c), (k.n_offset, c)):  # the outermost offset routes round the storm on either side
        off = sw.pos[i] - c
        assert sw.cost[i] < math.inf and off[np.argmax(np.abs(off))] == edge
        assert sw.cost[i] == pytest.approx(_evaluate(inst, sw.pos[i], sw.rpm[i])[0], rel=1e-12)
    assert sw.best_cost[0] < math.inf


def test_offset_route_goes_out_along_and_back():
    from pipeline.routing.engine.random_walk import Walk, random_walk_nb

    space = problem((30.0, -160.0), (35.0, -130.0), 144, n_lines=12, n_points=11).search_space()
    L2, c = space.lat.shape[0], space.centre
    nodes = np.empty(L2, np.int64)
    for offset in (-5, -2, 0, 3, 5):
        assert random_walk_nb(nodes, space.edge_ok, space.max_shift, Walk(12, 4000, 2, 0.0, 0.0, 1.0), offset,
                              np.random.default_rng(offset + 9))
        o = nodes - c
        k = abs(offset)
        i = np.arange(L2)
        expect = np.minimum(np.minimum(i, k), np.maximum(L2 - 2 - i, 0)) * np.sign(offset)  # home a line early
        np.testing.assert_array_equal(o, expect)


def test_bfoa_block_shift_moves_a_whole_plateau():
    from pipeline.routing.engine.swarm import _block

    nodes = np.array([5, 6, 7, 8, 8, 8, 8, 8, 8, 7, 6, 5], np.int64)  # out, a plateau on lines 3..8, back
    L = len(nodes) - 2
    vec = np.zeros(len(nodes), np.int64)
    seen = set()
    for seed in range(40):
        vec[:] = 0
        first = _block(L, nodes, vec, np.random.default_rng(seed))
        moved = np.flatnonzero(vec)
        assert moved[0] == first and np.all(np.diff(moved) == 1) and len(set(vec[moved].tolist())) == 1
        block = (int(moved[0]), int(moved[-1]))
        # the plateau itself, or from a line off it 4..L/2 lines (cut at the last inner line)
        assert block == (3, 8) or (first in (1, 2, 9, 10) and block[1] in (min(L, first + 3), min(L, first + 4)))
        seen.add(block)
    assert (3, 8) in seen and len(seen) > 2


def test_bfoa_stall_stop_ends_a_run_that_no_longer_gains():
    """Calm water: the swarm finds the great circle at once and stops `stall_cycles` cycles later; without the
    stall stop it runs every cycle. A run stops only after that many cycles without a gain of stall_tol."""
    pr = problem((30.0, -160.0), (35.0, -140.0), 110, n_lines=8, n_points=9)
    calm = wf.uniform("2020-12-01T00", 400)
    params = BfoaParams(n_bacteria=12, n_chemo=6, n_cycles=30, stall_cycles=4)
    stalled = solve(pr, calm, solver="bfoa", seed=1, params=params)
    full = solve(pr, calm, solver="bfoa", seed=1, params=BfoaParams(n_bacteria=12, n_chemo=6, n_cycles=30,
                                                                    stall_cycles=0))
    assert len(full.history) == 30 and len(stalled.history) < 30
    np.testing.assert_array_equal(stalled.history, full.history[:len(stalled.history)])  # the same run, cut
    h = stalled.history
    assert h[-1] >= h[-params.stall_cycles] * (1 - params.stall_tol)  # the last cycles gained nothing
    assert stalled.n_evals < full.n_evals and stalled.cost <= full.history[-1] * (1 + 1e-3)
    # round a storm a swarm started without the branch routes still gains after its first cycle: it stops later
    # than in calm water; started on them (the default) it is round the storm from the first cycle and stops as
    # early as in calm water, on a plan no dearer
    pr6, storm_f = problem(STORM_DEP, STORM_ARR, 144, max_hs_m=6.0), storm_field(8.0)
    unbranched = BfoaParams(n_bacteria=12, n_chemo=6, n_cycles=30, stall_cycles=4, branch_routes=False)
    storm = solve(pr6, storm_f, solver="bfoa", seed=1, params=unbranched)
    assert storm.status == "ok" and len(storm.history) > len(h)
    branched = solve(pr6, storm_f, solver="bfoa", seed=1, params=params)
    assert branched.status == "ok" and len(branched.history) == params.stall_cycles
    assert branched.cost <= storm.cost * (1 + 1e-9) and branched.n_evals < storm.n_evals
