"""Least-squares fits of the speed and fuel models, with diagnostics (the activation rule is in `refit`).

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

import numpy as np

from pipeline.performance import features, fit_kernels

K_FOLDS = 5
ROBUST_ITERATIONS = 8  # at most this many iteratively re-weighted least-squares solves with Huber weights
ROBUST_RTOL = 1e-5  # ... stopping once no coefficient moves by more than this (relative to the largest)
HUBER_K = 1.345


@dataclass(slots=True)
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


class FitBatch(list):
    """`FitResult`s of a batch of groups (one per group), with their coefficients as one matrix: `coef` (groups ×
    regressors), whose rows are the results' `coef`."""

    coef: np.ndarray


def coef_matrix(results: list[FitResult], groups=None) -> np.ndarray:
    """The coefficients of `results` (of `results[groups]`) as a matrix, one row per result."""
    m = getattr(results, "coef", None)
    if m is None:
        m = np.array([r.coef for r in results])
    return m if groups is None else m[np.asarray(groups, dtype=np.int64)]


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


def robust_default(form: str) -> bool:
    """Whether `form` is fitted with Huber re-weighting unless told otherwise (the thesis form is not)."""
    return features.ROBUST_DEFAULT[features.FORM_IDS[form]]


def design(form: str, target: str, inp: dict[str, np.ndarray]) -> np.ndarray:
    return features.design_matrix(features.FORM_IDS[form], target, inp["rpm"], inp["draft_m"], inp["trim_m"], inp["wind_kn"],
                                  inp["wind_rel_deg"], inp["hs_m"], inp["wave_rel_deg"], inp["months_dd"])


def designs(form: str, inp: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """{"speed": X, "fuel": X}: both design matrices in one pass over the inputs."""
    Xs, Xf = features.design_matrices(features.FORM_IDS[form], inp["rpm"], inp["draft_m"], inp["trim_m"], inp["wind_kn"],
                                      inp["wind_rel_deg"], inp["hs_m"], inp["wave_rel_deg"], inp["months_dd"])
    return {"speed": Xs, "fuel": Xf}


def fit_target(form: str, target: str, X: np.ndarray, y: np.ndarray, *, robust: bool = False, k_folds: int = K_FOLDS) -> FitResult:
    """Least squares of y on X (regressor names from `features`); all-zero regressors are dropped (β = 0).

    Constant columns: in a form with an intercept ("1") the others are dropped (they cannot be told
    apart from it); in a form without one (`features.KEEP_CONSTANT`, the thesis form) they are kept,
    being its only constant term. With `robust`, Huber
    weights (scale 1.4826·MAD) are re-estimated until the coefficients settle (ROBUST_RTOL), at most
    ROBUST_ITERATIONS solves.
    """
    return fit_targets(form, target, X, y, np.array([0, len(y)]), robust=robust, k_folds=k_folds)[0]


def fit_targets(form: str, target: str, X: np.ndarray, y: np.ndarray, bounds: np.ndarray, *, robust: bool = False,
                k_folds: int = K_FOLDS, start: np.ndarray | None = None, max_solves: int | None = None,
                ends: np.ndarray | None = None, rtol: float = ROBUST_RTOL) -> FitBatch:
    """`fit_target` for many groups (vessels) at once; group g is rows bounds[g]:bounds[g+1] of X and y
    — or, with `ends`, rows bounds[g]:ends[g] (groups need not tile X: no copy of the rows fitted).

    Weather and fouling regressors (`features.NON_NEGATIVE`, `features.NON_POSITIVE_SPEED`: fouling never speeds a
    ship up nor saves fuel) are held to their sign: one that comes out the wrong way is left out (β = 0, listed in
    `dropped`) and the rest solved again. Rows with a non-finite regressor or
    target are left out (per group, order kept). Each group
    stops re-weighting when its own coefficients settle, so it gets what `fit_target` gives it alone.
    `start` (groups × regressors): coefficients the robust re-weighting starts from (fewer solves when
    they are close, e.g. a fit of most of the same rows); `max_solves` caps the re-weighted solves (default
    ROBUST_ITERATIONS) and `rtol` the step that counts as settled; k_folds < 2: no cross-validation (cv_rmse NaN).
    """
    fid = features.FORM_IDS[form]
    names = (features.SPEED_REGRESSORS if target == "speed" else features.FUEL_REGRESSORS)[fid]
    X = np.ascontiguousarray(X, dtype=np.float64)
    y = np.ascontiguousarray(y, dtype=np.float64)
    bounds = np.ascontiguousarray(bounds, dtype=np.int64)
    starts, ends = (bounds[:-1], bounds[1:]) if ends is None else (bounds, np.ascontiguousarray(ends, dtype=np.int64))
    G, k = starts.size, X.shape[1]
    keep_all = features.KEEP_CONSTANT[fid]
    intercept = np.array([keep_all or nm == "1" for nm in names], dtype=np.bool_)  # constant but kept (if non-zero)
    coef, keep = np.zeros((G, k)), np.zeros((G, k), dtype=np.bool_)
    n, stats = np.zeros(G, dtype=np.int64), np.full((G, 3), np.nan)  # r2, rmse, cv_rmse
    nonneg = np.array([nm in features.NON_NEGATIVE for nm in names], dtype=np.bool_)
    # a coefficient held ≤ 0 (fouling on speed) is fitted as a ≥ 0 one on the negated regressor
    flip = np.array([target == "speed" and nm in features.NON_POSITIVE_SPEED for nm in names], dtype=np.bool_)
    warm = start is not None
    beta0 = np.ascontiguousarray(start, dtype=np.float64) if warm else np.zeros((G, k))
    sign = np.where(flip, -1.0, 1.0)  # the kernel fits on X·diag(sign): no copy of X
    if flip.any():
        nonneg = nonneg | flip
        beta0 = np.ascontiguousarray(np.where(flip, -beta0, beta0))
    solves = (max_solves or ROBUST_ITERATIONS) if robust else 1
    rule = fit_kernels.FitRule(intercept, nonneg, bool(robust), int(solves), float(rtol), float(HUBER_K),
                               max(int(k_folds), 1), bool(warm))
    fit_kernels.fit_groups_nb(fit_kernels.FitRows(X, sign, y), np.ascontiguousarray(starts), np.ascontiguousarray(ends),
                              rule, beta0, coef, keep, n, stats)
    if flip.any():
        coef[:, flip] *= -1.0
    out, dropped_for = FitBatch(), {}
    out.coef = coef
    for g, (kept, n_g, (r2, rmse, cv)) in enumerate(zip(map(tuple, keep.tolist()), n.tolist(), stats.tolist())):
        if kept not in dropped_for:
            dropped_for[kept] = [nm for nm, kp in zip(names, kept) if not kp]
        out.append(FitResult(form, target, names, coef[g], n_g, r2, rmse, cv, list(dropped_for[kept]), robust))
    return out


def holdout_start(n, frac: float = 0.2):
    """Index of the first held-out row for (an array of) group sizes n (round half to even): the newest `frac`
    of each group's time-ordered rows are held out (see `refit._split`)."""
    return np.round(np.asarray(n) * (1.0 - frac)).astype(np.int64)
