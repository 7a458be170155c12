"""The MLP form: one 5-30-2 network (the A*/MLP paper's structure, the thesis appendix's neural model)
giving speed through water (kn) and fuel rate (t/h) from the same five inputs.

Inputs: rpm, draft (m), trim (m), wind Vw·w(θw) (kn) and waves Hs·w(θs) (m), where w is the physical
form's direction shape (`features.direction_weight`: 1 head-on, 0.45 beam, 0.14 following). Wind
and waves enter as amounts already weighted by direction, so calm water (Vw = Hs = 0) has no
direction and cannot depend on the heading. One hidden layer of 30 tanh units, two linear outputs;
inputs and outputs are standardised with the training rows' means and standard deviations.

Training: full-batch Adam on the mean squared error of the standardised outputs with a small L2
penalty, early stopping on a time-ordered split (the newest `VAL_FRAC` of the training rows are
the validation rows; the parameters of the best validation epoch are kept), weights initialised
from an explicit seeded generator: the same rows and seed give the same network, bit for bit.
Plain numpy (a 256-parameter network on a few hundred reports needs no framework); the forward
pass is also a numba function so routing kernels evaluate it like the linear forms.

A network is one flat parameter vector (`N_PARAMS` values: layout in `_unpack`, then the least and the
largest value of each input in the training rows, then the coefficients of the physical form fitted on
the same rows — `PHYSICAL_SPEED`, `PHYSICAL_FUEL`), stored as the model's speed and its fuel
coefficients alike. `forward`/`forward_nb` evaluate the network at its inputs clamped to that range;
what routing gets (`features.stw_kn_nb`) is the guarded prediction: outside the conditions the network
was trained on (rpm, draft or trim beyond the least or largest seen, wind·w or waves·w beyond the
largest) it follows the physical form — the network's value at the nearest edge of its envelope plus the
change of the physical form's linear terms from that edge to the point. A tanh network extrapolates
anything (fuel falling to 0 below the lowest rpm it saw, speed rising in heavier seas); the physical form
extrapolates as a ship does. The two meet at the edge, and each of the physical form's terms depends on one
input with a held sign (weather costs speed and fuel), so the guarded prediction stays monotone where the
network and the physical form are.
"""

from __future__ import annotations

import math

import numba
import numpy as np

N_IN, N_HIDDEN, N_OUT = 5, 30, 2
N_PHYSICAL_SPEED, N_PHYSICAL_FUEL = 7, 6  # coefficients of the physical form (`features`; checked there)
N_NET = 2 * N_IN + N_IN * N_HIDDEN + N_HIDDEN + N_HIDDEN * N_OUT + N_OUT + 2 * N_OUT + 2 * N_IN
N_PARAMS = N_NET + N_PHYSICAL_SPEED + N_PHYSICAL_FUEL
PARAM_NAMES = tuple(f"p{i:03d}" for i in range(N_PARAMS))
VAL_FRAC = 0.2
MAX_EPOCHS = 1500
PATIENCE = 100
LEARNING_RATE = 0.01
L2 = 1e-4
DEFAULT_SEED = 1
# Monotone by construction: the first N_HIDDEN // 2 hidden units feed only the speed output, the others only the
# fuel output, each with an output weight ≥ 0, and the weights of rpm, wind and waves into a unit have the sign
# its output needs (projected after every training step; tanh rises and the standardisation keeps signs): speed
# never falls with rpm nor rises with wind or waves, fuel never falls with any of them — also where rows are few.
MONO_INPUTS = (0, 3, 4)  # rpm, wind·w, waves·w
MONO_SIGN = np.array([[1.0, 1.0], [-1.0, 1.0], [-1.0, 1.0]])  # (input, output): required sign of d output / d input

# offsets of the parts of a parameter vector
_XM, _XS = 0, N_IN
_W1 = 2 * N_IN
_B1 = _W1 + N_IN * N_HIDDEN
_W2 = _B1 + N_HIDDEN
_B2 = _W2 + N_HIDDEN * N_OUT
_YM = _B2 + N_OUT
_YS = _YM + N_OUT
_LO = _YS + N_OUT  # least and largest value of each input in the training rows: the network is evaluated
_HI = _LO + N_IN  # at inputs clamped to them (flat outside what it saw, never extrapolated)
PHYSICAL_SPEED = slice(N_NET, N_NET + N_PHYSICAL_SPEED)  # the physical form fitted on the same rows: what the
PHYSICAL_FUEL = slice(PHYSICAL_SPEED.stop, N_PARAMS)  # prediction follows outside the envelope (all 0: none)


def _unpack(p: np.ndarray):
    """(x_mean, x_std, W1 (5×30), b1, W2 (30×2), b2, y_mean, y_std) views of a parameter vector."""
    return (p[_XM:_XS], p[_XS:_W1], p[_W1:_B1].reshape(N_IN, N_HIDDEN), p[_B1:_W2], p[_W2:_B2].reshape(N_HIDDEN, N_OUT),
            p[_B2:_YM], p[_YM:_YS], p[_YS:_LO])


def input_bounds(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(least, largest) of each network input (rpm, draft, trim, wind·w, waves·w) in the rows it was trained on."""
    p = np.asarray(p, dtype=np.float64)
    return p[_LO:_HI], p[_HI:N_NET]


def with_physical(p: np.ndarray, speed_coef: np.ndarray, fuel_coef: np.ndarray) -> np.ndarray:
    """A copy of network p carrying the physical form's coefficients (fitted on the same rows) for its fallback."""
    out = np.array(p, dtype=np.float64)
    out[PHYSICAL_SPEED], out[PHYSICAL_FUEL] = speed_coef, fuel_coef
    return out


@numba.njit(cache=True)
def edge_nb(p, x0, x1, x2, x3, x4):
    """(whether the input row lies outside the network's envelope, the row clamped to it). The weather inputs
    count as outside above the largest seen only (calm water below the least seen is no extrapolation)."""
    x = (x0, x1, x2, x3, x4)
    e = np.empty(N_IN)
    outside = False
    for i in range(N_IN):
        lo, hi = p[_LO + i], p[_HI + i]
        e[i] = min(max(x[i], lo), hi)
        if x[i] > hi or (x[i] < lo and i < 3):
            outside = True
    return outside, e


def forward(p: np.ndarray, X: np.ndarray) -> np.ndarray:
    """(n × 2) outputs — speed (kn), fuel rate (t/h) — of the network p at the rows of X (n × 5)."""
    p = np.asarray(p, dtype=np.float64)
    xm, xs, W1, b1, W2, b2, ym, ys = _unpack(p)
    X = np.minimum(np.maximum(X, p[_LO:_HI]), p[_HI:N_NET])
    return (np.tanh(((X - xm) / xs) @ W1 + b1) @ W2 + b2) * ys + ym


@numba.njit(cache=True)
def forward_nb(p, x0, x1, x2, x3, x4, out_index):
    """Output `out_index` (0 speed, 1 fuel) of the network p for one input row (as `forward`)."""
    x = (x0, x1, x2, x3, x4)
    z = np.empty(N_IN)
    for i in range(N_IN):
        z[i] = (min(max(x[i], p[_LO + i]), p[_HI + i]) - p[_XM + i]) / p[_XS + i]
    o = p[_B2 + out_index]
    for j in range(N_HIDDEN):
        a = p[_B1 + j]
        for i in range(N_IN):
            a += z[i] * p[_W1 + i * N_HIDDEN + j]
        o += math.tanh(a) * p[_W2 + j * N_OUT + out_index]
    return o * p[_YS + out_index] + p[_YM + out_index]


def _project_monotone(W1: np.ndarray, W2: np.ndarray) -> None:
    """In place: each hidden unit feeds one output (speed: the first half, fuel: the rest) with a weight ≥ 0, and the
    weight of a monotone input into it has the sign MONO_SIGN asks for that output (else 0)."""
    half = N_HIDDEN // 2
    W2[:half, 1] = 0.0
    W2[half:, 0] = 0.0
    np.maximum(W2, 0.0, out=W2)
    which = (np.arange(N_HIDDEN) >= half).astype(int)
    for r, k in enumerate(MONO_INPUTS):
        want = MONO_SIGN[r, which]
        W1[k] = np.where(W1[k] * want < 0.0, 0.0, W1[k])


def train(X: np.ndarray, Y: np.ndarray, *, seed: int = DEFAULT_SEED, val_frac: float = VAL_FRAC, max_epochs: int = MAX_EPOCHS,
          patience: int = PATIENCE, lr: float = LEARNING_RATE, l2: float = L2, monotone: bool = True
          ) -> tuple[np.ndarray, dict]:
    """(parameter vector, info) of a network fitted to time-ordered rows X (n × 5) → Y (n × 2), non-finite rows left out.

    The newest `val_frac` of the rows (at least one, if there are two or more) are the validation rows
    of early stopping; `monotone`: keep the network monotone (see MONO_*); info: n_train,
    n_val, best_epoch, epochs, val_mse (standardised units).
    """
    ok = np.isfinite(X).all(axis=1) & np.isfinite(Y).all(axis=1)
    X, Y = X[ok], Y[ok]
    n = len(X)
    p = np.zeros(N_PARAMS)
    # the physical part stays 0 until `with_physical`: a zero physical form gives no ratio, the network stays clamped
    xm, xs, W1, b1, W2, b2, ym, ys = _unpack(p)
    if n == 0:
        xs[:], ys[:] = 1.0, 1.0
        p[_LO:_HI], p[_HI:N_NET] = -np.inf, np.inf
        return p, {"n_train": 0, "n_val": 0, "best_epoch": 0, "epochs": 0, "val_mse": float("nan")}
    n_val = min(max(int(round(n * val_frac)), 1), n - 1) if n >= 2 else 0
    n_fit = n - n_val
    p[_LO:_HI], p[_HI:N_NET] = X.min(axis=0), X.max(axis=0)
    xm[:], ym[:] = X[:n_fit].mean(axis=0), Y[:n_fit].mean(axis=0)
    xs[:] = np.where(X[:n_fit].std(axis=0) > 1e-12, X[:n_fit].std(axis=0), 1.0)
    ys[:] = np.where(Y[:n_fit].std(axis=0) > 1e-12, Y[:n_fit].std(axis=0), 1.0)
    Z, T = (X - xm) / xs, (Y - ym) / ys
    Zf, Tf, Zv, Tv = Z[:n_fit], T[:n_fit], Z[n_fit:], T[n_fit:]
    rng = np.random.default_rng(seed)
    W1[:] = rng.normal(0.0, 1.0 / math.sqrt(N_IN), W1.shape)
    W2[:] = rng.normal(0.0, 1.0 / math.sqrt(N_HIDDEN), W2.shape)
    params = (W1, b1, W2, b2)
    if monotone:  # start inside the constraints: signs flipped rather than weights zeroed
        half = N_HIDDEN // 2
        W2[:] = np.abs(W2)
        for r, k in enumerate(MONO_INPUTS):
            W1[k] = np.abs(W1[k]) * MONO_SIGN[r, (np.arange(N_HIDDEN) >= half).astype(int)]
        _project_monotone(W1, W2)
    m = [np.zeros_like(a) for a in params]
    v = [np.zeros_like(a) for a in params]
    b_1, b_2, eps = 0.9, 0.999, 1e-8
    best, best_p, best_epoch, since = np.inf, p.copy(), 0, 0
    epoch = 0
    for epoch in range(1, max_epochs + 1):
        H = np.tanh(Zf @ W1 + b1)
        E = H @ W2 + b2 - Tf
        dO = E * (2.0 / E.size)
        dH = (dO @ W2.T) * (1.0 - H * H)
        grads = (Zf.T @ dH + 2 * l2 * W1, dH.sum(axis=0), H.T @ dO + 2 * l2 * W2, dO.sum(axis=0))
        for a, g, mi, vi in zip(params, grads, m, v):
            mi *= b_1
            mi += (1 - b_1) * g
            vi *= b_2
            vi += (1 - b_2) * g * g
            a -= lr * (mi / (1 - b_1 ** epoch)) / (np.sqrt(vi / (1 - b_2 ** epoch)) + eps)
        if monotone:
            _project_monotone(W1, W2)
        if n_val:
            val = float(np.mean((np.tanh(Zv @ W1 + b1) @ W2 + b2 - Tv) ** 2))
        else:
            val = float(np.mean(E * E))
        if val < best - 1e-12:
            best, best_epoch, since = val, epoch, 0
            best_p[:] = p
        else:
            since += 1
            if since >= patience:
                break
    return best_p, {"n_train": n_fit, "n_val": n_val, "best_epoch": best_epoch, "epochs": epoch, "val_mse": best}
