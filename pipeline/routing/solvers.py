"""The solver registry: every solver answers one contract (contract.py), so comparing them is one loop. A new
solver is one module with a `search` function and one entry here."""

from __future__ import annotations

import math

import numpy as np

from pipeline.routing import astar, dp
from pipeline.routing.baseline import Baseline, evaluate
from pipeline.routing.bfoa import BfoaParams, run_bfoa
from pipeline.routing.contract import Found, NoOptions, Solver
from pipeline.routing.options import SOLVER_NAMES, DpOptions
from pipeline.routing.problem import RoutingInputError


def _bfoa(inst, base: Baseline, *, seed: int, options: BfoaParams) -> Found:
    space = inst.space
    seed_nodes = base.nodes if base.nodes is not None else space.base_route()
    seed_rpm = base.rpm_idx if base.rpm_idx is not None else np.zeros(len(seed_nodes) - 1, np.int64)
    nodes, rpm_idx, cost, history, n_evals = run_bfoa(seed, options, seed_nodes, seed_rpm, inst.graph, inst.vessel,
                                                      inst.wx, inst.objective)
    ok = math.isfinite(cost)
    return Found(nodes if ok else None, rpm_idx if ok else None, n_evals, history)


def _dp(inst, base: Baseline, *, seed: int, options: DpOptions) -> Found:
    """The DP, pruned by the cost of the incumbent solver's plan when it names one (seed 1, default options)."""
    upper = math.inf if options.upper_bound is None else float(options.upper_bound)
    incumbent = None
    if options.incumbent is not None:
        spec = SOLVERS[options.incumbent]
        found = spec.search(inst, base, seed=1, options=spec.options())
        if found.nodes is not None:
            upper = min(upper, evaluate(inst, found.nodes, found.rpm_idx)[0])
            incumbent = (found.nodes, found.rpm_idx)
    return dp.search(inst, base, seed=seed, options=options, upper=upper, incumbent=incumbent)


def _baseline(inst, base: Baseline, *, seed: int, options: NoOptions) -> Found:
    return Found(base.nodes, base.rpm_idx) if base.nodes is not None else Found(None, None)


SOLVERS: dict[str, Solver] = {
    "bfoa": Solver("bfoa", _bfoa, BfoaParams, seeded=True, doc="improved bacterial foraging optimisation (bfoa.py)"),
    "dp": Solver("dp", _dp, DpOptions, doc="dynamic programming over the graph (dp.py)"),
    "astar": Solver("astar", astar.search, astar.AstarOptions, doc="A* with the time-constraint weight sweep (astar.py)"),
    "gc": Solver("gc", _baseline, NoOptions, space_base=None, is_baseline=True,
                 doc="the shortest sea route along the great-circle graph at constant rpm"),
    "rhumb": Solver("rhumb", _baseline, NoOptions, space_base="rhumb", is_baseline=True,
                    doc="the shortest sea route along the rhumb-line graph at constant rpm"),
}

if tuple(SOLVERS) != SOLVER_NAMES:  # options.SOLVER_NAMES lets a run refuse a name before loading the solvers
    raise ImportError(f"solver registry {tuple(SOLVERS)} differs from options.SOLVER_NAMES {SOLVER_NAMES}")


def solver_spec(solver: str) -> Solver:
    """The registered solver of that name; RoutingInputError listing the known ones otherwise."""
    if solver not in SOLVERS:
        raise RoutingInputError(f"unknown solver {solver!r}; use one of {', '.join(SOLVERS)}")
    return SOLVERS[solver]
