"""The one best-speeds step of a fixed route (route_speeds.best_speeds): its settings stage is the DP it names or the
start it is given, its continuous stage is kept only when cheaper, and a start nothing beats is the answer."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.routing.baseline import evaluate
from pipeline.routing.engine_limits import EngineLimits, best_engine_plan, limited_plan
from pipeline.routing.route_speeds import Start, best_speeds
from pipeline.routing.savings import solver_instance
from routing_cases import field, problem, wavy


@pytest.fixture(scope="module")
def route():
    pr = problem((30.0, -160.0), (33.0, -146.0), 110.0, n_lines=8, n_points=5)
    inst, base = solver_instance(pr, pr.search_space(), field(wavy(7)))
    return inst, base


def test_without_limits_the_settings_stage_is_the_exact_dp_on_the_route(route):
    inst, base = route
    idx, cost, _ = best_engine_plan(inst, base)
    got = best_speeds(inst, base, None, continuous=False)
    assert got.settings_idx.tolist() == idx.tolist() and got.cost == cost and not got.refined
    assert got.fuel_t == pytest.approx(float(evaluate(inst, base, idx)[2]))
    assert got.rpm.tolist() == inst.rpm_options[idx].tolist()
    assert got.as_plan_settings(inst)[0] is inst  # settings only: the instance itself, no copy


def test_under_limits_the_settings_stage_is_the_held_dp(route):
    inst, base = route
    limits = EngineLimits(12.0, 0.05)
    got = best_speeds(inst, base, limits, continuous=False)
    held = limited_plan(inst, base, limits, gap=1e-3, buckets=64)
    assert got.held is not None and got.settings_idx.tolist() == held.rpm_idx.tolist() and got.cost == held.cost


def test_the_continuous_stage_is_kept_only_when_cheaper(route):
    inst, base = route
    settings = best_speeds(inst, base, None, continuous=False)
    refined = best_speeds(inst, base, None, continuous=True)
    assert refined.settings_cost == settings.cost and refined.cost <= settings.cost
    assert refined.refined == (refined.cost < settings.cost)
    if refined.refined:  # rpm of its own: handed on as the instance with those rpm among its settings
        at, idx = refined.as_plan_settings(inst)
        assert np.allclose(at.rpm_options[idx], refined.rpm)


def test_a_start_nothing_beats_is_the_answer(route):
    inst, base = route
    best = best_speeds(inst, base, None, continuous=False)
    # a start cheaper than the route's optimum (as a solver's plan priced differently could be): the DP, pruned by
    # it, finds nothing better, so the start itself is returned
    start = Start(best.rpm, best.cost - 1.0, 123.0)
    got = best_speeds(inst, base, None, continuous=False, start=start)
    assert got.cost == start.cost and got.fuel_t == 123.0 and got.rpm.tolist() == best.rpm.tolist()
    # a dearer start is beaten by the DP
    worse = Start(np.full(len(base) - 1, inst.rpm_options[-1]), best.cost + 50.0)
    assert best_speeds(inst, base, None, continuous=False, start=worse).cost == best.cost


def test_without_a_search_the_start_is_refined_only(route):
    inst, base = route
    dp = best_speeds(inst, base, None, continuous=False)
    start = Start(dp.rpm, dp.cost, dp.fuel_t)  # a solver's plan: here the route's optimum over the settings
    kept = best_speeds(inst, base, None, continuous=False, start=start, search=False)
    assert kept.rpm.tolist() == start.rpm.tolist() and kept.cost == dp.cost and kept.legs_sailed == 0
    # refined from the start without a DP: what the search-and-refine step gives from that same settings plan
    refined = best_speeds(inst, base, None, continuous=True, start=start, search=False)
    searched = best_speeds(inst, base, None, continuous=True)
    assert refined.legs_sailed == 0 < searched.legs_sailed
    assert refined.cost == searched.cost and refined.rpm.tolist() == searched.rpm.tolist()
    with pytest.raises(ValueError, match="needs a start"):
        best_speeds(inst, base, None, search=False)
