"""The grid DP (dp_grid.py) against exhaustive enumeration of its own decision space on small graphs.

The space: a node per line, an engine setting per leg, and at each node a departure at one of its line's times
(the grid t_dep + k·slot_h and the departures of the wait-free plans the DP knows: the baseline, and when that is
not on time the fastest plan, `_known`): the first after arriving,
or one up to `max_wait_h` later (waiting at `wait_tph`). The
enumeration below walks every route × setting × wait depth first with the legs' kernel and the objective; it
shares nothing with the DP but those. The DP keeping every state must equal it to rounding, and the DP with a
gap must be within that gap. Weather: static, storms moving across the route (with and without Hs/wind limits),
a storm whose limits close the route and then open it as it moves away, currents; loose, tight and impossible
RTAs (least late); both objectives; two to five settings."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from lxml import etree

from tests.exact_cases import ARR, DEP, LIMITED, enumerate_nb, instance, weather, window_problem
from tests.routing_cases import problem
from pipeline.routing.engine import leg as lk
from pipeline.routing.baseline import evaluate
from pipeline.export.rtz import route_to_rtz, validate_rtz
from pipeline.routing.options import DpOptions
from pipeline.routing.dp_grid import line_times
from pipeline.routing.engine_limits import EngineLimits, settings_held_h
from pipeline.routing.fastest_plan import fastest_plan
from pipeline.routing.objectives import LATE_STEP_T, OBJ_JIT, route_cost_nb
from pipeline.routing.solvers import SOLVERS

CALM_H = {"loose": 75.0, "tight": 48.0, "impossible": 30.0}  # the RTAs after departure: 100 rpm needs ≈ 40 h in calm water
GAP = 0.02


def _sail_with_waits(inst, nodes, rpm_idx, wait_h, wait_tph) -> float:
    """Cost of a plan that waits wait_h[i] at line i's node before its leg (checked on its own, leg by leg)."""
    g, v, o = inst.graph, inst.vessel, inst.objective
    t, fuel = o.t_dep_h, 0.0
    for i in range(len(nodes) - 1):
        assert wait_h[i] >= -1e-9
        t += wait_h[i]
        fuel += wait_tph * wait_h[i]
        a, b = nodes[i], nodes[i + 1]
        out = lk.sail_leg(g.lat[i, a], g.lon[i, a], g.lat[i + 1, b], g.lon[i + 1, b], t, v.rpm_options[rpm_idx[i]], v,
                          inst.weather)
        assert out[lk.CODE] == lk.OK
        t += out[lk.H]
        fuel += out[lk.FUEL]
    return float(route_cost_nb(o, t - o.t_dep_h, fuel))


CASES = []
for n, (kind, rta, obj, waits) in enumerate(itertools.product(("static", "storm", "current", "storm-limit", "storm-window"),
                                                              ("loose", "tight", "impossible"), ("jit", "thesis"),
                                                              ("round", "wait"))):
    rpms = [(70, 85, 100), (75, 100), (60, 70, 80, 90, 100)][n % 3]
    CASES.append((kind, rta, obj, waits, rpms, n))
# `make test-fast` runs one case of each weather that between them meet every RTA, objective and waiting rule (and two
# and three settings); `make test` runs them all
FAST_CASES = {("static", "loose", "jit", "round"), ("storm", "tight", "thesis", "wait"),
              ("current", "impossible", "jit", "wait"), ("storm-limit", "tight", "jit", "round"),
              ("storm-window", "impossible", "thesis", "round")}
CASE_PARAMS = [pytest.param(*c, id=f"{c[0]}-{c[1]}-{c[2]}-{c[3]}-{len(c[4])}rpm",
                            marks=() if c[:4] in FAST_CASES else pytest.mark.slow) for c in CASES]


def _known(inst, base) -> list:
    """The wait-free plans dp.search knows without an incumbent solver: the baseline, and when no plan known is on
    time the fastest plan (fastest_plan.py) when it costs less; their departure times are in the grid's space."""
    plans = [(base.nodes, base.rpm_idx)] if base.ok else []
    upper = evaluate(inst, base.nodes, base.rpm_idx)[0] if base.ok else math.inf
    if not upper < (LATE_STEP_T if inst.objective.kind == OBJ_JIT else 9999.9):
        nodes, rpm_idx, _, _ = fastest_plan(inst)
        if nodes is not None and evaluate(inst, nodes, rpm_idx)[0] < upper:
            plans.append((nodes, rpm_idx))
    return plans


@pytest.mark.parametrize("kind, rta, obj, waits, rpms, n", CASE_PARAMS)
@pytest.mark.slow
def test_grid_dp_equals_exhaustive_enumeration(kind, rta, obj, waits, rpms, n):
    slot_h, max_wait_h = (1.0, 0.0) if waits == "round" else (2.0, 6.0)  # "wait": up to 3 slots more at a node
    n_lines = 3 if waits == "round" and len(rpms) < 5 else 2
    inst, base = instance(kind, CALM_H[rta], rpms, n, obj=obj, n_lines=n_lines)
    wait_tph = 0.3
    times = line_times(inst, _known(inst, base), slot_h)  # the grid + the baseline's (and the fastest plan's)
    best = enumerate_nb(inst.graph, inst.vessel, inst.wx, inst.objective, times, max_wait_h, wait_tph)
    dp = SOLVERS["dp"]
    exact = dp.search(inst, base, seed=1, options=DpOptions(slot_h=slot_h, max_wait_h=max_wait_h, wait_tph=wait_tph,
                                                            incumbent=None))
    if not math.isfinite(best):
        assert exact.nodes is None
        return
    assert exact.nodes is not None
    got = _sail_with_waits(inst, exact.nodes, exact.rpm_idx, exact.wait_h, wait_tph)
    assert got == pytest.approx(best, rel=1e-12, abs=1e-12), (got, best)
    assert all(w <= (slot_h + max_wait_h) + 1e-9 for w in exact.wait_h[1:])  # rounding + the extra waits allowed
    trimmed = dp.search(inst, base, seed=1, options=DpOptions(slot_h=slot_h, max_wait_h=max_wait_h, wait_tph=wait_tph,
                                                              gap=GAP, incumbent=None))
    cost = _sail_with_waits(inst, trimmed.nodes, trimmed.rpm_idx, trimmed.wait_h, wait_tph)
    assert best - 1e-9 <= cost <= best * (1.0 + GAP) + 1e-9, (cost, best)
    if rta == "impossible":  # least late: every plan is late, the DP compares late plans
        assert best >= (LATE_STEP_T if obj == "jit" else 9999.9)


@pytest.mark.parametrize("kind, rta, obj, waits, rpms, n", CASE_PARAMS)
@pytest.mark.slow
def test_the_default_dp_equals_enumeration_over_the_grid_and_the_wait_free_optimum(kind, rta, obj, waits, rpms, n):
    """What `--solver dp` runs by default: the label DP first, then the grid DP over the grid and the departure
    times of the baseline and of the label DP's plan. Equal to enumeration of that space, never dearer than the
    label DP's wait-free plan (which lies in it), and it finds the waiting plans no wait-free plan can match."""
    slot_h, max_wait_h = (1.0, 0.0) if waits == "round" else (2.0, 6.0)
    n_lines = 3 if waits == "round" and len(rpms) < 5 else 2
    inst, base = instance(kind, CALM_H[rta], rpms, n, obj=obj, n_lines=n_lines)
    wait_tph = 0.3
    dp = SOLVERS["dp"]
    label = dp.search(inst, base, seed=1, options=DpOptions(incumbent=None))
    plans = _known(inst, base)
    if label.nodes is not None:
        plans.append((label.nodes, label.rpm_idx))
    best = enumerate_nb(inst.graph, inst.vessel, inst.wx, inst.objective, line_times(inst, plans, slot_h),
                         max_wait_h, wait_tph)
    got = dp.search(inst, base, seed=1, options=DpOptions(slot_h=slot_h, max_wait_h=max_wait_h, wait_tph=wait_tph,
                                                          wait_free_first=True, incumbent=None))
    if not math.isfinite(best):
        assert got.nodes is None and label.nodes is None
        return
    cost = _sail_with_waits(inst, got.nodes, got.rpm_idx, got.wait_h, wait_tph)
    assert cost == pytest.approx(best, rel=1e-12, abs=1e-12), (cost, best)
    if label.nodes is not None:
        assert cost <= evaluate(inst, label.nodes, label.rpm_idx)[0] + 1e-9


@pytest.mark.slow  # every window case solved through the product path
def test_the_window_cases_open_and_close():
    """storm-window closes the route's first legs at the start and opens them later: leaving at once is refused
    by the limit, leaving 4 h later is not. No wait-free plan exists; the grid DP's plan waits at the departure."""
    fld = weather("storm-window", 0)
    ves = lk.vessel(problem(DEP, ARR, 75.0).model, max_hs_m=4.5, max_wind_kn=45.0)
    leg = (30.0, -160.0, 30.7, -157.5)
    assert lk.sail_leg(*leg, 6.0, 85.0, ves, fld)[lk.CODE] in (lk.WAVE_LIMIT, lk.WIND_LIMIT)  # 06 UTC: departure
    assert lk.sail_leg(*leg, 10.0, 85.0, ves, fld)[lk.CODE] == lk.OK
    for n, rta in itertools.product(range(3), ("loose", "tight")):
        inst, base = instance("storm-window", CALM_H[rta], (70, 85, 100), n, n_lines=2)
        found = SOLVERS["dp"].search(inst, base, seed=1, options=DpOptions(slot_h=2.0, max_wait_h=12.0, incumbent=None))
        wait_free = SOLVERS["dp"].search(inst, base, seed=1, options=DpOptions(incumbent=None))
        assert wait_free.nodes is None  # every wait-free plan meets the storm at the departure
        assert found.nodes is not None and found.wait_h[0] >= 2.0  # the grid DP's plan waits for it to move on


@pytest.mark.parametrize("limits", [None, EngineLimits(min_hold_h=0.0, change_cost_t=0.05),
                                    EngineLimits(min_hold_h=200.0, change_cost_t=0.05)], ids=["free", "cost", "hold"])
@pytest.mark.slow
def test_route_carries_the_grid_dps_waits(limits):
    """Through solve() (what `jitroute route --solver dp --solver-option slot_h=2` runs), storm-window: no wait-free
    plan exists, the grid DP's plan waits at the departure for the storm to move on. The plan's legs carry the wait
    (etd after it, hours and fuel of the route include it), its cost is the enumerated optimum of the grid space,
    and its rows fit the route_legs definition. Holding a setting 200 h (longer than the voyage) is met by one
    setting throughout, so the waits are kept then too."""
    from routing_cases import solve
    from schemas.tables.routes import ROUTE_LEGS

    pr, fld = window_problem(), weather("storm-window", 0)
    opts = DpOptions(slot_h=2.0, max_wait_h=12.0, wait_tph=0.3, incumbent=None)
    plan = solve(pr, fld, solver="dp", options=opts, limits=limits, savings=True)
    assert plan.status == "ok", plan.reason
    assert plan.legs[0]["wait_h"] >= 2.0 and plan.wait_h == pytest.approx(sum(g["wait_h"] for g in plan.legs))
    assert "hove to" in plan.reason
    t = np.datetime64(pr.depart_utc, "s")
    for g in plan.legs:  # the legs follow each other: arrival, wait, departure
        assert np.datetime64(g["etd_utc"], "s") - t == np.timedelta64(int(round(g["wait_h"] * 3600)), "s")
        t = np.datetime64(g["eta_utc"], "s")
        assert g["wait_fuel_t"] == pytest.approx(0.3 * g["wait_h"])
    assert plan.hours == pytest.approx(sum(g["hours"] + g["wait_h"] for g in plan.legs))
    assert plan.fuel_t == pytest.approx(sum(g["fuel_t"] + g["wait_fuel_t"] for g in plan.legs))
    assert abs(float((t - np.datetime64(pr.depart_utc, "s")) / np.timedelta64(1, "s")) / 3600 - plan.hours) < 1e-3
    inst, base = instance("storm-window", CALM_H["loose"], (70, 85, 100), 0, n_lines=2)
    assert not base.ok  # so the grid is the 2 h grid alone
    best = enumerate_nb(inst.graph, inst.vessel, inst.wx, inst.objective, line_times(inst, [], 2.0), 12.0, 0.3)
    changes = (limits.change_cost_t * plan.n_engine_changes) if limits is not None else 0.0
    assert plan.cost == pytest.approx(best + changes, rel=1e-9)
    if limits is not None:
        assert plan.limits == limits and plan.limits_fuel_t == pytest.approx(0.0)
    row = plan.leg_rows("r1")[0]
    assert set(row) == {c.name for c in ROUTE_LEGS.columns}
    if limits is None:  # the RTZ schedule: ETD after ETA where the ship waits, valid against the published schema
        xml = route_to_rtz(plan.route_row("r1"), plan.leg_rows("r1"), version="1.1")
        validate_rtz(xml, version="1.1")
        els = etree.fromstring(xml).findall("r:schedules/r:schedule/r:calculated/r:scheduleElement", {"r": "http://www.cirm.org/RTZ/1/1"})
        for k, g in enumerate(plan.legs):
            assert els[k].get("etd") == g["etd_utc"].strftime("%Y-%m-%dT%H:%M:%SZ")
            if k > 0 and g["wait_h"] > 0.01:
                assert els[k].get("etd") > els[k].get("eta")


@pytest.mark.parametrize("kind, calm_h, rpms, slot_h, max_wait_h", [
    ("storm", 52.0, (60, 70, 80, 90, 100), 1.0, 6.0),  # a wait-free plan of the route holds: it replaces the waits
    ("storm-window", 56.0, (70, 85, 100), 2.0, 12.0),  # the storm blocks every wait-free plan: the waits stay
])
def test_a_waiting_plan_that_breaks_the_holds(kind, calm_h, rpms, slot_h, max_wait_h):
    """Held 12 h, a grid-DP plan that changes setting after a leg of about 10 h is re-planned wait-free on its route
    holding each setting; where the storm at the departure blocks every such plan, the waiting plan is kept, without
    the limits, and says which hold it breaks."""
    from routing_cases import solve

    pr = problem(DEP, ARR, calm_h, rpm_options=rpms, n_lines=4, n_points=5, max_shift=2, d_point_nm=25.0,
                 max_hs_m=4.5 if kind in LIMITED else None, max_wind_kn=45.0 if kind == "storm-window" else None)
    opts = DpOptions(slot_h=slot_h, max_wait_h=max_wait_h, wait_tph=0.3, incumbent=None)
    limits = EngineLimits(min_hold_h=12.0)
    free = solve(pr, weather(kind, 0), solver="dp", options=opts)
    assert free.status == "ok" and free.wait_h > 0 and min(h for _, h in settings_held_h(free.legs)) < 12.0
    held = solve(pr, weather(kind, 0), solver="dp", options=opts, limits=limits)
    assert held.status == "ok", held.reason
    if kind == "storm":
        assert held.wait_h == 0.0 and held.limits == limits
        assert "re-planned wait-free holding each setting" in held.reason
        runs = settings_held_h(held.legs)
        assert len(runs) == 1 or min(h for _, h in runs) >= 12.0 - 1e-6
    else:
        assert held.wait_h == pytest.approx(free.wait_h) and held.limits is None
        assert "no wait-free plan of its route holds each setting" in held.reason


def test_position_on_a_waiting_plan_is_its_wait_node():
    """A ship on a plan that waits is at the waiting node during the wait, not at the end of the voyage."""
    from pipeline.enroute import position_on_plan
    from routing_cases import solve

    opts = DpOptions(slot_h=2.0, max_wait_h=12.0, wait_tph=0.3, incumbent=None)
    plan = solve(window_problem(), weather("storm-window", 0), solver="dp", options=opts)
    first = plan.legs[0]
    during = np.datetime64(first["etd_utc"], "s") - np.timedelta64(60, "s")
    assert position_on_plan(plan.legs, during) == (first["lat0"], first["lon0"])


@pytest.mark.parametrize("slot_h, max_wait_h, wait_tph", [(0.0, 0.0, None), (-1.0, 0.0, None), (1.0, -2.0, None),
                                                      (1.0, 0.0, -0.5)])
def test_a_grid_that_is_no_grid_is_refused(slot_h, max_wait_h, wait_tph):
    """A negative waiting rate is refused too: the fuel-to-finish bounds assume waiting burns nothing less than 0."""
    inst, base = instance("static", CALM_H["loose"], (70, 85, 100), 0, n_lines=2)
    opts = DpOptions(slot_h=slot_h, max_wait_h=max_wait_h, wait_tph=wait_tph, incumbent=None)
    with pytest.raises(ValueError, match="slot_h must be > 0 h and max_wait_h, wait_tph ≥ 0"):
        SOLVERS["dp"].search(inst, base, seed=1, options=opts)
