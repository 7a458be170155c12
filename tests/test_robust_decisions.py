"""Robust decisions over an ensemble (pipeline/routing/robust.py, job.robust_plan): each rule can change a decision.

The members are fields built here: calm water, a uniform head or following current, a storm on the base route.
Expected values come from those fields (a current along the course changes the arrival by a known amount), not
from the code under test.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from pipeline.performance.model import reference_model
from pipeline.routing import robust
from pipeline.routing import weather_field as wf
from pipeline.routing.ensemble import sail_plan
from pipeline.routing.job import RouteJob, robust_plan
from pipeline.routing.options import RoutingOptions
from pipeline.routing.solve import solve
from routing_cases import T0, field, problem

DEP, ARR = (30.0, 200.0), (30.0, 212.0)  # ~623 NM along 30 N, eastbound


def _current(east_ms: float) -> wf.WeatherField:
    return field(lambda LA, LO: dict(uo=np.full(LA.shape, east_ms)), lat=(20.0, 40.0), lon=(190.0, 222.0))


def _storm_on_route(lat: float = 30.3, half_width_deg: float = 1.2) -> wf.WeatherField:
    """Head seas (Hs 8 m, 25 m/s easterly) on a band around `lat` over the middle of the voyage, calm elsewhere."""
    def fn(LA, LO):
        on = (np.abs(LA - lat) < half_width_deg) & (np.abs(LO - 206.0) < 2.5)
        return dict(swh=np.where(on, 8.0, 0.0), u10=np.where(on, -25.0, 0.0), mwd_deg=np.full(LA.shape, 90.0))
    return field(fn, lat=(20.0, 40.0), lon=(190.0, 222.0))


def _plan(weather, hours=55.0, **kw):
    p = problem(DEP, ARR, hours, **kw)
    return p, solve(p, weather, solver="dp")


def test_no_margin_with_one_member_or_when_the_members_agree():
    p, plan = _plan(_current(0.0))
    v = p.kernel_vessel()
    calm = _current(0.0)
    assert robust.arrival_margin_h(plan, [calm], v, 1.65) == 0.0
    assert robust.arrival_margin_h(plan, [calm, _current(0.0)], v, 1.65) == pytest.approx(0.0, abs=1e-9)
    assert robust.arrival_margin_h(plan, [calm, _current(0.5)], v, 0.0) == 0.0


def test_the_margin_is_k_sigma_of_the_arrival_when_the_members_disagree():
    p, plan = _plan(_current(0.0))
    v = p.kernel_vessel()
    members = [_current(0.0), _current(-0.4)]  # a head current of 0.4 m/s (0.78 kn) in the second
    hours = [sail_plan(plan.legs, plan.depart_utc, m, v)[0] for m in members]
    assert hours[1] > hours[0] + 1.0  # the head current makes it arrive hours later
    expected = 1.65 * np.std(hours, ddof=1)
    assert robust.arrival_margin_h(plan, members, v, 1.65, max_share=1.0) == pytest.approx(expected, rel=1e-9)
    # capped at the share of the passage
    assert robust.arrival_margin_h(plan, members, v, 1.65, max_share=0.01) == pytest.approx(0.01 * 55.0)


def _job(hours=55.0, **options) -> RouteJob:
    voyage = {"voyage_id": "VROB", "imo": 9140607, "dep_lat": DEP[0], "dep_lon": DEP[1], "arr_lat": ARR[0],
              "arr_lon": ARR[1], "depart_utc": np.datetime64(T0), "rta_utc": np.datetime64(T0) + np.timedelta64(int(hours * 60), "m"),
              "draft_m": 10.0, "trim_m": 0.0, "rpm_options": [70.0, 85.0, 100.0]}
    return RouteJob(voyage=voyage, vessel={"imo": 9140607, "rpm_max": 100.0}, model=reference_model().to_json(),
                    run_id="r1", cycle=None, exports=False, options=RoutingOptions(solver="dp", **options))


def test_a_plan_with_a_margin_arrives_that_much_earlier_and_keeps_the_voyages_rta():
    from pipeline.routing.job import plan_voyage

    calm, head = _current(0.0), _current(-0.4)
    weather_for = lambda problem, space: calm  # noqa: E731
    job = _job(arrival_margin_sigmas=1.65, arrival_margin_max_share=1.0)
    plan, _ = plan_voyage(job, weather_for)
    solvers_reason = plan.reason  # the solver's own (dp: the space it certifies)
    same, _ = robust_plan(job, plan, calm, weather_for, [calm])  # one member: the plan as the solver made it
    assert same is plan and same.reason == solvers_reason  # nothing added
    margin = robust.arrival_margin_h(plan, [calm, head], _vessel(job), 1.65, 1.0)
    assert margin > 1.0
    aimed, _ = robust_plan(job, plan, calm, weather_for, [calm, head])
    assert aimed.rta_utc == plan.rta_utc
    assert "before the RTA" in aimed.reason
    assert aimed.hours <= plan.hours - margin + 0.6  # arrives at least the margin earlier (within the 0.5 h rounding)
    assert aimed.fuel_t > plan.fuel_t  # faster costs fuel
    # off by default: the plan unchanged even with disagreeing members
    assert robust_plan(_job(), plan, calm, weather_for, [calm, head])[0] is plan


def _vessel(job):
    from pipeline.routing.job import routing_problem

    return routing_problem(job).kernel_vessel()


def test_a_plan_that_wins_in_one_member_and_loses_in_the_other_gives_way_to_its_baseline():
    storm = _storm_on_route()
    p, plan = _plan(storm)
    v = p.kernel_vessel()
    assert plan.baseline is not None and plan.legs
    assert plan.distance_nm > plan.baseline.distance_nm + 5.0  # it goes round the storm
    # the other forecast puts the storm where the plan goes round it (and none on the great circle)
    detour_lat = max((g["lat1"] for g in plan.legs), key=lambda la: abs(la - 30.0))
    elsewhere = _storm_on_route(detour_lat + (0.6 if detour_lat > 30.0 else -0.6), 0.8)
    wins = robust.wins_across(plan, [storm, elsewhere], v)
    assert (wins.n_members, wins.n_wins) == (2, 1)  # wins in the storm, loses where its way meets the other one
    assert not wins.preferred(0.75) and wins.preferred(0.5)
    kept = robust.baseline_kept(plan, wins, 0.75, [storm, elsewhere], v)
    assert [g["rpm"] for g in kept.legs] == [g["rpm"] for g in plan.baseline.legs]
    assert kept.fuel_t == plan.baseline.fuel_t and kept.savings.total_pct == 0.0
    assert "1 of 2 forecasts" in kept.reason and "kept the baseline" in kept.reason
    assert kept.spread.n_members == 2 and kept.spread.savings_p50_pct == pytest.approx(0.0)
    # the same rule through the job: min_win_share 0.75 keeps the baseline, 0 (the default) the plan
    job = _job(min_win_share=0.75)
    wf_storm = lambda problem, space: storm  # noqa: E731
    from pipeline.routing.job import plan_voyage

    jplan, _ = plan_voyage(job, wf_storm)
    assert jplan.distance_nm > jplan.baseline.distance_nm + 5.0
    assert robust_plan(job, jplan, storm, wf_storm, [storm, elsewhere])[0].distance_nm == pytest.approx(
        jplan.baseline.distance_nm)
    assert robust_plan(_job(), jplan, storm, wf_storm, [storm, elsewhere])[0] is jplan
    # a plan that wins in every member stays, and so does a plan that is its baseline (a tie everywhere)
    assert robust.wins_across(plan, [storm, storm], v).preferred(1.0)
    same = robust.wins_across(plan.baseline.__class__(**{**plan.baseline.__dict__, "baseline": plan.baseline}),
                              [storm, elsewhere], v)
    assert (same.n_members, same.n_wins) == (2, 2)


def test_a_replan_at_sea_with_a_gain_smaller_than_its_spread_is_not_taken():
    storm, calm = _storm_on_route(), _current(0.0)
    p, current = _plan(calm)
    v = p.kernel_vessel()
    p2, new = _plan(storm)  # the newest forecast has a storm on the great circle: the new plan goes round it
    assert new.distance_nm > current.distance_nm + 5.0
    detour_lat = max((g["lat1"] for g in new.legs), key=lambda la: abs(la - 30.0))
    elsewhere = _storm_on_route(detour_lat + (0.6 if detour_lat > 30.0 else -0.6), 0.8)  # the other: on the detour
    # a day more to go than either plan takes, so both are on time in every forecast and only the fuel counts
    new = replace(new, rta_utc=new.rta_utc + np.timedelta64(24, "h"))
    d = robust.replan_decision(current.legs, new, [storm, elsewhere], v, k_sigma=1.0)
    assert d.n_members == 2 and d.on_time_current == d.on_time_new == 2
    g = [sail_plan(current.legs, new.depart_utc, m, v)[1] - sail_plan(new.legs, new.depart_utc, m, v)[1]
         for m in (storm, elsewhere)]
    assert g[0] > 0 > g[1]  # gains in one forecast, loses in the other
    assert d.gain_mean_t == pytest.approx(np.mean(g)) and d.gain_sd_t == pytest.approx(np.std(g, ddof=1))
    assert not d.take_new and "current plan kept" in d.reason
    # with both forecasts showing the storm the gain is certain: taken
    d2 = robust.replan_decision(current.legs, new, [storm, storm], v, k_sigma=1.0)
    assert d2.gain_mean_t > 0 and d2.take_new
    # one forecast: nothing to weigh, the new plan is taken (as without the rule)
    assert robust.replan_decision(current.legs, new, [storm], v).take_new


def test_a_replan_on_time_in_more_members_is_taken_whatever_its_fuel():
    calm = _current(0.0)
    p, slow = _plan(calm, hours=70.0)  # the current plan is slow: late where the voyage must now take 55 h
    p2, fast = _plan(calm, hours=55.0)
    d = robust.replan_decision(slow.legs, fast, [calm, _current(0.1)], p.kernel_vessel(), k_sigma=1.0)
    assert d.on_time_new == 2 and d.on_time_current == 0
    assert d.gain_mean_t < 0 and d.take_new


def test_legs_ahead_starts_at_the_ship_and_drops_the_legs_sailed():
    p, plan = _plan(_current(0.0))
    mid = plan.legs[len(plan.legs) // 2]
    at = mid["etd_utc"] + (mid["eta_utc"] - mid["etd_utc"]) / 2
    ahead = robust.legs_ahead(plan.legs, at, 30.1, 205.0)
    assert len(ahead) == len(plan.legs) - len(plan.legs) // 2
    assert (ahead[0]["lat0"], ahead[0]["lon0"]) == (30.1, 205.0) and ahead[0]["wait_h"] == 0.0
    assert ahead[-1]["lat1"] == plan.legs[-1]["lat1"]
    assert math.isfinite(sail_plan(ahead, at, _current(0.0), p.kernel_vessel())[1])


def test_a_fleet_replan_at_sea_that_gains_nothing_keeps_the_current_plan():
    from pipeline.routing.job import kept_or_replanned, plan_voyage

    calm = _current(0.0)
    weather_for = lambda problem, space: calm  # noqa: E731
    base = _job(replan_gain_sigmas=1.0)
    current, _ = plan_voyage(base, weather_for)
    # at sea 10 h after departure, where the current plan puts the ship; the new plan from there in the same weather
    at = current.legs[0]["etd_utc"] + (current.legs[-1]["eta_utc"] - current.legs[0]["etd_utc"]) / 3
    ahead = robust.legs_ahead(current.legs, at, *_on_plan(current.legs, at))
    start = {"start_kind": "noon report", "dep_lat": ahead[0]["lat0"], "dep_lon": ahead[0]["lon0"],
             "depart_utc": np.datetime64(at, "s")}
    job = replace(base, voyage={**base.voyage, **start}, current_legs=tuple(current.legs))
    new, _ = plan_voyage(job, weather_for)
    kept = kept_or_replanned(job, new, calm, [calm, _current(0.0)])
    assert kept is not new and kept.reason.startswith("current plan kept")
    # the current route ahead, re-timed to the RTA: its speeds scaled by one factor
    assert [(g["lat1"], g["lon1"]) for g in kept.legs] == [(g["lat1"], g["lon1"]) for g in ahead]
    ratio = [k["rpm"] / g["rpm"] for k, g in zip(kept.legs, ahead)]
    assert max(ratio) - min(ratio) < 1e-9
    assert kept.legs[0]["etd_utc"] == np.datetime64(at, "s").item()
    assert kept.status == "ok" and kept.savings is not None
    assert np.datetime64(kept.legs[-1]["eta_utc"], "s") <= np.datetime64(kept.rta_utc, "s")
    assert kept.savings.total_pct == pytest.approx(
        100.0 * (kept.savings.baseline_fuel_t - kept.fuel_t) / kept.savings.baseline_fuel_t)
    # the rule off, one forecast, or a plan from the port: the new plan
    assert kept_or_replanned(replace(job, options=RoutingOptions(solver="dp")), new, calm, [calm, calm]) is new
    assert kept_or_replanned(job, new, calm, [calm]) is new
    port = replace(job, voyage={**job.voyage, "start_kind": "port"})
    assert kept_or_replanned(port, new, calm, [calm, calm]) is new


def _on_plan(legs, at):
    from pipeline.enroute import position_on_plan

    return position_on_plan(legs, at)


def test_a_stored_current_plan_reaches_the_job_with_its_rpm_and_waits_a_missing_wait_as_none(tmp_path):
    from flows.jobs.fleet import _plan_leg
    from storage import route_store
    from tests.test_route_store import _leg, _route

    db = tmp_path / "w.duckdb"
    route_store.begin_run(db, "r1", cycle="2020-12-01T00", solver="bfoa", trigger="manual", n_voyages=1)
    legs = [_leg("V1", 0), {**_leg("V1", 1), "wait_h": 2.0, "wait_fuel_t": 0.5, "rpm": 75.0}]
    route_store.write_run_results(db, tmp_path / "exports", "r1", [_route("V1", "ok", 90.0, 100.0)], legs)
    stored = [_plan_leg(g) for g in route_store.current_plan_legs(db, ["V1"])["V1"]]
    assert [g["rpm"] for g in stored] == [80.0, 75.0]
    assert [(g["wait_h"], g["wait_fuel_t"]) for g in stored] == [(0.0, 0.0), (2.0, 0.5)]  # unset: no wait
    assert stored[0]["etd_utc"] == np.datetime64("2020-12-01T06:00", "s")
    ahead = robust.legs_ahead(stored, np.datetime64("2020-12-01T08:00"), 34.6, 140.4)
    assert len(ahead) == 2 and (ahead[0]["lat0"], ahead[0]["lon0"], ahead[0]["wait_h"]) == (34.6, 140.4, 0.0)
    assert ahead[1]["wait_h"] == 2.0  # a leg not begun keeps its wait


def test_a_route_is_re_timed_to_the_rta_by_one_factor_on_its_speeds():
    calm, head = _current(0.0), _current(-0.3)
    p, plan = _plan(calm, hours=60.0)
    v = p.kernel_vessel()
    rta = plan.rta_utc
    late_h = sail_plan(plan.legs, plan.depart_utc, head, v)[0] - 60.0
    assert late_h > 1.0  # sailed as made into a head current it is late
    legs = robust.retimed(plan.legs, plan.depart_utc, rta, head, v)
    hours = sail_plan(legs, plan.depart_utc, head, v)[0]
    assert 60.0 - 0.05 <= hours <= 60.0  # re-timed: in at the RTA
    ratio = [g["rpm"] / h["rpm"] for g, h in zip(legs, plan.legs)]
    assert min(ratio) > 1.0 and max(ratio) - min(ratio) < 1e-9
    assert [(g["lat1"], g["lon1"]) for g in legs] == [(g["lat1"], g["lon1"]) for g in plan.legs]
    # no rpm above the highest setting, even when the RTA cannot be met
    fastest = robust.retimed(plan.legs, plan.depart_utc, plan.depart_utc + np.timedelta64(10, "h"), head, v)
    assert max(g["rpm"] for g in fastest) == pytest.approx(100.0)
