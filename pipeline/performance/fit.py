"""Least-squares fits of the speed and fuel models, with diagnostics and the activation rule.

Regressors come from `features.design_matrix` (one definition shared with routing). Columns
are scaled to unit RMS before solving the normal equations, so rpm³ and wind² terms do not
ruin the conditioning; k-fold cross-validation reuses per-fold XᵀX blocks instead of refitting
from the rows, which keeps a refit of a whole fleet close to one pass over the data.

A fleet is fitted in one go (`fit_targets`): one compiled loop takes the vessels one after
another, copies a vessel's rows (scaled, fold by fold) into a small scratch block that stays in
cache, and runs its Huber re-weighting, statistics and cross-validation folds there. Each
vessel stops re-weighting when its own coefficients settle, and a regressor dropped for it
becomes an identity row/column in its normal equations, so each vessel gets the coefficients it
would get alone (up to rounding). `fit_target` is the same code with one group.
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


def inputs_from_reports(reports) -> dict[str, np.ndarray]:
    """Model inputs (features order) and targets from validated noon reports (a DataFrame or a mapping
    of column → array)."""
    col = {c: np.asarray(reports[c], dtype=np.float64) for c in INPUT_COLUMNS}
    return {
        "rpm": col["rpm"], "draft_m": col["draft_m"], "trim_m": col["trim_m"],
        "wind_kn": col["wind_kn"], "wind_rel_deg": col["wind_dir_rel_deg"],
        "hs_m": col["wave_m"], "wave_rel_deg": col["wave_dir_rel_deg"],
        "months_dd": col["months_since_drydock"],
        "stw_kn": col["stw_kn"], "fuel_tph": col["fuel_t"] / col["hours"],
    }


def design(form: str, target: str, inp: dict[str, np.ndarray]) -> np.ndarray:
    return features.design_matrix(features.FORM_IDS[form], target, inp["rpm"], inp["draft_m"], inp["trim_m"], inp["wind_kn"],
                                  inp["wind_rel_deg"], inp["hs_m"], inp["wave_rel_deg"], inp["months_dd"])


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

    Rows with a non-finite regressor or target are left out (per group, order kept). Each group
    stops re-weighting when its own coefficients settle, so it gets what `fit_target` gives it alone.
    """
    fid = features.FORM_IDS[form]
    names = (features.SPEED_REGRESSORS if target == "speed" else features.FUEL_REGRESSORS)[fid]
    X = np.ascontiguousarray(X, dtype=np.float64)
    y = np.ascontiguousarray(y, dtype=np.float64)
    bounds = np.ascontiguousarray(bounds, dtype=np.int64)
    G, k = bounds.size - 1, X.shape[1]
    intercept = np.array([nm == "1" for nm in names], dtype=np.bool_)
    coef, keep = np.zeros((G, k)), np.zeros((G, k), dtype=np.bool_)
    n, stats = np.zeros(G, dtype=np.int64), np.full((G, 3), np.nan)  # r2, rmse, cv_rmse
    _fit_groups_nb(X, y, bounds, intercept, bool(robust), ROBUST_ITERATIONS if robust else 1, ROBUST_RTOL, HUBER_K,
                   max(int(k_folds), 1), int(k_folds) >= 2, coef, keep, n, stats)
    out = []
    for g in range(G):
        dropped = [names[j] for j in range(k) if not keep[g, j]]
        out.append(FitResult(form, target, names, coef[g], int(n[g]), float(stats[g, 0]), float(stats[g, 1]),
                             float(stats[g, 2]), dropped, robust))
    return out


@numba.njit(cache=True, fastmath={"reassoc", "contract"})
def _fit_groups_nb(X, y, bounds, intercept, robust, max_solves, rtol, huber_k, F, do_cv, coef, keep, n_out, stats):
    """Fit every group (see `fit_targets`); writes coef (unscaled, 0 where dropped), keep, row counts and
    stats[g] = (R², RMSE, CV-RMSE) (NaN where not defined).

    A group's finite rows are copied, scaled to unit RMS per regressor, into scratch laid out
    regressor by row, fold by fold (row p goes to CV fold p mod F), so every fold is one
    contiguous range and the whole group stays in cache through all its solves.
    """
    k = X.shape[1]
    G = bounds.size - 1
    nmax = 0
    for g in range(G):
        nmax = max(nmax, bounds[g + 1] - bounds[g])
    Z = np.empty((k + 1, nmax))  # scaled regressors, then the target
    w = np.empty(nmax)
    r = np.empty(nmax)
    buf = np.empty(nmax)
    ok = np.empty(nmax, dtype=np.bool_)
    gram = np.empty((F, k, k + 1))  # [ZᵀWZ | ZᵀWy] per fold
    A = np.empty((k, k + 1))
    beta, prev = np.empty(k), np.empty(k)
    betas = np.empty((F, k))
    top, bottom, sumsq, scale = np.empty(k), np.empty(k), np.empty(k), np.empty(k)
    nonzero = np.empty(k, dtype=np.bool_)
    lo, hi = np.empty(F, dtype=np.int64), np.empty(F, dtype=np.int64)
    for g in range(G):
        a, b = bounds[g], bounds[g + 1]
        # which rows are usable; per regressor: max, min, any non-zero, sum of squares
        m = 0
        for i in range(k):
            sumsq[i] = 0.0
            nonzero[i] = False
        for row in range(a, b):
            good = np.isfinite(y[row])
            for i in range(k):
                good = good and np.isfinite(X[row, i])
            ok[row - a] = good
            if not good:
                continue
            for i in range(k):
                v = X[row, i]
                if m == 0 or v > top[i]:
                    top[i] = v
                if m == 0 or v < bottom[i]:
                    bottom[i] = v
                if v != 0.0:
                    nonzero[i] = True
                sumsq[i] += v * v
            m += 1
        n_out[g] = m
        nf = float(max(m, 1))
        n_keep = 0
        for i in range(k):
            keep[g, i] = (intercept[i] and nonzero[i]) or (m > 0 and top[i] - bottom[i] > 1e-12)
            n_keep += keep[g, i]
            scale[i] = np.sqrt(sumsq[i] / nf)
            if scale[i] == 0.0 or not keep[g, i]:
                scale[i] = 1.0
        if m == 0 or n_keep == 0:
            continue  # nothing to fit: coefficients 0, statistics NaN
        # fold f is slots lo[f]:hi[f]
        s0 = 0
        for f in range(F):
            lo[f] = s0
            s0 += max((m - f + F - 1) // F, 0)
            hi[f] = s0
        p = 0
        for row in range(a, b):
            if not ok[row - a]:
                continue
            s = lo[p % F] + p // F
            for i in range(k):
                Z[i, s] = X[row, i] / scale[i] if keep[g, i] else 0.0
            Z[k, s] = y[row]
            p += 1
        for s in range(m):
            w[s] = 1.0
        for i in range(k):
            beta[i] = 0.0
        fresh = False  # gram holds the blocks of the current weights
        for it in range(max_solves):
            _fold_grams(Z, w, lo, hi, gram)
            fresh = True
            _sum_folds(gram, A)
            for i in range(k):
                prev[i] = beta[i]
            _solve_dropped(A, keep[g], beta)
            if it > 0:
                step, big = 0.0, 0.0
                for i in range(k):
                    step = max(step, abs(beta[i] - prev[i]))
                    big = max(big, abs(beta[i]))
                if step <= rtol * max(big, 1e-12):
                    break  # converged: `w` is still the weights `beta` was solved with
            if robust:
                _residuals(Z, beta, 0, m, r)
                _huber_weights(r, m, huber_k, buf, w)
                fresh = False
        # fit statistics on all rows
        _residuals(Z, beta, 0, m, r)
        ssr, ysum = 0.0, 0.0
        for s in range(m):
            ssr += r[s] * r[s]
            ysum += Z[k, s]
        ybar = ysum / nf
        sst = 0.0
        for s in range(m):
            d = Z[k, s] - ybar
            sst += d * d
        stats[g, 1] = np.sqrt(ssr / nf)
        if sst > 0:
            stats[g, 0] = 1.0 - ssr / sst
        for i in range(k):
            coef[g, i] = beta[i] / scale[i] if keep[g, i] else 0.0
        # k-fold CV: every fold's fit is the total normal equations (last weights) minus that fold's block
        if do_cv and m >= 2 * n_keep:
            if not fresh:
                _fold_grams(Z, w, lo, hi, gram)
            _sum_folds(gram, A)
            cv = 0.0
            for f in range(F):
                for i in range(k):
                    for j in range(k + 1):
                        gram[f, i, j] = A[i, j] - gram[f, i, j]
                _solve_dropped(gram[f], keep[g], betas[f])
                _residuals(Z, betas[f], lo[f], hi[f], r)
                for s in range(lo[f], hi[f]):
                    cv += r[s] * r[s]
            stats[g, 2] = np.sqrt(cv / m)


@numba.njit(cache=True, fastmath={"reassoc", "contract"})  # reassociation lets the row sums vectorise
def _fold_grams(Z, w, lo, hi, out):
    """out[f] = [ZᵀWZ | ZᵀWy] over slots lo[f]:hi[f]."""
    k = Z.shape[0] - 1
    for f in range(lo.size):
        a, b = lo[f], hi[f]
        wf = w[a:b]  # slices indexed from 0 up: no negative-index checks, so the loops vectorise
        for i in range(k):
            zi = Z[i, a:b]
            for j in range(i, k + 1):
                zj = Z[j, a:b]
                s = 0.0
                for q in range(b - a):
                    s += wf[q] * zi[q] * zj[q]
                out[f, i, j] = s
                if j < k:
                    out[f, j, i] = s


@numba.njit(cache=True)
def _sum_folds(gram, out):
    for i in range(out.shape[0]):
        for j in range(out.shape[1]):
            s = 0.0
            for f in range(gram.shape[0]):
                s += gram[f, i, j]
            out[i, j] = s


@numba.njit(cache=True)
def _residuals(Z, beta, a, b, out):
    """out[q] = y − z·β over slots a:b."""
    k = Z.shape[0] - 1
    o = out[a:b]
    o[:] = Z[k, a:b]
    for i in range(k):
        c = beta[i]
        zi = Z[i, a:b]
        for q in range(b - a):
            o[q] -= c * zi[q]


@numba.njit(cache=True)
def _solve_dropped(A, keep, x):
    """x solving A[:, :k]·x = A[:, k] with a dropped regressor's row and column replaced by the identity
    (β = 0 for it without touching the others). Gaussian elimination with partial pivoting; an exactly
    singular system falls back to least squares (minimum norm), as LAPACK's solver would refuse it."""
    k = A.shape[0]
    M = np.empty((k, k))
    v = np.empty(k)
    for i in range(k):
        for j in range(k):
            M[i, j] = A[i, j]
        M[i, i] += 0.0 if keep[i] else 1.0
        v[i] = A[i, k]
    L = M.copy()
    c = v.copy()
    for col in range(k):
        p = col
        for i in range(col + 1, k):
            if abs(L[i, col]) > abs(L[p, col]):
                p = i
        if L[p, col] == 0.0:
            x[:] = np.linalg.lstsq(M, v, rcond=2.220446049250313e-16 * k)[0]
            return
        if p != col:
            for j in range(k):
                L[col, j], L[p, j] = L[p, j], L[col, j]
            c[col], c[p] = c[p], c[col]
        inv = 1.0 / L[col, col]
        for i in range(col + 1, k):
            l = L[i, col] * inv
            if l != 0.0:
                for j in range(col + 1, k):
                    L[i, j] -= l * L[col, j]
                c[i] -= l * c[col]
    for i in range(k - 1, -1, -1):
        s = c[i]
        for j in range(i + 1, k):
            s -= L[i, j] * x[j]
        x[i] = s / L[i, i]


@numba.njit(cache=True)
def _huber_weights(r, m, huber_k, buf, w):
    """Huber weights of residuals r[:m] into w[:m]: scale = 1.4826 · MAD (1e-9 when the MAD is 0)."""
    for q in range(m):
        buf[q] = r[q]
    med = _median_inplace(buf, m)
    for q in range(m):
        buf[q] = abs(r[q] - med)
    s = 1.4826 * _median_inplace(buf, m)
    if s == 0.0:
        s = 1e-9
    c = huber_k * s
    for q in range(m):
        u = abs(r[q]) / c
        inv = 1.0 / u
        w[q] = inv if inv < 1.0 else 1.0  # 1 where u ≤ 1, else 1/u


@numba.njit(cache=True)
def _median_inplace(a, m):
    """np.median of a[:m] (reorders a[:m])."""
    half = m // 2
    hi = _select(a, 0, m - 1, half)
    if m % 2:
        return hi
    lo = a[0]  # the largest of a[:half], which `_select` left below a[half]
    for q in range(1, half):
        if a[q] > lo:
            lo = a[q]
    return (lo + hi) / 2


@numba.njit(cache=True)
def _select(a, left, right, kth):
    """Quickselect: reorder a[left:right+1] so a[kth] is in sorted position, smaller-or-equal before it."""
    while right > left:
        mid = (left + right) // 2  # median of three as pivot
        if a[mid] < a[left]:
            a[mid], a[left] = a[left], a[mid]
        if a[right] < a[left]:
            a[right], a[left] = a[left], a[right]
        if a[right] < a[mid]:
            a[right], a[mid] = a[mid], a[right]
        pivot = a[mid]
        i, j = left, right
        while i <= j:
            while a[i] < pivot:
                i += 1
            while a[j] > pivot:
                j -= 1
            if i <= j:
                a[i], a[j] = a[j], a[i]
                i += 1
                j -= 1
        if kth <= j:
            right = j
        elif kth >= i:
            left = i
        else:
            break
    return a[kth]


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
