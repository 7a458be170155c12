"""The solver registry: every solver answers one contract, so comparing them is one loop.

    search(instance, baseline, *, seed, options) -> Found

`instance` is a problem.Instance (graph, vessel, weather, objective), `baseline` the baseline.Baseline of
the voyage (its shortest sea route at constant rpm), `seed` the random seed (ignored by exact solvers) and
`options` an instance of the solver's own options class (`Solver.options`). A solver that finds nothing
feasible returns Found(None, None). A new solver is one module with a `search` function and one entry here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from pipeline.routing import astar, dp
from pipeline.routing.baseline import Baseline
from pipeline.routing.bfoa import BfoaParams, run_bfoa


@dataclass
class Found:
    """A solver's answer: node per line and rpm index per leg (None: nothing feasible), the legs or routes it
    sailed, and for iterative solvers the best cost after each cycle."""

    nodes: np.ndarray | None
    rpm_idx: np.ndarray | None
    n_evals: int = 0
    history: np.ndarray | None = None


@dataclass(frozen=True)
class NoOptions:
    """The solver has no settings."""


@dataclass(frozen=True)
class Solver:
    name: str
    search: Callable[..., Found]
    options: type
    space_base: str | None = None  # lay the search space along this base route when the caller gives none
    doc: str = ""


def _bfoa(inst, base: Baseline, *, seed: int, options: BfoaParams) -> Found:
    space = inst.space
    seed_nodes = base.nodes if base.nodes is not None else space.base_route()
    seed_rpm = base.rpm_idx if base.rpm_idx is not None else np.zeros(len(seed_nodes) - 1, np.int64)
    nodes, rpm_idx, cost, history, n_evals = run_bfoa(seed, options, seed_nodes, seed_rpm, inst.graph, inst.vessel,
                                                      inst.wx, inst.objective)
    ok = math.isfinite(cost)
    return Found(nodes if ok else None, rpm_idx if ok else None, n_evals, history)


def _baseline(inst, base: Baseline, *, seed: int, options: NoOptions) -> Found:
    return Found(base.nodes, base.rpm_idx) if base.nodes is not None else Found(None, None)


SOLVERS: dict[str, Solver] = {
    "bfoa": Solver("bfoa", _bfoa, BfoaParams, doc="improved bacterial foraging optimisation (bfoa.py)"),
    "dp": Solver("dp", dp.search, dp.DpOptions, doc="dynamic programming over the graph (dp.py)"),
    "astar": Solver("astar", astar.search, astar.AstarOptions, doc="A* with the time-constraint weight sweep (astar.py)"),
    "gc": Solver("gc", _baseline, NoOptions, space_base=None,
                 doc="the shortest sea route along the great-circle graph at constant rpm"),
    "rhumb": Solver("rhumb", _baseline, NoOptions, space_base="rhumb",
                    doc="the shortest sea route along the rhumb-line graph at constant rpm"),
}
