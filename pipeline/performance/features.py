"""Regressors of the performance models: the one definition used by fitting and by routing.

Inputs (all arrays or scalars):
  rpm               engine revolutions per minute
  draft_m, trim_m   mean draft and trim (m, trim > 0 by the stern)
  wind_kn           true wind speed (kn)
  wind_rel_deg      direction the wind comes FROM relative to the heading: 0 head, 180 following
  hs_m              significant wave height (m)
  wave_rel_deg      direction the waves come FROM relative to the heading: 0 head, 180 following
  months_dd         months since dry dock (hull fouling)

Each form maps these inputs to a row of regressors; a model is a coefficient vector per target
(speed through water in kn, fuel rate in t/h) and the prediction is the dot product. The
`*_nb` functions are numba-compiled and callable from routing kernels with plain scalars.

Forms (ids are what numba kernels take):
  FORM_THESIS = 0   V = a1·D + a2·T + a3·rpm + a4·WindDir + a5·WindSpd + a6·WaveDir + a7·WaveHt
                    (no intercept, relative directions in degrees 0..180, 0 in a calm); fuel the same form.
  FORM_PHYSICAL = 1 speed = calm(1, rpm, D, T, months) − loss,  loss = a_w·Vw²·w(θw) + a_s·Hs²·w(θs)
                    fuel  = calm(1, r³, r³·D, r³·months) + b_w·Vw²·w(θw) + b_s·Hs²·w(θs)   (r = rpm/100)
                    The weather terms enter the speed regressors negated ("wind_loss", "wave_loss") so
                    that every weather coefficient is ≥ 0: the fit holds them there (a term that comes
                    out as a gain is left out), so weather is never a gain. w(θ) is the direction
                    shape of Kwon's speed-loss coefficients (Beaufort 6, normalised to head seas):
                    1 head-on, 0.45 on the beam, 0.14 following. Predictions bound the loss to
                    MAX_SPEED_LOSS_SHARE of the calm-water speed and never put fuel below the
                    calm-water rate at the same rpm (nor the extra above MAX_FUEL_ADD_SHARE of it).
  FORM_MLP = 2      a 5-30-2 network, speed and fuel from the same inputs (see `mlp`); its "coefficients"
                    are the network's parameter vector, the same for both targets. No design matrix.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from pipeline.performance import mlp

FORM_THESIS = 0
FORM_PHYSICAL = 1
FORM_MLP = 2
FORM_IDS = {"thesis": FORM_THESIS, "physical": FORM_PHYSICAL, "mlp": FORM_MLP}

SPEED_REGRESSORS = {
    FORM_THESIS: ("draft_m", "trim_m", "rpm", "wind_dir_rel_deg", "wind_kn", "wave_dir_rel_deg", "wave_m"),
    FORM_PHYSICAL: ("1", "rpm", "draft_m", "trim_m", "wind_loss", "wave_loss", "months_dd"),
    FORM_MLP: mlp.PARAM_NAMES,
}
FUEL_REGRESSORS = {
    FORM_THESIS: SPEED_REGRESSORS[FORM_THESIS],
    FORM_PHYSICAL: ("1", "r3", "r3_draft", "r3_months", "wind_load", "wave_load"),
    FORM_MLP: mlp.PARAM_NAMES,
}
NON_NEGATIVE = {"wind_loss", "wave_loss", "wind_load", "wave_load"}  # weather costs speed and fuel, never gives
# fouling (months since dry dock) costs speed and fuel, never gives: the speed coefficient is held ≤ 0, the fuel one ≥ 0
FOULING_SPEED, FOULING_FUEL = "months_dd", "r3_months"
NON_POSITIVE_SPEED = {FOULING_SPEED}
NON_NEGATIVE |= {FOULING_FUEL}
N_SPEED = {k: len(v) for k, v in SPEED_REGRESSORS.items()}
# The thesis form has no intercept, so a constant column (e.g. a trim that never changes) is the only
# constant term and stays in the fit; a form with an intercept "1" drops its other constant columns.
KEEP_CONSTANT = {FORM_THESIS: True, FORM_PHYSICAL: False, FORM_MLP: False}
# Huber re-weighting by default: the thesis form is published as ordinary least squares.
ROBUST_DEFAULT = {FORM_THESIS: False, FORM_PHYSICAL: True, FORM_MLP: False}
N_FUEL = {k: len(v) for k, v in FUEL_REGRESSORS.items()}
assert (N_SPEED[FORM_PHYSICAL], N_FUEL[FORM_PHYSICAL]) == (mlp.N_PHYSICAL_SPEED, mlp.N_PHYSICAL_FUEL)  # the network's fallback


@numba.njit(cache=True, inline="always")
def fold_rel_deg(rel_deg: float) -> float:
    """Relative direction folded to 0..180 (port and starboard alike): |((rel + 180) mod 360) − 180|."""
    t = rel_deg + 180.0
    if 0.0 <= t < 360.0:  # the mod of the usual inputs without a division: same values exactly
        m = t
    elif 360.0 <= t < 720.0:
        m = t - 360.0  # exact (Sterbenz)
    else:
        m = t % 360.0
    return abs(m - 180.0)


# w(θ) = DIR_A + DIR_B·cos θ + DIR_C·cos² θ through Kwon's 2Cβ at Beaufort 6 (2, 0.9, 0.28 head, beam,
# following), normalised: w(0) = 1, w(90°) = 0.45, w(180°) = 0.14, falling all the way round.
DIR_A, DIR_B, DIR_C = 0.45, 0.43, 0.12
MAX_SPEED_LOSS_SHARE = 0.5  # weather takes at most half the calm-water speed
MAX_FUEL_ADD_SHARE = 1.0  # ... and at most doubles the calm-water fuel rate at the same rpm


@numba.njit(cache=True, inline="always")
def direction_weight(rel_deg: float) -> float:
    """Share of the head-on loss at relative direction rel_deg (0 head, 180 following; either side)."""
    c = math.cos(math.radians(fold_rel_deg(rel_deg)))
    return DIR_A + DIR_B * c + DIR_C * c * c


def direction_weight_array(rel_deg) -> np.ndarray:
    """`direction_weight` of an array (numpy)."""
    rel = np.asarray(rel_deg, dtype=np.float64)
    c = np.cos(np.radians(np.abs(((rel + 180.0) % 360.0) - 180.0)))
    return DIR_A + DIR_B * c + DIR_C * c * c


def mlp_inputs(rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m, wave_rel_deg) -> np.ndarray:
    """The MLP form's input matrix (n × 5) from broadcastable model inputs (see the `mlp` module docstring)."""
    cols = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m,
                                                                            wave_rel_deg)))
    rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m, wave_rel_deg = (c.ravel() for c in cols)
    return np.column_stack([rpm, draft_m, trim_m, wind_kn * direction_weight_array(wind_rel_deg),
                            hs_m * direction_weight_array(wave_rel_deg)])


@numba.njit(cache=True, inline="always")
def calm_dir_deg(amount, rel_deg):
    """The folded relative direction (0..180) of wind or waves, 0 when there are none (amount ≤ 0).

    A calm has no direction: routing derives it from atan2(−0, −0) = −180°, which would make the
    thesis form's linear direction term, and so calm-water speed and fuel, depend on the heading.
    0 is what the thesis's own records show for no waves (0/0).
    """
    return fold_rel_deg(rel_deg) if amount > 0.0 else 0.0


@numba.njit(cache=True, inline="always")
def weather_terms_nb(wind_kn, wind_rel_deg, hs_m, wave_rel_deg):
    """The physical form's weather loads (speed and fuel alike, ≥ 0): (Vw²·w(θw), Hs²·w(θs))."""
    return wind_kn * wind_kn * direction_weight(wind_rel_deg), hs_m * hs_m * direction_weight(wave_rel_deg)


@numba.njit(cache=True, inline="always")
def _speed_physical(rpm, draft_m, trim_m, wind_term, wave_term, months_dd, out):
    out[0] = 1.0
    out[1] = rpm
    out[2] = draft_m
    out[3] = trim_m
    out[4] = -wind_term
    out[5] = -wave_term
    out[6] = months_dd


@numba.njit(cache=True, inline="always")
def _fuel_physical(rpm, draft_m, months_dd, wind_term, wave_term, out):
    r = rpm / 100.0
    r3 = r * r * r
    out[0] = 1.0
    out[1] = r3
    out[2] = r3 * draft_m
    out[3] = r3 * months_dd
    out[4] = wind_term
    out[5] = wave_term


@numba.njit(cache=True)
def speed_row_nb(form, rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m, wave_rel_deg, months_dd, out):
    """Fill `out` with the speed regressors of one observation."""
    if form == FORM_THESIS:
        out[0] = draft_m
        out[1] = trim_m
        out[2] = rpm
        out[3] = calm_dir_deg(wind_kn, wind_rel_deg)
        out[4] = wind_kn
        out[5] = calm_dir_deg(hs_m, wave_rel_deg)
        out[6] = hs_m
    else:
        wind_term, wave_term = weather_terms_nb(wind_kn, wind_rel_deg, hs_m, wave_rel_deg)
        _speed_physical(rpm, draft_m, trim_m, wind_term, wave_term, months_dd, out)


@numba.njit(cache=True)
def fuel_row_nb(form, rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m, wave_rel_deg, months_dd, out):
    """Fill `out` with the fuel-rate regressors of one observation."""
    if form == FORM_THESIS:
        speed_row_nb(form, rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m, wave_rel_deg, months_dd, out)
        return
    wind_term, wave_term = weather_terms_nb(wind_kn, wind_rel_deg, hs_m, wave_rel_deg)
    _fuel_physical(rpm, draft_m, months_dd, wind_term, wave_term, out)


@numba.njit(cache=True, inline="always")
def _stw_physical_nb(coef, rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m, wave_rel_deg, months_dd):
    wind_term, wave_term = weather_terms_nb(wind_kn, wind_rel_deg, hs_m, wave_rel_deg)
    return stw_physical_terms_nb(coef, rpm, draft_m, trim_m, months_dd, wind_term, wave_term)


@numba.njit(cache=True, inline="always")
def stw_physical_terms_nb(coef, rpm, draft_m, trim_m, months_dd, wind_term, wave_term):
    """The physical form's STW from its weather loads (`weather_terms_nb`): what `stw_kn_nb` gives, for a caller that
    evaluates many conditions sharing the same directions (the sanity grid)."""
    calm = coef[0] + coef[1] * rpm + coef[2] * draft_m + coef[3] * trim_m + coef[6] * months_dd
    loss = max(coef[4] * wind_term + coef[5] * wave_term, 0.0)
    return max(calm - min(loss, MAX_SPEED_LOSS_SHARE * max(calm, 0.0)), 0.0)


@numba.njit(cache=True, inline="always")
def _fuel_physical_nb(coef, rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m, wave_rel_deg, months_dd):
    wind_term, wave_term = weather_terms_nb(wind_kn, wind_rel_deg, hs_m, wave_rel_deg)
    return fuel_physical_terms_nb(coef, rpm, draft_m, months_dd, wind_term, wave_term)


@numba.njit(cache=True, inline="always")
def fuel_physical_terms_nb(coef, rpm, draft_m, months_dd, wind_term, wave_term):
    """The physical form's fuel rate from its weather loads (as `stw_physical_terms_nb`)."""
    r = rpm / 100.0
    r3 = r * r * r
    calm = max(coef[0] + coef[1] * r3 + coef[2] * r3 * draft_m + coef[3] * r3 * months_dd, 0.0)
    extra = max(coef[4] * wind_term + coef[5] * wave_term, 0.0)
    return calm + min(extra, MAX_FUEL_ADD_SHARE * calm)


@numba.njit(cache=True)
def _mlp_guarded_nb(coef, out_index, rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m, wave_rel_deg, months_dd):
    """The network's speed (out_index 0) or fuel rate (1); outside its envelope, its value at the nearest edge plus
    the physical form's change (fitted on the same rows, its linear terms) from that edge to the point (see `mlp`)."""
    x3, x4 = wind_kn * direction_weight(wind_rel_deg), hs_m * direction_weight(wave_rel_deg)
    v = mlp.forward_nb(coef, rpm, draft_m, trim_m, x3, x4, out_index)
    outside, e = mlp.edge_nb(coef, rpm, draft_m, trim_m, x3, x4)
    if not outside:
        return v
    wind_e = wind_kn * e[3] / x3 if x3 > 0.0 else wind_kn  # the edge keeps the relative directions
    hs_e = hs_m * e[4] / x4 if x4 > 0.0 else hs_m
    if out_index == 0:
        c = coef[mlp.N_NET:mlp.N_NET + mlp.N_PHYSICAL_SPEED]
        at, edge = np.empty(c.size), np.empty(c.size)
        speed_row_nb(FORM_PHYSICAL, rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m, wave_rel_deg, months_dd, at)
        speed_row_nb(FORM_PHYSICAL, e[0], e[1], e[2], wind_e, wind_rel_deg, hs_e, wave_rel_deg, months_dd, edge)
    else:
        c = coef[mlp.N_NET + mlp.N_PHYSICAL_SPEED:mlp.N_PARAMS]
        at, edge = np.empty(c.size), np.empty(c.size)
        fuel_row_nb(FORM_PHYSICAL, rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m, wave_rel_deg, months_dd, at)
        fuel_row_nb(FORM_PHYSICAL, e[0], e[1], e[2], wind_e, wind_rel_deg, hs_e, wave_rel_deg, months_dd, edge)
    for k in range(c.size):
        v += c[k] * (at[k] - edge[k])
    return v


@numba.njit(cache=True)
def stw_kn_nb(form, coef, rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m, wave_rel_deg, months_dd):
    """Speed through water (kn) for one condition; never below 0. Physical form: the calm-water speed
    less a weather loss that is ≥ 0 and at most MAX_SPEED_LOSS_SHARE of it."""
    if form == FORM_MLP:
        return max(_mlp_guarded_nb(coef, 0, rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m, wave_rel_deg, months_dd), 0.0)
    if form == FORM_PHYSICAL:
        return _stw_physical_nb(coef, rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m, wave_rel_deg, months_dd)
    row = np.empty(coef.shape[0])
    speed_row_nb(form, rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m, wave_rel_deg, months_dd, row)
    v = 0.0
    for i in range(coef.shape[0]):
        v += coef[i] * row[i]
    return max(v, 0.0)


@numba.njit(cache=True)
def fuel_tph_nb(form, coef, rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m, wave_rel_deg, months_dd):
    """Fuel rate (t/h) for one condition; never below 0. Physical form: never below the calm-water rate
    at the same rpm, the weather adding at most MAX_FUEL_ADD_SHARE of it."""
    if form == FORM_MLP:
        return max(_mlp_guarded_nb(coef, 1, rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m, wave_rel_deg, months_dd), 0.0)
    if form == FORM_PHYSICAL:
        return _fuel_physical_nb(coef, rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m, wave_rel_deg, months_dd)
    row = np.empty(coef.shape[0])
    fuel_row_nb(form, rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m, wave_rel_deg, months_dd, row)
    f = 0.0
    for i in range(coef.shape[0]):
        f += coef[i] * row[i]
    return max(f, 0.0)


MODEL_INPUTS = ("rpm", "draft_m", "trim_m", "wind_kn", "wind_rel_deg", "hs_m", "wave_rel_deg", "months_dd")  # in call order


class Conditions(NamedTuple):
    """Conditions to predict at or observations to fit, one per row: equal-length float64 arrays, the model's inputs
    (MODEL_INPUTS) in call order."""

    rpm: np.ndarray
    draft_m: np.ndarray
    trim_m: np.ndarray
    wind_kn: np.ndarray
    wind_rel_deg: np.ndarray
    hs_m: np.ndarray
    wave_rel_deg: np.ndarray
    months_dd: np.ndarray


@numba.njit(cache=True)
def predict_nb(form, target_speed, coef, cond, out):
    """`stw_kn_nb` (target_speed) or `fuel_tph_nb` of every row of the Conditions `cond` into out."""
    rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m, wave_rel_deg, months_dd = cond
    for i in range(out.size):
        if target_speed:
            out[i] = stw_kn_nb(form, coef, rpm[i], draft_m[i], trim_m[i], wind_kn[i], wind_rel_deg[i], hs_m[i], wave_rel_deg[i],
                               months_dd[i])
        else:
            out[i] = fuel_tph_nb(form, coef, rpm[i], draft_m[i], trim_m[i], wind_kn[i], wind_rel_deg[i], hs_m[i], wave_rel_deg[i],
                                 months_dd[i])


@numba.njit(cache=True)
def predict_ranges_nb(form, target_speed, coefs, starts, ends, cond, out):
    """`predict_nb` of group g's coefficients coefs[g] at rows starts[g]:ends[g] of the Conditions `cond`, into
    consecutive slots of out."""
    rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m, wave_rel_deg, months_dd = cond
    q = 0
    for g in range(starts.size):
        c = coefs[g]
        for i in range(starts[g], ends[g]):
            if target_speed:
                out[q] = stw_kn_nb(form, c, rpm[i], draft_m[i], trim_m[i], wind_kn[i], wind_rel_deg[i], hs_m[i], wave_rel_deg[i],
                                   months_dd[i])
            else:
                out[q] = fuel_tph_nb(form, c, rpm[i], draft_m[i], trim_m[i], wind_kn[i], wind_rel_deg[i], hs_m[i],
                                     wave_rel_deg[i], months_dd[i])
            q += 1


@numba.njit(cache=True)
def predict_physical_ranges_nb(target_speed, coefs, starts, ends, cond, Xs, out):
    """`predict_ranges_nb` of the physical form, its weather loads read from the speed design matrix Xs (columns 4 and
    5 hold −Vw²·w(θw) and −Hs²·w(θs), `design_matrices`) instead of worked out again: the same values exactly."""
    rpm, draft_m, trim_m, months_dd = cond.rpm, cond.draft_m, cond.trim_m, cond.months_dd
    q = 0
    for g in range(starts.size):
        c = coefs[g]
        for i in range(starts[g], ends[g]):
            wind_term, wave_term = -Xs[i, 4], -Xs[i, 5]
            if target_speed:
                out[q] = stw_physical_terms_nb(c, rpm[i], draft_m[i], trim_m[i], months_dd[i], wind_term, wave_term)
            else:
                out[q] = fuel_physical_terms_nb(c, rpm[i], draft_m[i], months_dd[i], wind_term, wave_term)
            q += 1


def predict(form: int, target: str, coef, rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m, wave_rel_deg, months_dd) -> np.ndarray:
    """What routing gets (`stw_kn_nb` / `fuel_tph_nb`), for broadcastable inputs; flat float64 array."""
    cond = conditions(rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m, wave_rel_deg, months_dd)
    out = np.empty(cond.rpm.size)
    predict_nb(form, target == "speed", np.ascontiguousarray(coef, dtype=np.float64), cond, out)
    return out


def design_matrix(form: int, target: str, rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m, wave_rel_deg, months_dd) -> np.ndarray:
    """Regressor matrix (n_obs × n_regressors) for `target` in {"speed", "fuel"}."""
    _linear(form)
    cond = conditions(rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m, wave_rel_deg, months_dd)
    k = N_SPEED[form] if target == "speed" else N_FUEL[form]
    X = np.empty((cond.rpm.size, k))
    _fill_matrix(form, target == "speed", cond, X)
    return X


def design_matrices(form: int, rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m, wave_rel_deg, months_dd) -> tuple[np.ndarray, np.ndarray]:
    """(speed, fuel) regressor matrices, as `design_matrix` gives them, in one pass (weather terms computed once)."""
    _linear(form)
    cond = conditions(rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m, wave_rel_deg, months_dd)
    Xs, Xf = np.empty((cond.rpm.size, N_SPEED[form])), np.empty((cond.rpm.size, N_FUEL[form]))
    _fill_both(form, cond, Xs, Xf)
    return Xs, Xf


def _linear(form: int) -> None:
    if form == FORM_MLP:
        raise ValueError("the MLP form has no design matrix: its inputs are mlp_inputs(...)")


def conditions(rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m, wave_rel_deg, months_dd) -> Conditions:
    """Conditions of broadcastable inputs: each broadcast to the common shape, flat and float64."""
    cols = [np.asarray(a, dtype=np.float64) for a in (rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m, wave_rel_deg,
                                                      months_dd)]
    n = np.broadcast_shapes(*(c.shape for c in cols))
    return Conditions(*(np.broadcast_to(c, n).ravel() for c in cols))


@numba.njit(cache=True)
def _fill_matrix(form, speed, cond, X):
    rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m, wave_rel_deg, months_dd = cond
    for i in range(X.shape[0]):
        if speed:
            speed_row_nb(form, rpm[i], draft_m[i], trim_m[i], wind_kn[i], wind_rel_deg[i], hs_m[i], wave_rel_deg[i], months_dd[i], X[i])
        else:
            fuel_row_nb(form, rpm[i], draft_m[i], trim_m[i], wind_kn[i], wind_rel_deg[i], hs_m[i], wave_rel_deg[i], months_dd[i], X[i])


@numba.njit(cache=True)
def _fill_both(form, cond, Xs, Xf):
    rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m, wave_rel_deg, months_dd = cond
    for i in range(Xs.shape[0]):
        if form == FORM_THESIS:
            speed_row_nb(form, rpm[i], draft_m[i], trim_m[i], wind_kn[i], wind_rel_deg[i], hs_m[i], wave_rel_deg[i], months_dd[i], Xs[i])
            fuel_row_nb(form, rpm[i], draft_m[i], trim_m[i], wind_kn[i], wind_rel_deg[i], hs_m[i], wave_rel_deg[i], months_dd[i], Xf[i])
        else:
            wind_term, wave_term = weather_terms_nb(wind_kn[i], wind_rel_deg[i], hs_m[i], wave_rel_deg[i])
            _speed_physical(rpm[i], draft_m[i], trim_m[i], wind_term, wave_term, months_dd[i], Xs[i])
            _fuel_physical(rpm[i], draft_m[i], months_dd[i], wind_term, wave_term, Xf[i])
