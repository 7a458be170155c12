"""Whether a vessel's physical form leaves structure the network form could learn (`explained`, `share_needed`).

A refit with `--form best` trains the MLP only where it could be chosen. It replaces the
physical form only with a held-out score lower by `Gate.switch_margin` (5 %); the score adds the speed
and fuel RMSEs relative to their means, so at least one of them must fall by that share, i.e. a model of
the network's inputs would have to explain at least 1 − (1 − margin)² (9.75 %) of the variance of the
physical form's residuals in speed or in fuel. The screen measures what a smooth function of those
inputs explains: the residuals of the physical training fit, per vessel, regressed on a full quadratic
in the network's five inputs (rpm, draft, trim, wind·w, waves·w: 21 terms), with R² adjusted for the
terms fitted (0 expected when there is nothing to learn). The network is trained when that adjusted
R² reaches the share for speed or fuel; otherwise it could only win by chance, which the switch rule
exists to refuse, and the summary says it was not trained and why.

The quadratic is the second-order (Taylor) part of any smooth function of the inputs; a 30-unit network
fitted to a few hundred noisy daily reports with early stopping learns little beyond it. The screen is a
setting (`Gate.network_screen`, `--gate network_screen=false` trains the network for every vessel).
One compiled pass per fleet: the normal equations of the 21 terms are summed row by row, never stored.
"""

from __future__ import annotations

import numba
import numpy as np

N_INPUTS = 5
N_TERMS = 1 + N_INPUTS + N_INPUTS * (N_INPUTS + 1) // 2  # 1, x_i, x_i·x_j (i ≤ j)


def share_needed(margin: float) -> float:
    """Share of the residual variance a model must explain to lower that target's RMSE by `margin`."""
    return 1.0 - (1.0 - margin) ** 2


def explained(Z: np.ndarray, resid: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """(groups × targets) adjusted R² of the residuals resid[:, t] of rows starts[g]:ends[g] on a full quadratic in the
    columns of Z (n × 5, network inputs); rows with a non-finite value are left out; NaN where too few rows."""
    Z = np.asarray(Z, dtype=np.float64)
    mu = np.nanmean(Z, axis=0)
    sd = np.nanstd(Z, axis=0)
    Zs = np.ascontiguousarray((Z - mu) / np.where(sd > 1e-12, sd, 1.0))  # centred: the quadratic terms stay well-conditioned
    out = np.full((np.size(starts), resid.shape[1]), np.nan)
    _explained_nb(Zs, np.ascontiguousarray(resid, dtype=np.float64), np.asarray(starts, dtype=np.int64),
                  np.asarray(ends, dtype=np.int64), out)
    return out


@numba.njit(cache=True)
def _explained_nb(Z, R, starts, ends, out):
    q, m = N_TERMS, R.shape[1]
    A = np.empty((q, q))
    b = np.empty((q, m))
    phi = np.empty(q)
    s1, s2 = np.empty(m), np.empty(m)
    for g in range(starts.size):
        A[:] = 0.0
        b[:] = 0.0
        s1[:] = 0.0
        s2[:] = 0.0
        n = 0
        for i in range(starts[g], ends[g]):
            ok = True
            for j in range(Z.shape[1]):
                if not np.isfinite(Z[i, j]):
                    ok = False
            for t in range(m):
                if not np.isfinite(R[i, t]):
                    ok = False
            if not ok:
                continue
            n += 1
            phi[0] = 1.0
            k = 1
            for j in range(N_INPUTS):
                phi[k] = Z[i, j]
                k += 1
            for j in range(N_INPUTS):
                for l in range(j, N_INPUTS):
                    phi[k] = Z[i, j] * Z[i, l]
                    k += 1
            for u in range(q):
                pu = phi[u]
                for v in range(u, q):
                    A[u, v] += pu * phi[v]
                for t in range(m):
                    b[u, t] += pu * R[i, t]
            for t in range(m):
                s1[t] += R[i, t]
                s2[t] += R[i, t] * R[i, t]
        if n <= q + 1:
            continue
        for u in range(q):
            for v in range(u):
                A[u, v] = A[v, u]
        beta, _, rank, _ = np.linalg.lstsq(A, b, 1e-10)
        df = n - rank
        if df < 1:
            continue
        for t in range(m):
            tss = s2[t] - s1[t] * s1[t] / n
            if not tss > 0.0:
                out[g, t] = 0.0
                continue
            rss = s2[t]
            for u in range(q):
                rss -= beta[u, t] * b[u, t]
            r2 = 1.0 - max(rss, 0.0) / tss
            out[g, t] = 1.0 - (1.0 - r2) * (n - 1) / df
