"""The contract every solver answers, in a module of its own so solvers import it without importing each other.

    search(instance, baseline, *, seed, options) -> Found

`instance` is a problem.Instance (graph, vessel, weather, objective), `baseline` the baseline.Baseline of the
voyage (its shortest sea route at the one constant rpm that meets the RTA), `seed` the random seed (ignored by
exact solvers) and `options` an instance of the solver's own options class (`Solver.options`). A solver that
finds nothing feasible returns Found(None, None). The registry of solvers is solvers.SOLVERS.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Callable

import numpy as np


class UnknownSolverError(ValueError):
    """A solver name or solver option the registry does not know (the message lists the known ones)."""


@dataclass
class Found:
    """A solver's answer: node per line and rpm index per leg (None: nothing feasible), the legs or routes it
    sailed, for iterative solvers the best cost after each cycle, and for a solver whose plans may wait at nodes
    (the grid DP, dp_grid.py) the hours waited at each line's node before its leg (None: no waiting) and the fuel
    rate while waiting (t/h)."""

    nodes: np.ndarray | None
    rpm_idx: np.ndarray | None
    n_evals: int = 0
    history: np.ndarray | None = None
    wait_h: np.ndarray | None = None
    wait_tph: float = 0.0
    note: str | None = None  # what the plan's reason should add about the solver's space (e.g. its waits' grid)

    @property
    def waits(self) -> bool:
        """Whether the plan waits anywhere (a wait of more than a second)."""
        return self.wait_h is not None and bool(np.any(np.asarray(self.wait_h) > 1.0 / 3600.0))


@dataclass(frozen=True)
class NoOptions:
    """The solver has no settings."""


@dataclass(frozen=True)
class Solver:
    name: str
    search: Callable[..., Found]
    options: type
    space_base: str | None = None  # lay the search space along this base route ("gc" when None)
    seeded: bool = False  # whether the answer depends on the seed (the plan records the seed then)
    is_baseline: bool = False  # it returns the constant-speed voyage itself (no limits re-plan, no baseline)
    doc: str = ""

    @property
    def base(self) -> str:
        return self.space_base or "gc"

    def make_options(self, overrides: dict | None = None):
        """The solver's options with `overrides` (name → value, values as text are converted to the field's
        type); ValueError naming the unknown option or the bad value."""
        opts = self.options()
        if not overrides:
            return opts
        fields = {f.name: f for f in dataclasses.fields(self.options)}
        values = {}
        for key, value in overrides.items():
            if key not in fields:
                known = ", ".join(sorted(fields)) or "none"
                raise UnknownSolverError(f"solver {self.name!r} has no option {key!r} (its options: {known})")
            current = getattr(opts, key)
            values[key] = _convert(self.name, key, value, current)
        try:
            return dataclasses.replace(opts, **values)
        except ValueError as exc:  # the options' own checks (e.g. DpOptions.__post_init__)
            raise UnknownSolverError(f"solver {self.name!r}: {exc}") from None


def _convert(solver: str, key: str, value, current):
    if not isinstance(value, str):
        return value
    text = value.strip()
    try:
        if text.lower() in ("none", "null", ""):
            return None
        if isinstance(current, bool):
            if text.lower() not in ("true", "false", "1", "0", "yes", "no"):
                raise ValueError(text)
            return text.lower() in ("true", "1", "yes")
        if isinstance(current, int):
            return int(text)
        if isinstance(current, float) or current is None:
            try:
                return float(text)
            except ValueError:
                if current is None:
                    return text
                raise
        if isinstance(current, tuple):
            return tuple(float(x) for x in text.split(","))
        return text
    except ValueError:
        raise UnknownSolverError(f"solver {solver!r} option {key}={value!r}: expected a value like {current!r}") from None
