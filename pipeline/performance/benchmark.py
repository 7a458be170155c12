"""Held-out scores of every form against a known truth (see `pipeline.synthetic.truth`).

Each form is fitted to the reports as a refit would (older rows train, newest held out; accepted
or not), then set against reports of later days that were never part of the fit: speed RMSE
against the observed speed beside the noise floor (the truth's own RMSE against the
observations: no model can do better on average), and fuel MAPE against the true fuel rate.
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd

from pipeline.performance import features
from pipeline.performance.model import PerformanceModel
from pipeline.performance.refit import FORMS, Gate, refit_vessel

OPEN_GATE = Gate(min_r2=-np.inf, max_speed_rmse_share=np.inf, max_fuel_rmse_share=np.inf, min_rows_per_coef=0, mlp_min_rows=0)


def score_forms(fitted: pd.DataFrame, later: pd.DataFrame, truth_later: pd.DataFrame, forms=FORMS) -> pd.DataFrame:
    """One row per form: speed RMSE on `later` (kn) and the noise floor, their ratio, fuel MAPE (%) against the truth."""
    imo = int(fitted["imo"].iloc[0])
    out = []
    floor = float(np.sqrt(np.mean((later["stw_kn"].to_numpy() - truth_later["stw_kn"].to_numpy()) ** 2)))
    args = [later[c].to_numpy(float) for c in ("rpm", "draft_m", "trim_m", "wind_kn", "wind_dir_rel_deg", "wave_m", "wave_dir_rel_deg")]
    for form in forms:
        rows, _ = refit_vessel(imo, fitted, None, 1, form=form, gate=OPEN_GATE)
        coef = {r["target"]: np.array(list(json.loads(r["coefficients"]).values())) for r in rows}
        months = float(later["months_since_drydock"].iloc[0])
        m = PerformanceModel(form, coef["speed"], coef["fuel"], months_dd=months)
        stw, fuel = _predict(m, args, later["months_since_drydock"].to_numpy(float))
        rmse = float(np.sqrt(np.mean((stw - later["stw_kn"].to_numpy()) ** 2)))
        mape = float(100 * np.mean(np.abs(fuel / truth_later["fuel_tph"].to_numpy() - 1)))
        out.append({"form": form, "speed_rmse_kn": rmse, "noise_floor_kn": floor, "speed_vs_floor": rmse / floor, "fuel_mape_pct": mape})
    return pd.DataFrame(out)


def _predict(m: PerformanceModel, args, months) -> tuple[np.ndarray, np.ndarray]:
    """Speed and fuel at each row with that row's months since dry dock (the model's own is the refit's last)."""
    return (features.predict(m.form_id, "speed", m.speed_coef, *args, months),
            features.predict(m.form_id, "fuel", m.fuel_coef, *args, months))


def model_of_rows(rows: list[dict]) -> PerformanceModel:
    """The model of a refit's perf_models rows (the speed and fuel rows of one version), envelope included."""
    coef = {r["target"]: np.array(list(json.loads(r["coefficients"]).values())) for r in rows}
    r = rows[0]
    return PerformanceModel(r["form"], coef["speed"], coef["fuel"], months_dd=r["months_dd"], imo=r["imo"],
                            version=r["version"], envelope=json.loads(r["envelope"]) if r.get("envelope") else None)
