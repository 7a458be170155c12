"""`--solver dp` on late and long voyages: the fastest plan, the lateness in the DP's cost bound, the grid step scaled
with the voyage and stated in the plan's reason.

Checked against exhaustive enumeration on small graphs (every route × setting per leg, sailed with the legs' kernel):
the fastest plan arrives first, the bound on a plan's cost is never above the cost of a plan that burns and takes at
least as much, and a late voyage's DP (the fastest plan as its incumbent, its bound pricing the lateness) returns the
enumerated optimum; the grid DP on a coarser grid equals the enumeration of that grid and says it waits on it."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from tests.exact_cases import DEP, enumerate_nb, instance, weather, window_problem
from tests.routing_cases import problem, solve
from pipeline.routing.engine import leg as lk
from pipeline.routing.baseline import baseline as find_baseline, evaluate
from pipeline.routing.dp import grid_step_h
from pipeline.routing.options import DpOptions
from pipeline.routing.engine.bounds import cost_lb_nb
from pipeline.routing.dp_grid import line_times
from pipeline.routing.fastest_plan import fastest_plan
from pipeline.routing.objectives import objective, route_cost_nb
from pipeline.routing.solve import solver_instance
from pipeline.routing.contract import UnknownSolverError
from pipeline.routing.solvers import SOLVERS

def _every_plan(inst):
    """(hours, fuel) of every route × setting per leg that can be sailed."""
    g, v, w, o = inst.graph, inst.vessel, inst.wx, inst.objective
    L2, P = g.lat.shape
    ct, cf = np.empty(L2), np.empty(L2)
    for mid in itertools.product(range(P), repeat=L2 - 2):
        nodes = np.array((P // 2, *mid, P // 2), np.int64)
        if not all(g.edge_ok[i, nodes[i], nodes[i + 1]] for i in range(L2 - 1)):
            continue
        for rpm in itertools.product(range(len(v.rpm_options)), repeat=L2 - 1):
            code, _ = lk.sail_route_nb(nodes, np.array(rpm, np.int64), 0, g, v, w, o, ct, cf)
            if code == lk.OK:
                yield ct[-1] - o.t_dep_h, cf[-1]


@pytest.mark.parametrize("kind, rpms, n", [("static", (70, 85, 100), 0), ("storm", (75, 100), 1),
                                           ("current", (60, 80, 100), 2), ("storm", (70, 85, 100), 3)])
@pytest.mark.slow
def test_the_fastest_plan_arrives_first(kind, rpms, n):
    inst, _ = instance(kind, 30.0, rpms, n)
    nodes, rpm_idx, hours, n_legs = fastest_plan(inst)
    first = min(h for h, _ in _every_plan(inst))
    assert nodes is not None and n_legs > 0
    assert hours == pytest.approx(first, rel=1e-12)
    assert evaluate(inst, nodes, rpm_idx)[1] == pytest.approx(first, rel=1e-12)  # the plan returned takes those hours


@pytest.mark.parametrize("kind", ["jit", "thesis"])
def test_the_cost_bound_is_never_above_a_plan_that_burns_and_takes_at_least_as_much(kind):
    o = objective(kind, t_dep_h=0.0, max_hours=200.0, t_req_h=50.0, window_h=6.0, f_target=40.0)
    hours = np.array([0.0, 20.0, 42.0, 44.0, 49.9, 50.0, 50.0 + 1e-10, 50.5, 51.0, 80.0])
    fuel = np.array([0.0, 10.0, 39.0, 40.0, 55.0])
    for h_lb, f_lb in itertools.product(hours, fuel):
        lb = cost_lb_nb(o, f_lb, h_lb)
        for h, f in itertools.product(hours[hours >= h_lb], fuel[fuel >= f_lb]):
            assert lb <= route_cost_nb(o, h, f) + 1e-12, (h_lb, f_lb, h, f)
    if kind == "jit":  # the lateness is in it: an hour late is 1000 t plus 10,000 t per hour
        assert cost_lb_nb(o, 40.0, 51.0) == pytest.approx(40.0 + 1000.0 + 1.0e4)
    assert cost_lb_nb(o, math.inf, 10.0) == math.inf and cost_lb_nb(o, 10.0, math.inf) == math.inf


@pytest.mark.parametrize("kind, obj, rpms, n", [("static", "jit", (70, 85, 100), 0), ("storm", "jit", (75, 100), 1),
                                                ("current", "thesis", (60, 80, 100), 2),
                                                ("storm", "thesis", (70, 85, 100), 3)])
@pytest.mark.slow
def test_a_late_voyage_gets_the_enumerated_optimum_with_the_fastest_plan_as_incumbent(kind, obj, rpms, n):
    """An RTA 25 % under the calm full-speed passage: every plan is late. Without a BFOA incumbent the DP's only
    on-hand plan is the (late) baseline; it sails the fastest plan, prunes on lateness, and still returns the
    enumerated optimum (exact labels) or a plan within the gap."""
    inst, base = instance(kind, 30.0, rpms, n, obj=obj)
    best = min(route_cost_nb(inst.objective, h, f) for h, f in _every_plan(inst))
    assert best > 1000.0  # late under both objectives
    exact = SOLVERS["dp"].search(inst, base, seed=1, options=DpOptions(incumbent=None))
    trimmed = SOLVERS["dp"].search(inst, base, seed=1, options=DpOptions(gap=0.01, incumbent=None))
    assert evaluate(inst, exact.nodes, exact.rpm_idx)[0] == pytest.approx(best, rel=1e-12)
    assert best - 1e-9 <= evaluate(inst, trimmed.nodes, trimmed.rpm_idx)[0] <= best * 1.01 + 1e-9


def test_late_pricing_sails_fewer_legs_than_fuel_alone_on_a_longer_graph():
    """On 8 lines × 9 nodes with an impossible RTA the lateness bound and the fastest incumbent cut the legs the
    label DP sails (same plan as with the baseline's incumbent alone priced on fuel, which the exact labels give)."""
    pr = problem(DEP, (34.0, -146.0), 40.0, rpm_options=(70, 80, 90, 100), n_lines=8, n_points=9, max_shift=2,
                 d_point_nm=20.0)
    space = pr.search_space()
    inst, base_nodes = solver_instance(pr, space, weather("storm", 4))
    base = find_baseline(inst, base_nodes)
    found = SOLVERS["dp"].search(inst, base, seed=1, options=DpOptions(incumbent=None))
    plan_hours = evaluate(inst, found.nodes, found.rpm_idx)[1]
    assert plan_hours > inst.objective.t_req_h  # late
    assert plan_hours == pytest.approx(fastest_plan(inst)[2], abs=0.05)  # the least late, to a few minutes
    # the same search with no upper bound at all (pricing cannot prune): it must sail more and find the same cost
    from pipeline.routing.bound_tables import latest_departures
    from pipeline.routing.dp import _label_search

    _, _, cost_free, legs_free, _, _ = _label_search(inst, DpOptions(gap=0.0), math.inf, latest_departures(inst), base)
    assert cost_free == pytest.approx(evaluate(inst, found.nodes, found.rpm_idx)[0], rel=1e-12)
    assert found.n_evals < legs_free / 3


@pytest.mark.slow
def test_the_grid_step_grows_with_the_rta_and_the_reason_says_so():
    """slots_per_rta: the step is the RTA's hours over that many slots in whole hours when that is longer than
    slot_h. On storm-window (no wait-free plan: the ship must wait for the storm to move off) with a 75 h RTA and
    25 slots, the grid is 3 h: the plan is the enumerated optimum of the 3 h grid and its reason says so."""
    pr, fld = window_problem(), weather("storm-window", 0)
    inst, _ = solver_instance(pr, pr.search_space(), fld)
    assert grid_step_h(inst, DpOptions(slot_h=1.0)) == 1.0
    assert grid_step_h(inst, DpOptions(slot_h=1.0, slots_per_rta=240)) == 1.0  # 75 h: the 1 h grid
    assert grid_step_h(inst, DpOptions(slot_h=1.0, slots_per_rta=25)) == 3.0
    assert grid_step_h(inst, DpOptions(slot_h=1.0, slots_per_rta=20)) == 4.0  # 3.75 h rounded up
    assert grid_step_h(inst, DpOptions(slot_h=5.0, slots_per_rta=25)) == 5.0
    opts = DpOptions(slot_h=1.0, slots_per_rta=25, max_wait_h=12.0, wait_tph=0.3, incumbent=None)
    plan = solve(pr, fld, solver="dp", options=opts)
    assert plan.status == "ok" and plan.legs[0]["wait_h"] >= 3.0 - 1e-9
    assert "waits on a 3 h grid" in plan.reason
    best = enumerate_nb(inst.graph, inst.vessel, inst.wx, inst.objective, line_times(inst, [], 3.0), 12.0, 0.3)
    assert plan.cost == pytest.approx(best, rel=1e-9)
    on_1h = solve(pr, fld, solver="dp", options=DpOptions(slot_h=1.0, max_wait_h=12.0, wait_tph=0.3, incumbent=None))
    # the step asked for: the reason names the space certified, and no coarser grid
    assert on_1h.status == "ok" and "leaving each node on a 1 h grid" in on_1h.reason
    assert "waits on a" not in on_1h.reason


def test_a_label_search_past_its_legs_budget_keeps_fewer_labels_and_the_plan_says_so():
    """max_label_legs paces the wait-free label DP by legs sailed: within the budget it is the exact search, bit for
    bit; past it the search is given up and run again keeping at most capped_labels per node (never cheaper than the
    exact plan in weather that holds still, where the exact one is the optimum), and the plan's reason says so."""
    pr = problem(DEP, (34.0, -146.0), 70.0, rpm_options=(70, 80, 90, 100), n_lines=8, n_points=9, max_shift=2,
                 d_point_nm=20.0)
    space = pr.search_space()
    fld = weather("static", 0)
    inst, base_nodes = solver_instance(pr, space, fld)
    base = find_baseline(inst, base_nodes)
    exact = SOLVERS["dp"].search(inst, base, seed=1, options=DpOptions(incumbent=None))
    roomy = SOLVERS["dp"].search(inst, base, seed=1, options=DpOptions(incumbent=None, max_label_legs=exact.n_evals))
    assert "labels per node" not in roomy.note and roomy.n_evals == exact.n_evals
    assert roomy.note.startswith("dp: certified as the best wait-free plan")  # gap 0: the space it is exact over
    assert (roomy.nodes == exact.nodes).all() and (roomy.rpm_idx == exact.rpm_idx).all()
    budget = exact.n_evals // 4
    capped = [SOLVERS["dp"].search(inst, base, seed=1, options=DpOptions(incumbent=None, max_label_legs=budget,
                                                                        capped_labels=3)) for _ in range(2)]
    assert capped[0].note is not None and "at most 3 labels per node" in capped[0].note
    assert f"{budget:,} legs" in capped[0].note
    assert capped[0].n_evals == capped[1].n_evals > budget  # paced by legs: the same work on every run
    if capped[0].nodes is not None:  # else nothing it kept beat the baseline, which the plan then is
        cost_exact = evaluate(inst, exact.nodes, exact.rpm_idx)[0]
        assert evaluate(inst, capped[0].nodes, capped[0].rpm_idx)[0] >= cost_exact - 1e-9
    # through solve() with the product's two steps: the reason names the cap
    opts = DpOptions(slot_h=1.0, max_wait_h=6.0, wait_free_first=True, gap=1e-3, incumbent=None,
                     max_label_legs=budget, capped_labels=3)
    plan = solve(pr, fld, solver="dp", options=opts)
    assert plan.status == "ok" and "at most 3 labels per node" in plan.reason
    with pytest.raises(ValueError, match="capped_labels"):
        DpOptions(max_label_legs=10, capped_labels=0)
    for bad in ({"capped_labels": "0"}, {"max_label_legs": "lots"}, {"max_label_legs": "-5"}, {"max_label_legs": "0"}):
        with pytest.raises(UnknownSolverError, match=next(iter(bad))):
            SOLVERS["dp"].make_options(bad)
    assert SOLVERS["dp"].make_options({"max_label_legs": "2e6"}).max_label_legs == 2_000_000
    assert SOLVERS["dp"].make_options({"max_label_legs": "none"}).max_label_legs is None
