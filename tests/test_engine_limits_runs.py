"""The engine-limits DP leaves out the change runs an earlier label of the line dominates (engine.hold_search
.runs_to_sail_nb): fewer legs sailed, the same plan where its dominance rule is exact (weather steady in time)."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.routing import engine_limits as el
from pipeline.routing.engine import hold_search as hs
from pipeline.routing.baseline import shortest_route
from pipeline.routing.engine_limits import EngineLimits, limited_plan
from pipeline.routing.problem import Instance
from routing_cases import field, problem, wavy

C = 0.05  # t per change


def test_a_change_is_sailed_only_when_no_earlier_label_reaches_its_setting_as_cheaply():
    # kept labels of one line: (time h, fuel t, changes, setting); e = 0, so g = fuel + C·changes
    kt = np.array([10.0, 11.0, 9.0, 12.0])
    kf = np.array([5.0, 6.0, 7.0, 4.0])
    kn = np.array([0, 0, 1, 0], np.int64)
    kr = np.array([0, 1, 2, 0], np.int64)
    sail = hs.runs_to_sail_nb(kt, kf, kn, kr, 0, 4, 3, C, 0.0)
    # in time order: label 2 (9 h, g 7.05), label 0 (10 h, g 5), label 1 (11 h, g 6), label 3 (12 h, g 4)
    assert sail[2].tolist() == [True, True, False]  # the first of the line: both its changes
    assert sail[0].tolist() == [False, True, True]  # cheaper than label 2 after a change: both
    # label 1 changing to 0 (g 6.05) meets label 0 sailing on at 0 (g 5); to 2 (6.05) meets label 0's change (5.05)
    assert sail[1].tolist() == [False, False, False]
    assert sail[3].tolist() == [False, True, True]  # the cheapest yet, though the latest
    # a later label dominates nothing: the earliest label's changes are sailed whatever follows
    assert hs.runs_to_sail_nb(kt[[2]], kf[[2]], kn[[2]], kr[[2]], 0, 1, 3, C, 0.0)[0].tolist() == [True, True, False]


def test_the_early_rate_counts_the_later_arrival():
    # jit's early-arrival rate e: g = f − e·t, so a later label worth more than its extra fuel is not dominated
    kt, kf = np.array([10.0, 12.0]), np.array([5.0, 5.5])
    kn, kr = np.zeros(2, np.int64), np.array([0, 1], np.int64)
    assert hs.runs_to_sail_nb(kt, kf, kn, kr, 0, 2, 2, C, 0.0)[1].tolist() == [False, False]  # 5.55 ≥ 5
    assert hs.runs_to_sail_nb(kt, kf, kn, kr, 0, 2, 2, C, 0.5)[1].tolist() == [True, False]  # 0.05 − 6 < 0 − 5


@pytest.mark.parametrize("limits", [EngineLimits(12.0, 0.05), EngineLimits(20.0, 0.0)])
@pytest.mark.slow
def test_same_plan_as_the_dp_that_sails_every_change_in_steady_weather(limits, monkeypatch):
    pr = problem((30.0, -160.0), (33.0, -146.0), 100.0, n_lines=10, n_points=5)
    hours = pr.search_space().base_distance_nm / (0.14 * 82.0)  # the calm-water passage at 82 rpm
    pr = problem((30.0, -160.0), (33.0, -146.0), hours, n_lines=10, n_points=5)
    space = pr.search_space()
    inst = Instance.build(pr, space, field(wavy(7)))  # steady in time: the dominance is exact here
    nodes = shortest_route(space)
    kept = limited_plan(inst, nodes, limits)
    kept_near = limited_plan(inst, nodes, limits, gap=el.PLAN_GAP, buckets=el.PLAN_BUCKETS)
    # the DP as it was: its interpreted twin, every change run sailed
    every = lambda kt, kf, kn, kr, lo, hi, R, c, e: np.ones((hi - lo, R), np.bool_)  # noqa: E731
    monkeypatch.setattr(hs, "runs_to_sail_nb", every)
    monkeypatch.setattr(el, "hold_search_nb", hs.hold_search_nb.py_func)
    for mine, gap, buckets in ((kept, 0.0, 0), (kept_near, el.PLAN_GAP, el.PLAN_BUCKETS)):
        ref = limited_plan(inst, nodes, limits, gap=gap, buckets=buckets)
        assert ref.rpm_idx.tolist() == mine.rpm_idx.tolist()
        assert (ref.cost, ref.fuel_t, ref.n_changes) == (mine.cost, mine.fuel_t, mine.n_changes)
        assert mine.legs_sailed < ref.legs_sailed
    assert kept.n_changes > 0  # a plan that changes setting: the runs left out were real alternatives


def test_a_route_planned_under_the_limits_once_is_not_planned_again():
    from pipeline.routing.route_speeds import best_speeds
    from pipeline.routing.solve import solver_instance

    pr = problem((30.0, -160.0), (33.0, -146.0), 110.0, n_lines=8, n_points=5)
    space = pr.search_space()
    inst, base = solver_instance(pr, space, field(wavy(7)))
    limits = EngineLimits(12.0, 0.05)
    known: dict = {}
    first = best_speeds(inst, base, limits, True, known=known)
    assert list(known.values()) == [first]
    assert best_speeds(inst, base, limits, True, known=known) is first  # the same object: not planned again
    again = best_speeds(inst, base, limits, True)  # planned afresh: the same answer
    assert again.held.rpm_idx.tolist() == first.held.rpm_idx.tolist() and again.held.cost == first.held.cost
    assert again.cost == first.cost and again.rpm.tolist() == first.rpm.tolist()
    # the settings plan is the held DP's; the refinement is kept only when cheaper
    assert first.settings_cost == first.held.cost and first.cost <= first.held.cost
    assert first.refined == (first.cost < first.held.cost)
    if not first.refined:
        assert first.rpm.tolist() == inst.rpm_options[first.held.rpm_idx].tolist()
    # another route, or the same one without continuous speed, is another entry
    other = base.copy()
    other[1:-1] = np.clip(other[1:-1] + 1, 0, space.lat.shape[1] - 1)
    best_speeds(inst, other, limits, True, known=known)
    best_speeds(inst, base, limits, False, known=known)
    assert len(known) == 3
