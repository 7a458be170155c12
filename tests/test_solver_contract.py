"""Every registered solver answers one contract (contract.py): on time or least-late, never worse than the
constant-speed voyage on the base route in the same weather, the same seed gives the same plan, and the route keeps
clear of land. A new solver proves itself by being registered: this suite runs over solvers.SOLVERS.

The constant-speed voyage is computed here independently: the base route sailed leg by leg at one rpm found by
bisection on the passage time, not by the code under test.
"""

from __future__ import annotations

from dataclasses import replace

import pytest

from pipeline.routing.engine_limits import EngineLimits, settings_held_h
from pipeline.routing.options import SOLVER_NAMES, RoutingOptions, UnknownSolverError
from pipeline.routing.problem import RoutingInputError
from pipeline.routing.solvers import SOLVERS
from routing_cases import FAST, constant_speed, field, moving_storm, problem, solve, wavy

DEP, ARR = (30.0, -160.0), (33.0, -146.0)
WAVY = field(wavy(7))
STORM = field(moving_storm(3, 31.0, 203.0, drift_kn=(15.0, 0.0)), step_h=3, hours=200)
LIMITS = EngineLimits(12.0, 0.05)


def _rta_h(rpm: float) -> float:
    """Calm-water passage on the base line at `rpm` (reference model: STW = 0.14·rpm kn)."""
    return problem(DEP, ARR, 100.0).search_space().base_distance_nm / (0.14 * rpm)


CASES = {  # name → (weather, RTA as the calm passage at this rpm)
    "wavy-between-settings": (WAVY, 78.0),
    "wavy-tight": (WAVY, 97.0),
    "storm": (STORM, 80.0),
    "wavy-impossible": (WAVY, 115.0),  # faster than the fastest setting: least late
}


def _constant_speed(pr, weather, base: str = "gc") -> tuple[float, float, float]:
    """`constant_speed` along the base route (the great circle, or the rhumb line)."""
    return constant_speed(pr, replace(pr, base=base).search_space(), weather)


@pytest.mark.parametrize("case", sorted(CASES))
@pytest.mark.parametrize("solver", SOLVER_NAMES)
@pytest.mark.slow
def test_every_solver_is_never_worse_than_constant_speed(solver, case):
    weather, rpm_rta = CASES[case]
    pr = problem(DEP, ARR, _rta_h(rpm_rta), n_lines=6, n_points=7)
    rpm_b, hours_b, fuel_b = _constant_speed(pr, weather, SOLVERS[solver].base)
    # the product's options (what `jitroute route --solver NAME` runs); bfoa's cut short to keep the suite quick
    opts = FAST if solver == "bfoa" else SOLVERS[solver].make_options(RoutingOptions(solver=solver).solver_overrides())
    plan = solve(pr, weather, solver=solver, seed=3, options=opts, limits=LIMITS, savings=True)
    assert plan.legs, plan.reason
    if hours_b <= pr.t_req_h + 1e-6:  # the constant speed is on time: so is the plan, on no more fuel
        assert plan.status == "ok" and plan.hours <= pr.t_req_h + 1e-6, plan.reason
        assert plan.fuel_t <= fuel_b * (1 + 1e-6), (plan.fuel_t, fuel_b)
        assert plan.savings.total_pct >= -1e-7 and plan.savings.speed_profile_pct >= -1e-7
    else:  # least late: no later than full speed on the base route (another route may even be on time)
        assert plan.status in ("ok", "late") and plan.hours <= hours_b + 1e-6
    if not SOLVERS[solver].is_baseline:
        assert plan.baseline.legs and len({leg["rpm"] for leg in plan.baseline.legs}) == 1
        assert plan.baseline.legs[0]["rpm"] == pytest.approx(rpm_b, rel=1e-5)
        assert plan.baseline.fuel_t == pytest.approx(fuel_b, rel=1e-6)
        runs = settings_held_h(plan.legs)
        assert len(runs) == 1 or min(h for _, h in runs) >= LIMITS.min_hold_h - 1e-6
    assert plan.min_land_clearance_nm >= pr.land_clearance_nm - 1e-6
    again = solve(pr, weather, solver=solver, seed=3, options=opts, limits=LIMITS, savings=True)
    assert again.waypoints == plan.waypoints and [g["rpm"] for g in again.legs] == [g["rpm"] for g in plan.legs]


def test_a_voyage_too_short_to_change_setting_sails_one_well_chosen_rpm():
    """Shorter than the hold: one setting for the whole voyage, the constant rpm that arrives at the RTA, not the
    next listed setting (which arrives early on more fuel)."""
    dep, arr = (30.0, -160.0), (30.5, -158.5)
    pr0 = problem(dep, arr, 10.0, n_lines=3, n_points=5)
    hours = pr0.search_space().base_distance_nm / (0.14 * 78.0)  # between the listed 70 and 85 rpm
    pr = problem(dep, arr, hours, n_lines=3, n_points=5)
    rpm_b, _, fuel_b = _constant_speed(pr, WAVY)
    plan = solve(pr, WAVY, solver="bfoa", options=FAST, limits=LIMITS, savings=True)
    assert len({g["rpm"] for g in plan.legs}) == 1 and rpm_b not in pr.rpm_options
    assert plan.legs[0]["rpm"] == pytest.approx(rpm_b, rel=1e-5)
    assert plan.status == "ok" and plan.fuel_t <= fuel_b * (1 + 1e-6)


def test_unknown_solver_and_options_are_refused_before_routing():
    with pytest.raises(UnknownSolverError, match="use one of bfoa, dp, astar, gc, rhumb"):
        RoutingOptions(solver="dijkstra")
    with pytest.raises(UnknownSolverError, match="has no option 'gapp'.*gap"):
        SOLVERS["dp"].make_options({"gapp": "0"})
    with pytest.raises(UnknownSolverError, match="expected a value like"):
        SOLVERS["dp"].make_options({"gap": "tight"})
    product_dp = SOLVERS["dp"].make_options(RoutingOptions(solver="dp").solver_overrides())
    assert (product_dp.gap, product_dp.slot_h, product_dp.wait_free_first) == (1e-3, 1.0, True)
    assert SOLVERS["dp"].make_options({"slot_h": "none"}).slot_h is None  # the wait-free label DP alone
    assert SOLVERS["dp"].make_options({"gap": "0"}).gap == 0.0
    pr = problem(DEP, ARR, 60.0, n_lines=4, n_points=5)
    with pytest.raises(RoutingInputError, match="unknown solver"):
        solve(pr, WAVY, solver="dijkstra")


def test_rhumb_routes_along_the_rhumb_line_not_the_great_circle():
    dep, arr = (40.0, 190.0), (42.0, 235.0)  # long east-west leg: the two base lines part by tens of NM
    pr = problem(dep, arr, 200.0, n_lines=8, n_points=5)
    gc, rhumb = solve(pr, field(wavy(1)), solver="gc"), solve(pr, field(wavy(1)), solver="rhumb")
    assert gc.legs and rhumb.legs
    mid_gc, mid_rh = gc.waypoints[4], rhumb.waypoints[4]
    assert mid_gc[0] > mid_rh[0] + 0.3  # the great circle bends poleward of the rhumb line
    with pytest.raises(RoutingInputError, match="rhumb base route"):
        solve(pr, field(wavy(1)), solver="rhumb", space=pr.search_space())


@pytest.mark.slow  # jitroute child processes
def test_the_cli_refuses_an_unknown_solver_or_option_before_opening_anything(tmp_path):
    import os

    from processes import jitroute

    env = {**os.environ, "JITROUTE_DATA": str(tmp_path / "data")}
    for args, says in ((("--solver", "dijkstra"), "unknown solver 'dijkstra'; use one of bfoa, dp, astar, gc, rhumb"),
                       (("--solver", "dp", "--solver-option", "gapp=0"), "solver 'dp' has no option 'gapp'"),
                       (("--solver", "dp", "--solver-option", "gap"), "--solver-option must be NAME=VALUE"),
                       (("--refine-split", "0"), "refine_split must be a whole number ≥ 1 (1: no refinement), not 0")):
        done = jitroute("route", *args, "--voyage", "V1", env=env, timeout_s=120)
        assert done.returncode == 2, done.stderr
        assert done.stderr.count(says) == 1, done.stderr  # said once, as one error line
        assert "Traceback" not in done.stderr
    assert not (tmp_path / "data").exists()  # refused before the data root was opened
