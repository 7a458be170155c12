"""Refit benchmark: 1,000 vessels × 1 year of daily noon reports read from a real DuckDB file.

refit path   what the `refit-performance` flow does between opening the warehouse and saving
             the fits (its `load-reports` and `fit-vessels` tasks, without the Prefect engine):
             read the reports, active models, next versions and stored fits from DuckDB, fit the
             speed and fuel models of every vessel on its older reports (robust fit, cross-
             validation), score them on the newest, decide (gate), and refit the accepted ones on
             all their reports.
reference    one bare `numpy.linalg.lstsq` per vessel and target over the same design matrices
             (same rows), on arrays already in memory.

Generating and importing the demo fleet is set-up and is not timed. Each figure is the best of
a few runs, in CPU time of this process (`time.process_time`: a busy neighbour inflates it far less
than wall time). Target: refit path with the default form ≤ 3 × reference. Prints the figures; always exits 0.

    .venv/bin/python bench/refit.py [--vessels 1000] [--days 365] [--repeat 5] [--form physical,best]

Each form in `--form` is timed in the same run, interleaved with the reference. `physical` is the refit's
default; `best` (opt-in) considers every form, checks each candidate's physical sanity and trains the network
where the physical form leaves structure it could learn (see `screen`); the reference stays the
bare lstsq of the physical form.
"""

from __future__ import annotations

import argparse
from collections import Counter
import json
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from flows.jobs.refit import fit_vessels, load_reports, read_table  # noqa: E402
from pipeline.performance import features  # noqa: E402
from pipeline.performance.refit import Gate  # noqa: E402
from pipeline.performance.validate import validate_noon  # noqa: E402
from pipeline.synthetic.fleet import generate_fleet, write_fleet  # noqa: E402
from storage import fleet_store  # noqa: E402

TARGET_RATIO = 3.0
FORM = "physical"  # the form whose rpm terms are checked against the truth
FORMS = "physical,best"


def build_warehouse(out: Path, n_vessels: int, days: int) -> tuple[Path, dict]:
    """Demo fleet → CSV → validation → DuckDB, as `jitroute import-noon` does it."""
    fleet = generate_fleet("2020-12-01T00", n_vessels=n_vessels, days=days, seed=7)
    paths = write_fleet(fleet, out)
    db = out / "warehouse.duckdb"
    fleet_store.import_vessels(db, fleet.vessels)
    good, bad = validate_noon(read_table(Path(paths["noon_reports"])), fleet_store.known_imos(db), source="noon_reports.csv")
    counts = fleet_store.import_noon(db, good, bad)
    return db, {"truth": fleet.true_models, **counts}


def refit_path(db: Path, form: str = FORM) -> tuple[float, float, list[dict], list[dict], int]:
    """(load seconds, fit seconds, perf_models rows, summaries, reports) of one refit of every vessel."""
    t0 = time.process_time()
    reports, active, versions, fitted = load_reports(db, None)  # reports, active models, next versions, stored fits
    t1 = time.process_time()
    rows, summaries = fit_vessels(reports, active, versions, form, None, Gate(), fitted)
    t2 = time.process_time()
    return t1 - t0, t2 - t1, rows, summaries, len(reports["imo"])


def reference_inputs(db: Path) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per vessel and target: (design matrix, target) over the rows the fit uses (finite ones)."""
    reports = fleet_store.load_reports(db)
    out = []
    for _, g in reports.groupby("imo", sort=True):
        cols = [g[c].to_numpy(float) for c in ("rpm", "draft_m", "trim_m", "wind_kn", "wind_dir_rel_deg", "wave_m",
                                              "wave_dir_rel_deg", "months_since_drydock")]
        targets = {"speed": g["stw_kn"].to_numpy(float), "fuel": (g["fuel_t"] / g["hours"]).to_numpy(float)}
        for target, y in targets.items():
            X = features.design_matrix(features.FORM_IDS[FORM], target, *cols)
            ok = np.isfinite(X).all(axis=1) & np.isfinite(y)
            out.append((np.ascontiguousarray(X[ok]), np.ascontiguousarray(y[ok])))
    return out


def reference(mats) -> float:
    t0 = time.process_time()
    for X, y in mats:
        np.linalg.lstsq(X, y, rcond=None)
    return time.process_time() - t0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vessels", type=int, default=1000)
    ap.add_argument("--days", type=int, default=365)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--form", default=FORMS, help="forms the refit path fits, comma-separated, each timed (default physical,best)")
    a = ap.parse_args()
    forms = [f.strip() for f in a.form.split(",") if f.strip()]
    out_root = ROOT / "bench" / "out"
    out_root.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="refit-", dir=out_root) as tmp:
        t = time.perf_counter()
        db, info = build_warehouse(Path(tmp), a.vessels, a.days)
        setup_s = time.perf_counter() - t
        mats = reference_inputs(db)
        for f in forms:
            refit_path(db, f)  # warm-up: numba caches, DuckDB and page cache
        reference(mats)
        runs = {f: [] for f in forms}
        refs = []
        for _ in range(a.repeat):  # interleaved, so a busy neighbour slows every side alike
            for f in forms:
                runs[f].append(refit_path(db, f))
            refs.append(reference(mats))
        db_mb = db.stat().st_size / 1e6
    ref_s = min(refs)
    n_ref_rows = sum(len(y) for _, y in mats) // 2
    n_reports = runs[forms[0]][0][4]
    print(f"refit bench: {a.vessels} vessels, {n_reports:,} noon reports ({a.days} days each), "
          f"DuckDB file {db_mb:.1f} MB; set-up (generate + validate + import) {setup_s:.1f} s; best of {a.repeat}, CPU seconds")
    print(f"{'':48s}{'seconds':>9s}{'rows/s':>13s}")
    print(f"{'reference (numpy lstsq, arrays in memory)':48s}{ref_s:9.3f}{n_ref_rows / ref_s:13,.0f}")
    for f in forms:
        totals = [r[0] + r[1] for r in runs[f]]
        i = int(np.argmin(totals))
        load_s, fit_s, rows, summaries, _ = runs[f][i]
        path_s = totals[i]
        ratio = path_s / ref_s
        activated = sum(bool(s["changed"]) for s in summaries)
        err = []  # the fits must be right, not only fast: the rpm terms of the known true models are recovered
        for r in rows:
            if r["form"] != FORM:
                continue
            truth = info["truth"][r["imo"]]
            coef = list(json.loads(r["coefficients"]).values())
            true = truth.speed_coef[1] if r["target"] == "speed" else truth.fuel_coef[1]
            err.append(abs(coef[1] / true - 1.0))
        nets = sum(bool(s.get("network")) for s in summaries)
        print(f"form {f}: forms stored {dict(Counter(r['form'] for r in rows if r['target'] == 'speed'))}; "
              f"network trained for {nets} vessels; models activated {activated}/{len(summaries)}")
        print(f"{'  refit path (DuckDB load + fit every vessel)':48s}{path_s:9.3f}{n_reports / path_s:13,.0f}")
        print(f"{'    of which: load reports from DuckDB':48s}{load_s:9.3f}")
        print(f"{'    of which: fit, validate, gate, refit on all':48s}{fit_s:9.3f}")
        if err:
            print(f"  rpm-term error vs true models: median {100 * np.median(err):.2f} %, max {100 * np.max(err):.2f} %")
        print(f"  ratio refit path / reference, form {f}: {ratio:.2f}× (target ≤ {TARGET_RATIO:g}× for the default form): "
              f"{'met' if ratio <= TARGET_RATIO else 'NOT met'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
