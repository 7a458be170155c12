"""Least-squares fits of the speed and fuel models, with diagnostics and the activation rule.

Regressors come from `features.design_matrix` (one definition shared with routing). Columns
are scaled to unit RMS before solving the normal equations, so rpm³ and wind² terms do not
ruin the conditioning; k-fold cross-validation reuses per-fold XᵀX blocks instead of refitting
from the rows, which keeps a refit of a whole fleet close to one pass over the data.

A fleet is fitted in one go (`fit_targets`): vessels of similar report counts are padded into
one (vessel × regressor × row) stack and every step — normal equations, Huber re-weighting,
cross-validation folds — is one compiled loop or batched solve for all of them. Padding rows
carry zero weight, and a regressor dropped for one vessel becomes an identity row/column in
its normal equations, so each vessel gets the coefficients it would get alone (up to
rounding). `fit_target` is the same code with one group.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numba
import numpy as np
import pandas as pd

from pipeline.performance import features

K_FOLDS = 5
MIN_ROWS_PER_COEF = 5
NOT_WORSE_TOLERANCE = 1.02  # a new model may be at most 2 % worse on held-out rows
ROBUST_ITERATIONS = 8  # at most this many iteratively re-weighted least-squares solves with Huber weights
ROBUST_RTOL = 1e-5  # ... stopping once no coefficient moves by more than this (relative to the largest)
HUBER_K = 1.345
PAD_WASTE = 1.25  # groups padded together differ in row count by at most this factor
STACK_ROWS = 1 << 19  # padded rows per batched stack (bounds memory for very large fleets)


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


INPUT_COLUMNS = ("rpm", "draft_m", "trim_m", "wind_kn", "wind_dir_rel_deg", "wave_m", "wave_dir_rel_deg",
                 "months_since_drydock", "stw_kn", "fuel_t", "hours")  # noon-report columns a fit reads


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
    """Solve a stack of normal equations; a singular one falls back to least squares (the others are unaffected)."""
    try:
        return np.linalg.solve(XtX, Xty[..., None])[..., 0]
    except np.linalg.LinAlgError:
        A = XtX.reshape(-1, *XtX.shape[-2:])
        b = Xty.reshape(-1, Xty.shape[-1])
        out = np.empty_like(b)
        for i in range(len(A)):
            try:
                out[i] = np.linalg.solve(A[i], b[i])
            except np.linalg.LinAlgError:
                out[i] = np.linalg.lstsq(A[i], b[i], rcond=None)[0]
        return out.reshape(Xty.shape)


def fit_target(form: str, target: str, X: np.ndarray, y: np.ndarray, *, robust: bool = False, k_folds: int = K_FOLDS) -> FitResult:
    """Least squares of y on X (regressor names from `features`); constant/all-zero regressors are dropped.

    A constant column is kept only where it is the model's intercept ("1"). With `robust`, Huber
    weights (scale 1.4826·MAD) are re-estimated until the coefficients settle (ROBUST_RTOL), at most
    ROBUST_ITERATIONS solves.
    """
    return fit_targets(form, target, X, y, np.array([0, len(y)]), robust=robust, k_folds=k_folds)[0]


def fit_targets(form: str, target: str, X: np.ndarray, y: np.ndarray, bounds: np.ndarray, *, robust: bool = False,
                k_folds: int = K_FOLDS) -> list[FitResult]:
    """`fit_target` for many groups (vessels) at once; group g is rows bounds[g]:bounds[g+1] of X and y.

    Rows with a non-finite regressor or target are left out (per group, order kept).
    """
    fid = features.FORM_IDS[form]
    names = (features.SPEED_REGRESSORS if target == "speed" else features.FUEL_REGRESSORS)[fid]
    X = np.ascontiguousarray(X, dtype=np.float64)
    y = np.ascontiguousarray(y, dtype=np.float64)
    bounds = np.asarray(bounds, dtype=np.int64)
    ok = np.isfinite(X).all(axis=1) & np.isfinite(y)
    if not ok.all():
        kept_before = np.concatenate([[0], np.cumsum(ok)])
        X, y, bounds = X[ok], y[ok], kept_before[bounds]
    n = np.diff(bounds)
    out: list[FitResult | None] = [None] * n.size
    for groups in _stacks(n):
        for g, res in zip(groups, _fit_stack(form, target, names, X, y, bounds[groups], n[groups], robust, k_folds)):
            out[g] = res
    return out


def _stacks(n: np.ndarray) -> list[np.ndarray]:
    """Group indices in batches of similar row count (padding ≤ PAD_WASTE) and bounded size."""
    order = np.argsort(n, kind="stable")
    size_class = np.floor(np.log(np.maximum(n[order], 1)) / np.log(PAD_WASTE)).astype(np.int64)
    batches = []
    for part in np.split(order, np.flatnonzero(np.diff(size_class)) + 1):
        per = max(1, STACK_ROWS // max(int(n[part].max()), 1))
        batches += [part[i:i + per] for i in range(0, part.size, per)]
    return batches


def _fit_stack(form, target, names, X, y, starts, n, robust, k_folds) -> list[FitResult]:
    """Fit groups of similar size together.

    Arrays are (group, regressor, slot). A group's rows are laid out fold by fold (row p goes to
    CV fold p mod F), so every fold is one contiguous slot range; slots beyond a group's rows
    are padding with weight 0 and residual +inf (sorted last by the medians).
    """
    G, k = n.size, X.shape[1]
    rows = max(int(n.max()), 1)
    F = max(int(k_folds), 1)
    row_of_slot = np.concatenate([np.arange(f, rows, F) for f in range(F)])
    slot_of_row = np.empty(rows, np.int64)
    slot_of_row[row_of_slot] = np.arange(rows)
    fold_start = np.cumsum([0] + [(rows - f + F - 1) // F for f in range(F)])[:-1]
    lo = np.repeat(fold_start[None, :], G, axis=0)
    hi = lo + np.maximum((n[:, None] - np.arange(F) + F - 1) // F, 0)
    valid = row_of_slot[None, :] < n[:, None]
    nf = np.maximum(n, 1).astype(np.float64)

    ZY = np.zeros((G, k + 1, rows))  # scaled regressors, then the target
    top, bottom, sumsq = np.zeros((G, k)), np.zeros((G, k)), np.zeros((G, k))
    nonzero = np.zeros((G, k), dtype=np.bool_)
    _pack_nb(X, y, starts, n, slot_of_row, ZY, top, bottom, nonzero, sumsq)
    intercept = np.array([nm == "1" for nm in names])
    keep = (intercept & nonzero) | (top - bottom > 1e-12)
    n_keep = keep.sum(axis=1)
    live = (n > 0) & (n_keep > 0)
    scale = np.sqrt(sumsq / nf[:, None])
    scale[(scale == 0) | ~keep] = 1.0
    ZY[:, :k] /= scale[..., None]
    ZY[:, :k][~keep] = 0.0
    ident = np.zeros((G, k, k))
    ident[:, np.arange(k), np.arange(k)] = ~keep  # dropped regressor: β = 0 without touching the others

    w = valid.astype(np.float64)
    beta = np.zeros((G, k))
    gram = np.empty((G, F, k, k + 1))  # [ZᵀWZ | ZᵀWy] per group and fold
    resid = np.full((G, rows), np.inf)
    for it in range(ROBUST_ITERATIONS if robust else 1):
        _gram_nb(ZY, w, lo, hi, gram)
        total = gram.sum(axis=1)
        prev = beta.copy()
        beta[live] = _solve((total[..., :k] + ident)[live], total[live, :, k])
        if it and (np.abs(beta - prev).max(axis=1) <= ROBUST_RTOL * np.maximum(np.abs(beta).max(axis=1), 1e-12)).all():
            break  # converged: `w` is still the weights `beta` was solved with (the CV below reuses them)
        if robust:
            _resid_nb(ZY, np.repeat(beta[:, None], F, axis=1), lo, hi, resid)
            w = _huber_weights(resid, n)
    _resid_nb(ZY, np.repeat(beta[:, None], F, axis=1), lo, hi, resid)
    r = np.where(valid, resid, 0.0)
    ssr = (r * r).sum(axis=1)
    rmse = np.sqrt(ssr / nf)
    Y = ZY[:, k]
    dev = np.where(valid, Y - (Y.sum(axis=1) / nf)[:, None], 0.0)
    sst = (dev * dev).sum(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        r2 = np.where(sst > 0, 1.0 - ssr / sst, np.nan)

    # k-fold CV: every fold's fit is the total normal equations minus that fold's block
    cv = np.full(G, np.nan)
    ok = live & (n >= 2 * n_keep) & (k_folds >= 2)
    if ok.any():
        if robust:
            _gram_nb(ZY, w, lo, hi, gram)
        rest = (gram.sum(axis=1, keepdims=True) - gram)[ok]
        betas = np.zeros((G, F, k))
        betas[ok] = _solve(rest[..., :k] + ident[ok][:, None], rest[..., k])
        _resid_nb(ZY, betas, lo, hi, resid)
        r = np.where(valid, resid, 0.0)[ok]
        cv[ok] = np.sqrt((r * r).sum(axis=1) / n[ok])
    coef = np.where(keep, beta / scale, 0.0)

    out = []
    for g in range(G):
        dropped = [names[j] for j in range(k) if not keep[g, j]]
        if live[g]:
            out.append(FitResult(form, target, names, coef[g], int(n[g]), float(r2[g]), float(rmse[g]), float(cv[g]),
                                 dropped, robust))
        else:
            out.append(FitResult(form, target, names, np.zeros(k), int(n[g]), float("nan"), float("nan"), float("nan"),
                                 dropped, robust))
    return out


def _huber_weights(resid: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Huber weights per group (row g of `resid`: its n[g] residuals, +inf in padding → weight 0).

    Scale = 1.4826 · MAD of the group's residuals (1e-9 when the MAD is 0).
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        med = _row_medians(resid, n)
        s = 1.4826 * _row_medians(np.abs(resid - med[:, None]), n)
        s[s == 0] = 1e-9
        u = np.abs(resid) / (HUBER_K * s)[:, None]
        return np.minimum(1.0, 1.0 / u)  # 1 where u ≤ 1, else 1/u


def _row_medians(a: np.ndarray, n: np.ndarray) -> np.ndarray:
    """np.median of the n[g] finite values of row g (the rest of the row is +inf); NaN where n[g] = 0."""
    out = np.full(n.size, np.nan)
    for m in np.unique(n[n > 0]):
        rows = np.flatnonzero(n == m)
        half = int(m) // 2
        part = np.partition(a if rows.size == n.size else a[rows], half, axis=1)
        out[rows] = part[:, half] if m % 2 else (part[:, :half].max(axis=1) + part[:, half]) / 2
    return out


@numba.njit(cache=True)
def _pack_nb(X, y, starts, n, slot_of_row, ZY, top, bottom, nonzero, sumsq):
    """Copy each group's rows into its slots; per regressor: max, min, any non-zero, sum of squares."""
    k = X.shape[1]
    for g in range(n.size):
        for p in range(n[g]):
            row = starts[g] + p
            s = slot_of_row[p]
            for i in range(k):
                v = X[row, i]
                ZY[g, i, s] = v
                if p == 0 or v > top[g, i]:
                    top[g, i] = v
                if p == 0 or v < bottom[g, i]:
                    bottom[g, i] = v
                if v != 0.0:
                    nonzero[g, i] = True
                sumsq[g, i] += v * v
            ZY[g, k, s] = y[row]


@numba.njit(cache=True, fastmath={"reassoc", "contract"})  # reassociation lets the row sums vectorise
def _gram_nb(ZY, w, lo, hi, out):
    """out[g, f] = [ZᵀWZ | ZᵀWy] over slots lo[g, f]:hi[g, f] of group g."""
    k = ZY.shape[1] - 1
    for g in range(ZY.shape[0]):
        for f in range(lo.shape[1]):
            a, b = lo[g, f], hi[g, f]
            for i in range(k):
                for j in range(i, k + 1):
                    s = 0.0
                    for r in range(a, b):
                        s += w[g, r] * ZY[g, i, r] * ZY[g, j, r]
                    out[g, f, i, j] = s
                    if j < k:
                        out[g, f, j, i] = s


@numba.njit(cache=True)
def _resid_nb(ZY, beta, lo, hi, out):
    """out[g, r] = y − z·β[g, f] over slots lo[g, f]:hi[g, f]; other slots are left as they are."""
    k = ZY.shape[1] - 1
    for g in range(ZY.shape[0]):
        for f in range(lo.shape[1]):
            a, b = lo[g, f], hi[g, f]
            for r in range(a, b):
                out[g, r] = ZY[g, k, r]
            for i in range(k):
                c = beta[g, f, i]
                for r in range(a, b):
                    out[g, r] -= c * ZY[g, i, r]


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
    cut = int(holdout_start(n, frac))
    idx = np.arange(n)
    return idx[:cut], idx[cut:]


def holdout_start(n, frac: float = 0.2):
    """Index of the first held-out row for (an array of) group sizes n (round half to even)."""
    return np.round(np.asarray(n) * (1.0 - frac)).astype(np.int64)
