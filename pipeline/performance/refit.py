"""Refit vessels' speed and fuel models, validated on reports they were not fitted on, behind a gate.

Per vessel, its reports in time order:
  1. the older rows train, the newest `Gate.holdout_frac` are held out and never fitted on;
  2. every candidate form is fitted on the training rows and scored on the held-out rows (RMSE of
     speed and fuel rate) — the same rows for every form and for the active model;
  3. a form is proposed among those that pass the gate (all, if none does): the physical form, unless
     another is better on the held-out rows by a margin, significantly (paired) and in every block of
     them (`_choose`: ties and chance wins go to the simpler form);
  4. it is activated only if it passes the absolute gate (enough rows per coefficient, fit R² of
     speed and fuel ≥ `min_r2`, held-out RMSE ≤ a share of the held-out mean, physical sanity over the
     envelope of its reports — see `sanity`), is not worse than the active model on the same held-out
     rows (whatever the active model's form), and the reports newer than the active model do not
     contradict it (a step change in its residuals, e.g. a broken speed log: the vessel is flagged and
     nothing is activated);
  5. the proposed model is refitted on all rows and that fit is stored — active if accepted and it
     passes the sanity checks again over the envelope of all rows, else `rejected` with the reason.
Nothing is stored twice: the same rows fitted with the same form and settings (`data_hash`) give
the same model, so a refit with nothing new stores nothing, and a form switched back to re-activates
the version it gave before (if it wins the comparison) instead of storing a copy.

A fleet is refitted in one pass (`refit_fleet`): the fits are batched across vessels (see
`fit.fit_targets`) and only the bookkeeping is per vessel. `refit_vessel` is the same code for one.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from dataclasses import dataclass, field

import numba
import numpy as np
import pandas as pd

from pipeline.performance import features, fit, mlp, sanity, screen
from pipeline.performance.sanity import Limits

TARGETS = ("speed", "fuel")
FORMS = tuple(features.FORM_IDS)  # the forms a refit can fit
BEST = "best"  # fit every candidate form and propose the best on held-out rows
DEFAULT_FORM = "physical"  # what a refit fits unless told otherwise (see `refit_fleet`)
REPORT_COLUMNS = ("imo", "ts_utc", *fit.INPUT_COLUMNS)  # what a refit reads of the noon reports
TRAIN_RTOL = 1e-2  # robust re-weighting of a candidate on its training rows stops when no coefficient moves more
ALL_ROWS_SOLVES = 1  # robust solves of an accepted model's refit on all rows, from the training fit
_HASHED = ("rpm", "draft_m", "trim_m", "wind_kn", "wind_rel_deg", "hs_m", "wave_rel_deg", "months_dd", "stw_kn", "fuel_tph")


@dataclass(frozen=True)
class Gate:
    """What a new model must pass to become active (units: shares of the held-out mean, kn and t/h)."""

    min_r2: float = 0.5  # fit R² of speed and of fuel rate
    max_speed_rmse_share: float = 0.10  # held-out speed RMSE ≤ this × mean held-out speed
    max_fuel_rmse_share: float = 0.15  # held-out fuel-rate RMSE ≤ this × mean held-out fuel rate
    not_worse: float = 1.02  # worse than the active model (speed or fuel, on the held-out rows it was not fitted
    worse_sigmas: float = 2.0  # on) means RMSE above this share of its RMSE *and* squared errors larger by more than
    # this many standard errors (paired): two fits of the same truth differ by a few % by chance
    holdout_frac: float = 0.2  # newest share of each vessel's reports held out (see `_split`)
    min_holdout_rows: int = 5
    min_rows_per_coef: int = 5  # training rows per fitted coefficient
    step_sigmas: float = 4.0  # new reports whose mean residual under the active model moved by more than
    min_new_rows: int = 3  # ... this many standard deviations (with at least this many new rows) are flagged
    candidates: tuple[str, ...] = FORMS  # the forms `form="best"` tries
    mlp_seed: int = mlp.DEFAULT_SEED  # the MLP form's weights are initialised from this seed
    mlp_min_rows: int = 100  # training rows the MLP form needs
    network_screen: bool = True  # best: train the MLP only where the physical form leaves structure it could learn
    sanity: bool = True  # physical-sanity checks over the vessel's envelope before activation (see `sanity`)
    speed_tol_kn: float = 0.05  # ... STW may rise this much with head weather or fall this much with rpm (grid step)
    fuel_allowance_share: float = 0.03  # ... weather may lower fuel below calm by this share of it (air resistance)
    switch_margin: float = 0.05  # best: another form replaces the physical one only if its held-out score is lower by
    switch_sigmas: float = 2.0  # this share, by more than this many standard errors (paired over held-out rows),
    switch_blocks: int = 3  # and lower in each of this many consecutive blocks of held-out rows (repeatable)
    hull_flag_pct: float = 5.0  # hull performance: a month's speed loss against a clean hull above this is flagged

    @property
    def limits(self) -> Limits:
        return sanity.Limits(speed_tol_kn=self.speed_tol_kn, fuel_allowance_share=self.fuel_allowance_share)


REFERENCE_FORM = "physical"  # "best" keeps it unless another form is significantly better
SIMPLICITY = ("physical", "thesis", "mlp")  # ties go to the earlier (simpler) form


def describe_gate(gate: Gate) -> str:
    """'default', or the settings that differ from the default gate ('min_rows_per_coef=3, min_r2=0.1')."""
    base = Gate()
    diff = [f"{f.name}={getattr(gate, f.name)!r}".replace("'", "") for f in dataclasses.fields(Gate)
            if getattr(gate, f.name) != getattr(base, f.name)]
    return ", ".join(diff) or "default"


def gate_with(gate: Gate, overrides: dict[str, str] | list[str] | None) -> Gate:
    """`gate` with settings given as text ("name=value" items or a mapping), typed like the default; ValueError naming
    the setting and the choices when one is unknown or not a value of its type."""
    if not overrides:
        return gate
    if not isinstance(overrides, dict):
        pairs = {}
        for item in overrides:
            if "=" not in item:
                raise ValueError(f"gate setting {item!r} is not NAME=VALUE (e.g. min_rows_per_coef=3)")
            k, v = item.split("=", 1)
            pairs[k.strip()] = v.strip()
        overrides = pairs
    names = {f.name: f for f in dataclasses.fields(Gate)}
    out = {}
    for k, v in overrides.items():
        if k not in names:
            raise ValueError(f"unknown gate setting {k!r}; use one of: {', '.join(names)}")
        default = getattr(Gate(), k)
        try:
            if isinstance(default, bool):
                if str(v).lower() not in ("true", "false", "1", "0", "yes", "no"):
                    raise ValueError(v)
                out[k] = str(v).lower() in ("true", "1", "yes")
            elif isinstance(default, tuple):
                out[k] = tuple(check_form(x.strip()) for x in str(v).split(",") if x.strip())
            else:
                out[k] = type(default)(v)
        except ValueError as exc:
            raise ValueError(f"gate setting {k}={v!r}: not a {type(default).__name__} ({exc})") from None
    return dataclasses.replace(gate, **out)


def check_form(form: str) -> str:
    """`form` if a refit can fit it ("best" or one of `FORMS`), else ValueError naming the choices."""
    if form != BEST and form not in FORMS:
        raise ValueError(f"unknown model form {form!r}; use one of: {', '.join((BEST, *FORMS))}")
    return form


def refit_vessel(imo: int, reports: pd.DataFrame, active: dict | None, version: int, *, form: str = DEFAULT_FORM,
                 robust: bool | None = None, gate: Gate = Gate(), fitted: dict | None = None) -> tuple[list[dict], dict]:
    """(perf_models rows, summary) for one vessel's time-ordered reports; see `refit_fleet`."""
    imo = int(imo)
    reports = {c: np.asarray(reports[c]) for c in reports.columns} if isinstance(reports, pd.DataFrame) else reports
    reports = {**reports, "imo": np.full(len(reports["rpm"]), imo)}
    rows, summaries = refit_fleet(reports, {imo: active} if active else {}, {imo: version}, form=form, robust=robust,
                                  gate=gate, fitted={imo: fitted[imo]} if fitted and imo in fitted else None)
    return rows, summaries[0]


def refit_fleet(reports, active: dict[int, dict], versions: dict[int, int], *, form: str = DEFAULT_FORM,
                robust: bool | None = None, gate: Gate = Gate(), fitted: dict[int, dict] | None = None
                ) -> tuple[list[dict], list[dict]]:
    """Refit every vessel in `reports` (time-ordered within each vessel), fitted together.

    `reports`: a DataFrame or a mapping of column → array (as `fleet_store.load_for_refit` gives)
    with `fit.INPUT_COLUMNS` and "imo" ("ts_utc" if there, else row order is time). `active`:
    imo → active model (`fleet_store.active_models`); `versions`: imo → version of new rows (1 if
    absent); `fitted`: imo → {data_hash: (version, active)} of stored models (`fitted_from_rows`).
    `form`: one of `FORMS` (default `DEFAULT_FORM`, the physical form: against truths outside every form it
    is what "best" chooses for each ship of `bench/models.py`, at a fraction of the cost, and the network chosen
    on a thin margin is what a router exploited), or "best" for every form in `gate.candidates`; `robust`: Huber
    re-weighting, None for each form's default. Returns (perf_models rows to insert, one summary
    per vessel in IMO order); a summary's "reactivate" names a stored version to make active again,
    its "flag" a contradiction between new reports and the active model.
    """
    check_form(form)
    forms = tuple(gate.candidates) if form == BEST else (form,)
    imo = np.asarray(reports["imo"], dtype=np.int64)
    if imo.size == 0:
        return [], []
    inp = fit.inputs_from_reports(reports)
    ts = _timestamps(reports, imo.size)
    if (np.diff(imo) < 0).any():
        order = np.argsort(imo, kind="stable")  # keeps each vessel's time order
        imo, ts, inp = imo[order], ts[order], {c: v[order] for c, v in inp.items()}
    first = np.flatnonzero(np.r_[True, imo[1:] != imo[:-1]])
    return _refit(imo[first], np.r_[first, imo.size], inp, ts, active, versions, forms, robust, gate, fitted or {})


def storage_actions(summaries: list[dict]) -> tuple[dict[int, tuple[int, str]], dict[int, str]]:
    """(imo → (version to re-activate, reason), imo → flag on its active model) from refit summaries,
    as `fleet_store.save_fits` takes them beside the new rows. Every refitted vessel gets its flag: None clears
    one set before (its contradicting reports were replaced or excluded)."""
    return ({s["imo"]: (s["reactivate"], s["reason"]) for s in summaries if s.get("reactivate")},
            {s["imo"]: s.get("flag") for s in summaries if "flag" in s})


def fitted_from_rows(rows) -> dict[int, dict]:
    """imo → {data_hash: (version, active)} from stored (imo, version, data_hash, active) rows."""
    out: dict[int, dict] = {}
    for imo, version, data_hash, active in rows:
        if data_hash:
            out.setdefault(int(imo), {})[data_hash] = (int(version), bool(active))
    return out


def _timestamps(reports, n: int) -> np.ndarray:
    try:
        ts = reports["ts_utc"]
    except KeyError:
        return np.arange(n).astype("datetime64[us]")  # row order is time order
    ts = np.asarray(ts)
    if ts.dtype.kind != "M":
        ts = pd.to_datetime(pd.Series(ts), utc=True).dt.tz_localize(None).to_numpy()
    return ts.astype("datetime64[us]", copy=False)


def _ranges(start: np.ndarray, stop: np.ndarray) -> np.ndarray:
    """Concatenated aranges start[g]:stop[g]."""
    size = stop - start
    total = int(size.sum())
    if total == 0:
        return np.zeros(0, dtype=np.int64)
    offs = np.cumsum(size) - size
    return np.repeat(start - offs, size) + np.arange(total)


def _group_mean(v: np.ndarray, which: np.ndarray, G: int) -> np.ndarray:
    cnt = np.bincount(which, minlength=G)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.bincount(which, weights=v, minlength=G) / cnt


def _rmse_by_group(y, pred, which, G):
    """RMSE of y − pred per group (non-finite pairs left out; NaN for a group with none)."""
    sq = (y - pred) ** 2
    ok = np.isfinite(sq)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.sqrt(np.bincount(which, weights=np.where(ok, sq, 0.0), minlength=G) / np.bincount(which, weights=ok, minlength=G))


def _predict(form: str, target: str, coefs: np.ndarray, starts: np.ndarray, ends: np.ndarray, inp,
             X: dict | None = None) -> np.ndarray:
    """Predictions, as routing computes them, of group g's model (coefs[g]) at rows starts[g]:ends[g], concatenated.
    X: the form's design matrices of the same rows (`_designs`), if made: the physical form's weather loads are read
    from them."""
    starts, ends = np.asarray(starts, dtype=np.int64), np.asarray(ends, dtype=np.int64)
    out = np.empty(int((ends - starts).sum()))
    cond = features.Conditions(*(np.ascontiguousarray(inp[c], dtype=np.float64) for c in features.MODEL_INPUTS))
    coefs = np.ascontiguousarray(coefs, dtype=np.float64)
    if form == "physical" and X is not None:
        features.predict_physical_ranges_nb(target == "speed", coefs, starts, ends, cond, X["speed"], out)
        return out
    features.predict_ranges_nb(features.FORM_IDS[form], target == "speed", coefs, starts, ends, cond, out)
    return out


def _usable(model: dict | None) -> bool:
    """An active model whose coefficients are those of a form as defined now (older definitions are not)."""
    if not model or model.get("form") not in FORMS:
        return False
    fid = features.FORM_IDS[model["form"]]
    return all(t in model and tuple(model[t]) == names
               for t, names in (("speed", features.SPEED_REGRESSORS[fid]), ("fuel", features.FUEL_REGRESSORS[fid])))


def _data_hashes(inp, ts, bounds, forms, robust_of, gate) -> dict[str, list[str]]:
    """form → per vessel, a digest of its rows (every value and timestamp), the form and the fit settings."""
    # one array type for all (contiguous, read-only views: no copy) so numba takes them as one tuple type
    cols = tuple(_read_only_bits(inp[c]) for c in _HASHED) + (_read_only_bits(ts.astype("datetime64[us]", copy=False)),)
    h = np.empty((bounds.size - 1, 2), dtype=np.uint64)
    _row_hashes_nb(cols, np.ascontiguousarray(bounds, dtype=np.int64), h)
    digests = [f"{a:016x}{b:016x}" for a, b in h.tolist()]
    out = {}
    for f in forms:
        tag = hashlib.blake2b(f"{f}|robust={robust_of[f]}|holdout={gate.holdout_frac}".encode(), digest_size=4).hexdigest()
        out[f] = [d + tag for d in digests]
    return out


def _read_only_bits(values: np.ndarray) -> np.ndarray:
    """The 8-byte values' bit patterns as a contiguous, read-only uint64 view (a copy only if not contiguous)."""
    bits = np.ascontiguousarray(values).view(np.uint64)
    bits.flags.writeable = False
    return bits


@numba.njit(cache=True)
def _row_hashes_nb(bits, bounds, out):
    """Two independent 64-bit FNV-1a-style hashes per group of the bit patterns of rows bounds[g]:bounds[g+1] of
    the columns `bits` (a tuple of uint64 views), row by row: a change to any value or timestamp changes them."""
    for g in range(bounds.size - 1):
        h1 = np.uint64(14695981039346656037)
        h2 = np.uint64(0x9E3779B97F4A7C15)
        for i in range(bounds[g], bounds[g + 1]):
            for j in range(len(bits)):
                v = bits[j][i]
                h1 = (h1 ^ v) * np.uint64(1099511628211)
                h2 = (h2 ^ (v >> np.uint64(7))) * np.uint64(0x100000001B3) + np.uint64(0x632BE59BD9B4E019)
        out[g, 0] = h1
        out[g, 1] = h2


@dataclass
class _Candidate:
    form: str
    robust: bool
    X: dict
    train: dict  # target → list[FitResult] fitted on the training rows
    hold_rmse: dict = field(default_factory=dict)  # target → per vessel
    hold_pred: dict = field(default_factory=dict)  # target → prediction at each held-out row (hold_rows order)
    sane: list = field(default_factory=list)  # per vessel: why the training fit fails the sanity checks, or None
    skipped: dict = field(default_factory=dict)  # vessel → why this form was not fitted for it (the network's screen)


def _refit(imos, bounds, inp, ts, active, versions, forms, robust, gate: Gate, fitted) -> tuple[list[dict], list[dict]]:
    """Vessel g is rows bounds[g]:bounds[g+1] of the model inputs `inp`."""
    G = imos.size
    n = np.diff(bounds)
    hold_from = _split(imos, bounds, ts, active, gate)
    hold_rows = _ranges(hold_from, bounds[1:])
    n_hold = bounds[1:] - hold_from
    hold_which = np.repeat(np.arange(G), n_hold)
    y = {"speed": inp["stw_kn"], "fuel": inp["fuel_tph"]}
    hold_mean = {t: _group_mean(y[t][hold_rows], hold_which, G) for t in TARGETS}

    robust_of = {f: fit.robust_default(f) if robust is None else bool(robust) for f in forms}
    train_env, all_env = sanity.envelope_rows_until(inp, bounds[:-1], hold_from, bounds[1:])  # of training rows, all rows
    cands = {}
    for form in sorted(forms, key=lambda f: f == "mlp"):  # the network last: its screen looks at the physical fit
        X = _designs(form, inp, {f: c.X for f, c in cands.items()})
        skipped = {}
        if form == "mlp" and len(forms) > 1 and "physical" in cands and gate.network_screen:
            skipped = _network_screen(cands["physical"], X, y, bounds, hold_from, gate)
        # no k-fold CV (the candidate is scored on the held-out rows instead); re-weighting stops at TRAIN_RTOL:
        # the candidate is only scored and, if accepted, the start of the refit on all rows
        c = _Candidate(form, robust_of[form], X, _fit_form(form, X, y, bounds[:-1], hold_from, robust_of[form], gate,
                                                           k_folds=0, rtol=TRAIN_RTOL, skip=skipped), skipped=skipped)
        for t in TARGETS:
            coefs = fit.coef_matrix(c.train[t])
            c.hold_pred[t] = _predict(form, t, coefs, hold_from, bounds[1:], inp, X)
            if skipped:
                c.hold_pred[t][np.isin(hold_which, list(skipped))] = np.nan
            c.hold_rmse[t] = _rmse_by_group(y[t][hold_rows], c.hold_pred[t], hold_which, G)
        cands[form] = c
    hashes = _data_hashes(inp, ts, bounds, forms, robust_of, gate)
    hold_bounds = np.r_[0, np.cumsum(n_hold)]
    act_hold, act_flag = _judge_active(imos, bounds, hold_from, inp, ts, y, active, gate)

    # per-vessel values as Python numbers: the loop below reads them one by one
    scores_of = {f: (c.hold_rmse["speed"] / hold_mean["speed"] + c.hold_rmse["fuel"] / hold_mean["fuel"]).tolist()
                 for f, c in cands.items()}
    rmse_of = {f: {t: c.hold_rmse[t].tolist() for t in TARGETS} for f, c in cands.items()}
    mean_of = {t: hold_mean[t].tolist() for t in TARGETS}
    n_list, n_hold_list = n.tolist(), n_hold.tolist()
    gate_text = describe_gate(gate)
    plans, summaries = [], []
    # the absolute gate, then physical sanity (`sanity`) of the training fits that pass it, all vessels at once
    gated = {f: [_gate(c, g, n_hold_list[g], rmse_of[f], mean_of, gate) for g in range(G)] for f, c in cands.items()}
    for f, c in cands.items():
        c.sane = [None] * G
        todo = [g for g in range(G) if gated[f][g] is None] if gate.sanity else []
        if todo:
            why = sanity.check_models(f, fit.coef_matrix(c.train["speed"], todo), fit.coef_matrix(c.train["fuel"], todo),
                                      train_env.take(todo), gate.limits)
            for g, w in zip(todo, why):
                c.sane[g] = w
    for g, imo in enumerate(imos.tolist()):
        verdicts = {f: gated[f][g] or cands[f].sane[g] for f in cands}
        score = {f: scores_of[f][g] for f in forms}
        passing = [f for f in forms if verdicts[f] is None and math.isfinite(score[f])]
        pool = passing or [f for f in forms if math.isfinite(score[f])] or list(forms)
        sl = slice(hold_bounds[g], hold_bounds[g + 1])
        best, choice = (pool[0], "") if len(pool) == 1 else _choose(pool, score, forms, {f: cands[f] for f in pool}, sl,
                                                                     hold_rows, y, mean_of, g, gate)
        c = cands[best]
        act = active.get(imo)
        why = act_flag.get(g) or verdicts[best]  # a contradiction with the active model is the first thing to fix
        if why is None and g in act_hold:
            unseen, old_pred = act_hold[g]  # held-out rows the active model was not fitted on (all if too few)
            sl = slice(hold_bounds[g], hold_bounds[g + 1])
            worse = []
            for t in TARGETS:
                obs = y[t][hold_rows[sl]][unseen]
                new_rm, old_rm, sig = _paired(obs, c.hold_pred[t][sl][unseen], old_pred[t][unseen], gate.worse_sigmas)
                if not new_rm <= gate.not_worse * old_rm and sig:
                    worse.append(f"{t} {new_rm:.4g} vs active {old_rm:.4g}")
            if worse:
                why = f"worse than the active model on the {unseen.sum()} held-out rows it was not fitted on: RMSE " + ", ".join(worse)
        activate = why is None
        scores = "; ".join(f"{f} speed {rmse_of[f]['speed'][g]:.3f} kn, fuel {rmse_of[f]['fuel'][g]:.4f} t/h" for f in forms)
        if activate:
            why = (f"passes the gate and is not worse on held-out rows than the active v{act['version']} ({act['form']})"
                   if g in act_hold
                   else "first model" if not act else "passes the gate (active model not comparable)")
        reason = f"{best}: {why}; held-out ({n_hold_list[g]} newest rows): {scores}" + (f"; {choice}" if choice else "")
        dropped = sorted({d for t in TARGETS for d in c.train[t][g].dropped})
        if dropped:
            reason += f"; left out (constant, or weather or fouling that came out as a gain): {', '.join(dropped)}"
        network = "mlp" in cands and g not in cands["mlp"].skipped
        if "mlp" in cands and not network:
            reason += f"; mlp not trained: {cands['mlp'].skipped[g]}"
        summary = {"imo": imo, "n": n_list[g], "n_holdout": n_hold_list[g], "form": best, "changed": False,
                   "why": why, "reason": reason, "version": act.get("version") if act else None,
                   "flag": act_flag.get(g), "speed_holdout_rmse": rmse_of[best]["speed"][g],
                   "fuel_holdout_rmse": rmse_of[best]["fuel"][g], "gate": gate_text, "network": network}
        seen = fitted.get(imo, {}).get(hashes[best][g])
        if seen is not None:  # these rows were fitted with this form before: the same model
            summary.update(_scores({t: c.train[t][g] for t in TARGETS}))  # (a stored fit gets those of its fit on all rows)
            version, is_active = seen
            if is_active:
                summary.update(why="same as the active model", reason=f"same rows and form as the active v{version}: nothing new")
            elif activate:
                summary.update(changed=True, version=version, reactivate=version,
                               reason=f"re-activates v{version} (same rows and form); {reason}")
            else:
                summary.update(reason=f"same rows and form as v{version}, not stored again; {reason}")
            summaries.append(summary)
            continue
        summary.update(changed=activate, version=versions.get(imo, 1))
        plans.append((g, imo, best, activate, summary, hashes[best][g]))
        summaries.append(summary)
    return _rows(plans, cands, bounds, inp, ts, y, all_env, n_hold, gate), summaries


def _designs(form: str, inp, built: dict | None = None) -> dict[str, np.ndarray]:
    """target → the form's regressors (least-squares forms) or the network's inputs (MLP, both targets, and under
    "physical" the physical form's regressors: the network carries that form fitted on the same rows). `built`:
    form → designs made already."""
    if form == "mlp":
        X = features.mlp_inputs(*(inp[c] for c in features.MODEL_INPUTS[:-1]))
        return {**{t: X for t in TARGETS}, "physical": (built or {}).get("physical") or fit.designs("physical", inp)}
    return fit.designs(form, inp)


def _network_screen(phys: _Candidate, X: dict, y: dict, bounds, hold_from, gate: Gate) -> dict[int, str]:
    """vessel → why the network is not trained for it: its physical training fit leaves too little structure in
    speed and in fuel for a model of the network's inputs to reach the switch margin (see `screen`)."""
    starts = bounds[:-1]
    rows = _ranges(starts, hold_from)
    resid = np.column_stack([y[t][rows] - np.einsum("ij,ij->i", phys.X[t][rows], np.repeat(
        fit.coef_matrix(phys.train[t]), hold_from - starts, axis=0)) for t in TARGETS])
    at = np.r_[0, np.cumsum(hold_from - starts)]
    r2 = screen.explained(X["speed"][rows], resid, at[:-1], at[1:])
    need = screen.share_needed(gate.switch_margin)
    return {g: (f"the physical form's residuals show no structure it could learn (a quadratic in its inputs explains "
                f"{100 * max(r2[g, 0], 0):.1f} % of speed and {100 * max(r2[g, 1], 0):.1f} % of fuel; "
                f"{100 * need:.2f} % needed for a {100 * gate.switch_margin:g} % better score)")
            for g in range(starts.size) if not (np.nanmax(np.r_[r2[g], -1.0]) >= need)}


def _fit_form(form, X, y, starts, ends, robust, gate: Gate, *, k_folds=fit.K_FOLDS, start=None, max_solves=None,
              rtol=fit.ROBUST_RTOL, skip=None) -> dict:
    """target → one `fit.FitResult` per group: group g is rows starts[g]:ends[g] of X and y. The network is not
    trained for the groups in `skip` (their results have NaN parameters)."""
    if form != "mlp":
        return {t: fit.fit_targets(form, t, X[t], y[t], starts, ends=ends, robust=robust, k_folds=k_folds,
                                   start=None if start is None else start[t], max_solves=max_solves, rtol=rtol) for t in TARGETS}
    skip = skip or {}
    trained = np.array([g for g in range(starts.size) if g not in skip], dtype=np.int64)
    phys = {t: fit.fit_targets("physical", t, X["physical"][t], y[t], starts[trained], ends=ends[trained],
                               robust=fit.robust_default("physical"), k_folds=0) for t in TARGETS}
    Y = np.column_stack([y["speed"], y["fuel"]])
    out = {t: [] for t in TARGETS}
    nan = np.full(mlp.N_PARAMS, np.nan)
    j = 0
    for g, (a, b) in enumerate(zip(starts.tolist(), ends.tolist())):
        if g in skip:
            for t in TARGETS:
                out[t].append(fit.FitResult("mlp", t, mlp.PARAM_NAMES, nan, 0, np.nan, np.nan, np.nan))
            continue
        p, _ = mlp.train(X["speed"][a:b], Y[a:b], seed=gate.mlp_seed)
        p = mlp.with_physical(p, phys["speed"][j].coef, phys["fuel"][j].coef)
        j += 1
        pred = mlp.forward(p, X["speed"][a:b])
        for k, t in enumerate(TARGETS):
            out[t].append(_result("mlp", t, p, Y[a:b, k], np.maximum(pred[:, k], 0.0)))
    return out


def _result(form: str, target: str, coef: np.ndarray, y: np.ndarray, pred: np.ndarray) -> fit.FitResult:
    ok = np.isfinite(y) & np.isfinite(pred)
    r = y[ok] - pred[ok]
    n = int(ok.sum())
    sst = float(((y[ok] - y[ok].mean()) ** 2).sum()) if n else 0.0
    return fit.FitResult(form, target, mlp.PARAM_NAMES, coef, n, 1.0 - float(r @ r) / sst if sst > 0 else float("nan"),
                         float(np.sqrt(np.mean(r * r))) if n else float("nan"), float("nan"))


def _split(imos, bounds, ts, active, gate: Gate) -> np.ndarray:
    """First held-out row of each vessel: the newest `holdout_frac` of its rows; but where the active
    model was fitted on rows beyond that point and at least `min_holdout_rows` are newer than it, the
    first of those, so that a candidate learns from at least what the active model learnt from and
    both are judged on reports neither was fitted on."""
    n = np.diff(bounds)
    hold_from = bounds[:-1] + np.minimum(fit.holdout_start(n, gate.holdout_frac), np.maximum(n - 1, 0))
    for g, imo in enumerate(map(int, imos)):
        since = (active.get(imo) or {}).get("data_to_utc")
        if since is None:
            continue
        a, b = bounds[g], bounds[g + 1]
        first_new = a + int(np.searchsorted(ts[a:b], np.datetime64(pd.Timestamp(since).to_datetime64(), "us"), side="right"))
        if b - first_new >= gate.min_holdout_rows:
            hold_from[g] = max(hold_from[g], first_new)
    return hold_from


def _gate(c: _Candidate, g: int, n_hold: int, hold_rmse: dict, hold_mean: dict, gate: Gate) -> str | None:
    """Why candidate c fails the absolute gate for vessel g, or None."""
    if g in c.skipped:
        return f"not trained: {c.skipped[g]}"
    for t in TARGETS:
        r = c.train[t][g]
        if c.form == "mlp":  # regularised by early stopping rather than counted per parameter
            if r.n < gate.mlp_min_rows:
                return f"too few reports for the network: {r.n} training rows (need ≥ {gate.mlp_min_rows})"
            continue
        n_coef = len(r.names) - len(r.dropped)
        need = gate.min_rows_per_coef * max(n_coef, 1)  # a ship whose rows leave no coefficient still needs some
        if r.n < need:
            return f"under-determined: {r.n} training rows for {n_coef} {t} coefficients (need ≥ {need})"
    if n_hold == 0:
        return "no held-out rows to validate on"
    for t in TARGETS:
        r2 = c.train[t][g].r2
        if not (r2 >= gate.min_r2):
            return f"{t} R² {r2:.3f} below {gate.min_r2:g}"
    for t, share in (("speed", gate.max_speed_rmse_share), ("fuel", gate.max_fuel_rmse_share)):
        rmse, mean = hold_rmse[t][g], hold_mean[t][g]
        if not (rmse <= share * mean):
            return f"held-out {t} RMSE {rmse:.4g} above {100 * share:g} % of its mean {mean:.4g}"
    return None


def _choose(pool, score, forms, cands, sl, hold_rows, y, mean_of, g, gate: Gate) -> tuple[str, str]:
    """(form to propose, why another was not) among the forms in `pool` for vessel g.

    The reference is the physical form (or the simplest form in the pool without it); a form with a lower
    held-out score replaces it only when the improvement is significant and repeatable: its score lower by
    `switch_margin` of the reference's, the mean paired difference of the rows' squared errors (speed and
    fuel, each relative to its held-out mean) above `switch_sigmas` standard errors, and lower in each of
    `switch_blocks` consecutive blocks of the held-out rows. A single form is taken as it is."""
    finite = [f for f in pool if np.isfinite(score[f])]
    if len(pool) == 1 or not finite:
        return min(pool, key=lambda f: (score[f] if np.isfinite(score[f]) else np.inf, forms.index(f))), ""
    ref = REFERENCE_FORM if REFERENCE_FORM in finite else min(finite, key=lambda f: (SIMPLICITY.index(f), score[f]))
    rows = hold_rows[sl]

    def row_err(f):
        c = cands[f]
        return sum(((y[t][rows] - c.hold_pred[t][sl]) / mean_of[t][g]) ** 2 for t in TARGETS)

    e_ref = row_err(ref)
    notes = []
    for f in sorted((f for f in finite if f != ref and score[f] < score[ref]), key=lambda f: score[f]):
        d = e_ref - row_err(f)
        d = d[np.isfinite(d)]
        gain = 1.0 - score[f] / score[ref]
        se = float(np.std(d, ddof=1) / np.sqrt(d.size)) if d.size > 1 else np.inf
        blocks = [b.mean() for b in np.array_split(d, max(int(gate.switch_blocks), 1)) if b.size]
        if gain >= gate.switch_margin and d.size > 1 and d.mean() > gate.switch_sigmas * se and min(blocks) > 0:
            return f, f"{f} chosen over {ref}: {100 * gain:.1f} % better on held-out rows ({d.mean() / se:.1f} σ, in every block)"
        why = ("below the margin" if gain < gate.switch_margin else
               f"not significant ({d.mean() / se if se > 0 else 0:.1f} σ)" if not d.mean() > gate.switch_sigmas * se
               else "not better in every block of held-out rows")
        notes.append(f"{f} {100 * gain:.1f} % better than {ref}, {why}: {ref} kept")
    return ref, "; ".join(notes)


def _paired(y, new, old, sigmas: float) -> tuple[float, float, bool]:
    """(RMSE of new, RMSE of old, whether new is worse by more than `sigmas` standard errors of the mean
    paired difference of squared errors) over the rows where both are finite."""
    a, b = (y - new) ** 2, (y - old) ** 2
    ok = np.isfinite(a) & np.isfinite(b)
    if not ok.any():
        return float("nan"), float("nan"), False
    d = a[ok] - b[ok]
    se = float(np.std(d, ddof=1) / np.sqrt(d.size)) if d.size > 1 else 0.0
    return float(np.sqrt(a[ok].mean())), float(np.sqrt(b[ok].mean())), bool(d.mean() > sigmas * se)


def _judge_active(imos, bounds, hold_from, inp, ts, y, active, gate: Gate) -> tuple[dict, dict]:
    """For vessels whose active model has a form as defined now: ({g: (mask over the vessel's held-out rows of
    those the active model was not fitted on — all of them if fewer than `min_new_rows` —, {target: its
    predictions on the held-out rows})}, {g: flag text}).

    The flag: the mean residual of the active model on the reports newer than it moved, against the
    reports it was fitted on, by more than `step_sigmas` of their standard deviation.
    """
    by_form: dict[str, list[int]] = {}
    for g, imo in enumerate(map(int, imos)):
        if _usable(active.get(imo)):
            by_form.setdefault(active[imo]["form"], []).append(g)
    hold, flags = {}, {}
    for form, groups in by_form.items():
        gi = np.array(groups)
        rows = _ranges(bounds[gi], bounds[gi + 1])
        pred = {t: _predict(form, t, np.array([list(active[int(imos[g])][t].values()) for g in groups], dtype=np.float64),
                            bounds[gi], bounds[gi + 1], inp) for t in TARGETS}
        starts = np.r_[0, np.cumsum(bounds[gi + 1] - bounds[gi])]
        for j, g in enumerate(groups):
            a = active[int(imos[g])]
            since = a.get("data_to_utc")
            sl = slice(starts[j], starts[j + 1])
            r_ts = ts[rows[sl]]
            new = (r_ts > np.datetime64(pd.Timestamp(since).to_datetime64(), "us")) if since is not None else np.ones(r_ts.size, bool)
            h = slice(hold_from[g] - bounds[g], None)
            unseen = new[h] if new[h].sum() >= gate.min_new_rows else np.ones(new[h].size, bool)
            hold[g] = (unseen, {t: pred[t][sl][h] for t in TARGETS})
            if since is None or new.sum() < gate.min_new_rows or (~new).sum() < gate.min_new_rows:
                continue
            for t in TARGETS:
                r = y[t][rows[sl]] - pred[t][sl]
                old_r, new_r = r[~new][np.isfinite(r[~new])], r[new][np.isfinite(r[new])]
                if old_r.size < gate.min_new_rows or new_r.size < gate.min_new_rows:
                    continue
                sd = float(np.std(old_r)) or 1e-12
                shift = float(np.mean(new_r) - np.mean(old_r))
                if abs(shift) > gate.step_sigmas * sd:
                    unit = "kn" if t == "speed" else "t/h"
                    flags[g] = (f"new reports contradict the active model: {t} residuals stepped by {shift:+.3g} {unit} "
                                f"({shift / sd:+.1f} σ) over {new_r.size} reports since {pd.Timestamp(since)}; check the "
                                f"{'speed log' if t == 'speed' else 'fuel meters'} before these reports are used")
                    break
    return hold, flags


def _coefficients_json_of(results: list[fit.FitResult]) -> list[str]:
    """`json.dumps(r.coefficients())` of each result, formatted from a template where every value is finite (cheaper):
    one template per list of regressors, its results' coefficients checked and made Python floats together."""
    out: list[str] = [""] * len(results)
    by_names: dict[tuple, list[int]] = {}
    for i, r in enumerate(results):
        by_names.setdefault(r.names, []).append(i)
    for names, at in by_names.items():
        template = _TEMPLATES.get(names)
        if template is None:
            template = _TEMPLATES[names] = "{" + ", ".join(json.dumps(nm) + ": %r" for nm in names) + "}"
        coefs = np.array([results[i].coef for i in at], dtype=np.float64).reshape(len(at), len(names))
        for i, values, finite in zip(at, map(tuple, coefs.tolist()), np.isfinite(coefs).all(axis=1).tolist()):
            out[i] = template % values if finite else json.dumps(results[i].coefficients())
    return out


_TEMPLATES: dict[tuple, str] = {}


def _scores(result: dict) -> dict:
    """Summary fields of a vessel's fit statistics: target → `fit.FitResult`."""
    s, f = result["speed"], result["fuel"]
    return {"speed_r2": s.r2, "speed_rmse": s.rmse, "speed_cv_rmse": s.cv_rmse,
            "fuel_r2": f.r2, "fuel_rmse": f.rmse, "fuel_cv_rmse": f.cv_rmse}


def _rows(plans, cands, bounds, inp, ts, y, all_env, n_hold, gate: Gate) -> list[dict]:
    """perf_models rows: every proposed model validated on the held-out rows and then refitted on all its vessel's
    rows (what is stored, active or not); an accepted one is activated only if that fit passes the sanity checks
    over the envelope of all the rows."""
    full, envs = {}, {}
    accepted = {p[0] for p in plans if p[3]}
    for form in {p[2] for p in plans}:
        gs = np.array([p[0] for p in plans if p[2] == form])
        c = cands[form]
        # re-weighting starts from the training fit's coefficients: ALL_ROWS_SOLVES weighted solves take it to
        # all rows (the Huber weights of the rows it was fitted on hardly change)
        res = _fit_form(form, c.X, y, bounds[gs], bounds[gs + 1], c.robust, gate, max_solves=ALL_ROWS_SOLVES,
                        start={t: fit.coef_matrix(c.train[t], gs) for t in TARGETS})
        env = all_env.take(gs)
        active = [j for j, g in enumerate(gs.tolist()) if g in accepted]
        sane = [None] * gs.size
        if gate.sanity and active:
            why = sanity.check_models(form, fit.coef_matrix(res["speed"], active), fit.coef_matrix(res["fuel"], active),
                                      env.take(active), gate.limits)
            for j, w in zip(active, why):
                sane[j] = w
        for j, g in enumerate(gs):
            full[int(g)] = {t: res[t][j] for t in TARGETS}
            envs[int(g)] = (env.json(j), sane[j])
    out = []
    g_all = np.array([p[0] for p in plans], dtype=np.int64)
    last = bounds[1:][g_all] - 1
    used = (last >= bounds[:-1][g_all]).tolist()
    last = np.maximum(last, 0)
    months_of, data_to_of = inp["months_dd"][last].tolist(), ts[last].tolist()  # .tolist(): floats and datetimes
    coef_json = _coefficients_json_of([full[p[0]][t] for p in plans for t in TARGETS])
    n_hold = n_hold.tolist()
    for j, (g, imo, form, activate, summary, data_hash) in enumerate(plans):
        env_json, refused = envs[g]
        if activate and refused:
            activate = False
            summary.update(changed=False, why=f"{refused} (fitted on all rows)",
                           reason=f"{form}: refused after its fit on all rows: {refused}; {summary['reason']}")
        res = full[g]
        summary.update(_scores(res))
        months, data_to = (months_of[j], data_to_of[j]) if used[j] else (0.0, None)
        status, reason, gate_text = "active" if activate else "rejected", summary["reason"], summary.get("gate")
        for i, t in enumerate(TARGETS):
            r = res[t]
            out.append({"imo": imo, "version": summary["version"], "form": form, "target": t,
                        "coefficients": coef_json[2 * j + i], "n_rows": r.n, "r2": r.r2, "rmse": r.rmse,
                        "cv_rmse": r.cv_rmse, "holdout_rmse": summary[f"{t}_holdout_rmse"], "n_holdout": n_hold[g],
                        "status": status, "reason": reason, "active": activate,
                        "months_dd": months, "data_hash": data_hash, "data_to_utc": data_to,
                        "envelope": env_json, "gate": gate_text})
    return out
