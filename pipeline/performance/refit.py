"""Refit one vessel's speed and fuel models and decide whether the new pair replaces the active one."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd

from pipeline.performance import fit


def _rmse(coef: np.ndarray, X: np.ndarray, y: np.ndarray) -> float:
    return float(np.sqrt(np.mean((y - X @ coef) ** 2))) if y.size else float("nan")


def refit_vessel(imo: int, reports: pd.DataFrame, active: dict | None, version: int, *, form: str = "physical",
                 robust: bool = True) -> tuple[list[dict], dict]:
    """(perf_models rows for speed and fuel, summary dict) for one vessel's time-ordered reports.

    Both targets are activated together or not at all: routing needs a consistent pair. The new
    pair must not be worse than the active one on the newest 20 % of reports.
    """
    inp = fit.inputs_from_reports(reports)
    n = len(reports)
    months = float(reports["months_since_drydock"].iloc[-1]) if n else 0.0
    rows, decisions, results, unchanged = [], [], {}, []
    _, hold = fit.holdout_split(n)
    for target, y in (("speed", inp["stw_kn"]), ("fuel", inp["fuel_tph"])):
        X = fit.design(form, target, inp)
        res = fit.fit_target(form, target, X, y, robust=robust)
        results[target] = res
        old_hold = new_hold = None
        if active and active.get("form") == form and target in active and hold.size:
            old = np.array(list(active[target].values()))
            if old.shape == res.coef.shape and np.allclose(old, res.coef, rtol=1e-9, atol=1e-12):
                unchanged.append(target)
            new_hold = _rmse(res.coef, X[hold], y[hold])
            old_hold = _rmse(old, X[hold], y[hold])
        decisions.append(fit.decide(res, old_hold, new_hold))
    activate = all(d.activate for d in decisions)
    if len(unchanged) == 2:  # same data, same fit: nothing new to store
        return [], {"imo": int(imo), "n": n, "speed_r2": results["speed"].r2, "speed_rmse": results["speed"].rmse,
                    "speed_cv_rmse": results["speed"].cv_rmse, "fuel_r2": results["fuel"].r2, "fuel_rmse": results["fuel"].rmse,
                    "fuel_cv_rmse": results["fuel"].cv_rmse, "changed": False, "reason": "same as the active model",
                    "why": "same as the active model", "version": active.get("version")}
    reason = "; ".join(f"{t}: {d.reason}" for t, d in zip(("speed", "fuel"), decisions))
    dropped = sorted({c for r in results.values() for c in r.dropped})
    if dropped:
        reason += f"; dropped constant regressors: {', '.join(dropped)}"
    for target, res in results.items():
        rows.append({"imo": int(imo), "version": version, "form": form, "target": target,
                     "coefficients": json.dumps(res.coefficients()), "n_rows": res.n, "r2": res.r2, "rmse": res.rmse,
                     "cv_rmse": res.cv_rmse, "status": "active" if activate else "rejected", "reason": reason,
                     "active": activate, "months_dd": months})
    summary = {"imo": int(imo), "n": n, "speed_r2": results["speed"].r2, "speed_rmse": results["speed"].rmse,
               "speed_cv_rmse": results["speed"].cv_rmse, "fuel_r2": results["fuel"].r2, "fuel_rmse": results["fuel"].rmse,
               "fuel_cv_rmse": results["fuel"].cv_rmse, "changed": activate, "reason": reason, "version": version,
               "why": next((d.reason for d in decisions if not d.activate), decisions[0].reason)}
    return rows, summary
