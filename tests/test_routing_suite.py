"""The stored optima of the routing benchmark suite (bench/optima.json) still hold for its small instances.

The stored plan, sailed again, must cost what was stored, and the DP solved again must agree with it within
the gap both are certified to. When an instance changed since its optimum was stored (its hash differs) the
check is skipped with the command that refreshes it."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

_env = os.environ.get("NUMBA_NUM_THREADS")
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
import routing_instances as suite  # noqa: E402

if _env is None:  # the bench scripts pin numba to one thread when imported: not this test process's children
    os.environ.pop("NUMBA_NUM_THREADS", None)
else:
    os.environ["NUMBA_NUM_THREADS"] = _env

SMALL = ("short-coastal", "luzon-strait")


@pytest.fixture(scope="module", params=SMALL)
def stored(request):
    spec = suite.BY_NAME[request.param]
    problem, space, weather = suite.build(spec)
    rec = suite.stored_optimum(spec, suite.instance_hash(spec, problem, space, weather))
    if rec is None:
        pytest.skip(f"{spec.name} changed since its optimum was stored (or none is): run "
                    f".venv/bin/python bench/routing_suite.py --only {spec.name} --no-bfoa to store it again")
    return spec, problem, space, weather, rec


def test_suite_covers_the_kinds_asked_for():
    kinds = " ".join(s.kinds for s in suite.INSTANCES)
    for word in ("short", "ocean", "east-bound", "west-bound", "strait", "limits", "tight RTA", "loose RTA",
                 "moving storm", "dateline", "thesis"):
        assert word in kinds, word
    assert len(suite.INSTANCES) >= 8
    assert set(suite.read_optima()) == {s.name for s in suite.INSTANCES}


def test_stored_plan_costs_what_was_stored(stored):
    spec, problem, space, weather, rec = stored
    assert rec["status"] == "ok"
    cost = suite.plan_cost(problem, space, weather, rec["nodes"], rec["rpm_idx"])
    assert cost == pytest.approx(rec["cost"], rel=1e-9)


def test_dp_solved_again_agrees_within_its_gap(stored):
    spec, problem, space, weather, rec = stored
    again, plan = suite.solve_optimum(spec, problem, space, weather)
    assert plan.status == "ok"
    gap = max(rec["gap"], again["gap"])
    assert rec["cost"] / (1.0 + gap) <= again["cost"] <= rec["cost"] * (1.0 + gap)
