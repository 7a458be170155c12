"""Continuous speed (pipeline/routing/continuous_speed.py): each run of a plan's setting may take any rpm between the
lowest and the highest allowed one, outside barred ranges; refining never makes a plan dearer or late, and keeps
the engine-change limits.

The reference for how good the refinement is: an enumeration of every pair of rpm (on a 0.25 rpm grid) for the
same two runs, sailed with the same kernel; not the code under test."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from pipeline.routing.baseline import constant_rpm_for_rta
from pipeline.routing.continuous_speed import refine_rpm, runs_of, split_runs
from pipeline.routing.engine_limits import EngineLimits, settings_held_h
from pipeline.routing.objectives import route_cost_nb
from pipeline.routing.problem import RoutingInputError
from pipeline.routing.solve import solver_instance
from routing_cases import FAST, field, moving_storm, problem, solve, wavy

STORM = field(moving_storm(5, 33.0, 225.0, drift_kn=(-10.0, 0.0), hs_peak=6.0), step_h=6, hours=240)
DEP, ARR = (30.0, -160.0), (35.0, -130.0)


def _sail(inst, nodes, rpm):
    from pipeline.routing.continuous_speed import sail_from_nb
    from pipeline.routing.engine.leg import OnRoute

    ct, cf = np.empty(len(nodes)), np.empty(len(nodes))
    ct[0], cf[0] = inst.objective.t_dep_h, 0.0
    code = sail_from_nb(OnRoute(inst.graph, np.asarray(nodes, np.int64), inst.vessel, inst.wx),
                        np.asarray(rpm, np.float64), 0, ct, cf)
    return code, ct, cf


@pytest.mark.slow
def test_refined_speeds_come_within_a_grid_enumeration_of_the_same_two_runs():
    """A ≈ 40 h voyage into a moving storm at one constant rpm: refining cuts it in two runs of ≈ 20 h; every pair
    of rpm for those two runs (0.25 rpm apart, each held ≥ 12 h, arriving by the RTA; changes free) is sailed, and the refined
    plan must come within 0.1 % of the best pair, and below the constant-speed voyage."""
    dep, arr = (31.0, -145.0), (34.0, -137.0)  # into the storm drifting west
    near = problem(dep, arr, 48.0, n_lines=8, n_points=5)
    pr = problem(dep, arr, near.search_space().base_distance_nm / (0.14 * 80.0), n_lines=8, n_points=5)
    space = pr.search_space()
    inst, nodes = solver_instance(pr, space, STORM)
    rpm0, hours0, fuel0 = constant_rpm_for_rta(inst, nodes)
    assert 70.0 < rpm0 < 100.0 and abs(hours0 - pr.t_req_h) < 1e-3
    plan0 = np.full(len(nodes) - 1, rpm0)
    got = refine_rpm(inst, nodes, plan0, min_hold_h=12.0, change_cost_t=0.0)
    assert got is not None and got.hours <= pr.t_req_h + 1e-9
    assert got.fuel_t < fuel0 * (1.0 - 1e-3)  # a real saving against the constant speed
    _, ct, _ = _sail(inst, nodes, plan0)
    starts, ends = split_runs(plan0, ct, 24.0)
    assert len(starts) == 2
    k = int(ends[0])
    grid = np.arange(70.0, 100.0 + 1e-9, 0.25)
    best = np.inf
    for r1, r2 in itertools.product(grid, grid):
        rpm = np.r_[np.full(k, r1), np.full(len(nodes) - 1 - k, r2)]
        code, t, f = _sail(inst, nodes, rpm)
        if code != 0 or t[-1] - t[0] > pr.t_req_h:
            continue
        if r1 != r2 and min(t[k] - t[0], t[-1] - t[k]) < 12.0:
            continue
        best = min(best, route_cost_nb(inst.objective, t[-1] - t[0], f[-1]))
    assert np.isfinite(best)
    assert best * (1.0 - 1e-3) <= got.cost <= best * (1.0 + 1e-3), (got.cost, best)


@pytest.mark.parametrize("case", ["storm", "wavy", "thesis"])
@pytest.mark.slow
def test_refining_never_costs_more_is_never_late_and_holds_each_setting(case):
    if case == "thesis":
        pr = problem((35.0, -140.0), (28.0, -132.0), 52, rpm_options=(80, 100), objective="thesis", n_lines=6,
                     n_points=9)
        fld = field(wavy(3))
    elif case == "wavy":
        pr, fld = problem(DEP, (33.0, -145.0), 72, n_lines=8, n_points=9), field(wavy(2))
    else:
        pr, fld = problem(DEP, ARR, 150, max_hs_m=7.0, n_lines=10, n_points=11), STORM
    space = pr.search_space()
    limits = EngineLimits(12.0, 0.05)
    for solver in ("bfoa", "dp"):
        kw = dict(solver=solver, seed=2, params=FAST if solver == "bfoa" else None, space=space, limits=limits,
                  savings=True)
        settings = solve(pr, fld, continuous=False, **kw)
        smooth = solve(pr, fld, **kw)
        assert smooth.status == "ok" and settings.status == "ok"
        assert smooth.cost <= settings.cost + 1e-9, (case, solver)
        assert smooth.hours <= pr.t_req_h + 1e-9
        runs = settings_held_h(smooth.legs)
        assert len(runs) == 1 or min(h for _, h in runs) >= limits.min_hold_h - 1e-6
        rpm = np.array([leg["rpm"] for leg in smooth.legs])
        assert rpm.min() >= pr.rpm_options[0] - 1e-9 and rpm.max() <= pr.rpm_options[-1] + 1e-9
        s = smooth.savings
        assert s.total_pct >= -1e-9 and s.speed_profile_pct >= -1e-9
        assert smooth.limits_fuel_t >= -1e-9  # the reference without limits is no dearer than the plan


def test_a_storm_gives_a_speed_profile_saving_the_settings_alone_could_not():
    """On the storm voyage the best engine plan over the settings on the base route is the constant speed (no
    speed-profile saving); with continuous speed the base route itself is sailed cheaper (each setting held 12 h;
    with 0.05 t a change the gain here is smaller than the changes cost, and the plan stays at one rpm)."""
    pr = problem(DEP, ARR, 150, max_hs_m=7.0, n_lines=10, n_points=11)
    space = pr.search_space()
    kw = dict(solver="gc", space=space)
    held = EngineLimits(12.0, 0.0)
    settings = solve(pr, STORM, solver="bfoa", seed=4, params=FAST, space=space, limits=held, savings=True,
                     continuous=False)
    smooth = solve(pr, STORM, solver="bfoa", seed=4, params=FAST, space=space, limits=held, savings=True)
    assert settings.savings.speed_profile_pct == pytest.approx(0.0, abs=1e-9)
    assert smooth.savings.speed_profile_pct > 0.05
    assert smooth.savings.total_pct >= settings.savings.total_pct - 1e-9
    assert solve(pr, STORM, **kw).fuel_t == pytest.approx(smooth.savings.baseline_fuel_t, rel=1e-9)


def test_barred_rpm_is_never_sailed_and_the_baseline_leaves_it_upwards():
    """Constant speed for the RTA would be ≈ 82 rpm; with 79–84 rpm barred the baseline sails 84 rpm (arriving
    early) and no leg of any plan is inside the barred range."""
    pr0 = problem(DEP, ARR, 150, max_hs_m=7.0, n_lines=10, n_points=11)
    free = solve(pr0, STORM, solver="gc", space=pr0.search_space())
    assert 79.0 < free.legs[0]["rpm"] < 84.0
    pr = problem(DEP, ARR, 150, max_hs_m=7.0, n_lines=10, n_points=11, barred_rpm=((79.0, 84.0),))
    space = pr.search_space()
    plan = solve(pr, STORM, solver="bfoa", seed=1, params=FAST, space=space, limits=EngineLimits(), savings=True)
    assert plan.status == "ok"
    assert plan.savings.baseline_rpm == 84.0 and plan.baseline.hours < pr.t_req_h - 0.5
    for p in (plan, plan.baseline):
        assert not any(79.0 < leg["rpm"] < 84.0 for leg in p.legs)
    assert plan.savings.total_pct >= 0.0
    with pytest.raises(RoutingInputError, match="barred"):
        problem(DEP, ARR, 150, rpm_options=(70, 80, 100), barred_rpm=((79.0, 84.0),))
    with pytest.raises(RoutingInputError, match="barred"):
        problem(DEP, ARR, 150, barred_rpm=((90.0, 80.0),))


def test_runs_of_and_split_runs():
    rpm = np.array([80.0, 80.0, 85.0, 85.0, 85.0, 80.0])
    s, e = runs_of(rpm)
    assert s.tolist() == [0, 2, 5] and e.tolist() == [2, 5, 6]
    cum_t = np.arange(7) * 10.0  # 10 h a leg
    s, e = split_runs(np.full(6, 80.0), cum_t, 20.0)
    assert s.tolist() == [0, 2, 4] and e.tolist() == [2, 4, 6]


def test_barred_ranges_come_from_the_vessels_file_and_move_listed_settings_out():
    import pandas as pd

    from pipeline.engine_ranges import parse_barred_rpm
    from pipeline.fleet_validate import validate_vessels
    from pipeline.routing.voyage import problem_from_voyage
    from routing_cases import MODEL

    raw = pd.DataFrame({"imo": ["9074729", "9176187", "9223100"], "name": ["A", "B", "C"],
                        "barred_rpm": ["52-60; 70-72.5", "60-52", ""]})
    good, bad = validate_vessels(raw)
    assert good["imo"].tolist() == [9074729, 9223100]
    assert bad["reason"].tolist() == ["bad barred_rpm '60-52' (expected low-high rpm, e.g. 52-60, separated by ';')"]
    assert parse_barred_rpm("52-60; 70-72.5") == ((52.0, 60.0), (70.0, 72.5)) and parse_barred_rpm(None) == ()
    voyage = {"voyage_id": "VB", "imo": 9074729, "dep_lat": DEP[0], "dep_lon": DEP[1], "arr_lat": ARR[0],
              "arr_lon": ARR[1], "depart_utc": np.datetime64("2020-12-01T06"), "rta_utc": np.datetime64("2020-12-07T06"),
              "rpm_options": [70.0, 83.0, 100.0]}
    pr = problem_from_voyage(voyage, MODEL, barred_rpm="80-90")
    assert pr.rpm_options == (70.0, 80.0, 100.0) and pr.barred_rpm == ((80.0, 90.0),)
    assert "83 rpm lie in the engine's barred range(s) 80-90: moved to 80" in pr.rpm_note
    with pytest.raises(RoutingInputError, match="voyage VB: vessel 9074729: bad barred_rpm"):
        problem_from_voyage(voyage, MODEL, barred_rpm="90-80")
