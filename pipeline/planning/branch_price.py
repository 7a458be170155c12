"""Branch-and-price: raises the set-partitioning LP bound by branching until the plan is proven within the gap asked.

The LP bound alone can sit more than 1 % under the optimum (its solution splits vessels between columns); branching
cuts those splits off. A node is the list of decisions on vessel–contract pairs taken from the root:
- (k, j, True): vessel k lifts contract j — j is compulsory (master_lp: leaving it costs more than any plan) and
  every other vessel is forbidden it;
- (k, j, False): vessel k does not lift j.
Each plan of the parent keeps exactly one of the two, so the children share its plans between them. When every
vessel–contract pair is whole in a node's LP, each vessel's columns there hold one and the same set of contracts:
the LP solution is a plan, and the node is solved.

Node LP: column generation over the pool shared by every node (master_lp.MasterLP: the columns a node forbids are
closed, the others kept, so a node starts from everything its parent priced), pricing (colgen.price) with the
node's forbidden pairs blocked, until no column has a negative reduced cost; its LP value is then the node's bound.
Before that, Lasdon's bound (LP value + Σ per vessel least reduced cost, colgen.py) is valid too and prunes the
node as soon as it reaches the incumbent.

Search: best bound first (ties: deepest first, towards plans), so the proven bound — the least bound of the open
nodes — rises as fast as the nodes are solved; the children of a node are opened with its bound and its final LP
basis, from which their LPs start (best first jumps across the tree, so the last solve's basis is far from a child's;
from the parent's the dual simplex takes about half the iterations on 50 × 200). Branching pair:
the most fractional x[k, j] (how much of j vessel k lifts in the LP). New plans: each node's LP rounded
(colgen.round_lp) and whole node solutions; the caller may add plans from elsewhere through `improve`.
"""

from __future__ import annotations

import dataclasses
import heapq
import itertools
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from pipeline.planning import colgen, local_search
from pipeline.planning.master_lp import MasterLP
from pipeline.planning.problem import FleetPlan, PlanData, assemble
from pipeline.planning.work_budget import UNITS_PER_S, WorkBudget

BLOCKED = -1e18  # a contract dual this low blocks the contract in pricing (colgen.price)


@dataclass(order=True)
class Node:
    bound: float
    neg_depth: int
    seq: int
    decisions: tuple[tuple[int, int, bool], ...] = field(compare=False)
    basis: tuple | None = field(default=None, compare=False)  # its parent's final LP basis (MasterLP.basis)


@dataclass
class Outcome:
    """What the search proved: the best plan found, the least bound of the nodes left open (its own cost when
    none is), whether the tree was closed, and how many nodes were solved."""

    plan: FleetPlan
    bound: float
    closed: bool
    nodes: int


def node_constraints(decisions, n_vessels: int, n_contracts: int) -> tuple[np.ndarray, np.ndarray]:
    """(blocked[k, j]: vessel k may not lift j, compulsory[j]) of a node's decisions."""
    blocked = np.zeros((n_vessels, n_contracts), bool)
    compulsory = np.zeros(n_contracts, bool)
    for k, j, lifts in decisions:
        if lifts:
            blocked[:, j] = True
            blocked[k, j] = False
            compulsory[j] = True
        else:
            blocked[k, j] = True
    return blocked, compulsory


def solve_node(data: PlanData, master: MasterLP, blocked: np.ndarray, compulsory: np.ndarray, cutoff: float,
               budget: WorkBudget, max_new: int = 10) -> tuple[float, np.ndarray | None, bool]:
    """Column generation at one node: (bound, y of its last LP, LP optimum reached). The bound is the LP value
    when reached, else the best Lasdon bound met (at least `cutoff` when the node can be pruned). Every LP and pricing
    spends from `budget` (work_budget.py); once it is exhausted the node stops (after the LP under way)."""
    master.set_node(blocked, compulsory)
    bound = -np.inf
    while True:
        z, pi, mu, y = master.solve(budget)
        least, new = 0.0, []
        for k in range(master.V):
            if budget.exhausted():  # a round cut short proves nothing (y must stay one per pool column)
                return bound, y, False
            pik = pi.copy()
            pik[blocked[k]] = BLOCKED
            rc, cols = colgen.price(data, k, pik, float(mu[k]), max_new=max_new, budget=budget)
            least += min(0.0, rc)
            new += cols
        bound = max(bound, z + least)
        if least > -colgen.EPS * max(1.0, abs(z)):
            return max(bound, z), y, True
        if bound >= cutoff or budget.exhausted() or not master.add(new):  # y: one per pool column
            return bound, y, False


def solve_root(data: PlanData, master: MasterLP, budget: WorkBudget) -> tuple[float, bool]:
    """Column generation at the root (no decisions): (the LP bound, or Lasdon's once `budget` is spent; LP optimum
    reached)."""
    blocked, compulsory = node_constraints((), len(data.vessels), len(data.contracts))
    bound, _, converged = solve_node(data, master, blocked, compulsory, np.inf, budget)
    return bound, converged


def _whole_plan(master: MasterLP, y: np.ndarray) -> dict[int, tuple[int, ...]] | None:
    """The plan an LP solution is, when every vessel–contract pair is whole in it (None otherwise)."""
    x = master.lifted_by(y)
    if np.any(np.minimum(x, 1.0 - x) > 1e-6):
        return None
    out: dict[int, tuple[int, float]] = {}
    for i in np.flatnonzero(y > 1e-6):
        col = master.columns[i]
        if col.k not in out or y[i] > out[col.k][1]:
            out[col.k] = (i, y[i])
    return {k: master.columns[i].sequence for k, (i, _) in out.items()}


def column_decisions(data: PlanData, k: int, sequence: tuple[int, ...]) -> tuple[tuple[int, int, bool], ...]:
    """The decisions that make vessel k lift exactly the contracts of `sequence`: it lifts each of them (so no other
    vessel may) and none of the other contracts it could lift."""
    inside = set(sequence)
    return (tuple((k, j, True) for j in sequence)
            + tuple((k, j, False) for j in data.per_vessel[k].contracts if j not in inside))


def dive(data: PlanData, master: MasterLP, decisions: tuple, budget: WorkBudget, *, fix_at: float = 0.6
         ) -> dict[int, tuple[int, ...]]:
    """A plan by diving from a node: fix the columns the node's LP takes at least `fix_at` (those sharing no contract
    with a column of higher value; else its largest column), each as "its vessel lifts exactly its contracts"
    (column_decisions), re-solve the LP with pricing, until it is whole. A fixed column stays in the pool and
    allowed, so the LP can always lift every compulsory contract. Once `budget` is spent the last LP is rounded
    (colgen.round_lp). Fixing whole columns keeps each vessel's sequence as the LP priced it; fixing single
    vessel–contract pairs instead ends further from the optimum (1.1 % against 5 % above it on a 20 × 80 fleet)."""
    n, V = len(data.contracts), len(data.vessels)
    fixed: set[int] = set()  # vessels whose column the dive fixed
    while True:
        blocked, compulsory = node_constraints(decisions, V, n)
        _, y, _ = solve_node(data, master, blocked, compulsory, np.inf, budget)
        whole = _whole_plan(master, y)
        if whole is not None:
            return whole
        if budget.exhausted() or np.any(master.slack()[compulsory] > 1e-6):
            return colgen.round_lp(data, master.columns, y * master.allowed(blocked))
        order = [i for i in np.argsort(-y, kind="stable") if y[i] > 1e-6 and master.columns[i].k not in fixed]
        take = [i for i in order if y[i] >= fix_at] or order[:1]
        taken: set[int] = set()
        for i in take:
            col = master.columns[i]
            if col.k in fixed or taken.intersection(col.sequence):
                continue
            taken.update(col.sequence)
            fixed.add(col.k)
            decisions = decisions + column_decisions(data, col.k, col.sequence)
        if not take:  # nothing fractional is left to fix (cannot happen when the LP is not whole): round
            return colgen.round_lp(data, master.columns, y * master.allowed(blocked))


# Penalty factors of penalty_dives, most promising first (on the bench's 50 × 200 fleets ×2 and ×3 gave the best
# first plans; ×1.5 stays nearer the true trade-off between lifting a contract and leaving it)
PENALTY_FACTORS = (2.0, 3.0, 1.5)


def penalty_dives(data: PlanData, master: MasterLP, budget: WorkBudget,
                  factors: tuple[float, ...] = PENALTY_FACTORS) -> list[dict[int, tuple[int, ...]]]:
    """Plans from dives (`dive`) on the LP with every contract's penalty raised by each factor, until `budget` is
    spent.

    The root LP lifts fractions of contracts that its dive then leaves to the spot market (on a 50 × 200 fleet it
    lifts 197.25 contracts, the dive's plan 196); with dearer penalties the dive keeps lifting them and can end in a
    plan that is cheaper at the true penalties (1.21 % above the LP instead of 1.73 % there). Columns do not depend on
    the penalties, so each dive starts from the pool `master` holds, and the columns it prices join that pool."""
    plans = []
    for factor in factors:
        if budget.exhausted():
            break
        dearer = dataclasses.replace(data, contracts=[dataclasses.replace(c, penalty=c.penalty * factor)
                                                      for c in data.contracts])
        scaled = MasterLP(dearer)
        scaled.add(master.columns)
        solve_root(dearer, scaled, budget)
        plans.append(dive(dearer, scaled, (), budget))
        master.add(scaled.columns)
    return plans


def branching_pair(master: MasterLP, y: np.ndarray) -> tuple[int, int]:
    """The vessel–contract pair (k, j) whose x[k, j] is nearest ½."""
    x = master.lifted_by(y)
    k, j = np.unravel_index(np.argmin(np.abs(x - 0.5)), x.shape)
    return int(k), int(j)


def search(data: PlanData, master: MasterLP, incumbent: FleetPlan, budget: WorkBudget, *, root_bound: float = -np.inf,
           rel_gap: float = 0.0, dive_share: float = 0.3, improve: Callable[[FleetPlan, float], FleetPlan] | None = None) -> Outcome:
    """Best-bound branch-and-price from the root (whose columns `master` holds, `root_bound` proven) until the plan is proven within
    `rel_gap` of the optimum, the tree is closed or `budget` (work_budget.py) is spent. Up to `dive_share` of the work
    goes to dives (`dive`, then local_search) from the node just solved, for better plans. `improve(best, bound)`, when
    given, is called after each node and may return a better plan."""
    n, V = len(data.contracts), len(data.vessels)
    best = incumbent
    counter = itertools.count()
    open_nodes = [Node(root_bound, 0, next(counter), ())]
    solved = 0
    began, diving = budget.spent, 0.0  # work spent before the search; of it, on dives
    floor = np.inf  # the least bound of the nodes dropped only because they are within `rel_gap` of the incumbent

    def cutoff() -> float:
        return best.cost * (1 - rel_gap) - 1e-6 * max(1.0, abs(best.cost))

    def plan_of(sequences) -> FleetPlan:
        return assemble(data, sequences, solver="milp", status="feasible", gap=np.nan, runtime_s=0.0)

    while open_nodes and not budget.exhausted():
        node = heapq.heappop(open_nodes)
        if node.bound >= cutoff():
            floor = min(floor, node.bound)
            continue
        blocked, compulsory = node_constraints(node.decisions, V, n)
        if node.basis is not None:
            master.restore(node.basis)
        bound, y, converged = solve_node(data, master, blocked, compulsory, cutoff(), budget)
        bound = max(bound, node.bound)
        solved += 1
        if not converged:
            if bound < cutoff():  # cut short by the budget: still open
                heapq.heappush(open_nodes, Node(bound, node.neg_depth, node.seq, node.decisions, node.basis))
            else:
                floor = min(floor, bound)
            continue
        whole = _whole_plan(master, y)
        if whole is not None:
            plan = plan_of(whole)
            if plan.cost < best.cost:
                best = plan
            continue
        basis = master.basis()  # before the dive moves the LP elsewhere
        rounded = plan_of(colgen.round_lp(data, master.columns, y * master.allowed(blocked)))
        if rounded.cost < best.cost:
            best = rounded
        if diving < dive_share * (budget.spent - began):
            d0 = budget.spent
            sequences = dive(data, master, node.decisions, budget)
            dived = local_search.improve(data, sequences, budget=budget.phase(1.0 * UNITS_PER_S))
            best = min(best, plan_of(dived), key=lambda p: p.cost)
            diving += budget.spent - d0
        if improve is not None:
            best = min(best, improve(best, min([bound] + [o.bound for o in open_nodes])), key=lambda p: p.cost)
        if bound >= cutoff():
            floor = min(floor, bound)
            continue
        k, j = branching_pair(master, y)
        depth = node.neg_depth - 1
        for lifts in (True, False):
            heapq.heappush(open_nodes, Node(bound, depth, next(counter), node.decisions + ((k, j, lifts),), basis))
    live = [o.bound for o in open_nodes]
    return Outcome(best, min(live + [floor, best.cost]), not live, solved)
