"""Refit vessels' speed and fuel models and decide whether each new pair replaces the active one.

A whole fleet is refitted in one pass (`refit_fleet`): the fits are batched across vessels
(see `fit.fit_targets`) and only the bookkeeping — decisions, rows, summaries — is per vessel.
`refit_vessel` is the same code for one vessel.
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd

from pipeline.performance import fit

TARGETS = ("speed", "fuel")
FORMS = tuple(fit.features.FORM_IDS)  # the forms a refit can fit


def check_form(form: str) -> str:
    """`form` if a refit can fit it, else ValueError naming the forms that exist."""
    if form not in FORMS:
        raise ValueError(f"unknown model form {form!r}; use one of: {', '.join(FORMS)}")
    return form
REPORT_COLUMNS = ("imo", *fit.INPUT_COLUMNS)  # what a refit reads of the noon reports


def refit_vessel(imo: int, reports: pd.DataFrame, active: dict | None, version: int, *, form: str = "physical",
                 robust: bool | None = None) -> tuple[list[dict], dict]:
    """(perf_models rows for speed and fuel, summary dict) for one vessel's time-ordered reports.

    `robust`: Huber re-weighting; None takes the form's default (`fit.robust_default`: off for the thesis form).
    Both targets are activated together or not at all: routing needs a consistent pair. The new
    pair must not be worse than the active one on the newest 20 % of reports.
    """
    imo = int(imo)
    rows, summaries = _refit(np.array([imo]), np.array([0, len(reports)]), fit.inputs_from_reports(reports),
                             {imo: active} if active else {}, {imo: version}, form, robust)
    return rows, summaries[0]


def refit_fleet(reports, active: dict[int, dict], versions: dict[int, int], *, form: str = "physical",
                robust: bool | None = None) -> tuple[list[dict], list[dict]]:
    """`refit_vessel` for every vessel in `reports` (time-ordered within each vessel), fitted together.

    `reports`: a DataFrame or a mapping of column → array (as `fleet_store.load_for_refit` gives)
    with at least `REPORT_COLUMNS`. `active`: imo → active model (as `fleet_store.active_models`
    returns); `versions`: imo → version of the new rows (1 if absent). Returns (perf_models rows,
    one summary per vessel in IMO order).
    """
    imo = np.asarray(reports["imo"], dtype=np.int64)
    if imo.size == 0:
        return [], []
    inp = fit.inputs_from_reports(reports)
    if (np.diff(imo) < 0).any():
        order = np.argsort(imo, kind="stable")  # keeps each vessel's time order
        imo, inp = imo[order], {c: v[order] for c, v in inp.items()}
    first = np.flatnonzero(np.r_[True, imo[1:] != imo[:-1]])
    return _refit(imo[first], np.r_[first, imo.size], inp, active, versions, form, robust)


def _refit(imos: np.ndarray, bounds: np.ndarray, inp: dict[str, np.ndarray], active: dict, versions: dict, form: str,
           robust: bool | None) -> tuple[list[dict], list[dict]]:
    """Vessel g is rows bounds[g]:bounds[g+1] of the model inputs `inp`."""
    check_form(form)
    robust = fit.robust_default(form) if robust is None else bool(robust)
    n = np.diff(bounds)
    y = {"speed": inp["stw_kn"], "fuel": inp["fuel_tph"]}
    X = fit.designs(form, inp)
    results = {t: fit.fit_targets(form, t, X[t], y[t], bounds, robust=robust) for t in TARGETS}
    hold_from = bounds[:-1] + fit.holdout_start(n)
    compared = {t: _compare_with_active(t, imos, bounds, hold_from, X[t], y[t], results[t], active, form) for t in TARGETS}
    coef_json = {t: _coefficients_json(results[t]) for t in TARGETS}
    rows, summaries = [], []
    for g, imo in enumerate(map(int, imos)):
        res = {t: results[t][g] for t in TARGETS}
        act = active.get(imo)
        decisions, unchanged = [], []
        for t in TARGETS:
            same, old_hold, new_hold = compared[t].get(g, (False, None, None))
            if same:
                unchanged.append(t)
            decisions.append(fit.decide(res[t], old_hold, new_hold))
        scores = {"speed_r2": res["speed"].r2, "speed_rmse": res["speed"].rmse, "speed_cv_rmse": res["speed"].cv_rmse,
                  "fuel_r2": res["fuel"].r2, "fuel_rmse": res["fuel"].rmse, "fuel_cv_rmse": res["fuel"].cv_rmse}
        if len(unchanged) == 2:  # same data, same fit: nothing new to store
            summaries.append({"imo": imo, "n": int(n[g]), **scores, "changed": False, "reason": "same as the active model",
                              "why": "same as the active model", "version": act.get("version")})
            continue
        activate = all(d.activate for d in decisions)
        version = versions.get(imo, 1)
        months = float(inp["months_dd"][bounds[g + 1] - 1]) if n[g] else 0.0
        reason = "; ".join(f"{t}: {d.reason}" for t, d in zip(TARGETS, decisions))
        dropped = sorted({c for r in res.values() for c in r.dropped})
        if dropped:
            reason += f"; left out (constant, or weather that came out as a gain): {', '.join(dropped)}"
        for t, r in res.items():
            rows.append({"imo": imo, "version": version, "form": form, "target": t,
                         "coefficients": coef_json[t][g], "n_rows": r.n, "r2": r.r2, "rmse": r.rmse,
                         "cv_rmse": r.cv_rmse, "status": "active" if activate else "rejected", "reason": reason,
                         "active": activate, "months_dd": months})
        summaries.append({"imo": imo, "n": int(n[g]), **scores, "changed": activate, "reason": reason, "version": version,
                          "why": next((d.reason for d in decisions if not d.activate), decisions[0].reason)})
    return rows, summaries


def _coefficients_json(results: list[fit.FitResult]) -> list[str]:
    """`json.dumps(r.coefficients())` of every result, formatted from one template."""
    coef = np.array([r.coef for r in results], dtype=np.float64)
    if not results or not np.isfinite(coef).all():  # json spells non-finite numbers its own way
        return [json.dumps(r.coefficients()) for r in results]
    template = "{" + ", ".join(json.dumps(name) + ": %r" for name in results[0].names) + "}"
    return [template % row for row in map(tuple, coef.tolist())]


def _compare_with_active(target: str, imos, bounds, hold_from, X, y, results, active: dict, form: str) -> dict:
    """vessel index → (new coefficients equal to the active ones, active RMSE, new RMSE on the held-out rows),
    for vessels whose active model has the same form and a `target` part of the same length."""
    groups, old = [], []
    for g, imo in enumerate(map(int, imos)):
        a = active.get(imo)
        if a and a.get("form") == form and target in a and hold_from[g] < bounds[g + 1]:
            coef = np.array(list(a[target].values()), dtype=np.float64)
            if coef.shape == results[g].coef.shape:
                groups.append(g)
                old.append(coef)
    if not groups:
        return {}
    g = np.array(groups)
    old = np.stack(old)
    new = np.stack([results[i].coef for i in groups])
    same = (np.abs(old - new) <= 1e-12 + 1e-9 * np.abs(new)).all(axis=1)  # np.allclose(old, new, rtol=1e-9, atol=1e-12)
    size = bounds[g + 1] - hold_from[g]
    which = np.repeat(np.arange(g.size), size)
    row = np.repeat(hold_from[g], size) + np.arange(which.size) - np.repeat(np.cumsum(size) - size, size)
    Xh, yh = X[row], y[row]
    rmse = {}
    for key, coef in (("old", old), ("new", new)):
        sq = (yh - np.einsum("nk,nk->n", Xh, coef[which])) ** 2
        rmse[key] = np.sqrt(np.bincount(which, weights=sq, minlength=g.size) / size)
    return {int(gi): (bool(same[j]), float(rmse["old"][j]), float(rmse["new"][j])) for j, gi in enumerate(g)}
