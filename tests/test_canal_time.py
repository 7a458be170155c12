"""A canal is sailed on its fixed fairway at its own pace: a voyage through Suez spends the canal's transit and
waiting hours (passages.py: 14 h and 12 h) in every solver's plan and in the constant-speed baseline alike, at the
lowest setting's calm-water fuel rate (canal_time.py), and reports its least distance to land outside the fairway.

The voyage: from the sea north-west of Port Said through the canal into the Gulf of Suez, on the global sea-route
layer's route, in smooth analytic weather. The checks work the canal's hours and fuel out from the legs."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.routing import geodesy as geo
from pipeline.routing.clearance import clearance, least_clearance_nm
from pipeline.routing.global_routes import sea_route
from pipeline.routing.solve import solve
from routing_cases import FAST, MODEL, T0, field, problem, wavy

DEP, ARR = (33.0, 31.0), (28.5, 33.0)  # off the Nile delta; the Gulf of Suez
TRANSIT_H, WAIT_H = 14.0, 12.0
LOWEST_RPM = 70.0


@pytest.fixture(scope="module")
def suez():
    route = sea_route(DEP, ARR)
    assert [p.name for p in route.passages] == ["suez"]
    weather = field(wavy(2), lat=(25.0, 36.0), lon=(28.0, 36.0))
    # 300 NM, 26 h of them in the canal: on time only above the lowest setting (9.8 kn in calm water)
    return route, weather, problem(DEP, ARR, 44.0, n_lines=None, n_points=11, base_route=route)


def _canal_legs(plan, route):
    p = route.passages[0]
    fairway = list(zip(route.lat[p.start_index:p.end_index + 1], route.lon[p.start_index:p.end_index + 1]))

    def on_fairway(lat, lon):
        return min(geo.gc_distance_nm(lat, lon, a, b) for a, b in fairway) < 0.01

    return [g for g in plan.legs if on_fairway(g["lat0"], g["lon0"]) and on_fairway(g["lat1"], g["lon1"])]


@pytest.mark.parametrize("solver", ["bfoa", "dp", "astar", "gc"])
@pytest.mark.slow
def test_a_suez_voyage_spends_the_canal_s_transit_and_waiting_hours(suez, solver):
    route, weather, pr = suez
    plan = solve(pr, weather, solver=solver, seed=1, options=FAST if solver == "bfoa" else None)
    assert plan.status == "ok", plan.reason
    for p in (plan, plan.baseline) if plan.baseline is not None else (plan,):
        canal = _canal_legs(p, route)
        assert len(canal) >= 2
        assert sum(g["hours"] for g in canal) == pytest.approx(TRANSIT_H + WAIT_H, abs=1e-9)
        # fuel: the lowest setting's calm-water rate for every hour in the canal and waiting for it
        assert sum(g["fuel_t"] for g in canal) == pytest.approx((TRANSIT_H + WAIT_H) * MODEL.fuel_tph(LOWEST_RPM, 10.0, 0.0))
        # the waiting allowance is spent before entering: on the first leg of the fairway
        first = canal[0]
        assert first["hours"] > WAIT_H and first["dist_nm"] / (first["hours"] - WAIT_H) == pytest.approx(
            sum(g["dist_nm"] for g in canal) / TRANSIT_H, rel=1e-9)
        # the ETA holds the canal's hours: the arrival is the departure plus every leg's hours
        eta = np.datetime64(p.legs[-1]["eta_utc"])
        assert abs((eta - (np.datetime64(T0) + np.timedelta64(int(round(p.hours * 3600)), "s"))) / np.timedelta64(1, "s")) <= 1
        sea_nm = sum(g["dist_nm"] for g in p.legs) - sum(g["dist_nm"] for g in canal)
        assert p.hours > TRANSIT_H + WAIT_H + sea_nm / (0.14 * 100 + 2.0)  # the sea part at most full speed + current
    assert plan.fuel_t <= plan.baseline.fuel_t + 1e-9 if plan.baseline is not None else True
    assert "suez canal (14 h transit + 12 h waiting" in plan.reason


def test_the_suez_voyage_s_clearance_is_measured_outside_the_canal(suez):
    route, weather, pr = suez
    plan = solve(pr, weather, solver="bfoa", seed=1, options=FAST)
    assert plan.status == "ok", plan.reason
    # the canal runs between its banks (the land mask holds it as land): over the whole route the least distance is 0
    whole = least_clearance_nm(plan.waypoints, clearance(DEP, ARR, 2.0, 10.0))
    assert whole == 0.0
    # outside the fairway (and the approach radius at its ends, as at a port) the route keeps the clearance
    assert 2.0 - 0.1 <= plan.min_land_clearance_nm < 25.0


def test_the_dp_s_bounds_count_the_canal_s_hours_and_stay_below_a_plan(suez):
    """The exact DP prunes with the least hours and fuel to finish: across a canal those are its fixed hours and
    fuel (not the open sea's), and still no more than a plan that sails the canal needs."""
    from pipeline.routing.canal_time import canal_lines
    from pipeline.routing.bound_tables import finish_bounds
    from pipeline.routing.problem import Instance

    route, weather, pr = suez
    space = pr.search_space()
    inst = Instance.build(pr, space, weather)
    _, m_lam, t_min, _, _ = finish_bounds(inst)
    c = space.centre
    (_, _, _, lines), = canal_lines(space)
    first = lines[0]
    assert t_min[first, c] >= TRANSIT_H + WAIT_H - 1e-6
    assert m_lam[0, first, c] >= (TRANSIT_H + WAIT_H) * MODEL.fuel_tph(LOWEST_RPM, 10.0, 0.0) - 1e-6  # λ = 0: fuel
    plan = solve(pr, weather, solver="gc")
    after = plan.legs[first:]
    assert sum(g["hours"] for g in after) >= t_min[first, c]
    assert sum(g["fuel_t"] for g in after) >= m_lam[0, first, c]
