"""Branch-and-price (pipeline/planning/branch_price.py, master_lp.py): the warm LP equals the reference LP, pricing
under branch decisions never returns a forbidden pair and finds the least reduced cost brute force finds among the
allowed sets, and the search reaches the brute-force optimum on small instances whose root LP is fractional."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.planning import branch_price, brute, colgen, local_search, milp, problem
from pipeline.planning.master_lp import MasterLP
from pipeline.planning.problem import assemble
from pipeline.planning.work_budget import WorkBudget
from pipeline.synthetic.contracts import random_instance


def _instance(rng, seed):
    vessels, contracts, dist = random_instance(int(rng.integers(2, 4)), int(rng.integers(5, 8)), seed=seed,
                                               horizon_days=12, n_ports=5, window_days=6)
    return problem.build(vessels, contracts, dist, fuel_price=600.0)


def _pairs(data):
    """Every vessel–contract pair a vessel could lift."""
    return [(k, j) for k in range(len(data.vessels)) for j in data.per_vessel[k].contracts]


def _optimum_over_every_column(data) -> float:
    """The optimum: HiGHS's MILP over every enumerated column (routes.vessel_columns, itself equal to brute
    force's columns), solved to the end."""
    from pipeline.planning.routes import vessel_columns

    every = [col for k in range(len(data.vessels)) for col in vessel_columns(data, k)[0]]
    sequences, _, finished = milp._set_partitioning(data, every, WorkBudget(), 0.0, 1.0)
    assert finished
    return assemble(data, sequences, solver="t", status="", gap=0.0, runtime_s=0.0).cost


def _root(data):
    master = MasterLP(data)
    bound, converged = branch_price.solve_root(data, master, WorkBudget())
    assert converged
    return master, bound


def test_the_warm_lp_equals_the_reference_lp_at_the_root():
    rng = np.random.default_rng(41)
    for seed in range(10):
        data = _instance(rng, 900 + seed)
        master, bound = _root(data)
        ref, *_ = colgen.solve_lp(data, master.columns)
        assert bound == pytest.approx(ref, rel=1e-7), f"seed {seed}"


def test_pricing_under_branch_decisions_blocks_forbidden_pairs_and_finds_the_least_allowed_reduced_cost():
    """Random decisions (pairs forbidden, a pair lifted): every column the node's pricing returns and every column
    its LP uses lifts no forbidden pair, and the least reduced cost pricing reports equals brute force's least over
    the sets each vessel may still lift."""
    rng = np.random.default_rng(43)
    n_blocked = 0
    for seed in range(30):
        data = _instance(rng, 1000 + seed)
        V, n = len(data.vessels), len(data.contracts)
        pairs = _pairs(data)
        master, _ = _root(data)
        picks = rng.choice(len(pairs), size=min(3, len(pairs)), replace=False)
        decisions = tuple((*pairs[i], bool(q == 0)) for q, i in enumerate(picks))
        blocked, compulsory = branch_price.node_constraints(decisions, V, n)
        master.set_node(blocked, compulsory)
        _, pi, mu, y = master.solve()
        for k in range(V):
            pik = pi.copy()
            pik[blocked[k]] = branch_price.BLOCKED
            least, cols = colgen.price(data, k, pik, float(mu[k]), max_new=1000)
            assert not any(blocked[k, j] for col in cols for j in col.sequence), f"seed {seed} vessel {k}"
            exact = min([0.0] + [c - sum(data.contracts[j].penalty + pi[j] for j in seq) - mu[k]
                                 for key, (c, seq) in brute.best_per_subset(data, k).items()
                                 if seq and not any(blocked[k, j] for j in key)])
            assert least == pytest.approx(exact, rel=1e-7, abs=1e-3), f"seed {seed} vessel {k}"
            n_blocked += int(blocked[k].sum())
        branch_price.solve_node(data, master, blocked, compulsory, np.inf, WorkBudget())
        _, _, _, y = master.solve()
        for i in np.flatnonzero(y > 1e-9):
            col = master.columns[i]
            assert not any(blocked[col.k, j] for j in col.sequence), f"seed {seed}"
    assert n_blocked > 30


def _brute_under(data, decisions):
    """Brute-force optimum over the plans that keep `decisions` (inf: none does)."""
    import itertools

    V, n = len(data.vessels), len(data.contracts)
    blocked, compulsory = branch_price.node_constraints(decisions, V, n)
    tables = [[(key, c) for key, (c, _) in brute.best_per_subset(data, k).items() if not any(blocked[k, j] for j in key)]
              for k in range(V)]
    best = np.inf
    for pick in itertools.product(*tables):
        sets = [key for key, _ in pick]
        used = frozenset().union(*sets)
        if sum(len(s) for s in sets) != len(used) or any(compulsory[j] and j not in used for j in range(n)):
            continue
        best = min(best, sum(c for _, c in pick) + sum(data.contracts[j].penalty for j in range(n) if j not in used))
    return best


def test_a_node_bound_never_exceeds_the_best_plan_that_keeps_its_decisions():
    rng = np.random.default_rng(47)
    checked = 0
    for seed in range(20):
        data = _instance(rng, 1100 + seed)
        V, n = len(data.vessels), len(data.contracts)
        pairs, (master, _) = _pairs(data), _root(data)
        i = int(rng.integers(len(pairs)))
        for lifts in (True, False):
            decisions = ((*pairs[i], lifts),)
            blocked, compulsory = branch_price.node_constraints(decisions, V, n)
            bound, _, converged = branch_price.solve_node(data, master, blocked, compulsory, np.inf,
                                                          WorkBudget())
            want = _brute_under(data, decisions)
            assert converged
            assert bound <= want * (1 + 1e-9) + 1e-6, f"seed {seed} {decisions}"
            checked += np.isfinite(want)
    assert checked > 20


def test_branching_reaches_the_exact_optimum_where_the_root_lp_is_fractional():
    """The search alone (root LP, its rounding improved by local search as the starting plan, then branching):
    the tree closes and its plan costs the optimum — brute force's on small instances, HiGHS's MILP over every
    enumerated column (routes.vessel_columns, itself equal to brute force's columns) on fleets of 5 × 20 with wide
    windows, where the root LP is often below the optimum."""
    rng = np.random.default_rng(53)
    fractional = 0
    for seed in range(30):
        if seed % 5 == 0:
            data = _instance(rng, 1200 + seed)
            best = brute.solve(data).cost
        else:
            vessels, contracts, dist = random_instance(5, 20, seed=700 + seed, horizon_days=25, n_ports=8,
                                                       window_days=6)
            data = problem.build(vessels, contracts, dist, fuel_price=600.0)
            best = _optimum_over_every_column(data)
        master, bound = _root(data)
        _, _, _, y = master.solve()
        start = local_search.improve(data, colgen.round_lp(data, master.columns, y))
        start_plan = assemble(data, start, solver="t", status="", gap=0.0, runtime_s=0.0)
        fractional += bound < best - 1.0
        out = branch_price.search(data, master, start_plan, WorkBudget(), root_bound=bound)
        assert out.closed, f"seed {seed}"
        assert out.plan.cost == pytest.approx(best, rel=1e-9), f"seed {seed}"
        assert out.bound == pytest.approx(best, rel=1e-9)
    assert fractional >= 5  # the branching is exercised where the LP bound proves nothing


def test_a_dive_past_its_budget_still_returns_a_feasible_plan():
    """Cut short (its work budget already spent, at a node whose decisions need new columns), the dive rounds its
    last LP: a plan whose sequences are all feasible and that keeps the node's forbidden pairs."""
    for seed in range(4):
        vessels, contracts, dist = random_instance(5, 20, seed=1500 + seed, horizon_days=25, n_ports=8, window_days=6)
        data = problem.build(vessels, contracts, dist, fuel_price=600.0)
        master, _ = _root(data)
        _, _, _, y = master.solve()
        x = master.lifted_by(y)
        forbid = tuple((int(k), int(j), False) for k, j in np.argwhere(x > 1e-6))  # everything the root LP lifts
        n_columns = len(master.columns)
        plan = branch_price.dive(data, master, forbid, WorkBudget(0))
        assert len(master.columns) == n_columns  # past the budget nothing priced is added
        assert not any(j in plan.get(k, ()) for k, j, _ in forbid)
        assemble(data, plan, solver="t", status="", gap=0.0, runtime_s=0.0)  # raises on an infeasible sequence


def test_column_decisions_leave_the_vessel_only_its_column_and_the_others_none_of_its_contracts():
    data = problem.build(*random_instance(5, 20, seed=1600, horizon_days=25, n_ports=8, window_days=6), fuel_price=600.0)
    V, n = len(data.vessels), len(data.contracts)
    master, _ = _root(data)
    col = max(master.columns, key=lambda c: len(c.sequence))
    blocked, compulsory = branch_price.node_constraints(branch_price.column_decisions(data, col.k, col.sequence), V, n)
    assert set(np.flatnonzero(compulsory)) == set(col.sequence)
    assert set(np.flatnonzero(~blocked[col.k])) & set(data.per_vessel[col.k].contracts) == set(col.sequence)
    others = [k for k in range(V) if k != col.k]
    assert blocked[np.ix_(others, list(col.sequence))].all()
    allowed = master.allowed(blocked)
    assert allowed[master.columns.index(col)]
    assert all(set(c.sequence) <= set(col.sequence) for c, ok in zip(master.columns, allowed) if ok and c.k == col.k)


def test_a_column_dive_ends_in_a_plan_of_priced_columns_costing_their_sum_between_the_lp_bound_and_the_optimum():
    """From the root, the dive's plan is made of pool columns (a whole LP solution): its cost is the sum of those
    columns' costs and the penalties of the contracts it leaves — the LP's own costing, no offset — and lies between
    the root LP bound and the optimum (HiGHS's MILP over every enumerated column), on fleets of 6 × 24 where the root
    LP is often fractional."""
    fractional = 0
    for seed in range(8):
        vessels, contracts, dist = random_instance(6, 24, seed=1700 + seed, horizon_days=20, n_ports=8, window_days=6)
        data = problem.build(vessels, contracts, dist, fuel_price=600.0)
        best = _optimum_over_every_column(data)
        master, bound = _root(data)
        _, _, _, y = master.solve()
        fractional += branch_price._whole_plan(master, y) is None
        plan = branch_price.dive(data, master, (), WorkBudget())
        pool = {(c.k, c.sequence): c.cost for c in master.columns}
        lifted = {j for seq in plan.values() for j in seq}
        by_columns = (sum(pool[(k, seq)] for k, seq in plan.items())
                      + sum(c.penalty for j, c in enumerate(data.contracts) if j not in lifted))
        cost = assemble(data, plan, solver="t", status="", gap=0.0, runtime_s=0.0).cost
        assert cost == pytest.approx(by_columns, rel=1e-12), f"seed {seed}"
        assert bound - 1e-6 <= best + 1e-6 <= cost + 2e-6, f"seed {seed}"
    assert fractional >= 3  # the dive fixed columns, not just read a whole root LP


def test_a_restored_basis_re_solves_its_node_without_an_iteration_after_other_nodes_and_new_columns():
    """MasterLP.basis / restore: a node's final basis, restored after other nodes were solved and columns were added,
    re-solves that node to the same LP value in no simplex iteration; without it the re-solve needs iterations."""
    vessels, contracts, dist = random_instance(6, 24, seed=1702, horizon_days=20, n_ports=8, window_days=6)
    data = problem.build(vessels, contracts, dist, fuel_price=600.0)
    master, _ = _root(data)
    V, n = len(data.vessels), len(data.contracts)
    _, _, _, y = master.solve()
    k, j = branch_price.branching_pair(master, y)
    assert 0.1 < master.lifted_by(y)[k, j] < 0.9  # a fractional root: the two children's LPs differ
    first = branch_price.node_constraints(((k, j, True),), V, n)
    value, _, converged = branch_price.solve_node(data, master, *first, np.inf, WorkBudget())
    assert converged
    saved = master.basis()
    other = branch_price.node_constraints(((k, j, False),), V, n)
    branch_price.solve_node(data, master, *other, np.inf, WorkBudget())
    plan = branch_price.dive(data, master, (), WorkBudget())  # more columns, the LP elsewhere
    assert plan
    for restore, moved in ((True, False), (False, True)):
        branch_price.solve_node(data, master, *other, np.inf, WorkBudget())
        if restore:
            assert master.restore(saved)
        master.set_node(*first)
        z, *_ = master.solve()
        assert z == pytest.approx(value, rel=1e-9)
        assert (master.h.getInfo().simplex_iteration_count > 0) == moved


def test_penalty_dives_return_plans_of_the_true_problem_and_leave_the_true_penalties_alone():
    """Dives under dearer penalties (branch_price.penalty_dives) on fleets of 6 × 24: at factor 1 the dive is the
    plain dive's, plan for plan; at dearer factors each plan is made of pool columns of the true problem (the
    columns the dearer LPs priced join the pool), lifts each contract at most once, costs at least the optimum at the
    true penalties; on some fleets (2 of these 6) such a plan lifts more contracts than the plain dive's and is
    cheaper at the true penalties; the problem's penalties are unchanged."""
    better = 0
    for seed in range(6):
        vessels, contracts, dist = random_instance(6, 24, seed=1700 + seed, horizon_days=20, n_ports=8, window_days=6)
        data = problem.build(vessels, contracts, dist, fuel_price=600.0)
        penalties = [c.penalty for c in data.contracts]
        best = _optimum_over_every_column(data)
        master, _ = _root(data)
        plain = branch_price.dive(data, master, (), WorkBudget())
        (same,) = branch_price.penalty_dives(data, _root(data)[0], WorkBudget(), factors=(1.0,))
        assert same == plain, f"seed {seed}"
        plans = branch_price.penalty_dives(data, master, WorkBudget(), factors=(2.0, 3.0))
        assert len(plans) == 2
        pool = {(c.k, c.sequence) for c in master.columns}
        for plan in plans:
            lifted = [j for seq in plan.values() for j in seq]
            assert len(lifted) == len(set(lifted)), f"seed {seed}"
            assert all((k, seq) in pool for k, seq in plan.items()), f"seed {seed}"
            cost = assemble(data, plan, solver="t", status="", gap=0.0, runtime_s=0.0).cost
            assert cost >= best - 1e-6, f"seed {seed}"
            better += (len(lifted) > sum(map(len, plain.values()))
                       and cost < assemble(data, plain, solver="t", status="", gap=0.0, runtime_s=0.0).cost)
        assert [c.penalty for c in data.contracts] == penalties
    assert better >= 2


def test_a_plan_whose_work_is_already_spent_is_feasible_and_claims_no_proof():
    """With no work left (a budget of 0 units), the planner (column generation forced by a cap of 3 labels per
    vessel) prices nothing more and returns at once a feasible plan, neither optimal nor with a gap, and says the
    effort stopped it."""
    data = problem.build(*random_instance(5, 20, seed=1800, horizon_days=25, n_ports=8, window_days=6), fuel_price=600.0)
    plan = milp.solve(data, max_labels=3, budget=WorkBudget(0))
    assert plan.status == "feasible" and not np.isfinite(plan.gap)
    assert plan.stopped_by == f"effort: {plan.work_units:,.0f} units spent, no lower bound yet"
    assert len(plan.schedules) + len(plan.unassigned) >= 1
    full = milp.solve(data, max_labels=3)
    assert full.status == "optimal" and full.cost <= plan.cost and full.stopped_by == "proven optimal"
