"""The fleet planner's budget: a count of work done, not a clock, so the same input and the same effort give the same
plan on any machine under any load.

Every step of the search spends work units for what it did, each a deterministic count (weights below, chosen so a
unit is about a microsecond of one quiet core here: they only balance the phases, never decide the plan by chance):
- a partial sequence (label) made by the Python enumerations (routes.vessel_columns) or an arc tried from one
  (gap_columns.vessel_columns_within); a label made by the compiled pricing (colgen.price);
- a sequence scheduled and costed (problem.schedule: pricing's new columns, local search's moves);
- a simplex iteration of the master LP (HiGHS reports them), an interior-point iteration (per non-zero);
- a branch-and-bound node of HiGHS's MILP (per column of the MILP: HiGHS is given `node_limit` from what is left).

A phase takes a share (`phase`): its own budget, spending into its parent's too, exhausted at its own limit or its
parent's. `exhausted` is what every pacing decision asks. An optional wall-clock safety cap (`wall_limit_s`, off by
default) can also end the search — then, and only then, the plan depends on the machine, and the plan says so.
"""

from __future__ import annotations

import math
import time

# weights: work units per ... (a unit is about a microsecond of CPU here, measured per phase on 20 x 80 and 50 x 200:
# the phases' shares of the budget then match the shares of time they were given when the planner was timed)
PYTHON_LABEL = 15.0  # label made by routes.vessel_columns (each costs a leg in Python)
GAP_ARC = 4.0  # arc tried from a label by gap_columns.vessel_columns_within
PRICE_LABEL = 0.5  # label made by the compiled pricing (colgen._price_nb)
SCHEDULE = 50.0  # sequence scheduled and costed (problem.schedule)
MEMO_HIT = 1.5  # sequence cost looked up again by local search
SIMPLEX_ITERATION_PER_ROW = 0.5  # simplex iteration of the master LP, per row (contracts + vessels) ...
SIMPLEX_ITERATION_PER_COLUMN = 0.02  # ... and per column of the pool (its pricing row grows with the pool)
IPM_ITERATION_PER_NONZERO = 0.2  # interior-point iteration of colgen.solve_lp, per non-zero of its matrix
MILP_ROOT_PER_COLUMN = 1000.0  # HiGHS's MILP over the columns: its root (presolve, cuts, heuristics), per column
MILP_NODE_PER_COLUMN = 50.0  # ... and each further branch-and-bound node, per column

# effort 1 (the default): what the planner spends at most. Calibrated on the bench's 50 x 200 fleet (bench/planning.py,
# bench/README.md): it reaches the plan today's default 60 s reached on a quiet machine.
UNITS_PER_EFFORT = 60_000_000.0
# a second of work, for the pacing rules that were stated in seconds (e.g. "give each step at least 1 s")
UNITS_PER_S = 1_000_000.0


class WorkBudget:
    """`units` of work (inf: no limit), optionally under a wall-clock safety cap of `wall_limit_s` seconds from now."""

    def __init__(self, units: float = math.inf, *, wall_limit_s: float | None = None,
                 parent: "WorkBudget | None" = None):
        if not units >= 0:
            raise ValueError(f"a work budget needs units ≥ 0, not {units!r}")
        self.units = float(units)
        self.spent = 0.0
        self.parent = parent
        if wall_limit_s is not None and not (math.isfinite(wall_limit_s) and wall_limit_s > 0):
            raise ValueError(f"a time limit (safety cap) needs seconds above 0, not {wall_limit_s!r}")
        self.wall_limit_s = wall_limit_s
        self._wall_deadline = None if wall_limit_s is None else time.perf_counter() + float(wall_limit_s)
        self.capped = False  # the safety cap was reached

    @classmethod
    def of_effort(cls, effort: float, wall_limit_s: float | None = None) -> "WorkBudget":
        """The budget of `effort` (1 = the default search; 0.1 a quick one; 10 a long one)."""
        if not (isinstance(effort, (int, float)) and math.isfinite(effort) and effort > 0):
            raise ValueError(f"effort {effort!r}: give a number above 0 (1 = the default search)")
        return cls(effort * UNITS_PER_EFFORT, wall_limit_s=wall_limit_s)

    def spend(self, units: float) -> None:
        self.spent += units
        if self.parent is not None:
            self.parent.spend(units)

    def left(self) -> float:
        """Units left (at most the parent's left)."""
        mine = self.units - self.spent
        return mine if self.parent is None else min(mine, self.parent.left())

    def exhausted(self) -> bool:
        """No work left, or the safety cap reached (this budget's or its parent's)."""
        if self.spent >= self.units or self.cap_reached():
            return True
        return self.parent is not None and self.parent.exhausted()

    def cap_reached(self) -> bool:
        """The wall-clock safety cap has passed (recorded in `capped`)."""
        if not self.capped and self._wall_deadline is not None and time.perf_counter() > self._wall_deadline:
            self.capped = True
        return self.capped or (self.parent is not None and self.parent.cap_reached())

    def wall_left_s(self) -> float | None:
        """Seconds left before the safety cap (None: no cap), for HiGHS's own time limit."""
        mine = None if self._wall_deadline is None else max(0.0, self._wall_deadline - time.perf_counter())
        up = None if self.parent is None else self.parent.wall_left_s()
        return up if mine is None else (mine if up is None else min(mine, up))

    def phase(self, units: float) -> "WorkBudget":
        """A share of this budget: at most `units` (and what is left here), spending into this budget too."""
        return WorkBudget(max(0.0, min(float(units), self.left())), parent=self)

    def highs_options(self, root_units: float, units_per_node: float) -> dict:
        """scipy.optimize.milp options bounding HiGHS's MILP by what is left: `node_limit` (the root costing
        `root_units`, each further node `units_per_node`; at least the root), and the safety cap's time left as
        `time_limit` when there is one."""
        options: dict = {}
        if math.isfinite(self.left()):
            options["node_limit"] = 1 + int(max(0.0, self.left() - root_units) // max(units_per_node, 1e-9))
        wall = self.wall_left_s()
        if wall is not None:
            options["time_limit"] = max(0.01, wall)
        return options


def unlimited() -> WorkBudget:
    return WorkBudget()
