"""Fleet planning: how much better a plan two heuristics on top of the planner's first plan find (a measurement).

On the bench's random instance (`pipeline/synthetic/contracts.py`, seed 1): the root LP by column generation
(`branch_price.solve_root`), the planner's first plan (the dive fixing whole columns, then `local_search`, as
`milp.solve` makes it), then from that plan, each for the time given:
- price-and-branch: HiGHS's MILP over the columns priced so far whose root reduced cost is at most a share of the
  gap between plan and LP (`--shares`), plus the plan's own columns, started from the plan (`setSolution`) with
  its primal heuristics raised (`mip_heuristic_effort`); and again over the larger pool left after `--tree-s`
  seconds of branch-and-price (`branch_price.search`) from the plan, started from its best plan;
- large-neighbourhood search: free 2 to `--vessels` vessels (one drawn at random, seeded, and those most linked
  to it), their contracts and every contract left to the spot market one of them could lift; enumerate each
  freed vessel's sequences over just those contracts (`routes.vessel_columns` with `among`) and solve that small
  set partitioning exactly (HiGHS, at most 3 s a move); take it when cheaper. Two links: `lp` — the vessels
  sharing contracts in the root LP's solution —, `arcs` — arcs of either vessel between the two sequences.
Printed: each plan's cost and its gap to the LP bound, the time used and the number of moves.

    .venv/bin/python bench/planning_plans.py [--size 50x200] [--pool-s 15] [--tree-s 30] [--lns-s 30] [--vessels 4]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from pipeline.planning.work_budget import WorkBudget  # noqa: E402


def pool_milp(data, columns, start: dict, time_limit_s: float, effort: float) -> dict:
    """HiGHS's MILP over `columns` (each vessel and contract at most once), started from the plan `start`."""
    from scipy.optimize._highspy import _core as highs

    from pipeline.planning import colgen

    c, A = colgen._master(data, columns)
    A = A.tocsc()
    m, rows = len(columns), A.shape[0]
    h = highs._Highs()
    for name, value in (("output_flag", False), ("time_limit", float(time_limit_s)),
                        ("mip_heuristic_effort", float(effort)), ("random_seed", 0)):
        h.setOptionValue(name, value)
    lp = highs.HighsLp()
    lp.num_col_, lp.num_row_ = m, rows
    lp.col_cost_, lp.col_lower_, lp.col_upper_ = c, np.zeros(m), np.ones(m)
    lp.row_lower_, lp.row_upper_ = np.full(rows, -h.getInfinity()), np.ones(rows)
    lp.a_matrix_.format_ = highs.MatrixFormat.kColwise
    lp.a_matrix_.start_, lp.a_matrix_.index_, lp.a_matrix_.value_ = A.indptr, A.indices, A.data
    lp.integrality_ = [highs.HighsVarType.kInteger] * m
    h.passModel(lp)
    sol = highs.HighsSolution()
    sol.col_value = [1.0 if start.get(col.k) == col.sequence else 0.0 for col in columns]
    sol.value_valid = True
    h.setSolution(sol)
    h.run()
    x = np.asarray(h.getSolution().col_value)
    return {columns[i].k: columns[i].sequence for i in np.flatnonzero(x > 0.5)} if x.size else start


def neighbourhoods(data, sequences: dict, link: np.ndarray, time_limit_s: float, max_vessels: int, seed: int = 0):
    """(the plan after the large-neighbourhood moves, moves made)."""
    from pipeline.planning import milp
    from pipeline.planning.problem import schedule
    from pipeline.planning.routes import Column, vessel_columns

    deadline = time.perf_counter() + time_limit_s
    rng = np.random.default_rng(seed)
    V, pen = len(data.vessels), [ct.penalty for ct in data.contracts]
    can = [frozenset(va.contracts) for va in data.per_vessel]
    seqs, moves = dict(sequences), 0
    while time.perf_counter() < deadline:
        moves += 1
        k0 = int(rng.integers(V))
        related = link(seqs, k0) + rng.uniform(0.0, 0.5, V)
        related[k0] = -np.inf
        chosen = [k0] + [int(k) for k in np.argsort(-related, kind="stable")[:int(rng.integers(1, max_vessels))]]
        lifted = {j for k in chosen for j in seqs.get(k, ())}
        owned = {j for s in seqs.values() for j in s}
        free = frozenset(lifted | {j for k in chosen for j in can[k] if j not in owned})
        columns = [Column(k, seqs[k], schedule(data, k, seqs[k]).cost) for k in chosen if k in seqs]
        before = sum(col.cost for col in columns) + sum(pen[j] for j in free - lifted)
        for k in chosen:
            columns += vessel_columns(data, k, max_labels=20_000, among=free,
                                    budget=WorkBudget(wall_limit_s=max(1e-3, deadline - time.perf_counter())))[0]
        got, _, _ = milp._set_partitioning(
            data, columns, WorkBudget(wall_limit_s=min(3.0, max(0.01, deadline - time.perf_counter()))), 0.0, 1.0)
        if got is None:
            continue
        lifted_after = {j for s in got.values() for j in s}
        after = sum(schedule(data, k, s).cost for k, s in got.items()) + sum(pen[j] for j in free - lifted_after)
        if after < before - 1e-6:
            seqs = {k: s for k, s in seqs.items() if k not in chosen} | got
    return seqs, moves


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="50x200", help="vessels x contracts (default 50x200)")
    ap.add_argument("--pool-s", type=float, default=15.0, help="seconds per price-and-branch run (default 15)")
    ap.add_argument("--shares", default="0.3,1.0", help="reduced-cost limits as shares of the gap (default 0.3,1.0)")
    ap.add_argument("--tree-s", type=float, default=30.0, help="seconds of branch-and-price before the last "
                    "price-and-branch run (default 30; 0: none)")
    ap.add_argument("--lns-s", type=float, default=30.0, help="seconds per large-neighbourhood run (default 30)")
    ap.add_argument("--vessels", type=int, default=4, help="at most this many vessels freed a move (default 4)")
    a = ap.parse_args()

    from pipeline.planning import branch_price, colgen, local_search
    from pipeline.planning.master_lp import MasterLP
    from pipeline.planning.problem import assemble, schedule
    from pipeline.planning.routes import Column
    from planning_instances import planning_data

    data = planning_data(a.size)

    def cost(sequences) -> float:
        return assemble(data, sequences, solver="t", status="", gap=np.nan, runtime_s=0.0).cost

    master = MasterLP(data)
    lp, converged = branch_price.solve_root(data, master, WorkBudget(wall_limit_s=300))
    _, pi, mu, y = master.solve()
    x = master.lifted_by(y)
    plan = local_search.improve(data, branch_price.dive(data, master, (), WorkBudget(wall_limit_s=60)), budget=WorkBudget(wall_limit_s=6.0))
    first = cost(plan)
    print(f"{a.size}: LP bound {lp:,.0f} (converged {converged}), first plan {first:,.0f} "
          f"({100 * (first - lp) / first:.2f} % above), {len(master.columns)} columns", flush=True)

    def report(what: str, sequences, seconds: float, extra: str = "") -> None:
        got = cost(sequences)
        print(f"  {what:40} {got:13,.0f}  {100 * (got - lp) / got:5.2f} % above LP  {100 * (first - got) / first:5.2f} % "
              f"better  {seconds:5.1f} s{extra}", flush=True)

    rc = colgen.reduced_costs(data, master.columns, pi, mu)
    own = [Column(k, s, schedule(data, k, s).cost) for k, s in plan.items() if (k, s) not in master.have]
    for share in (float(s) for s in a.shares.split(",")):
        pool = [col for col, r in zip(master.columns, rc) if r <= share * (first - lp)] + own
        for effort in (0.05, 0.5):
            t0 = time.perf_counter()
            got = pool_milp(data, pool, plan, a.pool_s, effort)
            report(f"price-and-branch ≤ {share:g} gap, {len(pool)} cols, effort {effort:g}", got, time.perf_counter() - t0)

    if a.tree_s > 0:
        tree = branch_price.search(data, master, assemble(data, plan, solver="t", status="", gap=np.nan, runtime_s=0.0),
                                   WorkBudget(wall_limit_s=a.tree_s), root_bound=lp)
        best = {s.k: s.sequence for s in tree.plan.schedules}
        report(f"branch-and-price, {tree.nodes} nodes", best, a.tree_s, f"  bound {tree.bound:,.0f}")
        pool = list(master.columns) + [Column(k, s, schedule(data, k, s).cost) for k, s in best.items()
                                       if (k, s) not in master.have]
        t0 = time.perf_counter()
        got = pool_milp(data, pool, best, a.pool_s, 0.5)
        report(f"then price-and-branch, {len(pool)} cols, effort 0.5", got, time.perf_counter() - t0)

    def lp_link(seqs, k0):
        return x @ x[k0]

    def arc_link(seqs, k0):
        arcs0, mine = data.per_vessel[k0].arcs, seqs.get(k0, ())
        return np.array([sum(((i, j) in arcs0) + ((j, i) in arcs0) + ((i, j) in data.per_vessel[k].arcs)
                             + ((j, i) in data.per_vessel[k].arcs) for i in mine for j in seqs.get(k, ()))
                         for k in range(len(data.vessels))], float)

    for name, link in (("lp", lp_link), ("arcs", arc_link)):
        t0 = time.perf_counter()
        got, moves = neighbourhoods(data, plan, link, a.lns_s, a.vessels)
        report(f"neighbourhoods ≤ {a.vessels} vessels, link {name}", got, time.perf_counter() - t0, f"  {moves} moves")


if __name__ == "__main__":
    main()
