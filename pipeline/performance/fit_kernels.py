"""Compiled kernels of the fleet fit (`fit.fit_targets`): per vessel, pack its finite rows fold by fold
into a cache-resident scratch block, scale the columns, form the normal equations from per-fold Gram
blocks, re-weight with Huber weights until the vessel's coefficients settle, and compute R², RMSE and
k-fold cross-validated RMSE from the same blocks.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from pipeline.performance.huber import huber_weights


class FitRows(NamedTuple):
    """The rows every group is fitted on: the regressors X (rows × k), a sign ±1 per column (the fit is of
    X·diag(sign): a coefficient held ≤ 0 is fitted as a ≥ 0 one on its negated regressor, without a copy of X) and
    the target y."""

    X: np.ndarray
    sign: np.ndarray
    y: np.ndarray


class FitRule(NamedTuple):
    """How each group is fitted: the regressors kept even when constant (`intercept`) and held ≥ 0 (`nonneg`); Huber
    re-weighting (`robust`) of at most `max_solves` solves, settled when no coefficient moves more than `rtol` of the
    largest, with Huber's `huber_k`; `folds` cross-validation folds (1: no cross-validation); `warm`: the
    re-weighting starts from given coefficients."""

    intercept: np.ndarray
    nonneg: np.ndarray
    robust: bool
    max_solves: int
    rtol: float
    huber_k: float
    folds: int
    warm: bool


class FitScratch(NamedTuple):
    """Scratch of one group's fit, sized for the largest group: the scaled regressors then the target (Z, k + 1 rows),
    the weighted regressors (T), weights, residuals, the medians' buffer, the rows packed, the per-fold Gram blocks
    [ZᵀWZ | ZᵀWy] and each fold's slots lo[f]:hi[f]."""

    Z: np.ndarray
    T: np.ndarray
    w: np.ndarray
    r: np.ndarray
    buf: np.ndarray
    rows: np.ndarray
    gram: np.ndarray
    lo: np.ndarray
    hi: np.ndarray


@numba.njit(cache=True)
def fit_groups_nb(data, starts, ends, rule, beta0, coef, keep, n_out, stats):
    """Fit every group (group g: rows starts[g]:ends[g] of `data`, a FitRows; see `fit_targets`) as `rule` (a FitRule)
    says; writes coef (unscaled, of X·diag(sign), 0 where dropped), keep, row counts and stats[g] = (R², RMSE,
    CV-RMSE) (NaN where not defined). With `rule.warm` (and `robust`), group g's first Huber weights come from the
    coefficients beta0[g] (e.g. a fit of most of the same rows)."""
    k = data.X.shape[1]
    G = starts.size
    F = rule.folds
    nmax = 0
    for g in range(G):
        nmax = max(nmax, ends[g] - starts[g])
    scr = FitScratch(np.empty((k + 1, nmax)), np.empty((k, nmax)), np.empty(nmax), np.empty(nmax), np.empty((3, nmax)),
                     np.empty(nmax, dtype=np.int64), np.empty((F, k, k + 1)), np.empty(F, dtype=np.int64),
                     np.empty(F, dtype=np.int64))
    for g in range(G):
        n_out[g] = _fit_group(data, starts[g], ends[g], rule, beta0[g], coef[g], keep[g], stats[g], scr)


@numba.njit(cache=True)
def _fit_group(data, a, b, rule, beta0, coef, keep, stats, scr):
    """Fit rows a:b of `data` (FitRows) as `rule` (FitRule) says; returns how many were finite (see `fit_groups_nb`
    for the outputs; `scr`: a FitScratch).

    The finite rows are copied, scaled to unit RMS per regressor, into scratch laid out regressor
    by row, fold by fold (row p goes to CV fold p mod F), so every fold is one contiguous range and
    the whole group stays in cache through all its solves.
    """
    intercept, nonneg, robust, max_solves, rtol = rule.intercept, rule.nonneg, rule.robust, rule.max_solves, rule.rtol
    huber_k, do_cv, warm = rule.huber_k, rule.folds >= 2, rule.warm
    Z, T, w, r, buf, gram, lo, hi = scr.Z, scr.T, scr.w, scr.r, scr.buf, scr.gram, scr.lo, scr.hi
    k = data.X.shape[1]
    F = lo.size
    m = _pack(data, a, b, scr)
    scale = np.empty(k)
    n_keep = _scale(Z, m, intercept, keep, scale)
    if m == 0 or n_keep == 0:
        return m  # nothing to fit: coefficients 0, statistics NaN
    nf = float(m)
    full, end = np.zeros(1, dtype=np.int64), np.full(1, m)
    w[:m] = 1.0
    beta, prev = np.zeros(k), np.empty(k)
    med, s = np.nan, np.nan  # the last Huber location and scale: where the next ones probably lie
    started = warm and robust
    if started:  # weights from the given coefficients: the re-weighting starts near where it ends
        for i in range(k):
            beta[i] = beta0[i] * scale[i] if keep[i] else 0.0
        _residuals(Z, beta, 0, m, r)
        med, s = huber_weights(r, m, huber_k, med, s, buf, w)
    do_cv = do_cv and m >= 2 * n_keep
    A = np.empty((k, k + 1))
    for it in range(max_solves):
        if do_cv:  # the folds' blocks, summed: the cross-validation below reuses the last solve's blocks
            _grams(Z, w, lo, hi, T, gram)
            A[:] = gram[0]
            for f in range(1, F):
                A += gram[f]
        else:
            _grams(Z, w, full, end, T, gram)
            A[:] = gram[0]
        prev[:] = beta
        _solve_nonneg(A, keep, nonneg, beta, Z, m)
        if it > 0 or started:
            step, big = 0.0, 0.0
            for i in range(k):
                step = max(step, abs(beta[i] - prev[i]))
                big = max(big, abs(beta[i]))
            if step <= rtol * max(big, 1e-12):
                break  # converged: `w` is still the weights `beta` was solved with
        if robust and it < max_solves - 1:  # new weights only for a solve that follows
            _residuals(Z, beta, 0, m, r)
            med, s = huber_weights(r, m, huber_k, med, s, buf, w)
    # fit statistics on all rows
    _residuals(Z, beta, 0, m, r)
    ssr, sst, _ = _sums(r, Z[k], m)
    stats[1] = np.sqrt(ssr / nf)
    if sst > 0:
        stats[0] = 1.0 - ssr / sst
    for i in range(k):
        coef[i] = beta[i] / scale[i] if keep[i] else 0.0
    # k-fold CV: every fold's fit is the total normal equations (last weights) minus that fold's block; the blocks
    # are the last solve's, less the rows and columns of regressors it left out (as if their columns were zero)
    if do_cv:
        for i in range(k):
            if not keep[i]:
                for f in range(F):
                    gram[f, i, :] = 0.0
                    gram[f, :, i] = 0.0
        A[:] = gram[0]
        for f in range(1, F):
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
def _pack(data, a, b, scr):
    """Copy the finite rows among a:b of X·diag(sign) and y (`data`) into scr.Z[:, :m] (regressors, then the target)
    fold by fold: the p-th of them goes to fold p mod F (F = scr.lo.size), and fold f is slots scr.lo[f]:scr.hi[f].
    Returns m."""
    X, sign, y = data.X, data.sign, data.y
    rows, lo, hi, Z = scr.rows, scr.lo, scr.hi, scr.Z
    F = lo.size
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
                Z[i, s] = X[row, i] * sign[i]
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
def _solve_nonneg(A, keep, nonneg, x, Z, m):
    """`_solve_dropped`, then while a regressor that must not be negative (`nonneg`) is, leave the most
    negative one out (keep False, β = 0, its column of Z zeroed for later solves) and solve again.
    A (the normal equations) is overwritten."""
    k = A.shape[0]
    while True:
        _solve_dropped(A, keep, x)
        worst, low = -1, 0.0
        for i in range(k):
            if keep[i] and nonneg[i] and x[i] < low:
                worst, low = i, x[i]
        if worst < 0:
            return
        keep[worst] = False
        for j in range(k + 1):
            A[worst, j] = 0.0
        for j in range(k):
            A[j, worst] = 0.0
        Z[worst, :m] = 0.0


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
