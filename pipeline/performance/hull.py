"""Hull and propeller performance in the spirit of ISO 19030: speed loss against a clean hull, month by month.

For every noon report of a vessel, the reference is its active model with a clean hull (months since dry
dock 0) in the report's own conditions (rpm, draft, trim, wind and waves): the speed loss is
100 · (1 − measured STW / reference STW) %. Weather is thereby corrected by the model, and what remains is
fouling (and the noise of the log). The month's loss is the median over its reports (a few bad reports do not
move it); a month whose loss is above
the threshold is flagged. The trend (% per month) is the least-squares slope over the monthly means (the
`hull_performance` view computes it from the stored months).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd

from pipeline.performance.model import PerformanceModel

DEFAULT_FLAG_PCT = 5.0  # speed loss flagged above this (ISO 19030 leaves the threshold to the operator)


def monthly_speed_loss(model: PerformanceModel, reports: pd.DataFrame, flag_pct: float = DEFAULT_FLAG_PCT) -> pd.DataFrame:
    """Per calendar month of `reports` (noon-report columns, naive UTC `ts_utc`): n_reports, speed_loss_pct (the
    median over the month's reports with a positive reference speed) and flag (loss above `flag_pct`)."""
    cols = ["month", "n_reports", "speed_loss_pct", "flag"]
    if reports.empty:
        return pd.DataFrame(columns=cols)
    clean = dataclasses.replace(model, months_dd=0.0)
    f = lambda c, d=0.0: pd.to_numeric(reports[c], errors="coerce").fillna(d).to_numpy(float)  # noqa: E731
    ref = clean.stw_kn(f("rpm"), f("draft_m"), f("trim_m"), f("wind_kn"), f("wind_dir_rel_deg"), f("wave_m"),
                       f("wave_dir_rel_deg"))
    stw = pd.to_numeric(reports["stw_kn"], errors="coerce").to_numpy(float)
    ok = (ref > 0.5) & np.isfinite(stw) & np.isfinite(ref)
    loss = pd.Series(100.0 * (1.0 - stw[ok] / ref[ok]))
    month = pd.to_datetime(reports["ts_utc"].to_numpy()[ok]).to_period("M").to_timestamp()
    out = loss.groupby(month).agg(["size", "median"]).reset_index()
    out.columns = ["month", "n_reports", "speed_loss_pct"]
    out["flag"] = out["speed_loss_pct"] > flag_pct
    return out[cols]


def trend_pct_per_month(monthly: pd.DataFrame) -> float:
    """Least-squares slope of the monthly speed loss (% per month); NaN with fewer than two months."""
    if len(monthly) < 2:
        return float("nan")
    t = pd.to_datetime(monthly["month"])
    x = (t.dt.year * 12 + t.dt.month).to_numpy(float)
    return float(np.polyfit(x, monthly["speed_loss_pct"].to_numpy(float), 1)[0])
