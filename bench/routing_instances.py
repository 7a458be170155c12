"""The routing benchmark suite as the bench scripts use it: the instances and their helpers live in the package
(pipeline.synthetic.routing_suite, shared with tests/test_routing_suite.py); the optima are stored beside the
benches in `bench/optima.json`."""

from __future__ import annotations

from pathlib import Path

from pipeline.synthetic import routing_suite as _suite
from pipeline.synthetic.routing_suite import (BY_NAME, DP_GAP, INSTANCES, MODEL, SuiteInstance, build,  # noqa: F401
                                              instance_hash, plan_cost, route_nodes, solve_optimum, voyage_weather)

OPTIMA = Path(__file__).resolve().parent / "optima.json"


def read_optima() -> dict:
    return _suite.read_optima(OPTIMA)


def stored_optimum(spec: SuiteInstance, digest: str) -> dict | None:
    """The stored DP result of the instance, None when there is none or the instance changed since."""
    return _suite.stored_optimum(spec, digest, read_optima())
