"""The weather ranges the exact DP's bounds are priced in, and those bounds, against what the ship really meets.

The ranges must hold for every sample the leg kernel takes from the corners they were made of (sampled here at
random places and times, NaN holes included); the bound tables built from them must stay below the fuel and hours
of every plan that keeps within the windows, enumerated on small graphs with moving storms."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from routing_cases import field, moving_storm, problem
from pipeline.performance.features import direction_weight
from pipeline.routing import bound_tables as bt
from pipeline.routing import geodesy as geo
from pipeline.routing.engine import leg as lk
from pipeline.routing.engine.bounds import fuel_to_finish_lb
from pipeline.routing.problem import Instance
from pipeline.routing.reachable_weather import _box_ranges, _cos_range, _course_range_nb, _edge_box
from pipeline.routing.weather_field import SWH, U10, UO, V10, VO, WAVE_X, WAVE_Y, Grid, Weather, sample_nb

DEP, ARR = (30.0, -160.0), (33.0, -150.0)  # ≈ 560 NM: 70 rpm ≈ 57 h, 100 rpm ≈ 40 h in calm water


@pytest.mark.parametrize("seed", range(6))
def test_cos_range_by_sampling(seed):
    rng = np.random.default_rng(seed)
    for _ in range(200):
        lo = rng.uniform(-400.0, 400.0)
        hi = lo + rng.choice([rng.uniform(0.0, 20.0), rng.uniform(0.0, 200.0), rng.uniform(0.0, 400.0)])
        c = np.cos(np.radians(np.linspace(lo, hi, 20001)))
        got_lo, got_hi = _cos_range(lo, hi)
        assert got_lo <= c.min() + 1e-12 and got_hi >= c.max() - 1e-12
        assert got_lo >= c.min() - 1e-6 and got_hi <= c.max() + 1e-6  # and not looser than it has to be


@pytest.mark.parametrize("lat0, lon0, lat1, lon1", [(30.0, -160.0, 31.0, -155.0), (48.0, 170.0, 44.0, -175.0),
                                                    (-20.0, 10.0, -25.0, 18.0), (2.0, 100.0, -3.0, 104.0),
                                                    (33.0, 179.5, 33.5, -179.0)])
def test_course_range_holds_along_the_chord(lat0, lon0, lat1, lon1):
    """Every course the kernel takes along a leg (at its step starts) lies in the range."""
    lo, hi = _course_range_nb(lat0, lon0, lat1, lon1)
    ch = geo.chord(lat0, lon0, lat1, lon1)
    for f in np.linspace(0.0, 0.999, 200):
        crs = geo.chord_course_deg(ch, *geo.chord_point(ch, f))
        assert any(lo - 1e-9 <= crs + k * 360.0 <= hi + 1e-9 for k in (-1, 0, 1)), (crs, lo, hi)
    if lat0 * lat1 > 0:
        assert hi - lo < 20.0  # a real range, not the whole compass


@pytest.mark.parametrize("wraps", [True, False])
def test_edge_box_holds_every_corner_the_leg_reads(wraps):
    """Sampling anywhere on a leg reads only corners inside its box: Hs is 1 m in the box and 1,000 m outside."""
    rng = np.random.default_rng(7)
    grid = Grid(10.0, 1.0, 41, 0.0, 1.0, 360, True) if wraps else Grid(10.0, 0.5, 81, 150.0, 0.5, 141, False)
    for _ in range(300):
        lat0, lon0 = rng.uniform(12.0, 48.0), rng.uniform(153.0, 217.0)
        lat1 = np.clip(lat0 + rng.uniform(-2.0, 2.0), 10.5, 49.5)
        lon1 = lon0 + rng.uniform(-2.5, 2.5)
        y0, y1, c0, nc = _edge_box(lat0, lon0, lat1, lon1, grid)
        assert y1 - y0 <= 6 and nc <= 8  # a leg's own cells, not the grid
        cells = np.zeros((grid.nlat, grid.nlon, 1, 7), np.float32)
        cells[..., SWH] = 1000.0
        cols = (c0 + np.arange(nc)) % grid.nlon
        cells[y0:y1, cols, :, SWH] = 1.0
        w, out = Weather(cells, np.zeros(1), grid), np.empty(7)
        ch = geo.chord(lat0, lon0, lat1, lon1)
        for f in np.linspace(0.0, 1.0, 101):
            sample_nb(w, 0.0, *geo.chord_point(ch, f), out)
            assert out[SWH] == pytest.approx(1.0), (lat0, lon0, lat1, lon1, f)


def _random_cells(rng, nan_share, steady):
    """Corners (nlat 4, nlon 5, nt 6, 7 vars) of wind, waves and current, steady in direction or not, with NaN holes."""
    nlat, nlon, nt = 4, 5, 6
    cells = np.empty((nlat, nlon, nt, 7), np.float32)
    speed = rng.uniform(2.0, 20.0, (nlat, nlon, nt))
    wdir = rng.uniform(0, 2 * np.pi) + (rng.normal(0, 0.3, speed.shape) if steady else rng.uniform(0, 2 * np.pi, speed.shape))
    cells[..., U10], cells[..., V10] = speed * np.sin(wdir), speed * np.cos(wdir)
    cells[..., SWH] = rng.uniform(0.5, 6.0, speed.shape)
    sdir = wdir + rng.normal(0, 0.2, speed.shape) + np.pi
    cells[..., WAVE_X], cells[..., WAVE_Y] = np.sin(sdir), np.cos(sdir)
    cdir = rng.uniform(0, 2 * np.pi) + (rng.normal(0, 0.4, speed.shape) if steady else rng.uniform(0, 6.3, speed.shape))
    cur = rng.uniform(0.0, 1.5, speed.shape)
    cells[..., UO], cells[..., VO] = cur * np.sin(cdir), cur * np.cos(cdir)
    for v in range(7):
        cells[..., v][rng.random(speed.shape) < nan_share] = np.nan
    return cells


@pytest.mark.parametrize("seed, nan_share, steady", [(s, n, st) for s in range(4) for n in (0.0, 0.08)
                                                      for st in (True, False)])
@pytest.mark.slow
def test_box_ranges_hold_for_every_sample(seed, nan_share, steady):
    """Wind and Hs within their ranges, the relative directions' direction weights and the current along course
    within what the ranges allow, at 3,000 samples anywhere in the box and its time span, any course in range."""
    rng = np.random.default_rng(seed)
    cells = _random_cells(rng, nan_share, steady)
    w = Weather(cells, np.arange(6.0) * 3.0, Grid(30.0, 1.0, 4, 200.0, 1.0, 5, False))
    crs_lo = rng.uniform(0.0, 360.0)
    crs_hi = crs_lo + rng.uniform(0.0, 15.0)
    box = np.empty(9)
    _box_ranges(cells, w.grid, (0, 4, 0, 5), 0, 5, crs_lo, crs_hi, box)
    wlo, whi, wdlo, wdhi, hlo, hhi, sdlo, sdhi, cur_hi = box
    wind_cos = _cos_range(wdlo + 180.0 - crs_hi, wdhi + 180.0 - crs_lo)
    wave_cos = _cos_range(sdlo - crs_hi, sdhi - crs_lo)
    out = np.empty(7)
    n_dir = 0
    for _ in range(3000):
        t, lat, lon = rng.uniform(0.0, 15.0), rng.uniform(30.0, 33.0), rng.uniform(200.0, 204.0)
        sample_nb(w, t, lat, lon, out)
        u, v = (0.0 if math.isnan(x) else x for x in out[[U10, V10]])
        hs = 0.0 if math.isnan(out[SWH]) else out[SWH]
        sx = 0.0 if math.isnan(out[WAVE_X]) else out[WAVE_X]
        sy = 1.0 if math.isnan(out[WAVE_Y]) else out[WAVE_Y]
        uo, vo = (0.0 if math.isnan(x) else x for x in out[[UO, VO]])
        crs = rng.uniform(crs_lo, crs_hi)
        speed = math.hypot(u, v)
        assert wlo - 1e-6 <= speed <= whi + 1e-6
        assert hlo - 1e-6 <= hs <= hhi + 1e-6
        assert geo.along_course(uo, vo, crs) <= cur_hi + 1e-6
        if speed > 0.0:
            c = math.cos(math.radians(math.degrees(math.atan2(-u, -v)) - crs))
            assert wind_cos[0] - 1e-9 <= c <= wind_cos[1] + 1e-9
            n_dir += wdhi - wdlo < 360.0
        c = math.cos(math.radians(math.degrees(math.atan2(sx, sy)) - crs))
        assert wave_cos[0] - 1e-9 <= c <= wave_cos[1] + 1e-9
    if steady and nan_share == 0.0:
        assert wlo > 0.0 and n_dir > 0 and wind_cos[1] - wind_cos[0] < 1.5  # the ranges are not the trivial ones
        assert direction_weight(0.0) > direction_weight(90.0)  # (w falls with the folded angle: the corners suffice)


def _plans(inst):
    """Every (route, engine plan) of the small graph that sails, with its times and fuel per line."""
    g, v, w, o = inst.graph, inst.vessel, inst.wx, inst.objective
    L2, P = g.lat.shape
    R = len(v.rpm_options)
    for mid in itertools.product(range(P), repeat=L2 - 2):
        nodes = np.array((P // 2, *mid, P // 2), np.int64)
        if not all(g.edge_ok[i, nodes[i], nodes[i + 1]] for i in range(L2 - 1)):
            continue
        for plan in itertools.product(range(R), repeat=L2 - 1):
            ct, cf = np.empty(L2), np.empty(L2)
            rpm = np.array(plan, np.int64)
            if lk.sail_route_nb(nodes, rpm, 0, g, v, w, o, ct, cf)[0] == lk.OK:
                yield nodes, rpm, ct, cf


def _storm(kind: str, seed: int):
    """A storm crossing the route while the ship sails (as in test_routing_exact): time matters."""
    if kind == "storm":
        return field(moving_storm(seed, 31.5, 206.0, drift_kn=(-12.0, 2.0), hs_peak=7.0), step_h=3, hours=200)
    return field(moving_storm(seed, 32.8, 209.0, drift_kn=(-12.0, 0.0), radius_nm=60.0, hs_peak=6.0), step_h=3,
                 hours=200)


@pytest.mark.parametrize("kind, rta_h, n", [("storm", 48.0, 1), ("storm", 75.0, 2), ("storm-limit", 48.0, 4),
                                            ("storm", 52.0, 5), ("storm-limit", 60.0, 6)])
@pytest.mark.slow
def test_windowed_bounds_hold_for_every_plan_within_the_windows(kind, rta_h, n):
    """For every plan of the graph (enumerated) that keeps within the windows (on time, when the windows are the
    on-time ones): each leg takes at least d·τ hours and d·φ fuel of its node and setting, and from every line on the
    rest of the plan burns at least the fuel-to-finish bound for the hours it takes. So the DP, pruning with these
    bounds, never drops the optimum. The bounds must also be tighter than the ones for any time."""
    pr = problem(DEP, ARR, rta_h, rpm_options=(70, 85, 100), n_lines=3, n_points=5, max_shift=2, d_point_nm=25.0,
                 max_hs_m=4.5 if kind == "storm-limit" else None)
    inst = Instance.build(pr, pr.search_space(), _storm(kind, n))
    o, sp = inst.objective, inst.space
    plans = list(_plans(inst))
    assert len(plans) > 1000
    ld = bt.latest_departures(inst)
    any_time = bt.finish_bounds(inst)
    for on_time in (True, False):
        lams, m_lam, t_min, tau, phi = bt.finish_bounds(inst, bt.reachable_windows(inst, ld, on_time))
        n_checked = 0
        for nodes, rpm, ct, cf in plans:
            if on_time and ct[-1] > o.t_dep_h + o.t_req_h:
                continue
            for i in range(len(nodes) - 1):
                a, b = nodes[i], nodes[i + 1]
                d = geo.gc_distance_nm(sp.lat[i, a], sp.lon[i, a], sp.lat[i + 1, b], sp.lon[i + 1, b])
                assert ct[i + 1] - ct[i] >= d * tau[i, a, rpm[i]] * (1.0 - 1e-9)
                assert cf[i + 1] - cf[i] >= d * phi[i, a, rpm[i]] * (1.0 - 1e-9)
                assert cf[-1] - cf[i] >= fuel_to_finish_lb(m_lam[:, i, a], lams, t_min[i, a], ct[-1] - ct[i]) - 1e-9
            n_checked += 1
        assert n_checked > (10 if on_time else 1000)
        best = min(cf[-1] for _, _, ct, cf in plans if not on_time or ct[-1] <= o.t_dep_h + o.t_req_h)
        upper = best if on_time else math.inf  # an on-time incumbent, or none
        lb = bt.cost_lower_bound(inst, upper, lams, m_lam, t_min)
        assert lb <= best + 1e-9  # jit: the cost of an on-time plan is at least its fuel
        assert lb >= bt.cost_lower_bound(inst, upper, *any_time[:3]) - 1e-9
    assert lb > bt.cost_lower_bound(inst, upper, *any_time[:3]) + 1e-3  # the weather met tightens it


@pytest.mark.parametrize("kind, rta_h, n, budget_share", [("storm", 48.0, 1, 1.02), ("storm", 60.0, 2, 1.1),
                                                          ("storm-limit", 60.0, 6, 1.05)])
@pytest.mark.slow
def test_fuel_windowed_leg_bounds_hold_for_every_plan_within_the_budget(kind, rta_h, n, budget_share):
    """With a fuel budget the windows narrow to the times a plan within it can be at each node; every on-time plan
    burning at most the budget still sails each leg in at least its leg's τ and φ (per leg, as dp_exact_nb takes
    them) and finishes above the bound from every line."""
    pr = problem(DEP, ARR, rta_h, rpm_options=(70, 85, 100), n_lines=3, n_points=5, max_shift=2, d_point_nm=25.0,
                 max_hs_m=4.5 if kind == "storm-limit" else None)
    inst = Instance.build(pr, pr.search_space(), _storm(kind, n))
    o, sp = inst.objective, inst.space
    on_time = [p for p in _plans(inst) if p[2][-1] <= o.t_dep_h + o.t_req_h]
    budget = budget_share * min(cf[-1] for _, _, _, cf in on_time)
    windows = bt.reachable_windows(inst, bt.latest_departures(inst), True)
    lams, m_lam, t_min, tau, phi = bt.finish_bounds(inst, windows, budget, per_leg=True)
    assert tau.shape == phi.shape == sp.lat.shape + (5, 3)
    n_checked = 0
    for nodes, rpm, ct, cf in on_time:
        if cf[-1] > budget:
            continue
        for i in range(len(nodes) - 1):
            a, b = nodes[i], nodes[i + 1]
            d = geo.gc_distance_nm(sp.lat[i, a], sp.lon[i, a], sp.lat[i + 1, b], sp.lon[i + 1, b])
            assert ct[i + 1] - ct[i] >= d * tau[i, a, b - a + 2, rpm[i]] * (1.0 - 1e-9)
            assert cf[i + 1] - cf[i] >= d * phi[i, a, b - a + 2, rpm[i]] * (1.0 - 1e-9)
            assert cf[-1] - cf[i] >= fuel_to_finish_lb(m_lam[:, i, a], lams, t_min[i, a], ct[-1] - ct[i]) - 1e-9
        n_checked += 1
    assert n_checked >= 1
    narrowed = bt.fuel_windows(inst, windows, budget, *_tables(inst, windows))
    assert (narrowed[0] >= windows[0]).all() and (narrowed[1] <= windows[1]).all()
    if rta_h >= 60.0:  # windows of a loose RTA are wide: a tight budget narrows some
        assert (narrowed[1] - narrowed[0] < windows[1] - windows[0] - 1.0).any()


def _tables(inst, windows):
    """(lams, m_lam, t_min, tau_e, phi_e) of the windows alone, as fuel_windows takes them."""
    lams, m_lam, t_min, tau_e, phi_e = bt.finish_bounds(inst, windows, per_leg=True)
    return lams, m_lam, t_min, tau_e, phi_e


def test_corner_bounds_of_the_thesis_form_hold_just_above_a_calm():
    """The thesis form drops its direction terms in a calm: with a following wind that adds speed (direction
    coefficient > 0) a light breeze from astern is faster than both a calm and a strong wind, so the bound must
    take the corner just above the calm."""
    from pipeline.performance.features import FORM_THESIS, fuel_tph_nb, stw_kn_nb

    speed = np.array([0.1, 0.0, 0.12, 0.005, -0.05, 0.0, -0.3])  # draft, trim, rpm, wind dir, wind, wave dir, Hs
    fuel = np.array([0.0, 0.0, 0.02, -0.0005, 0.002, 0.0, 0.05])
    v = lk.Vessel(FORM_THESIS, 10.0, 0.0, 0.0, np.inf, np.inf, 1.0, speed, fuel, np.array([100.0]))
    rng = np.zeros((1, 9))
    rng[0, bt.WIND_HI], rng[0, bt.WIND_REL_HI], rng[0, bt.WAVE_REL_HI] = 20.0, 180.0, 180.0
    tau, phi = np.empty((1, 1)), np.empty((1, 1))
    bt._corner_bounds(v, rng, tau, phi)
    for wind_kn in (0.0, 1e-3, 0.5, 5.0, 20.0):
        for rel in (0.0, 90.0, 180.0):
            stw = stw_kn_nb(FORM_THESIS, speed, 100.0, 10.0, 0.0, wind_kn, rel, 0.0, 0.0, 0.0)
            rate = fuel_tph_nb(FORM_THESIS, fuel, 100.0, 10.0, 0.0, wind_kn, rel, 0.0, 0.0, 0.0)
            assert tau[0, 0] <= 1.0 / stw and phi[0, 0] <= rate / stw
    assert 1.0 / tau[0, 0] > stw_kn_nb(FORM_THESIS, speed, 100.0, 10.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0) + 0.8
