"""Model benchmark: held-out accuracy of every performance-model form against a truth outside all of them.

Vessels from `pipeline.synthetic.truth` (quadratic weather losses with their own direction shape, 5 %
noise, 2 % outliers): each form is fitted to a year of daily reports and scored on the following days,
which were never part of the fit — speed RMSE beside the noise floor, fuel MAPE against the true
rate — and the form a refit chooses (every form on the same held-out split) is named.

    .venv/bin/python bench/models.py [--vessels 4] [--days 365] [--later 60]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import pandas as pd  # noqa: E402

from pipeline.performance.benchmark import score_forms  # noqa: E402
from pipeline.performance.refit import refit_vessel  # noqa: E402
from pipeline.synthetic import truth  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vessels", type=int, default=4)
    ap.add_argument("--days", type=int, default=365)
    ap.add_argument("--later", type=int, default=60)
    a = ap.parse_args()
    tables = []
    for k in range(a.vessels):
        v = truth.TrueVessel(9140000 + k, design_speed_kn=13.0 + k, design_fuel_tph=1.2 + 0.3 * k)
        df, true = truth.reports(v, "2020-12-01", a.days + a.later, seed=k + 1)
        fitted, later = df.iloc[: a.days], df.iloc[a.days:]
        _, chosen = refit_vessel(v.imo, fitted, None, 1)
        t = score_forms(fitted, later, true.iloc[a.days:])
        t.insert(0, "imo", v.imo)
        t["chosen"] = t["form"] == chosen["form"]
        tables.append(t)
    out = pd.concat(tables, ignore_index=True)
    print(out.round(3).to_string(index=False))
    print("\nmean per form:")
    print(out.groupby("form")[["speed_vs_floor", "fuel_mape_pct"]].mean().round(3).to_string())
    ch = out[out.chosen]
    print(f"\nchosen forms: speed RMSE / noise floor ≤ {ch.speed_vs_floor.max():.3f} (target ≤ 1.10), "
          f"fuel MAPE ≤ {ch.fuel_mape_pct.max():.2f} % (target ≤ 5 %)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
