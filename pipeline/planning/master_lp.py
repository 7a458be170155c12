"""The set-partitioning LP over a growing pool of columns, kept in one HiGHS instance so each solve starts from the
last basis (a branch-and-price node re-solves in a few simplex iterations instead of from scratch), or from a basis
saved earlier (`basis` / `restore`: a node from its parent's).

Rows and variables:
- contract j: Σ y (columns lifting j) + s_j = 1, with s_j ≥ 0 costing j's penalty (left to the spot market);
- vessel k: Σ y (columns of k) ≤ 1; y ≥ 0, costing the column's fuel and days out of service.
Its optimum equals colgen.solve_lp's. A branch-and-price node (branch_price.py) forbids vessel–contract pairs — the
columns that lift a forbidden pair get an upper bound of 0 — and may make a contract compulsory by raising the cost
of its slack to `COMPULSORY_PENALTY`: a plan leaving it is then dearer than any plan at all (every plan costs at most
the sum of the penalties), and the LP stays feasible, so its value is a bound of the node whatever columns it has.

HiGHS is the one scipy ships (`scipy.optimize._highspy`, the same solver as `linprog(method="highs")`); its object
interface is what keeps the basis between solves.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize._highspy import _core as highs

from pipeline.planning.problem import PlanData
from pipeline.planning.routes import Column
from pipeline.planning.work_budget import SIMPLEX_ITERATION_PER_COLUMN, SIMPLEX_ITERATION_PER_ROW, WorkBudget


class MasterLP:
    def __init__(self, data: PlanData):
        self.n, self.V = len(data.contracts), len(data.vessels)
        self.penalty = np.array([c.penalty for c in data.contracts], float)
        self.columns: list[Column] = []
        self.have: set[tuple[int, tuple[int, ...]]] = set()
        self._k: list[int] = []  # per column: its vessel
        self._ptr: list[int] = [0]  # per column: where its contracts start in _members
        self._members: list[int] = []
        self._open = np.zeros(0, bool)  # per column: open (else forbidden at this node: upper bound 0)
        self._slack_cost = self.penalty.copy()
        h = highs._Highs()
        h.setOptionValue("output_flag", False)
        inf = h.getInfinity()
        lp = highs.HighsLp()
        lp.num_col_, lp.num_row_ = 0, self.n + self.V
        lp.row_lower_ = np.concatenate([np.ones(self.n), np.full(self.V, -inf)])
        lp.row_upper_ = np.ones(self.n + self.V)
        h.passModel(lp)
        idx = np.arange(self.n, dtype=np.int32)
        # no upper bounds but the rows' (an explicit y ≤ 1 would carry a dual of its own, which pricing does not see)
        self.inf = inf
        h.addCols(self.n, self.penalty, np.zeros(self.n), np.full(self.n, inf), self.n, idx, idx, np.ones(self.n))
        self.h = h

    def add(self, columns: list[Column]) -> int:
        """Add the columns not in the pool yet (open at the current node's bounds: the caller prices only columns
        the node allows); returns how many were new."""
        new = [c for c in columns if (c.k, c.sequence) not in self.have]
        if not new:
            return 0
        starts, idx = [], []
        for c in new:
            self.have.add((c.k, c.sequence))
            self.columns.append(c)
            self._k.append(c.k)
            starts.append(len(idx))
            idx += list(c.sequence) + [self.n + c.k]
            self._members += c.sequence
            self._ptr.append(len(self._members))
        m = len(new)
        self.h.addCols(m, np.array([c.cost for c in new], float), np.zeros(m), np.full(m, self.inf), len(idx),
                       np.array(starts, np.int32), np.array(idx, np.int32), np.ones(len(idx)))
        self._open = np.concatenate([self._open, np.ones(m, bool)])
        return m

    def allowed(self, blocked: np.ndarray) -> np.ndarray:
        """Per pool column: it lifts no pair forbidden by `blocked` (vessels × contracts, True: may not lift)."""
        ptr = np.asarray(self._ptr, np.int64)
        if not self._members:
            return np.ones(len(self.columns), bool)
        owner = np.repeat(np.asarray(self._k, np.int64), np.diff(ptr))
        bad = blocked[owner, np.asarray(self._members, np.int64)]
        hit = np.add.reduceat(bad.astype(np.int64), ptr[:-1]) if bad.size else np.zeros(len(self.columns), np.int64)
        hit[np.diff(ptr) == 0] = 0  # reduceat on an empty span repeats the next value
        return hit == 0

    def set_node(self, blocked: np.ndarray, compulsory: np.ndarray) -> None:
        """Bounds of a node: columns lifting a pair `blocked` forbids are closed; contracts `compulsory` (bool per
        contract) cost COMPULSORY_PENALTY when left."""
        want = self.allowed(blocked)
        change = np.flatnonzero(want != self._open)
        if change.size:
            ub = np.where(want[change], self.inf, 0.0)
            self.h.changeColsBounds(change.size, (change + self.n).astype(np.int32), np.zeros(change.size), ub)
            self._open = want
        cost = np.where(compulsory, compulsory_penalty(self.penalty), self.penalty)
        moved = np.flatnonzero(cost != self._slack_cost)
        if moved.size:
            self.h.changeColsCost(moved.size, moved.astype(np.int32), cost[moved])
            self._slack_cost = cost

    def solve(self, budget: WorkBudget | None = None) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
        """(LP value, contract duals as colgen.solve_lp gives them — prize of lifting j less its penalty —, vessel
        duals μ ≤ 0, column values y in pool order). Its simplex iterations are spent from `budget` when given (an LP
        solve is never cut short)."""
        h = self.h
        h.run()
        self._spend(budget)
        status = h.getModelStatus()
        if status != highs.HighsModelStatus.kOptimal:
            h.clearSolver()  # a stale basis can stall the simplex: once more from scratch
            h.run()
            self._spend(budget)
            status = h.getModelStatus()
            if status != highs.HighsModelStatus.kOptimal:
                raise RuntimeError(f"the planning LP failed: {h.modelStatusToString(status)}")
        sol = h.getSolution()
        dual = np.asarray(sol.row_dual)
        x = np.asarray(sol.col_value)
        return float(h.getObjectiveValue()), dual[:self.n] - self.penalty, np.minimum(dual[self.n:], 0.0), x[self.n:]

    def _spend(self, budget: WorkBudget | None) -> None:
        """The last run's simplex iterations, spent from `budget` (when given)."""
        if budget is not None:
            per_iteration = (SIMPLEX_ITERATION_PER_ROW * (self.n + self.V)
                             + SIMPLEX_ITERATION_PER_COLUMN * (self.n + len(self.columns)))
            budget.spend(per_iteration * max(0, self.h.getInfo().simplex_iteration_count))

    def basis(self) -> tuple[list, list]:
        """The last solve's basis (HiGHS's column and row statuses), to start a later solve from (`restore`)."""
        b = self.h.getBasis()
        return list(b.col_status), list(b.row_status)

    def restore(self, saved: tuple[list, list]) -> bool:
        """Start the next solve from a basis `basis` returned, the columns added since nonbasic at 0 (their lower
        bound, so the basis stays valid whatever the node's bounds). Returns whether HiGHS took it; if not, the next
        solve starts from the current basis, as without it."""
        cols, rows = saved
        b = highs.HighsBasis()
        b.col_status = cols + [highs.HighsBasisStatus.kLower] * (self.n + len(self.columns) - len(cols))
        b.row_status = rows
        return self.h.setBasis(b) == highs.HighsStatus.kOk

    def slack(self) -> np.ndarray:
        """How much of each contract the last solve left (s_j)."""
        return np.asarray(self.h.getSolution().col_value)[:self.n]

    def lifted_by(self, y: np.ndarray) -> np.ndarray:
        """x[k, j]: how much of contract j vessel k lifts in the LP solution `y`."""
        x = np.zeros((self.V, self.n))
        for i in np.flatnonzero(y > 1e-9):
            x[self._k[i], self._members[self._ptr[i]:self._ptr[i + 1]]] += y[i]
        return x


def compulsory_penalty(penalty: np.ndarray) -> float:
    """A cost of leaving a compulsory contract above that of any plan (every plan costs at most Σ penalties)."""
    return float(penalty.sum()) + 1.0
