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


def designs(form: str, inp: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """{"speed": X, "fuel": X}: both design matrices in one pass over the inputs."""
    Xs, Xf = features.design_matrices(features.FORM_IDS[form], inp["rpm"], inp["draft_m"], inp["trim_m"], inp["wind_kn"],
                                      inp["wind_rel_deg"], inp["hs_m"], inp["wave_rel_deg"], inp["months_dd"])
    return {"speed": Xs, "fuel": Xf}


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
    out, dropped_for = [], {}
    for g, (kept, n_g, (r2, rmse, cv)) in enumerate(zip(map(tuple, keep.tolist()), n.tolist(), stats.tolist())):
        if kept not in dropped_for:
            dropped_for[kept] = [nm for nm, kp in zip(names, kept) if not kp]
        out.append(FitResult(form, target, names, coef[g], n_g, r2, rmse, cv, list(dropped_for[kept]), robust))
    return out


@numba.njit(cache=True)
def _fit_groups_nb(X, y, bounds, intercept, robust, max_solves, rtol, huber_k, F, do_cv, coef, keep, n_out, stats):
    """Fit every group (see `fit_targets`); writes coef (unscaled, 0 where dropped), keep, row counts and
    stats[g] = (R², RMSE, CV-RMSE) (NaN where not defined)."""
    k = X.shape[1]
    G = bounds.size - 1
    nmax = 0
    for g in range(G):
        nmax = max(nmax, bounds[g + 1] - bounds[g])
    Z = np.empty((k + 1, nmax))  # scaled regressors, then the target
    T = np.empty((k, nmax))  # weighted regressors
    w, r, buf = np.empty(nmax), np.empty(nmax), np.empty((3, nmax))
    rows = np.empty(nmax, dtype=np.int64)
    gram = np.empty((F, k, k + 1))  # [ZᵀWZ | ZᵀWy] per fold
    lo, hi = np.empty(F, dtype=np.int64), np.empty(F, dtype=np.int64)
    for g in range(G):
        n_out[g] = _fit_group(X, y, bounds[g], bounds[g + 1], intercept, robust, max_solves, rtol, huber_k, do_cv,
                              coef[g], keep[g], stats[g], Z, T, w, r, buf, rows, gram, lo, hi)


@numba.njit(cache=True)
def _fit_group(X, y, a, b, intercept, robust, max_solves, rtol, huber_k, do_cv, coef, keep, stats, Z, T, w, r, buf, rows,
               gram, lo, hi):
    """Fit rows a:b of X and y; returns how many were finite (see `_fit_groups_nb` for the outputs;
    Z … hi are scratch).

    The finite rows are copied, scaled to unit RMS per regressor, into scratch laid out regressor
    by row, fold by fold (row p goes to CV fold p mod F), so every fold is one contiguous range and
    the whole group stays in cache through all its solves.
    """
    k = X.shape[1]
    F = lo.size
    m = _pack(X, y, a, b, F, rows, lo, hi, Z)
    scale = np.empty(k)
    n_keep = _scale(Z, m, intercept, keep, scale)
    if m == 0 or n_keep == 0:
        return m  # nothing to fit: coefficients 0, statistics NaN
    nf = float(m)
    full, end = np.zeros(1, dtype=np.int64), np.full(1, m)
    w[:m] = 1.0
    beta, prev = np.zeros(k), np.empty(k)
    med, s = np.nan, np.nan  # the last Huber location and scale: where the next ones probably lie
    for it in range(max_solves):
        _grams(Z, w, full, end, T, gram)
        prev[:] = beta
        _solve_dropped(gram[0], keep, beta)
        if it > 0:
            step, big = 0.0, 0.0
            for i in range(k):
                step = max(step, abs(beta[i] - prev[i]))
                big = max(big, abs(beta[i]))
            if step <= rtol * max(big, 1e-12):
                break  # converged: `w` is still the weights `beta` was solved with
        if robust:
            _residuals(Z, beta, 0, m, r)
            med, s = _huber_weights(r, m, huber_k, med, s, buf, w)
    # fit statistics on all rows
    _residuals(Z, beta, 0, m, r)
    ssr, sst, _ = _sums(r, Z[k], m)
    stats[1] = np.sqrt(ssr / nf)
    if sst > 0:
        stats[0] = 1.0 - ssr / sst
    for i in range(k):
        coef[i] = beta[i] / scale[i] if keep[i] else 0.0
    # k-fold CV: every fold's fit is the total normal equations (last weights) minus that fold's block
    if do_cv and m >= 2 * n_keep:
        _grams(Z, w, lo, hi, T, gram)
        A = np.zeros((k, k + 1))
        for f in range(F):
            A += gram[f]
        beta_f = np.empty(k)
        cv = 0.0
        for f in range(F):
            for i in range(k):
                for j in range(k + 1):
                    gram[f, i, j] = A[i, j] - gram[f, i, j]
            _solve_dropped(gram[f], keep, beta_f)
            _residuals(Z, beta_f, lo[f], hi[f], r)
            for q in range(lo[f], hi[f]):
                cv += r[q] * r[q]
        stats[2] = np.sqrt(cv / nf)
    return m


@numba.njit(cache=True)
def _pack(X, y, a, b, F, rows, lo, hi, Z):
    """Copy the finite rows among a:b of X and y into Z[:, :m] (regressors, then the target) fold by fold:
    the p-th of them goes to fold p mod F, and fold f is slots lo[f]:hi[f]. Returns m."""
    k = X.shape[1]
    if _all_finite(X[a:b].ravel()) and _all_finite(y[a:b]):
        m = b - a
        for p in range(m):
            rows[p] = a + p
    else:
        m = 0
        for row in range(a, b):
            good = np.isfinite(y[row])
            for i in range(k):
                good &= np.isfinite(X[row, i])
            rows[m] = row
            m += good
    s = 0
    for f in range(F):
        lo[f] = s
        for p in range(f, m, F):
            row = rows[p]
            for i in range(k):
                Z[i, s] = X[row, i]
            Z[k, s] = y[row]
            s += 1
        hi[f] = s
    return m


@numba.njit(cache=True, fastmath={"reassoc"})
def _all_finite(v):
    """No NaN or ±inf in v (x·0 is 0 exactly for finite x, NaN otherwise)."""
    s = 0.0
    for q in range(v.size):
        s += v[q] * 0.0
    return s == 0.0


@numba.njit(cache=True, fastmath=True)  # finite values only (`_pack` left the others out)
def _column_stats(z):
    """(max, min, any non-zero, sum of squares) of a finite, non-empty array."""
    n = z.size
    t0 = t1 = t2 = t3 = b0 = b1 = b2 = b3 = z[0]  # four lanes each, which the compiler keeps in vector registers
    q = 0
    while q + 4 <= n:
        v0, v1, v2, v3 = z[q], z[q + 1], z[q + 2], z[q + 3]
        t0, t1, t2, t3 = max(t0, v0), max(t1, v1), max(t2, v2), max(t3, v3)
        b0, b1, b2, b3 = min(b0, v0), min(b1, v1), min(b2, v2), min(b3, v3)
        q += 4
    for p in range(q, n):
        t0, b0 = max(t0, z[p]), min(b0, z[p])
    top, bottom = max(max(t0, t1), max(t2, t3)), min(min(b0, b1), min(b2, b3))
    sq = 0.0
    for p in range(n):
        sq += z[p] * z[p]
    return top, bottom, top != 0.0 or bottom != 0.0, sq


@numba.njit(cache=True)
def _scale(Z, m, intercept, keep, scale):
    """Decide which regressors to keep (not constant, or the intercept) and scale the kept ones in Z[:, :m]
    to unit RMS; a dropped one becomes 0. Returns how many are kept."""
    k = Z.shape[0] - 1
    n_keep = 0
    for i in range(k):
        zi = Z[i, :m]
        keep[i] = False
        scale[i] = 1.0
        if m == 0:
            continue
        top, bottom, nonzero, sq = _column_stats(zi)
        keep[i] = (intercept[i] and nonzero) or top - bottom > 1e-12
        if keep[i]:
            n_keep += 1
            rms = np.sqrt(sq / m)
            if rms != 0.0:
                scale[i] = rms
            c = scale[i]
            for q in range(m):
                zi[q] = zi[q] / c
        else:
            zi[:] = 0.0
    return n_keep


@numba.njit(cache=True, fastmath={"reassoc", "contract"})
def _sums(r, yv, m):
    """(Σ r², Σ (y − ȳ)², ȳ) over the first m slots."""
    ssr, ysum = 0.0, 0.0
    for q in range(m):
        ssr += r[q] * r[q]
        ysum += yv[q]
    ybar = ysum / m
    sst = 0.0
    for q in range(m):
        d = yv[q] - ybar
        sst += d * d
    return ssr, sst, ybar


@numba.njit(cache=True, fastmath={"reassoc", "contract"})  # reassociation lets the row sums vectorise
def _grams(Z, w, lo, hi, T, out):
    """out[f] = [ZᵀWZ | ZᵀWy] over slots lo[f]:hi[f] (T: scratch for the weighted regressors)."""
    k = Z.shape[0] - 1
    for f in range(lo.size):
        a, b = lo[f], hi[f]
        n = b - a
        wf = w[a:b]  # slices indexed from 0 up: no negative-index checks, so the loops vectorise
        for i in range(k):
            zi, ti = Z[i, a:b], T[i, :n]
            for q in range(n):
                ti[q] = wf[q] * zi[q]
        for i in range(k):
            ti = T[i, :n]
            j = i
            while j + 3 <= k:  # four columns per sweep over the rows
                z0, z1, z2, z3 = Z[j, a:b], Z[j + 1, a:b], Z[j + 2, a:b], Z[j + 3, a:b]
                s0 = s1 = s2 = s3 = 0.0
                for q in range(n):
                    t = ti[q]
                    s0 += t * z0[q]
                    s1 += t * z1[q]
                    s2 += t * z2[q]
                    s3 += t * z3[q]
                out[f, i, j], out[f, i, j + 1], out[f, i, j + 2], out[f, i, j + 3] = s0, s1, s2, s3
                j += 4
            while j <= k:
                zj = Z[j, a:b]
                s0 = 0.0
                for q in range(n):
                    s0 += ti[q] * zj[q]
                out[f, i, j] = s0
                j += 1
            for j in range(i + 1, k):
                out[f, j, i] = out[f, i, j]


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
def _huber_weights(r, m, huber_k, med_guess, s_guess, buf, w):
    """Huber weights of residuals r[:m] into w[:m]: scale s = 1.4826 · MAD (1e-9 when the MAD is 0).

    Returns (median, s); the previous ones, if known (else NaN), are guesses that make the medians
    cheap. buf: (3, ≥ m) scratch.
    """
    if not (np.isfinite(med_guess) and np.isfinite(s_guess)):  # guess from the mean and standard deviation
        mean, sq = 0.0, 0.0
        for q in range(m):
            mean += r[q]
        mean /= m
        for q in range(m):
            sq += (r[q] - mean) * (r[q] - mean)
        med_guess, s_guess = mean, np.sqrt(sq / m)
    med = _median(r, m, med_guess, 0.1 * s_guess, buf)
    for q in range(m):
        w[q] = abs(r[q] - med)  # w is scratch until the weights go in
    s = 1.4826 * _median(w, m, s_guess / 1.4826, 0.1 * s_guess, buf)
    if s == 0.0:
        s = 1e-9
    c = huber_k * s
    for q in range(m):
        u = abs(r[q]) / c
        inv = 1.0 / u
        w[q] = inv if inv < 1.0 else 1.0  # 1 where u ≤ 1, else 1/u
    return med, s


@numba.njit(cache=True)
def _median(a, m, guess, width, buf):
    """np.median of a[:m] (a is only read; buf: (3, ≥ m) scratch).

    If guess ± width brackets the middle order statistics, only the values inside the bracket are
    selected among (few, when the guess is good); otherwise all of them.
    """
    half = m // 2
    low, high = guess - width, guess + width
    below, inside = 0, 0
    near = buf[2]
    for q in range(m):
        v = a[q]
        below += v < low
        near[inside] = v
        inside += (v >= low) & (v <= high)
    if below <= half - 1 + m % 2 and half < below + inside:
        return _middle(near, inside, half - below, m % 2 == 0, buf[0], buf[1])
    return _middle(a, m, half, m % 2 == 0, buf[0], buf[1])


@numba.njit(cache=True)
def _middle(a, n, kth, even, s0, s1):
    """The kth smallest of a[:n], or with `even` the mean of the (kth − 1)th and kth (a is only read)."""
    upper = _kth(a, n, kth, s0, s1)
    if not even:
        return upper
    less, lower = 0, -np.inf  # how many are below `upper`, and the largest of them
    for q in range(n):
        v = a[q]
        less += v < upper
        lower = max(lower, v if v < upper else -np.inf)
    return ((lower if less == kth else upper) + upper) / 2


@numba.njit(cache=True)
def _kth(a, n, kth, s0, s1):
    """The kth smallest of a[:n] (a is only read; s0, s1: scratch of length ≥ n).

    Quickselect with a branch-free partition (values ping-pong between s0 and s1), which does not
    stall on unpredictable comparisons the way swapping in place does.
    """
    src, dst = a, s0
    lo, hi = 0, n
    while hi - lo > 24:
        x, y, z = src[lo], src[(lo + hi) // 2], src[hi - 1]
        pivot = max(min(x, y), min(max(x, y), z))  # median of three
        left, right = lo, hi - 1
        for q in range(lo, hi):  # smaller than the pivot to the left, the others to the right
            v = src[q]
            c = v < pivot
            dst[left] = v
            dst[right] = v
            left += c
            right -= 1 - c
        if kth < left:
            hi = left
        elif left > lo:
            lo = left
        else:  # nothing below the pivot (many equal values): finish with the swapping quickselect
            for q in range(lo, hi):
                s1[q] = dst[q]
            return _select(s1, lo, hi - 1, kth)
        src, dst = dst, (s1 if dst is s0 else s0)
    if src is a:
        for q in range(lo, hi):
            s0[q] = a[q]
        src = s0
    for i in range(lo + 1, hi):  # insertion sort of the few left
        v = src[i]
        j = i - 1
        while j >= lo and src[j] > v:
            src[j + 1] = src[j]
            j -= 1
        src[j + 1] = v
    return src[kth]


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
