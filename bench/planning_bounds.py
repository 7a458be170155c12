"""Fleet planning: how far two other bounds rise above the set-partitioning LP in the planner's time (a measurement).

On the bench's random instance (`pipeline/synthetic/contracts.py`, seed 1), after the root LP by column generation
(`branch_price.solve_root`):
- **Global branching rows**: the LP re-solved to its optimum with pricing under one more row, on either side of its
  fractional value: the number of vessels used (Σ y ≤ ⌊v⌋ or ≥ ⌈v⌉; its dual adds to every vessel's μ in pricing)
  and the number of contracts lifted (Σ |sequence| y; its dual adds to every contract's prize). A branch on the row
  raises the bound by the lesser of its two sides.
- **A partial reduced-cost finish**: every column whose reduced cost at the root duals is ≤ Δ
  (`gap_columns.vessel_columns_within`), then HiGHS's MILP over them for `--milp-s`. A plan of cost ≤ LP + Δ uses
  only such columns, so min(HiGHS's dual bound over them, LP + Δ) is a proven bound on the whole problem. Δ is
  given as a share of the LP (`--shares`).

    .venv/bin/python bench/planning_bounds.py [--size 50x200] [--shares 0.1 0.2 0.35] [--milp-s 60]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np
from scipy import sparse
from scipy.optimize import linprog

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from pipeline.planning.work_budget import WorkBudget  # noqa: E402


def lp_with_row(data, columns: list, kind: str, rhs: float, at_least: bool) -> tuple[float, float]:
    """(LP optimum with the row `kind` ≤ rhs, or ≥ rhs with `at_least`, priced to its optimum; the row's value)."""
    from pipeline.planning import colgen

    n, V = len(data.contracts), len(data.vessels)
    penalty = np.array([c.penalty for c in data.contracts])
    columns = list(columns)
    have = {(c.k, c.sequence) for c in columns}
    sign = -1.0 if at_least else 1.0
    while True:
        weight = np.array([1.0 if kind == "vessels" else len(c.sequence) for c in columns])
        cost, A = colgen._master(data, columns)  # contract rows, then vessel rows
        A = sparse.vstack([A, sparse.csr_array(sign * weight[None, :])]).tocsr()
        b = np.concatenate([np.ones(n + V), [sign * rhs]])
        res = linprog(cost, A_ub=A, b_ub=b, bounds=(0, None), method="highs-ds")
        if res.status != 0:
            raise RuntimeError(res.message)
        duals = res.ineqlin.marginals
        pi, mu, lam = duals[:n], duals[n:n + V], sign * duals[n + V]
        z = float(res.fun) + penalty.sum()
        least, new = 0.0, []
        for k in range(V):
            if kind == "vessels":
                rc, found = colgen.price(data, k, pi, float(mu[k] + lam))
            else:
                rc, found = colgen.price(data, k, pi + lam, float(mu[k]))
            least += min(0.0, rc)
            new += [c for c in found if (c.k, c.sequence) not in have]
        if least > -colgen.EPS * max(1.0, abs(z)) or not new:
            return z, float(res.x @ weight)
        have.update((c.k, c.sequence) for c in new)
        columns += new


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="50x200", help="vessels x contracts (default 50x200)")
    ap.add_argument("--shares", type=float, nargs="+", default=[0.1, 0.2, 0.35], help="Δ, %% of the LP")
    ap.add_argument("--milp-s", type=float, default=60.0, help="HiGHS's time over each pool")
    ap.add_argument("--max-labels", type=int, default=2_000_000, help="partial sequences per vessel, at most")
    a = ap.parse_args()

    from pipeline.planning import branch_price, gap_columns, milp, problem
    from pipeline.planning.master_lp import MasterLP
    from planning_instances import planning_data

    data = planning_data(a.size)
    master = MasterLP(data)
    t0 = time.perf_counter()
    lp, converged = branch_price.solve_root(data, master, WorkBudget(wall_limit_s=300))
    _, pi, mu, y = master.solve()
    print(f"{a.size}: root LP {lp:,.0f} ({'converged' if converged else 'NOT converged'}, "
          f"{time.perf_counter() - t0:.1f} s, {len(master.columns)} columns)")

    def above(value: float) -> str:
        return f"{value:14,.0f} (+{100 * (value - lp) / lp:.3f} %)"

    for kind in ("vessels", "contracts"):
        weight = np.array([1.0 if kind == "vessels" else len(c.sequence) for c in master.columns])
        value = float(y @ weight)
        sides = []
        for rhs, at_least in ((math.floor(value), False), (math.ceil(value), True)):
            t1 = time.perf_counter()
            z, _ = lp_with_row(data, master.columns, kind, rhs, at_least)
            sides.append(z)
            print(f"  {kind} {'≥' if at_least else '≤'} {rhs}: LP {above(z)}  ({time.perf_counter() - t1:.1f} s)",
                  flush=True)
        print(f"  branch on {kind} used (LP {value:.2f}): bound {above(min(sides))}")

    for share in a.shares:
        slack = share / 100 * lp
        t1, pool = time.perf_counter(), []
        for k in range(len(data.vessels)):
            cols, complete = gap_columns.vessel_columns_within(data, k, pi, float(mu[k]), slack,
                                                               max_labels=a.max_labels)
            if not complete:
                print(f"  Δ {share} %: vessel {k} has more than {a.max_labels:,} partial sequences; stopped")
                break
            pool += cols
        else:
            enum_s = time.perf_counter() - t1
            t2 = time.perf_counter()
            sequences, pool_bound, finished = milp._set_partitioning(data, pool, WorkBudget(wall_limit_s=a.milp_s), 0.0, 1.0)
            plan = (problem.assemble(data, sequences, solver="milp", status="feasible", gap=np.nan, runtime_s=0.0).cost
                    if sequences is not None else np.inf)
            print(f"  Δ {share} % ({slack:,.0f}): {len(pool):,} columns in {enum_s:.1f} s; HiGHS "
                  f"{time.perf_counter() - t2:.1f} s, {'solved' if finished else 'stopped'}, its bound "
                  f"{above(pool_bound)}, plan {plan:,.0f} → proven bound {above(min(pool_bound, lp + slack))}",
                  flush=True)


if __name__ == "__main__":
    main()
