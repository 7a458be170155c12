"""The exact DP against exhaustive enumeration of every route × engine plan on small graphs.

Each case is small enough to sail every route (one node per line) with every rpm per leg; the best of them
under the objective must be what the DP keeping every label returns, to rounding, and the ε-trimmed DP must be within the
gap it certifies. Cases cross static and moving storms, weather
limits that close parts of the graph, strong currents, loose, tight and impossible RTAs, both objectives and
two to five engine settings."""

from __future__ import annotations

import functools
import itertools
import math

import numpy as np
import pytest

from routing_cases import MODEL, field, moving_storm, problem, solve, wavy
from pipeline.routing.engine import leg as lk
from pipeline.routing.bound_tables import (finish_bounds, fuel_budget_t, label_bounds, latest_departures,
                                           reachable_windows, trim_eps)
from pipeline.routing.options import DpOptions
from pipeline.routing.engine.label_search import dp_exact_nb
from pipeline.routing.engine.bounds import fuel_to_finish_lb
from pipeline.routing.engine.labels import EXACT
from pipeline.routing.objectives import route_cost_nb
from pipeline.routing.problem import Instance
from pipeline.routing.solve import solver_instance

GAP = 0.02  # ε-trimming coarse enough to trim labels on graphs this small
DEP, ARR = (30.0, -160.0), (33.0, -150.0)  # ≈ 560 NM: 70 rpm (9.8 kn) ≈ 57 h, 100 rpm (14 kn) ≈ 40 h in calm water


@functools.cache  # made once per module: a field is only read (the solvers and kernels never write it)
def _weather(kind: str, seed: int):
    if kind == "static":
        return field(wavy(seed))
    if kind == "storm":  # a storm drifting west across the route while the ship sails east: time matters
        return field(moving_storm(seed, 31.5, 206.0, drift_kn=(-12.0, 2.0), hs_peak=7.0), step_h=3, hours=200)
    if kind == "storm-limit":  # a smaller storm along the north of the corridor, against a 4.5 m limit
        return field(moving_storm(seed, 32.8, 209.0, drift_kn=(-12.0, 0.0), radius_nm=60.0, hs_peak=6.0), step_h=3,
                     hours=200)
    if kind == "current":
        return field(lambda LA, LO: dict(uo=1.2 * np.sin(np.radians(40 * (LA - 30))), vo=0.8 * np.cos(np.radians(30 * LO)),
                                         swh=2.0 + np.cos(np.radians(20 * LO)), mwd_deg=np.full(LA.shape, 250.0)))
    raise ValueError(kind)


CASES = []
for n, (kind, rta, obj) in enumerate(itertools.product(("static", "storm", "current", "storm-limit"),
                                                        ("loose", "tight", "impossible"), ("jit", "thesis"))):
    rpms = [(70, 85, 100), (75, 100), (60, 70, 80, 90, 100)][n % 3]
    CASES.append((kind, rta, obj, rpms, n))


def _enumerate(inst) -> float:
    g, v, w, o = inst.graph, inst.vessel, inst.wx, inst.objective
    L2, P = g.lat.shape
    R = len(v.rpm_options)
    ct, cf = np.empty(L2), np.empty(L2)
    best = math.inf
    for mid in itertools.product(range(P), repeat=L2 - 2):
        nodes = np.array((P // 2, *mid, P // 2), np.int64)
        if not all(g.edge_ok[i, nodes[i], nodes[i + 1]] for i in range(L2 - 1)):
            continue
        for plan in itertools.product(range(R), repeat=L2 - 1):
            code, _ = lk.sail_route_nb(nodes, np.array(plan, np.int64), 0, g, v, w, o, ct, cf)
            if code == lk.OK:
                best = min(best, route_cost_nb(o, ct[-1] - o.t_dep_h, cf[-1]))
    return best


@pytest.mark.parametrize("kind, rta, obj, rpms, n", CASES, ids=[f"{c[0]}-{c[1]}-{c[2]}-{len(c[3])}rpm" for c in CASES])
@pytest.mark.slow
def test_dp_equals_exhaustive_enumeration(kind, rta, obj, rpms, n):
    fld = _weather(kind, n)
    n_lines = 2 if len(rpms) == 5 else 3
    calm_h = {"loose": 75.0, "tight": 48.0, "impossible": 30.0}[rta]  # 100 rpm needs ≈ 40 h in calm water
    pr = problem(DEP, ARR, calm_h, rpm_options=rpms, objective=obj, n_lines=n_lines, n_points=5, max_shift=2,
                 d_point_nm=25.0, max_hs_m=4.5 if kind == "storm-limit" else None)
    space = pr.search_space()
    plan = solve(pr, fld, solver="dp", space=space, continuous=False)
    trimmed = solve(pr, fld, solver="dp", space=space, options=DpOptions(gap=GAP), continuous=False)
    inst, _ = solver_instance(pr, space, fld)  # the settings the DP chooses from: listed + constant-speed rpm
    if plan.baseline.legs:
        inst.f_target = max(plan.baseline.fuel_t, 1e-6)  # as solve() sets it
    best = _enumerate(inst)
    if not math.isfinite(best):
        assert plan.status == "infeasible"
        return
    assert plan.status in ("ok", "late"), plan.reason
    assert plan.cost == pytest.approx(best, rel=1e-12, abs=1e-12), (plan.cost, best)
    assert best - 1e-9 <= trimmed.cost <= best * (1.0 + GAP) + 1e-9, (trimmed.cost, best)
    if rta == "impossible":
        assert plan.status == "late"


@pytest.mark.parametrize("kind, obj, gap, n", [("storm", "jit", 0.0, 1), ("storm", "jit", 0.001, 2),
                                                ("storm-limit", "thesis", 0.001, 4), ("current", "jit", 0.01, 5)])
@pytest.mark.slow
def test_skipping_legs_whose_label_would_be_dropped_keeps_the_same_labels(kind, obj, gap, n):
    """dp_exact_nb does not sail a leg whose candidate a candidate made before it is sure to drop: the labels kept and
    the plan are bit for bit those of sailing every leg, with fewer legs sailed."""
    pr = problem(DEP, (34.0, -146.0), 70.0, rpm_options=(70, 80, 90, 100), objective=obj, n_lines=6, n_points=9,
                 max_shift=2, d_point_nm=20.0, max_hs_m=4.5 if kind == "storm-limit" else None)
    space = pr.search_space()
    fld = _weather(kind, n)
    inst, _ = solver_instance(pr, space, fld)
    base = solve(pr, fld, solver="gc", space=space, continuous=False)
    inst.f_target = max(base.fuel_t, 1e-6)  # as solve() sets it
    upper = base.cost if base.status == "ok" else math.inf
    ld = latest_departures(inst)
    on_time = upper < math.inf
    fb = label_bounds(inst, ld, reachable_windows(inst, ld, on_time),
                      fuel_budget_t(inst.objective, upper, gap) if on_time else math.inf)
    eps = trim_eps(inst, gap, upper, fb.lams, fb.m_lam, fb.t_min)
    args = (inst.graph, inst.vessel, inst.wx, inst.objective, upper, fb, eps)
    *skipping, legs_skipping, kept_skipping = dp_exact_nb(*args, EXACT)
    *every, legs_every, kept_every = dp_exact_nb(*args, EXACT._replace(skip_dropped=False))
    assert np.isfinite(every[2]) and kept_every > 20
    assert kept_skipping == kept_every
    assert (skipping[0] == every[0]).all() and (skipping[1] == every[1]).all() and skipping[2] == every[2]
    assert legs_skipping < legs_every


def _case(kind, rta, obj, rpms, n):
    pr = problem(DEP, ARR, {"loose": 75.0, "tight": 48.0, "impossible": 30.0}[rta], rpm_options=rpms, objective=obj,
                 n_lines=2 if len(rpms) == 5 else 3, n_points=5, max_shift=2, d_point_nm=25.0,
                 max_hs_m=4.5 if kind == "storm-limit" else None)
    return solve(pr, _weather(kind, n), solver="dp", continuous=False)


def test_the_cases_are_not_trivial():
    """The enumeration cases exercise what they claim: time-varying weather, mixed engine plans, a DP cheaper than
    the baseline, a weather limit that closes the baseline route but not every route."""
    storm = _weather("storm", 1)
    leg = (30.0, -160.0, 31.0, -155.0)
    h6 = lk.sail_leg(*leg, 6.0, 85.0, lk.vessel(MODEL), storm)[lk.H]
    h30 = lk.sail_leg(*leg, 30.0, 85.0, lk.vessel(MODEL), storm)[lk.H]
    assert abs(h6 - h30) > 0.05  # the same leg takes different hours at different times
    tight = _case("storm", "tight", "jit", (60, 70, 80, 90, 100), 8)
    assert tight.status == "ok" and tight.cost < tight.baseline.cost - 0.5  # the constant speed at the RTA
    assert len({g["rpm"] for g in tight.legs}) > 1
    closed = _case("storm-limit", "loose", "thesis", (75, 100), 19)
    assert closed.baseline.status == "infeasible" and "wave height" in closed.baseline.reason
    assert closed.status == "ok" and max(g["hs_m"] for g in closed.legs) <= 4.5
    assert all(_case(*c).status == "late" for c in CASES if c[1] == "impossible")


def test_fuel_to_finish_bound_by_hand():
    lams = np.array([0.0, 1.0])
    m_lam = np.array([5.0, 12.0])  # least Σ d·φ = 5 t, least Σ d·(φ + 1·τ) = 12
    assert fuel_to_finish_lb(m_lam, lams, 6.0, 10.0) == 5.0  # max(5, 12 − 10)
    assert fuel_to_finish_lb(m_lam, lams, 6.0, 6.5) == 5.5  # 12 − 6.5: little time costs fuel
    assert fuel_to_finish_lb(m_lam, lams, 6.0, 5.9) == math.inf  # below the least hours at full speed


@pytest.mark.parametrize("kind, n", [("storm", 1), ("storm-limit", 4), ("current", 2), ("static", 3)])
@pytest.mark.slow
def test_fuel_to_finish_bound_holds_for_every_completion(kind, n):
    """The DP's pruning bound is below the fuel of every way to finish from every node of line 1, for the hours
    that way takes (the bound may be loose, never above)."""
    pr = problem(DEP, ARR, 48.0, rpm_options=(70, 85, 100), n_lines=3, n_points=5, max_shift=2, d_point_nm=25.0,
                 max_hs_m=4.5 if kind == "storm-limit" else None)
    space = pr.search_space()
    inst = Instance.build(pr, space, _weather(kind, n))
    lams, m_lam, t_min, _, _ = finish_bounds(inst)
    g, v, w, o = inst.graph, inst.vessel, inst.wx, inst.objective
    ct, cf = np.empty(5), np.empty(5)
    n_checked = 0
    for a in range(5):
        for start_h in (0.0, 9.0, 21.0):
            for rest in itertools.product(range(5), repeat=2):
                nodes = np.array((2, a, *rest, 2), np.int64)
                for plan in itertools.product(range(3), repeat=3):
                    rpm = np.array((0, *plan), np.int64)
                    ct[1], cf[1] = o.t_dep_h + start_h, 0.0
                    code, _ = lk.sail_route_nb(nodes, rpm, 1, g, v, w, o, ct, cf)
                    if code != lk.OK:
                        continue
                    hours = ct[-1] - ct[1]
                    assert hours >= t_min[1, a]
                    assert cf[-1] >= fuel_to_finish_lb(m_lam[:, 1, a], lams, t_min[1, a], hours) - 1e-12
                    n_checked += 1
    assert n_checked > 500
    assert np.isfinite(m_lam[:, 1]).any() and lams.size > 3


@pytest.mark.parametrize("kind, obj, n", [("storm", "jit", 5), ("current", "thesis", 6)])
def test_bfoa_polish_finds_the_best_plan_in_its_corridor(kind, obj, n):
    """With a window wide enough to hold every plan and no trimming, BFOA's polish returns the best of every route
    within ±1 node of the given one × every engine plan (enumerated), and never a dearer plan than it was given."""
    from dataclasses import replace

    from pipeline.routing.bfoa import BfoaParams, polish

    pr = problem(DEP, ARR, 48.0, rpm_options=(70, 85, 100), objective=obj, n_lines=3, n_points=5, max_shift=2,
                 d_point_nm=25.0)
    space = pr.search_space()
    inst = Instance.build(pr, space, _weather(kind, n))
    base = solve(pr, _weather(kind, n), solver="gc", space=space)
    inst.f_target = max(base.fuel_t, 1e-6)  # as solve() sets it
    g, v, w, o = inst.graph, inst.vessel, inst.wx, inst.objective
    nodes, rpm = np.array([2, 1, 0, 1, 2], np.int64), np.zeros(4, np.int64)
    ct, cf = np.empty(5), np.empty(5)
    assert lk.sail_route_nb(nodes, rpm, 0, g, v, w, o, ct, cf)[0] == lk.OK
    cost = route_cost_nb(o, ct[-1] - o.t_dep_h, cf[-1])
    wide = BfoaParams(polish_width=1, polish_window_h=1e6, polish_fuel=1e6, polish_gap=0.0)
    got_nodes, got_rpm, got, _ = polish(nodes, rpm, cost, wide, g, v, w, o)
    best = cost
    for mid in itertools.product(*[range(max(0, a - 1), min(5, a + 2)) for a in nodes[1:-1]]):
        route = np.array((2, *mid, 2), np.int64)
        if not all(g.edge_ok[i, route[i], route[i + 1]] for i in range(4)):
            continue
        for plan in itertools.product(range(3), repeat=4):
            if lk.sail_route_nb(route, np.array(plan, np.int64), 0, g, v, w, o, ct, cf)[0] == lk.OK:
                best = min(best, route_cost_nb(o, ct[-1] - o.t_dep_h, cf[-1]))
    assert got == pytest.approx(best, rel=1e-12) and got < cost
    assert lk.sail_route_nb(got_nodes, got_rpm, 0, g, v, w, o, ct, cf)[0] == lk.OK
    assert route_cost_nb(o, ct[-1] - o.t_dep_h, cf[-1]) == pytest.approx(got, rel=1e-12)
    narrow = polish(nodes, rpm, cost, replace(wide, polish_window_h=0.0, polish_fuel=0.0), g, v, w, o)[2]
    assert narrow <= cost


def test_a_model_form_without_corner_bounds_gets_zero_bounds_that_prune_nothing():
    """The MLP has no speed/fuel corner bounds: the tables must still be lower bounds (zero), not an error, so the
    engine-limits post-pass and the DP route such a vessel (a demo vessel with an MLP model once failed here)."""
    from dataclasses import replace

    pr = problem(DEP, ARR, 48.0, rpm_options=(70, 85, 100), n_lines=3, n_points=5, max_shift=2, d_point_nm=25.0)
    inst = Instance.build(pr, pr.search_space(), _weather("static", 0))
    inst = replace(inst, vessel=inst.vessel._replace(form_id=2))
    lams, m_lam, t_min, tau, phi = finish_bounds(inst)
    L2, P = inst.space.lat.shape
    assert m_lam.shape == (len(lams), L2, P) and t_min.shape == (L2, P) and tau.shape == phi.shape == (L2, P, 3)
    assert not (m_lam.any() or t_min.any() or tau.any() or phi.any())
    assert fuel_to_finish_lb(m_lam[:, 0, 0], lams, t_min[0, 0], 10.0) == 0.0


def test_a_head_current_that_passes_does_not_close_the_legs_behind_it():
    """A current of 23 kn against the course east of 202° E for the first 12 h: the legs there have no headway
    early and are open later, when every plan gets there. The latest departures used to skip a leg with no
    headway at the voyage's departure time, so every node before it looked unable to make the RTA and the DP
    answered `infeasible` (the label DP) where enumeration finds an on-time plan."""
    from pipeline.routing.baseline import baseline as find_baseline, evaluate

    def fn(LA, LO, h):
        return dict(uo=np.where((LO > 202.0) & (h < 12.0), -12.0, 0.0), swh=np.full(LA.shape, 1.5),
                    mwd_deg=np.full(LA.shape, 250.0))

    fld = field(fn, step_h=3, hours=200)
    pr = problem(DEP, ARR, 75.0, n_lines=3, n_points=5, max_shift=2, d_point_nm=25.0)
    inst, base_nodes = solver_instance(pr, pr.search_space(), fld)
    g = inst.graph
    assert lk.sail_leg(g.lat[1, 2], g.lon[1, 2], g.lat[2, 2], g.lon[2, 2], 8.0, 100.0, inst.vessel,
                       fld)[lk.CODE] == lk.NO_HEADWAY  # closed early ...
    assert lk.sail_leg(g.lat[1, 2], g.lon[1, 2], g.lat[2, 2], g.lon[2, 2], 12.0, 100.0, inst.vessel,
                       fld)[lk.CODE] == lk.OK  # ... open when a ship gets there
    ld = latest_departures(inst)
    assert np.isfinite(ld[0, 2]) and np.isfinite(ld[1:-1]).all()  # the departure and every node can make the RTA
    base = find_baseline(inst, base_nodes)
    best = _enumerate(inst)
    assert math.isfinite(best)
    from pipeline.routing.solvers import SOLVERS

    for opts in (DpOptions(incumbent=None), DpOptions(gap=1e-3, slot_h=1.0, max_wait_h=6.0, wait_free_first=True,
                                                      incumbent=None)):
        found = SOLVERS["dp"].search(inst, base, seed=1, options=opts)
        assert found.nodes is not None
        assert evaluate(inst, found.nodes, found.rpm_idx)[0] <= best * (1 + opts.gap) + 1e-9
