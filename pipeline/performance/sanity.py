"""Physical sanity of a fitted model over its vessel's operating envelope, for every form.

A router exploits whatever a model gets wrong: a model in which head seas are faster than calm water, or
in which weather saves fuel, sends the ship into the storm. Before a model is activated it is evaluated
(as routing evaluates it) on a grid over the envelope of the reports it was fitted on — rpm and draft
from their least to their largest value, wind 0..largest and waves 0..largest, from five relative
directions (0 head … 180 following) — and must pass four checks, each with a small tolerance:

  head_weather_speed  STW does not rise as wind or waves from ahead (relative direction ≤ 45°) grow
  weather_fuel        weather never puts the fuel rate below the calm-water rate at the same rpm by more
                      than `fuel_allowance_share` of it (a following wind takes a little air resistance)
  rpm_speed           STW does not fall as rpm rises, and rises from the least to the largest rpm seen
  rpm_fuel            the fuel rate does not fall as rpm rises, and rises over the rpm range seen

A failure names the check and the worst grid point (`check_models`).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numba
import numpy as np

from pipeline.performance import features

N_RPM, N_DRAFT, N_WIND, N_WAVE = 5, 2, 3, 3
DIRECTIONS_DEG = (0.0, 45.0, 90.0, 135.0, 180.0)
AHEAD = (0, 1)  # indices of DIRECTIONS_DEG counted as "from ahead"
CHECKS = ("head_weather_speed", "weather_fuel", "rpm_speed", "rpm_fuel")


_ENVELOPE_JSON = '{"rpm": [%r, %r], "draft_m": [%r, %r], "wind_kn": %r, "hs_m": %r, "trim_m": %r, "months_dd": %r}'


@dataclass(frozen=True)
class Envelope:
    """The conditions a model was fitted on (ranges of its reports; weather from 0 up to the largest seen)."""

    rpm: tuple[float, float]
    draft_m: tuple[float, float]
    wind_kn: float  # largest true wind seen
    hs_m: float  # largest significant wave height seen
    trim_m: float = 0.0  # mean trim (held fixed on the grid)
    months_dd: float = 0.0  # months since dry dock of the newest report (held fixed on the grid)

    def to_json(self) -> str:
        values = (*self.rpm, *self.draft_m, self.wind_kn, self.hs_m, self.trim_m, self.months_dd)
        if all(type(v) is float and math.isfinite(v) for v in values):  # what json.dumps writes, from a template
            return _ENVELOPE_JSON % values
        return json.dumps({"rpm": list(self.rpm), "draft_m": list(self.draft_m), "wind_kn": self.wind_kn,
                           "hs_m": self.hs_m, "trim_m": self.trim_m, "months_dd": self.months_dd})

    @classmethod
    def from_json(cls, text: str | dict | None) -> "Envelope | None":
        if not text:
            return None
        d = json.loads(text) if isinstance(text, str) else text
        return cls(tuple(d["rpm"]), tuple(d["draft_m"]), float(d["wind_kn"]), float(d["hs_m"]),
                   float(d.get("trim_m", 0.0)), float(d.get("months_dd", 0.0)))

    def outside(self, rpm: float, draft_m: float, wind_kn: float, hs_m: float) -> list[str]:
        """What of the given conditions lies outside the envelope (empty: inside), e.g. ['rpm 130 > 122']."""
        out = []
        for name, v, lo, hi in (("rpm", rpm, *self.rpm), ("draft_m", draft_m, *self.draft_m),
                                ("wind_kn", wind_kn, 0.0, self.wind_kn), ("hs_m", hs_m, 0.0, self.hs_m)):
            if v < lo - 1e-9:
                out.append(f"{name} {v:g} < {lo:g}")
            elif v > hi + 1e-9:
                out.append(f"{name} {v:g} > {hi:g}")
        return out


def envelope_of(inp: dict[str, np.ndarray], start: int, stop: int) -> Envelope:
    """The envelope of rows start:stop of model inputs (`fit.inputs_from_reports`); NaNs left out."""
    return envelopes(inp, np.array([start]), np.array([stop]))[0]


def envelopes(inp: dict[str, np.ndarray], starts, stops) -> list[Envelope]:
    """`envelope_of` of the row ranges starts[g]:stops[g] (non-empty ones), in one compiled pass: least and
    largest rpm and draft, largest wind and waves, mean trim, months since dry dock of the last row."""
    return envelopes_until(inp, starts, stops, stops)[1]


def envelopes_until(inp: dict[str, np.ndarray], starts, splits, stops) -> tuple[list[Envelope], list[Envelope]]:
    """(`envelopes` of starts[g]:splits[g], `envelopes` of starts[g]:stops[g]) in one pass over the rows (e.g. of
    each vessel's training rows and of all its rows)."""
    until_split, until_stop = envelope_rows_until(inp, starts, splits, stops)
    return [until_split[g] for g in range(len(until_split))], [until_stop[g] for g in range(len(until_stop))]


class EnvelopeRows:
    """Envelopes as the rows of one (G, 8) array (least and largest rpm, least and largest draft, largest wind and
    waves, trim, months since dry dock), for a fleet: `check_models` reads the array, an `Envelope` is made only
    for the rows asked for (`rows[g]`), and `json(g)` is `rows[g].to_json()` without making it."""

    def __init__(self, values: np.ndarray):
        self.values = np.ascontiguousarray(values, dtype=np.float64).reshape(-1, 8)
        self._rows = self.values.tolist()  # Python floats, as `Envelope` holds them

    def __len__(self) -> int:
        return len(self._rows)

    def __getitem__(self, g: int) -> Envelope:
        v = self._rows[g]
        return Envelope((v[0], v[1]), (v[2], v[3]), v[4], v[5], v[6], v[7])

    def take(self, groups) -> "EnvelopeRows":
        return EnvelopeRows(self.values[np.asarray(groups, dtype=np.int64)])

    def json(self, g: int) -> str:
        v = self._rows[g]
        return _ENVELOPE_JSON % tuple(v) if all(map(math.isfinite, v)) else self[g].to_json()


def envelope_rows_until(inp: dict[str, np.ndarray], starts, splits, stops) -> tuple[EnvelopeRows, EnvelopeRows]:
    """`envelopes_until` as `EnvelopeRows` (no `Envelope` made)."""
    starts, splits, stops = (np.asarray(a, dtype=np.int64) for a in (starts, splits, stops))
    e = np.empty((2, starts.size, 8))
    if starts.size:
        cond = features.Conditions(*(np.ascontiguousarray(inp[c], dtype=np.float64) for c in features.MODEL_INPUTS))
        _envelopes_nb(cond, starts, splits, stops, e)
    return EnvelopeRows(e[0]), EnvelopeRows(e[1])


@numba.njit(cache=True)
def _envelopes_nb(cond, starts, splits, stops, out):
    """out[1, g] = (least and largest rpm, least and largest draft, largest wind and waves (≥ 0), mean trim, months since
    dry dock of the last row) of rows starts[g]:stops[g] of the features.Conditions `cond`, non-finite values left out,
    0 where there is none; out[0, g] the same of rows starts[g]:splits[g] (starts ≤ splits ≤ stops)."""
    rpm, draft, wind, hs, trim, months = cond.rpm, cond.draft_m, cond.wind_kn, cond.hs_m, cond.trim_m, cond.months_dd
    for g in range(starts.size):
        a, b = starts[g], stops[g]
        r_lo, r_hi, d_lo, d_hi, w_hi, h_hi = np.inf, -np.inf, np.inf, -np.inf, 0.0, 0.0
        t_sum, t_n = 0.0, 0
        for i in range(a, b + 1):
            if i == splits[g]:
                _envelope_row((r_lo, r_hi, d_lo, d_hi, w_hi, h_hi), t_sum, t_n, months[i - 1] if i > a else 0.0,
                              out[0, g])
            if i == b:
                break
            if np.isfinite(rpm[i]):
                r_lo, r_hi = min(r_lo, rpm[i]), max(r_hi, rpm[i])
            if np.isfinite(draft[i]):
                d_lo, d_hi = min(d_lo, draft[i]), max(d_hi, draft[i])
            if np.isfinite(wind[i]):
                w_hi = max(w_hi, wind[i])
            if np.isfinite(hs[i]):
                h_hi = max(h_hi, hs[i])
            if np.isfinite(trim[i]):
                t_sum += trim[i]
                t_n += 1
        _envelope_row((r_lo, r_hi, d_lo, d_hi, w_hi, h_hi), t_sum, t_n, months[b - 1] if b > a else 0.0, out[1, g])


@numba.njit(cache=True, inline="always")
def _envelope_row(ranges, t_sum, t_n, m, row):
    """row = the envelope: `ranges` (rpm least and largest, draft least and largest, wind and waves largest), the mean
    trim t_sum / t_n and the months m; 0 where not finite."""
    r_lo, r_hi, d_lo, d_hi, w_hi, h_hi = ranges
    vals = (r_lo, r_hi, d_lo, d_hi, w_hi, h_hi, t_sum / t_n if t_n else 0.0, m)
    for k in range(8):
        row[k] = vals[k] if np.isfinite(vals[k]) else 0.0


@dataclass(frozen=True)
class Limits:
    """Tolerances of the checks (kn, and shares of the calm-water fuel rate)."""

    speed_tol_kn: float = 0.05
    fuel_allowance_share: float = 0.03
    fuel_tol_share: float = 0.005


GRID_SHAPE = (N_RPM, N_DRAFT, N_WIND, N_WAVE, len(DIRECTIONS_DEG))
# the grid in units of each envelope's ranges (0..1), and the directions, flattened in GRID_SHAPE order
_U = np.meshgrid(np.linspace(0.0, 1.0, N_RPM), np.linspace(0.0, 1.0, N_DRAFT), np.linspace(0.0, 1.0, N_WIND),
                 np.linspace(0.0, 1.0, N_WAVE), np.asarray(DIRECTIONS_DEG), indexing="ij")
_U = [u.ravel() for u in _U]


def _grids(envelopes: list[Envelope]) -> list[np.ndarray]:
    """Inputs (features.MODEL_INPUTS order) on each envelope's (rpm, draft, wind, wave, direction) grid: arrays
    (G, grid points)."""
    e = np.array([(v.rpm[0], v.rpm[1], v.draft_m[0], v.draft_m[1], max(v.wind_kn, 0.0), max(v.hs_m, 0.0), v.trim_m, v.months_dd)
                  for v in envelopes], dtype=np.float64).reshape(-1, 8)
    m = _U[0].size
    rpm = e[:, :1] + (e[:, 1:2] - e[:, :1]) * _U[0]
    draft = e[:, 2:3] + (e[:, 3:4] - e[:, 2:3]) * _U[1]
    wind, wave = e[:, 4:5] * _U[2], e[:, 5:6] * _U[3]
    rel = np.broadcast_to(_U[4], (len(e), m))
    return [rpm, draft, np.repeat(e[:, 6:7], m, axis=1), wind, rel, wave, rel, np.repeat(e[:, 7:8], m, axis=1)]


def evaluate(form: str, speed_coefs: np.ndarray, fuel_coefs: np.ndarray, envelopes: list[Envelope]
             ) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """(STW, fuel rate) of model g (coefficient rows g) on envelope g's grid: arrays (G, *GRID_SHAPE), and the grid
    inputs (arrays (G, grid points), features.MODEL_INPUTS order)."""
    grid = _grids(envelopes)
    G, m = len(envelopes), _U[0].size
    cond = features.Conditions(*(np.ascontiguousarray(c, dtype=np.float64).ravel() for c in grid))
    starts = np.arange(G, dtype=np.int64) * m
    out = []
    for target, coefs in (("speed", speed_coefs), ("fuel", fuel_coefs)):
        o = np.empty(G * m)
        features.predict_ranges_nb(features.FORM_IDS[form], target == "speed", np.ascontiguousarray(coefs, dtype=np.float64),
                                   starts, starts + m, cond, o)
        out.append(o.reshape(G, *GRID_SHAPE))
    return out[0], out[1], grid


def _point(grid, g_idx: tuple[int, ...]) -> str:
    r, d, w, h, a = g_idx
    flat = np.ravel_multi_index(g_idx, GRID_SHAPE)
    rpm, draft, _, wind, rel, hs = grid[0][flat], grid[1][flat], grid[2][flat], grid[3][flat], grid[4][flat], grid[5][flat]
    return f"rpm {rpm:.4g}, draft {draft:.3g} m, wind {wind:.3g} kn and waves {hs:.3g} m from {rel:g}° relative"


def check_one(S: np.ndarray, F: np.ndarray, grid, limits: Limits = Limits()) -> str | None:
    """Why the model with STW S and fuel F (GRID_SHAPE) fails the sanity checks, or None. Names the check and the
    worst point."""
    if not (np.isfinite(S).all() and np.isfinite(F).all()):
        return "physical sanity (finite): the model gives a non-finite value on its envelope"
    tol = limits.speed_tol_kn
    # 1. head weather never speeds the ship up: along wind (waves fixed) and waves (wind fixed), from ahead
    ahead = S[..., list(AHEAD)]
    rise = np.full(ahead.shape, -np.inf)
    rise[:, :, 1:] = np.diff(ahead, axis=2)
    rise[:, :, :, 1:] = np.maximum(rise[:, :, :, 1:], np.diff(ahead, axis=3))
    i = np.unravel_index(int(np.argmax(rise)), rise.shape)
    if rise[i] > tol:
        idx = (*i[:4], AHEAD[i[4]])
        return (f"physical sanity (head_weather_speed): STW rises by {rise[i]:.3f} kn as wind or waves from ahead grow, "
                f"at {_point(grid, idx)}")
    # 2. weather never lowers fuel below calm at the same rpm (beyond an air-resistance allowance)
    calm = F[:, :, :1, :1, :1]
    below = (calm - F) - limits.fuel_allowance_share * np.abs(calm)
    i = np.unravel_index(int(np.argmax(below)), below.shape)
    if below[i] > 1e-9:
        return (f"physical sanity (weather_fuel): fuel {F[i]:.4g} t/h is below calm water's {calm[i[0], i[1], 0, 0, 0]:.4g} t/h "
                f"at the same rpm, at {_point(grid, i)}")
    # 3./4. STW and fuel rise with rpm
    for name, V, t, unit in (("rpm_speed", S, tol, "kn"), ("rpm_fuel", F, limits.fuel_tol_share * float(np.abs(F).max()), "t/h")):
        if N_RPM < 2:
            break
        fall = -np.diff(V, axis=0)
        i = np.unravel_index(int(np.argmax(fall)), fall.shape)
        what = "STW" if name == "rpm_speed" else "fuel rate"
        if fall[i] > t:
            return (f"physical sanity ({name}): {what} falls by {fall[i]:.3g} {unit} as rpm rises to the next grid step, "
                    f"at {_point(grid, i)}")
        total = V[-1, :, 0, 0, 0] - V[0, :, 0, 0, 0]
        rpm_lo, rpm_hi = grid[0][0], grid[0][-1]
        if rpm_hi - rpm_lo > 1e-6 and not (total > 0).all():
            d = int(np.argmin(total))
            return (f"physical sanity ({name}): calm-water {what} does not rise from {rpm_lo:.4g} to {rpm_hi:.4g} rpm "
                    f"({total[d]:+.3g} {unit}) at draft {grid[1][np.ravel_multi_index((0, d, 0, 0, 0), GRID_SHAPE)]:.3g} m")
    return None


def check_models(form: str, speed_coefs: np.ndarray, fuel_coefs: np.ndarray, envelopes: "list[Envelope] | EnvelopeRows",
                 limits: Limits = Limits()) -> list[str | None]:
    """Per model g (coefficient rows g, envelope g): why it fails the sanity checks (check and worst point), or None.
    The checks run on all models at once in one compiled pass (`_failing_nb`: the grid, each model's values on it
    and the checks of `check_one`, vessel by vessel, nothing stored); only a failing one is evaluated again
    (`check_one`) for its message."""
    if not len(envelopes):
        return []
    G = len(envelopes)
    if isinstance(envelopes, EnvelopeRows):
        e = envelopes.values.copy()
        e[:, 4:6] = np.maximum(e[:, 4:6], 0.0)
    else:
        e = np.array([(v.rpm[0], v.rpm[1], v.draft_m[0], v.draft_m[1], max(v.wind_kn, 0.0), max(v.hs_m, 0.0), v.trim_m,
                       v.months_dd) for v in envelopes], dtype=np.float64).reshape(-1, 8)
    bad = np.zeros(G, dtype=np.bool_)
    _failing_nb(features.FORM_IDS[form], np.ascontiguousarray(speed_coefs, dtype=np.float64).reshape(G, -1),
                np.ascontiguousarray(fuel_coefs, dtype=np.float64).reshape(G, -1), e, _AXES, _DIRECTIONS,
                (float(limits.speed_tol_kn), float(limits.fuel_allowance_share), float(limits.fuel_tol_share)), bad)
    out: list[str | None] = [None] * G
    failing = np.flatnonzero(bad)
    if failing.size:
        S, F, grids = evaluate(form, np.asarray(speed_coefs)[failing], np.asarray(fuel_coefs)[failing],
                               [envelopes[g] for g in failing])
        for j, g in enumerate(failing.tolist()):
            out[g] = check_one(S[j], F[j], [c[j] for c in grids], limits)
    return out


# each axis of the grid in units of the envelope's ranges (`_U` before the meshgrid), and the directions
_AXES = tuple(np.linspace(0.0, 1.0, n) for n in (N_RPM, N_DRAFT, N_WIND, N_WAVE))
_DIRECTIONS = np.asarray(DIRECTIONS_DEG, dtype=np.float64)


@numba.njit(cache=True)
def _failing_nb(form, speed_coefs, fuel_coefs, env, axes, directions, tols, bad):
    """bad[g]: whether model g fails a check of `check_one` on envelope g's grid (env[g]: rpm least and largest, draft
    least and largest, wind and waves largest, trim, months since dry dock) with the limits' tolerances `tols` =
    (speed_tol_kn, fuel_allowance_share, fuel_tol_share). The grid's inputs are those of `_grids`
    (same arithmetic), the values those of `features.stw_kn_nb` / `fuel_tph_nb` — for the physical form from the
    weather loads of each direction, computed once per grid rather than once per point (the same values)."""
    ur, ud, uw, uh = axes
    R, D, W, H, A = ur.size, ud.size, uw.size, uh.size, directions.size
    S = np.empty((R, D, W, H, A))
    F = np.empty((R, D, W, H, A))
    wdir = np.empty(A)
    for a in range(A):
        wdir[a] = features.direction_weight(directions[a])
    for g in range(speed_coefs.shape[0]):
        cs, cf = speed_coefs[g], fuel_coefs[g]
        rpm_lo, rpm_hi, d_lo, d_hi, wind_hi, hs_hi, trim, months = env[g]
        finite = True
        for r in range(R):
            rpm = rpm_lo + (rpm_hi - rpm_lo) * ur[r]
            for d in range(D):
                draft = d_lo + (d_hi - d_lo) * ud[d]
                for w in range(W):
                    wind = wind_hi * uw[w]
                    for h in range(H):
                        hs = hs_hi * uh[h]
                        for a in range(A):
                            if form == features.FORM_PHYSICAL:
                                wt, vt = wind * wind * wdir[a], hs * hs * wdir[a]
                                s = features.stw_physical_terms_nb(cs, rpm, draft, trim, months, wt, vt)
                                f = features.fuel_physical_terms_nb(cf, rpm, draft, months, wt, vt)
                            else:
                                s = features.stw_kn_nb(form, cs, rpm, draft, trim, wind, directions[a], hs, directions[a], months)
                                f = features.fuel_tph_nb(form, cf, rpm, draft, trim, wind, directions[a], hs, directions[a], months)
                            S[r, d, w, h, a], F[r, d, w, h, a] = s, f
                            finite &= np.isfinite(s) & np.isfinite(f)
        bad[g] = not finite or _fails(S, F, rpm_hi - rpm_lo > 1e-6, tols)


@numba.njit(cache=True)
def _fails(S, F, span, tols):
    """The checks of `check_one` on finite grids S and F (GRID_SHAPE), with `tols` as `_failing_nb`'s."""
    tol, allowance, fuel_tol_share = tols
    R, D, W, H, A = S.shape
    top = 0.0
    for r in range(R):
        for d in range(D):
            calm = F[r, d, 0, 0, 0]
            for w in range(W):
                for h in range(H):
                    for a in range(A):
                        top = max(top, abs(F[r, d, w, h, a]))
                        if (calm - F[r, d, w, h, a]) - allowance * abs(calm) > 1e-9:
                            return True  # weather_fuel
                        if a < 2:  # AHEAD
                            if w > 0 and S[r, d, w, h, a] - S[r, d, w - 1, h, a] > tol:
                                return True  # head_weather_speed, along the wind
                            if h > 0 and S[r, d, w, h, a] - S[r, d, w, h - 1, a] > tol:
                                return True  # ... along the waves
    if R < 2:
        return False
    for r in range(R - 1):
        for d in range(D):
            for w in range(W):
                for h in range(H):
                    for a in range(A):
                        if -(S[r + 1, d, w, h, a] - S[r, d, w, h, a]) > tol:
                            return True  # rpm_speed
                        if -(F[r + 1, d, w, h, a] - F[r, d, w, h, a]) > fuel_tol_share * top:
                            return True  # rpm_fuel
    if span:
        for d in range(D):
            if not (S[R - 1, d, 0, 0, 0] - S[0, d, 0, 0, 0] > 0) or not (F[R - 1, d, 0, 0, 0] - F[0, d, 0, 0, 0] > 0):
                return True  # calm water does not rise over the rpm range
    return False


def check_model(model, envelope: Envelope, limits: Limits = Limits()) -> str | None:
    """`check_models` for one `PerformanceModel`."""
    return check_models(model.form, model.speed_coef[None, :], model.fuel_coef[None, :], [envelope], limits)[0]

