"""Routing under bad input and bad weather: a clear status and reason, never a crash, others unaffected."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from pipeline.performance.model import reference_model
from pipeline.routing import weather_field as wf
from pipeline.routing.problem import RoutingInputError
from pipeline.routing.search_space import VoyageGeometryError
from pipeline.routing.solve import BfoaParams, RoutingProblem
from tests.routing_cases import solve

MODEL = reference_model(14.0, 100.0, 1.5)
FAST = BfoaParams(n_bacteria=8, n_chemo=6, n_cycles=8)
DEP, ARR = (34.85, 139.85), (30.0, 147.0)  # Tokyo Bay approach → open Pacific, about 450 NM


def problem(**kw):
    base = dict(dep=DEP, arr=ARR, depart_utc="2020-12-01T06", rta_utc="2020-12-03T06", model=MODEL,
                rpm_options=(70, 85, 100), n_lines=8, n_points=11, voyage_id="VTEST")
    base.update(kw)
    return RoutingProblem(**base)


def calm():
    return wf.uniform("2020-12-01T00", 200)


def test_departure_on_land_is_named():
    with pytest.raises(VoyageGeometryError, match="VTEST.*on land"):
        solve(problem(dep=(35.68, 139.76), dep_name="Tokyo city"), calm())


def test_rta_in_the_past_is_refused_with_the_voyage_named():
    with pytest.raises(RoutingInputError, match="VTEST.*RTA .* not after departure"):
        problem(rta_utc="2020-11-30T00")


def test_destination_unreachable_inside_the_limits():
    # a limit line fencing the destination off completely
    fence = [(31.5, 140.0), (31.5, 150.0)]
    plan = solve(problem(limit_lines=(fence,)), calm(), seed=1)
    assert plan.status == "infeasible" and "no route at sea" in plan.reason and plan.legs == []


def test_weather_limits_blocking_every_route():
    storm = wf.uniform("2020-12-01T00", 200, swh_m=9.0)
    for solver in ("bfoa", "dp", "gc"):
        plan = solve(problem(max_hs_m=6.0), storm, solver=solver, seed=1)
        assert plan.status == "infeasible", solver
        assert "wave height above the vessel's limit" in plan.reason


def test_cube_with_nan_holes_still_routes():
    lat = np.arange(20.0, 45.01, 0.5)
    lon = np.arange(130.0, 160.01, 0.5)
    times = np.datetime64("2020-12-01T00") + np.arange(0, 120, 6).astype("timedelta64[h]")
    shape = (len(times), len(lat), len(lon))
    swh = np.full(shape, 2.0)
    swh[:, 20:30, 20:40] = np.nan  # a hole across the route
    u = np.full(shape, 5.0)
    u[3:6] = np.nan  # whole time steps missing
    field = wf.from_arrays(lat, lon, times, u10=u, v10=np.zeros(shape), swh=swh, mwd_deg=np.full(shape, 90.0),
                           uo=np.zeros(shape), vo=np.zeros(shape))
    plan = solve(problem(), field, seed=2, params=FAST)
    assert plan.status == "ok" and np.isfinite(plan.fuel_t)
    assert all(np.isfinite([g["hs_m"], g["wind_kn"], g["sog_kn"]]).all() for g in plan.legs)


def test_voyage_outside_the_weather_area_is_refused():
    lat = np.arange(0.0, 10.01, 0.5)
    lon = np.arange(100.0, 120.01, 0.5)
    times = np.datetime64("2020-12-01T00") + np.arange(0, 48, 6).astype("timedelta64[h]")
    z = np.zeros((len(times), len(lat), len(lon)))
    field = wf.from_arrays(lat, lon, times, u10=z, v10=z, swh=z, mwd_deg=z, uo=z, vo=z)
    with pytest.raises(RoutingInputError, match="VTEST.*weather covers only"):
        solve(problem(), field)


def test_departure_after_the_forecast_horizon_is_refused():
    short = wf.uniform("2020-11-28T00", 24)  # forecast ends long before departure (2020-12-01T06)
    with pytest.raises(RoutingInputError, match=r"VTEST: departs 2020-12-01T06:00:00, 54.0 h after the last valid "
                                                r"time .* later cycle"):
        solve(problem(), short, seed=1, params=FAST)


def test_voyage_running_past_the_forecast_horizon_is_flagged_with_its_hours():
    # the forecast (cycle 2020-12-01T00) ends 12 h after departure at 06:00: the rest of the passage is not
    fld = wf.uniform("2020-12-01T00", 18)
    fld = dataclasses.replace(fld, cycle=np.datetime64("2020-12-01T00"))
    plan = solve(problem(), fld, seed=1, params=FAST)
    assert plan.status == "ok" and plan.forecast_flag == "beyond horizon"
    eta_h = (plan.eta_utc - np.datetime64("2020-12-01T00")) / np.timedelta64(1, "h")
    assert plan.hours_beyond_forecast == pytest.approx(eta_h - 18.0, abs=1e-3)  # ETA rounded to the second
    assert f"{plan.hours_beyond_forecast:.1f} h of the voyage" in plan.reason and "beyond the forecast horizon" in plan.reason
    row = plan.route_row()
    assert row["forecast_flag"] == "beyond horizon" and row["hours_beyond_forecast"] == pytest.approx(eta_h - 18.0, abs=1e-3)
    assert row["n_legs_beyond_forecast"] == plan.n_beyond_forecast > 0


def test_departure_before_the_cycle_is_flagged_with_its_hours():
    # cycle 2020-12-01T12, weather from 2020-12-01T00 (an analysis-time field padded backwards): departure at 06:00
    fld = wf.uniform("2020-12-01T00", 200)
    fld = dataclasses.replace(fld, cycle=np.datetime64("2020-12-01T12"))
    plan = solve(problem(), fld, seed=1, params=FAST)
    assert plan.status == "ok" and plan.forecast_flag == "before cycle"
    assert plan.hours_before_cycle == pytest.approx(6.0, abs=1e-6)
    assert "6.0 h of the voyage before the forecast cycle" in plan.reason
    inside = solve(problem(), wf.uniform("2020-12-01T00", 200), seed=1, params=FAST)
    assert inside.forecast_flag is None and inside.reason is None


def test_a_bad_voyage_does_not_stop_the_others():
    from flows.jobs.route_worker import route_one
    from pipeline.routing.job import RouteJob, RoutingOptions

    options = RoutingOptions(solver="bfoa", objective="jit", arrival_window_h=6.0, seed=1, n_lines=8, n_points=11)
    good = {"voyage_id": "VOK", "imo": 1, "dep_lat": DEP[0], "dep_lon": DEP[1], "arr_lat": ARR[0], "arr_lon": ARR[1],
            "depart_utc": np.datetime64("2020-12-01T06"), "rta_utc": np.datetime64("2020-12-03T06"), "rpm_options": [70, 85, 100]}
    jobs = [
        dict(good),
        dict(good, voyage_id="VLAND", dep_lat=35.68, dep_lon=139.76),
        dict(good, voyage_id="VPAST", rta_utc=np.datetime64("2020-11-01T00")),
        dict(good, voyage_id="VNOMODEL"),
        dict(good, voyage_id="VNOPOS", arr_lat=None),
    ]
    out = {}
    for v in jobs:
        model = None if v["voyage_id"] == "VNOMODEL" else MODEL.to_json()
        res = route_one(RouteJob(voyage=v, vessel={"rpm_max": 100}, model=model, run_id="r1", cycle="2020-12-01T00",
                                 exports=False, options=options), cube_path=None)
        out[v["voyage_id"]] = res["route"]
    assert out["VOK"]["status"] == "ok" and out["VOK"]["n_legs"] == 9
    assert out["VLAND"]["status"] == "failed" and "on land" in out["VLAND"]["reason"]
    assert out["VPAST"]["status"] == "failed" and "not after departure" in out["VPAST"]["reason"]
    assert out["VNOMODEL"]["status"] == "failed" and "jitroute refit" in out["VNOMODEL"]["reason"]
    assert out["VNOPOS"]["status"] == "failed" and "arr_lat is missing" in out["VNOPOS"]["reason"]


def test_an_rta_years_after_departure_is_refused_not_routed_ok():
    with pytest.raises(RoutingInputError, match=r"VTEST: RTA 2030-12-03T06:00:00 is 3654 days after departure .* check the RTA"):
        problem(rta_utc="2030-12-03T06")
    assert problem(rta_utc="2021-02-20T06").t_req_h == pytest.approx(81 * 24)  # a long but real passage is fine


@pytest.mark.parametrize("names, says", [({}, "voyage VTEST: departure 35.6800,139.7600 is on land"),
                                         ({"dep_name": "departure"}, "voyage VTEST: departure 35.6800,139.7600 is on land"),
                                         ({"dep_name": "Tokyo city"}, "voyage VTEST: departure Tokyo city 35.6800,139.7600 is on land")])
def test_messages_say_each_thing_once(names, says):
    with pytest.raises(VoyageGeometryError) as exc:
        solve(problem(dep=(35.68, 139.76), **names), calm())
    assert str(exc.value).startswith(says) and "departure departure" not in str(exc.value)
    with pytest.raises(VoyageGeometryError) as exc:
        solve(problem(arr=DEP), calm())
    assert str(exc.value).startswith("voyage VTEST: departure and destination are the same place"), str(exc.value)
    assert str(exc.value).count("VTEST") == 1
