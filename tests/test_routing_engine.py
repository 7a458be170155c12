"""The compiled core the routing searches share (pipeline/routing/engine/): its pruning rule on hand-made bound tables,
and the routing modules' imports (one way in: no module takes another's private helpers, nothing imports the old
paths)."""

from __future__ import annotations

import ast
import math
from pathlib import Path

import numpy as np
import pytest

from pipeline.routing.engine.bounds import FinishBounds, cost_lb_nb, fuel_to_finish_lb, is_on_time, label_priced_out
from pipeline.routing.engine.labels import grow, prefix_min, put_min, time_span_nb
from pipeline.routing.objectives import LATE_STEP_T, OBJ_JIT, OBJ_THESIS, Objective

ROUTING = Path(__file__).resolve().parents[1] / "pipeline" / "routing"


def _objective(kind: int = OBJ_JIT) -> Objective:
    return Objective(kind=kind, t_dep_h=10.0, t_req_h=50.0, f_target=30.0, early_t_per_h=0.0, late_t_per_h=10.0,
                     window_h=0.0, max_hours=100.0)


def _bounds() -> FinishBounds:
    """Two lines of one node: from (1, 0) the arrival takes at least 20 h and, for λ = 0 and 0.5 t/h, at least 12 t and
    22 t − 0.5·hours (so 12 t within 20 h, and more the less time is left)."""
    lams = np.array([0.0, 0.5])
    m_lam = np.array([[[0.0], [12.0]], [[0.0], [22.0]]])  # (K, L+2, P)
    t_min = np.array([[0.0], [20.0]])
    legs = np.zeros((2, 1, 1, 1))
    return FinishBounds(lams, m_lam, t_min, legs, legs.copy(), np.full((2, 1), np.inf))


def test_the_fuel_to_finish_bound_is_the_best_price_and_inf_below_the_least_hours():
    fb = _bounds()
    assert fuel_to_finish_lb(fb.m_lam[:, 1, 0], fb.lams, fb.t_min[1, 0], 20.0) == pytest.approx(12.0)
    assert fuel_to_finish_lb(fb.m_lam[:, 1, 0], fb.lams, fb.t_min[1, 0], 40.0) == pytest.approx(12.0)  # 22 − 20 = 2
    assert fuel_to_finish_lb(fb.m_lam[:, 1, 0], fb.lams, fb.t_min[1, 0], 19.9) == math.inf


def test_a_label_is_priced_out_when_its_fuel_and_the_least_to_finish_cost_more_than_the_incumbent():
    """jit, on time (the deadline is the RTA, t = 10 + 50 = 60 h): a label at t = 30 h has 30 h left; the least to
    finish is 12 t. With 20 t burnt it can cost no less than 32 t: kept under an incumbent of 32.5 t, priced out under
    31.5 t. At t = 45 h only 15 h are left, under the 20 h it takes: priced out whatever its fuel."""
    o, fb = _objective(), _bounds()
    assert is_on_time(o, 32.5) and not is_on_time(o, LATE_STEP_T + 1.0)
    assert not label_priced_out(o, fb, 1, 0, 30.0, 20.0, 32.5, 1e-9, True)
    assert label_priced_out(o, fb, 1, 0, 30.0, 20.0, 31.5, 1e-9, True)
    assert label_priced_out(o, fb, 1, 0, 45.0, 0.0, 1e6, 1e-9, True)


def test_without_an_on_time_incumbent_a_label_is_priced_with_its_lateness():
    """No incumbent on time: the deadline is the horizon (10 + 100 h) and a label that can only arrive late is priced
    at its fuel plus the lateness of its earliest arrival (1000 t + 10 t/h): at t = 45 h it arrives at 65 h at the
    earliest, 5 h late, so it costs at least 0 + 12 + 1000 + 50 t."""
    o, fb = _objective(), _bounds()
    assert cost_lb_nb(o, 12.0, 55.0) == pytest.approx(12.0 + LATE_STEP_T + 10.0 * 5.0)
    assert not label_priced_out(o, fb, 1, 0, 45.0, 0.0, 1062.5, 1e-9, False)
    assert label_priced_out(o, fb, 1, 0, 45.0, 0.0, 1061.5, 1e-9, False)


def test_thesis_prices_an_on_time_label_by_its_fuel_against_the_target():
    """thesis, on time: a plan costs at least 0.85 + 3·F/F_target; 20 t burnt + 12 t to finish with F_target 30 t is
    0.85 + 3.2 = 4.05."""
    o, fb = _objective(OBJ_THESIS), _bounds()
    assert not label_priced_out(o, fb, 1, 0, 30.0, 20.0, 4.06, 1e-9, True)
    assert label_priced_out(o, fb, 1, 0, 30.0, 20.0, 4.04, 1e-9, True)


def test_the_label_stores_grow_keep_their_contents_and_the_prefix_minimum_looks_back_only():
    a = np.arange(4.0)
    b = grow(a, 5)
    assert b.shape[0] == 8 and (b[:4] == a).all() and grow(a, 3).shape[0] == 4
    tree = np.full((2, 9), np.inf)
    put_min(tree, 1, 3, 5.0)
    put_min(tree, 1, 6, 2.0)
    assert prefix_min(tree, 1, 2) == math.inf and prefix_min(tree, 1, 5) == 5.0 and prefix_min(tree, 1, 8) == 2.0
    assert prefix_min(tree, 0, 8) == math.inf  # another node's row
    assert [time_span_nb(t, 10.0, 20.0, 4) for t in (10.0, 14.9, 15.0, 30.0)] == [0, 0, 1, 3]
    assert time_span_nb(12.0, 10.0, 0.0, 4) == 0


def _imports(path: Path):
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            yield node.module, [a.name for a in node.names]
        elif isinstance(node, ast.Import):
            for a in node.names:
                yield a.name, []


def test_no_routing_module_takes_another_modules_private_names_or_the_old_leg_module():
    """Each helper one way in: a name two modules need is public where it lives (the label primitives in engine/, the
    land mask's file helpers, the clearance kernels)."""
    bad = []
    for path in sorted(ROUTING.rglob("*.py")):
        for module, names in _imports(path):
            if module == "pipeline.routing.leg_kernel" or module.endswith(".leg_kernel") or (
                    module == "pipeline.routing" and "leg_kernel" in names):
                bad.append(f"{path.relative_to(ROUTING)} imports the leg from {module}")
            if module.startswith("pipeline.routing"):
                bad += [f"{path.relative_to(ROUTING)} imports {module}.{n}" for n in names if n.startswith("_")]
    assert not bad, bad
    assert not (ROUTING / "leg_kernel.py").exists()
