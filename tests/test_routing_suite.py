"""The stored optima of the routing benchmark suite (bench/optima.json) still hold for its small instances.

The stored plan, sailed again, must cost what was stored, and the DP solved again must agree with it within
the gap both are certified to. When an instance changed since its optimum was stored (its hash differs) the
check fails with the command that refreshes it: a pinned reference that drifts is a change to explain, not a
test to skip."""

from __future__ import annotations

from pathlib import Path

import pytest

from pipeline.synthetic import routing_suite as suite

OPTIMA = Path(__file__).resolve().parents[1] / "bench" / "optima.json"

SMALL = ("short-coastal", "luzon-strait")


@pytest.fixture(scope="module", params=SMALL)
def stored(request):
    spec = suite.BY_NAME[request.param]
    problem, space, weather = suite.build(spec)
    rec = suite.stored_optimum(spec, suite.instance_hash(spec, problem, space, weather), suite.read_optima(OPTIMA))
    if rec is None:
        pytest.fail(f"{spec.name} changed since its optimum was stored in {OPTIMA} (or none is): if the change is "
                    f"meant, run .venv/bin/python bench/routing_suite.py --only {spec.name} --no-bfoa to store it "
                    "again and say in the commit why the instance changed")
    return spec, problem, space, weather, rec


def test_suite_covers_the_kinds_asked_for():
    kinds = " ".join(s.kinds for s in suite.INSTANCES)
    for word in ("short", "ocean", "east-bound", "west-bound", "strait", "limits", "tight RTA", "loose RTA",
                 "moving storm", "dateline", "thesis"):
        assert word in kinds, word
    assert len(suite.INSTANCES) >= 8
    assert set(suite.read_optima(OPTIMA)) == {s.name for s in suite.INSTANCES}


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
