"""Honest savings (constant speed arriving at the RTA, split into speed profile and route) and engine-change limits
(each rpm setting held a minimum time, a cost per change) on small voyages in steady, non-uniform weather.

Expected values come from exhaustive enumeration or from the definitions, not from the code under test.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from pipeline.routing.engine import leg as lk
from pipeline.routing.baseline import shortest_route
from pipeline.routing.engine_limits import (PLAN_BUCKETS, PLAN_GAP, REFERENCE_BUCKETS, EngineLimits, best_engine_plan,
                                            incumbent_cost, limited_plan, settings_held_h)
from pipeline.routing.objectives import route_cost_nb
from pipeline.routing.problem import Instance
from pipeline.routing.solve import solver_instance
from routing_cases import field, moving_storm, problem, solve, wavy

DEP, ARR = (30.0, -160.0), (33.0, -146.0)
WEATHER = field(wavy(7))  # steady in time: the limited plan's dominance rule is exact here


def _voyage(rpm_rta: float, **kw):
    """A voyage whose RTA is the calm-water passage at `rpm_rta` (reference model: STW = 0.14·rpm kn)."""
    pr0 = problem(DEP, ARR, 100.0, **kw)
    hours = pr0.search_space().base_distance_nm / (0.14 * rpm_rta)
    return problem(DEP, ARR, hours, **kw)


def _brute_force(inst, nodes, limits: EngineLimits) -> float:
    """Least objective + change cost over every rpm sequence that holds each setting (all but a single one)."""
    L = len(nodes) - 1
    ct, cf = np.empty(L + 1), np.empty(L + 1)
    best = np.inf
    for seq in itertools.product(range(len(inst.rpm_options)), repeat=L):
        rpm_idx = np.array(seq, np.int64)
        code, _ = lk.sail_route_nb(nodes, rpm_idx, 0, inst.graph, inst.vessel, inst.wx, inst.objective, ct, cf)
        if code != lk.OK:
            continue
        hours = np.diff(ct)
        runs = [sum(hours[i] for i, _ in grp) for _, grp in itertools.groupby(enumerate(seq), key=lambda x: x[1])]
        if len(runs) > 1 and min(runs) < limits.min_hold_h - 1e-9:
            continue
        cost = route_cost_nb(inst.objective, ct[-1] - inst.t_dep_h, cf[-1]) + limits.change_cost_t * (len(runs) - 1)
        best = min(best, cost)
    return best


@pytest.mark.parametrize("limits", [EngineLimits(12.0, 0.05), EngineLimits(20.0, 0.0), EngineLimits(0.0, 0.5),
                                    EngineLimits(0.0, 0.0)])
def test_limited_plan_equals_brute_force_over_hold_respecting_sequences(limits):
    pr = _voyage(80.0, n_lines=6, n_points=5)  # 7 legs of ≈ 7 h, 3 settings: 2,187 sequences
    space = pr.search_space()
    inst = Instance.build(pr, space, WEATHER)
    nodes = shortest_route(space)
    got = limited_plan(inst, nodes, limits)
    best = _brute_force(inst, nodes, limits)
    assert got.cost == pytest.approx(best, rel=1e-12)
    near = limited_plan(inst, nodes, limits, gap=0.01)  # ε-trimmed labels: within 1 % of the best
    assert best - 1e-9 <= near.cost <= best * 1.01
    # bucketed labels (as routing runs it): a real plan, never dearer than one setting held throughout; with
    # routing's bucket count a graph this small keeps its optimum
    single = incumbent_cost(inst, nodes, limits, one_change=False)
    for buckets in (1, 2, PLAN_BUCKETS):
        coarse = limited_plan(inst, nodes, limits, gap=PLAN_GAP, buckets=buckets)
        assert best - 1e-9 <= coarse.cost <= single + 1e-9
        ct, cf = np.empty(len(nodes)), np.empty(len(nodes))
        lk.sail_route_nb(nodes, coarse.rpm_idx, 0, inst.graph, inst.vessel, inst.wx, inst.objective, ct, cf)
        changes = int(np.count_nonzero(np.diff(coarse.rpm_idx)))
        assert coarse.cost == pytest.approx(route_cost_nb(inst.objective, ct[-1] - inst.t_dep_h, cf[-1])
                                            + limits.change_cost_t * changes, rel=1e-12)
    assert limited_plan(inst, nodes, limits, gap=PLAN_GAP, buckets=PLAN_BUCKETS).cost <= best * (1 + PLAN_GAP)
    ct, cf = np.empty(len(nodes)), np.empty(len(nodes))
    lk.sail_route_nb(nodes, got.rpm_idx, 0, inst.graph, inst.vessel, inst.wx, inst.objective, ct, cf)
    assert got.fuel_t == pytest.approx(cf[-1], rel=1e-12)
    assert got.n_changes == int(np.count_nonzero(np.diff(got.rpm_idx)))


STORM = field(moving_storm(3, 31.0, 203.0, drift_kn=(15.0, 0.0)), step_h=3, hours=200)  # crosses the route


@pytest.mark.parametrize("weather, rpm_rta", [(WEATHER, 80.0), (WEATHER, 98.0), (WEATHER, 120.0), (STORM, 80.0)])
def test_best_engine_plan_on_a_route_equals_enumeration(weather, rpm_rta):
    # what A*, the savings split and the limits' reference use: on time at least fuel, else least late; exact by
    # default, within its gap when asked (the RTA at 120 rpm cannot be met: the least-late plan)
    pr = _voyage(rpm_rta, n_lines=6, n_points=5)
    inst = Instance.build(pr, pr.search_space(), weather)
    nodes = shortest_route(inst.space)
    best = _brute_force(inst, nodes, EngineLimits(0.0, 0.0))
    rpm_idx, cost, _ = best_engine_plan(inst, nodes)
    assert cost == pytest.approx(best, rel=1e-12)
    ct, cf = np.empty(len(nodes)), np.empty(len(nodes))
    lk.sail_route_nb(nodes, rpm_idx, 0, inst.graph, inst.vessel, inst.wx, inst.objective, ct, cf)
    assert route_cost_nb(inst.objective, ct[-1] - inst.t_dep_h, cf[-1]) == pytest.approx(cost, rel=1e-12)
    _, near, _ = best_engine_plan(inst, nodes, gap=0.01)
    assert best - 1e-9 <= near <= best * 1.01
    _, coarse, _ = best_engine_plan(inst, nodes, gap=PLAN_GAP, buckets=REFERENCE_BUCKETS)  # the limits' reference
    assert best - 1e-9 <= coarse <= best * (1 + PLAN_GAP)


@pytest.mark.slow
def test_limited_plan_holds_every_setting_and_costs_fuel():
    pr = _voyage(80.0, n_lines=6, n_points=7)
    limits = EngineLimits(min_hold_h=12.0, change_cost_t=0.05)
    space = pr.search_space()
    # over the settings alone (continuous=False), where every engine plan on a route can be enumerated
    free = solve(pr, WEATHER, solver="dp", space=space, continuous=False)
    held = solve(pr, WEATHER, solver="dp", space=space, limits=limits, continuous=False)
    assert min(h for _, h in settings_held_h(free.legs)) < limits.min_hold_h  # the limits bind on this voyage
    runs = settings_held_h(held.legs)
    assert len(runs) == 1 or min(h for _, h in runs) >= limits.min_hold_h - 1e-6
    assert held.status == "ok" and held.hours <= pr.t_req_h + 1e-6
    # what the limits cost: against the best engine plan on the held plan's route without them (enumerated)
    inst, _ = solver_instance(pr, space, WEATHER)
    nodes = np.array([space.centre] + [
        int(np.argmin((space.lat[i] - la) ** 2 + ((space.lon[i] - lo + 180.0) % 360.0 - 180.0) ** 2))
        for i, (la, lo) in enumerate(held.waypoints[1:-1], start=1)] + [space.centre], np.int64)
    assert held.unlimited_fuel_t == pytest.approx(_brute_force(inst, nodes, EngineLimits(0.0, 0.0)), rel=1e-3)
    assert free.fuel_t <= held.unlimited_fuel_t + 1e-9 <= held.fuel_t + 2e-9
    assert held.limits_fuel_t == held.fuel_t - held.unlimited_fuel_t
    assert held.cost == pytest.approx(held.fuel_t + 0.05 * held.n_engine_changes)  # on time inside the window
    row = held.route_row()
    assert row["min_engine_hold_h"] == 12.0 and row["n_engine_changes"] == len(runs) - 1
    assert row["limits_fuel_t"] == pytest.approx(held.limits_fuel_t)


def test_what_the_limits_cost_is_measured_against_the_best_plan_on_the_route_not_the_solvers():
    """A solver plan with a poor engine plan must not make the limits look like a saving: the reference is the best
    engine plan on the route without limits (certified within 0.1 %), here checked by enumerating every rpm
    sequence on the route."""
    from pipeline.routing.solve import _plan, _with_limits

    pr = _voyage(80.0, n_lines=6, n_points=5)
    inst = Instance.build(pr, pr.search_space(), WEATHER)
    nodes = shortest_route(inst.space)
    poor = _plan(inst, "bfoa", nodes, np.array([2, 0, 2, 0, 2, 0, 2], np.int64))  # fast and slow by turns
    assert poor.status == "ok"
    best_free = _brute_force(inst, nodes, EngineLimits(0.0, 0.0))
    assert poor.cost > best_free * 1.01  # the poor plan burns clearly more than the best on its route
    held = _with_limits(inst, poor, nodes, EngineLimits(12.0, 0.05), continuous=False)
    assert held.unlimited_fuel_t == pytest.approx(best_free, rel=1e-3)  # jit on time: cost = fuel
    assert 0.0 <= held.limits_fuel_t < poor.fuel_t - best_free
    # with continuous speed the reference is at least as good as every plan over the settings, and still no dearer
    # than the held plan: the limits never look like a saving
    smooth = _with_limits(inst, poor, nodes, EngineLimits(12.0, 0.05))
    assert smooth.unlimited_fuel_t <= best_free + 1e-9
    assert 0.0 <= smooth.limits_fuel_t and smooth.fuel_t <= held.fuel_t + 1e-9


def test_honest_baseline_arrives_at_the_rta_and_the_split_adds_up():
    """RTA between two settings: the baseline is the constant speed between them that arrives at the RTA (the
    faster listed setting would arrive hours early, a saving the old figure credited to routing)."""
    pr = _voyage(72.0)
    plan = solve(pr, WEATHER, solver="dp", savings=True)
    sp = plan.savings
    assert pr.t_req_h - 1e-2 <= plan.baseline.hours <= pr.t_req_h + 1e-9  # the baseline arrives at the RTA
    assert {g["rpm"] for g in plan.baseline.legs} == {sp.baseline_rpm}
    assert 70.0 < sp.baseline_rpm < 100.0 and sp.baseline_rpm not in pr.rpm_options
    assert pr.t_req_h - 1e-3 - 1e-9 <= sp.baseline_hours <= pr.t_req_h
    # the constant rpm, sailed independently, gives the baseline's hours and fuel
    inst = Instance.build(pr, pr.search_space(), WEATHER)
    one = inst.vessel._replace(rpm_options=np.array([sp.baseline_rpm]))
    nodes = shortest_route(inst.space)
    ct, cf = np.empty(len(nodes)), np.empty(len(nodes))
    lk.sail_route_nb(nodes, np.zeros(len(nodes) - 1, np.int64), 0, inst.graph, one, inst.wx, inst.objective, ct, cf)
    assert ct[-1] - inst.t_dep_h == pytest.approx(sp.baseline_hours) and cf[-1] == pytest.approx(sp.baseline_fuel_t)
    assert sp.plan_fuel_t == plan.fuel_t
    assert sp.speed_profile_pct + sp.route_pct == pytest.approx(sp.total_pct, abs=1e-12)
    assert sp.total_pct == pytest.approx(100 * (sp.baseline_fuel_t - plan.fuel_t) / sp.baseline_fuel_t)
    assert plan.savings_pct == pytest.approx(sp.total_pct, rel=1e-9) and sp.total_pct >= 0.0
    assert sp.speed_profile_pct >= 0.0  # the constant speed is one of the engine plans on the base route
    row = plan.route_row()
    assert row["savings_total_pct"] == sp.total_pct and row["honest_baseline_rpm"] == sp.baseline_rpm
