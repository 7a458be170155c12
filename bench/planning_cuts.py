"""Fleet planning: how much of the set-partitioning LP's gap cuts in the master would close (a measurement).

On the bench's random instance (`pipeline/synthetic/contracts.py`, seed 1): the root LP by column generation
(`branch_price.solve_root`), then on the columns in hand — with `--optimum C`, also every column whose reduced cost
is within C − LP (`gap_columns.vessel_columns_within`), so that every plan up to the optimum is in the pool:
- subset-row cuts on triples of contracts (Σ of the columns lifting ≥ 2 of the three ≤ 1), separated on the
  fractional LP (every triple checked, the 50 most violated added per round) until none is violated;
- HiGHS's own root cuts: its MILP over the same columns stopped after the root node (`node_limit` 1).
Both are measured on a fixed pool, without pricing under the cuts: a column left out could only lower the LP
again, so the share of the gap they close is an upper estimate of what the same cuts would close in
branch-and-price. The gap is to `--optimum` when given (the optimum), else to `--plan` (a plan's cost).

    .venv/bin/python bench/planning_cuts.py --size 20x80 --optimum 13472640
    .venv/bin/python bench/planning_cuts.py --size 50x200 --plan 28516564
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from scipy import sparse
from scipy.optimize import LinearConstraint, linprog, milp

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from pipeline.planning.work_budget import WorkBudget  # noqa: E402


def violated_triples(members: np.ndarray, y: np.ndarray, most: int = 50) -> list[tuple[int, int, int]]:
    """The `most` most violated subset-row triples of the LP solution `y` (columns × contracts `members`)."""
    on = y > 1e-6
    m, yf = members[on].astype(np.int8), y[on]
    frac = np.flatnonzero(yf @ m > 1e-6)
    found = []
    for p, a in enumerate(frac):
        for b in frac[p + 1:]:
            lhs = yf @ ((m[:, a] + m[:, b])[:, None] + m[:, frac] >= 2)
            found += [(lhs[i], (int(a), int(b), int(frac[i]))) for i in np.flatnonzero(lhs > 1 + 1e-3) if frac[i] > b]
    return [t for _, t in sorted(found, reverse=True)[:most]]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="20x80", help="vessels x contracts (default 20x80)")
    ap.add_argument("--optimum", type=float, help="the known optimum: columns within it are added to the pool")
    ap.add_argument("--plan", type=float, help="a plan's cost, to measure the gap against when no optimum is known")
    a = ap.parse_args()

    from pipeline.planning import branch_price, colgen, gap_columns
    from pipeline.planning.master_lp import MasterLP
    from planning_instances import planning_data

    data = planning_data(a.size)
    n_v, n_c = len(data.vessels), len(data.contracts)
    master = MasterLP(data)
    lp, converged = branch_price.solve_root(data, master, WorkBudget(wall_limit_s=300))
    _, pi, mu, _ = master.solve()
    pool = list(master.columns)
    top = a.optimum or a.plan
    if a.optimum:
        have = set(master.have)
        for k in range(n_v):
            cols, complete = gap_columns.vessel_columns_within(data, k, pi, float(mu[k]), a.optimum - lp + 1.0,
                                                               max_labels=5_000_000)
            assert complete, "the columns within the gap are too many to enumerate"
            pool += [c for c in cols if (c.k, c.sequence) not in have]
    const = sum(c.penalty for c in data.contracts)
    c, A = colgen._master(data, pool)
    members = A[:n_c].T.toarray() > 0

    def closed(value: float) -> str:
        return f"{value:14,.0f}  gap {100 * (top - value) / top:5.3f} %  closed {100 * (value - lp) / (top - lp):5.1f} %"

    print(f"{a.size}: root LP {closed(lp)}  ({'converged' if converged else 'NOT converged'}; "
          f"{len(master.columns)} columns priced, pool {len(pool)})")
    triples: list[tuple[int, int, int]] = []
    while True:
        rows = sparse.vstack([A] + [sparse.csr_array(members[:, list(t)].sum(1)[None, :] >= 2, dtype=float)
                                    for t in triples])
        res = linprog(c, A_ub=rows, b_ub=np.ones(rows.shape[0]), bounds=(0, None), method="highs")
        new = violated_triples(members, res.x)
        print(f"  subset-row cuts {len(triples):4}: LP {closed(res.fun + const)}  ({len(new)} more violated)", flush=True)
        if not new:
            break
        triples += new
    t0 = time.perf_counter()
    res = milp(c, integrality=np.ones(len(c)), bounds=(0, 1), constraints=LinearConstraint(A, -np.inf, 1.0),
               options={"node_limit": 1, "time_limit": 300.0})
    print(f"  HiGHS root cuts: bound {closed(res.mip_dual_bound + const)}  ({time.perf_counter() - t0:.1f} s)")


if __name__ == "__main__":
    main()
