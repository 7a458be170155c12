"""Least-squares fits of the speed and fuel models, with diagnostics and the activation rule.

Regressors come from `features.design_matrix` (one definition shared with routing). Columns
are scaled to unit RMS before solving the normal equations, so rpm³ and wind² terms do not
ruin the conditioning; k-fold cross-validation reuses per-fold XᵀX blocks instead of refitting
from the rows, which keeps a refit of a whole fleet close to one pass over the data.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from pipeline.performance import features

K_FOLDS = 5
MIN_ROWS_PER_COEF = 5
NOT_WORSE_TOLERANCE = 1.02  # a new model may be at most 2 % worse on held-out rows


@dataclass
class FitResult:
    form: str
    target: str  # speed | fuel
    names: tuple[str, ...]
    coef: np.ndarray  # full length (dropped regressors have 0)
    n: int
    r2: float
    rmse: float
    cv_rmse: float
    dropped: list[str] = field(default_factory=list)
    robust: bool = False

    def predict(self, X: np.ndarray) -> np.ndarray:
        return X @ self.coef

    def coefficients(self) -> dict[str, float]:
        return {k: float(v) for k, v in zip(self.names, self.coef)}


def inputs_from_reports(df: pd.DataFrame) -> dict[str, np.ndarray]:
    """Model inputs (features order) and targets from validated noon reports."""
    return {
        "rpm": df["rpm"].to_numpy(float), "draft_m": df["draft_m"].to_numpy(float), "trim_m": df["trim_m"].to_numpy(float),
        "wind_kn": df["wind_kn"].to_numpy(float), "wind_rel_deg": df["wind_dir_rel_deg"].to_numpy(float),
        "hs_m": df["wave_m"].to_numpy(float), "wave_rel_deg": df["wave_dir_rel_deg"].to_numpy(float),
        "months_dd": df["months_since_drydock"].to_numpy(float),
        "stw_kn": df["stw_kn"].to_numpy(float), "fuel_tph": (df["fuel_t"] / df["hours"]).to_numpy(float),
    }


def design(form: str, target: str, inp: dict[str, np.ndarray]) -> np.ndarray:
    return features.design_matrix(features.FORM_IDS[form], target, inp["rpm"], inp["draft_m"], inp["trim_m"], inp["wind_kn"],
                                  inp["wind_rel_deg"], inp["hs_m"], inp["wave_rel_deg"], inp["months_dd"])


def _solve(XtX: np.ndarray, Xty: np.ndarray) -> np.ndarray:
    """Solve (a stack of) normal equations; falls back to least squares when singular."""
    try:
        return np.linalg.solve(XtX, Xty[..., None])[..., 0]
    except np.linalg.LinAlgError:
        if XtX.ndim == 2:
            return np.linalg.lstsq(XtX, Xty, rcond=None)[0]
        return np.stack([np.linalg.lstsq(a, b, rcond=None)[0] for a, b in zip(XtX, Xty)])


def _huber_weights(resid: np.ndarray, k: float = 1.345) -> np.ndarray:
    s = 1.4826 * np.median(np.abs(resid - np.median(resid))) or 1e-9
    u = np.abs(resid) / (k * s)
    return np.where(u <= 1.0, 1.0, 1.0 / u)


def fit_target(form: str, target: str, X: np.ndarray, y: np.ndarray, *, robust: bool = False, k_folds: int = K_FOLDS) -> FitResult:
    """Least squares of y on X (regressor names from `features`); constant/all-zero regressors are dropped.

    A constant column is kept only where it is the model's intercept ("1").
    """
    fid = features.FORM_IDS[form]
    names = (features.SPEED_REGRESSORS if target == "speed" else features.FUEL_REGRESSORS)[fid]
    n, k = X.shape
    ok = np.isfinite(X).all(axis=1) & np.isfinite(y)
    X, y = X[ok], y[ok]
    n = y.size
    spread = X.max(axis=0) - X.min(axis=0) if n else np.zeros(k)
    keep = np.array([(names[j] == "1" and np.any(X[:, j] != 0)) or (spread[j] > 1e-12) for j in range(k)])
    dropped = [names[j] for j in range(k) if not keep[j]]
    coef = np.zeros(k)
    if n == 0 or keep.sum() == 0:
        return FitResult(form, target, names, coef, n, float("nan"), float("nan"), float("nan"), dropped, robust)
    Xk = X[:, keep]
    scale = np.sqrt((Xk**2).mean(axis=0))
    scale[scale == 0] = 1.0
    Z = Xk / scale
    w = np.ones(n)
    for _ in range(8 if robust else 1):
        Zw = Z * w[:, None]
        beta = _solve(Zw.T @ Z, Zw.T @ y)
        if robust:
            w = _huber_weights(y - Z @ beta)
    resid = y - Z @ beta
    rmse = float(np.sqrt(np.mean(resid**2)))
    sst = float(np.sum((y - y.mean()) ** 2))
    r2 = 1.0 - float(np.sum(resid**2)) / sst if sst > 0 else float("nan")
    cv = _cv_rmse(Z, y, w, k_folds)
    coef[keep] = beta / scale
    return FitResult(form, target, names, coef, n, r2, rmse, cv, dropped, robust)


def _cv_rmse(Z: np.ndarray, y: np.ndarray, w: np.ndarray, k_folds: int) -> float:
    n, k = Z.shape
    if n < 2 * k or k_folds < 2:
        return float("nan")
    fold = np.arange(n) % k_folds
    Zw = Z * w[:, None]
    XtX = np.stack([Zw[fold == f].T @ Z[fold == f] for f in range(k_folds)])
    Xty = np.stack([Zw[fold == f].T @ y[fold == f] for f in range(k_folds)])
    betas = _solve(XtX.sum(0)[None] - XtX, Xty.sum(0)[None] - Xty)
    pred = np.einsum("nk,nk->n", Z, betas[fold])
    return float(np.sqrt(np.mean((y - pred) ** 2)))


@dataclass(frozen=True)
class Decision:
    activate: bool
    reason: str


def decide(new: FitResult, old_rmse_on_holdout: float | None, new_rmse_on_holdout: float | None) -> Decision:
    """Activate only with enough rows and when not worse than the active model on held-out rows."""
    n_coef = len(new.names) - len(new.dropped)
    if new.n < MIN_ROWS_PER_COEF * max(n_coef, 1):
        return Decision(False, f"under-determined: {new.n} rows for {n_coef} coefficients (need ≥ {MIN_ROWS_PER_COEF * n_coef})")
    if not np.isfinite(new.rmse):
        return Decision(False, "fit failed (no usable rows)")
    if old_rmse_on_holdout is None or not np.isfinite(old_rmse_on_holdout):
        return Decision(True, "first model")
    if new_rmse_on_holdout is not None and new_rmse_on_holdout > NOT_WORSE_TOLERANCE * old_rmse_on_holdout:
        return Decision(False, f"worse on held-out rows: RMSE {new_rmse_on_holdout:.3f} vs active {old_rmse_on_holdout:.3f}")
    return Decision(True, f"held-out RMSE {new_rmse_on_holdout:.3f} vs active {old_rmse_on_holdout:.3f}")


def holdout_split(n: int, frac: float = 0.2) -> tuple[np.ndarray, np.ndarray]:
    """Train on the older rows, hold out the newest `frac` (rows must be time-ordered)."""
    cut = int(round(n * (1.0 - frac)))
    idx = np.arange(n)
    return idx[:cut], idx[cut:]
