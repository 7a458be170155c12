"""A forecast-error model calibrated from what happened: how far verified plans were from their claims, by lead.

The lagged ensemble (ensemble.py) says how much the forecasts disagree among themselves; in the hindcast of issue 41
that is about 1 h of arrival over a week's passage, far below how far plans sailed as made really arrive from their
claim. `plan_verification` (verification.py) holds, per plan, the claimed arrival and fuel and the realised ones in
the analysed weather that came. `fit_error_model` fits, against the hours the plan had ahead of it (its claimed
passage, "lead"):

- arrival error e = realised − claimed ETA (hours): a bias growing with the lead, β·h, and the spread of the rest
  σ_eta(h) = a · h^b;
- fuel error as a share of the claimed fuel: a bias (mean) and σ_fuel(h) = a · h^b;
- the saving: realised ≈ skill × claimed (least squares through the origin, skill within 0..1: the forecast-skill
  factor), and the spread of the rest σ_saving(h) = a · h^b, in points.

The weather ahead matters as much as the hours: a passage through a forecast storm belt arrives further from its claim
than one in the trades. Where the verified plans say so, the model is split by the forecast's severity along the
plan's route, `route_hs_mean_m` (the hour-weighted mean significant wave height its legs meet inside the forecast it
was made on: known at departure): below a threshold the "calm" model, at or above it the "stormy" one, each fitted as
above on its own plans (`ErrorModel.given`). The threshold is chosen among the severities' quantiles, and the split is
kept only when it explains the arrival errors better than the hours alone by more than its extra parameters (normal
likelihood, AIC); a plan whose severity is unknown, or a model without a split, uses the hours-only model.

Each σ(h) is fitted by its growth b on the residuals' RMS in bins of lead (a line in log–log), then a = the RMS of
residual / h^b. With fewer than `MIN_PLANS` verified plans the stated `DEFAULT` applies,
and then only where a lagged ensemble of two or more members shows that forecasts differ at all (`in_effect`):
a plan made on one cycle with no verification history stays as the solver made it.

Used for (robust.py, job.py) the arrival margin: aim bias + k·σ_eta(hours ahead) before the RTA, re-planned at sea
each cycle so the margin shrinks as the voyage nears its end; and for the claim's spread: P(on time), fuel and saving
P10/P50/P90 around the expected realisation (the claimed saving × skill).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, replace

import numpy as np

MIN_PLANS = 8  # fewer verified plans than this: the stated DEFAULT model
MIN_HOURS = 1.0  # leads shorter than this are taken as this (the power laws at h → 0)
Z90 = 1.2815515655446004  # the standard normal's 90th percentile
N_BINS = 6  # leads binned by equal count to find how the spread grows
_B_RANGE = (0.0, 1.5)  # exponents outside this are not believed (few plans, all at similar leads)


@dataclass(frozen=True)
class PowerLaw:
    """σ(h) = a · max(h, MIN_HOURS)^b."""

    a: float
    b: float

    def at(self, hours: float) -> float:
        return float(self.a * max(float(hours), MIN_HOURS) ** self.b)


SPLIT_QUANTILES = (0.3, 0.4, 0.5, 0.6, 0.7)  # candidate severity thresholds (quantiles of the plans' severities)
SPLIT_EXTRA_PARAMS = 4  # a split adds a threshold and a second bias, σ scale and growth: the AIC penalty


@dataclass(frozen=True)
class ErrorModel:
    """How far plans realise from their claims, by the hours they have ahead (their claimed passage)."""

    eta_bias_share: float  # mean arrival error per hour ahead (realised − claimed; > 0: late)
    eta_sd_h: PowerLaw  # σ of the arrival error around that bias, hours
    fuel_bias_share: float  # mean (realised − claimed fuel) / claimed fuel
    fuel_sd_share: PowerLaw  # σ of that share around its bias
    skill: float  # realised saving ≈ skill × claimed saving (0..1)
    saving_sd_pts: PowerLaw  # σ of realised − skill × claimed, percentage points
    n_plans: int  # verified plans it was fitted on (0: the stated default)
    source: str  # "calibrated" | "default"
    # split by the forecast's severity along the route (route_hs_mean_m): None without a split
    severity_split_m: float = math.nan  # mean Hs (m) at or above which `stormy` applies
    calm: "ErrorModel | None" = None
    stormy: "ErrorModel | None" = None
    severity_m: float = math.nan  # the severity this model was picked for (given); NaN: not picked

    def given(self, severity_m: float) -> "ErrorModel":
        """The model for a plan whose route meets a mean Hs of `severity_m` in its forecast (route_hs_mean_m): the
        calm or the stormy part of a split model; itself without a split or a known severity."""
        if self.calm is None or self.stormy is None or not math.isfinite(_finite(severity_m)):
            return self
        part = self.stormy if severity_m >= self.severity_split_m else self.calm
        return replace(part, severity_split_m=self.severity_split_m, severity_m=float(severity_m))

    def eta_bias_h(self, hours_ahead: float) -> float:
        return self.eta_bias_share * max(float(hours_ahead), 0.0)

    def note(self) -> str:
        """Which model, for a plan's reason."""
        if self.source == "calibrated" and math.isfinite(self.severity_m):
            side = "at or above" if self.severity_m >= self.severity_split_m else "below"
            return (f"forecast error calibrated from {self.n_plans} verified plans whose route's mean Hs in the forecast "
                    f"was {side} {self.severity_split_m:.1f} m, as this plan's {self.severity_m:.1f} m")
        if self.source == "calibrated":
            return f"forecast error calibrated from {self.n_plans} verified plans"
        return (f"forecast error from the stated default model (only {self.n_plans} verified plans, fewer than "
                f"{MIN_PLANS})")


# The stated default: fitted by bench/hindcast.py on its training voyages (seed 1041: 12 voyages of 1,600-4,000 NM
# along and across a North-Pacific storm belt, each re-planned every 12 h, 207 plans re-sailed on the truth; leads to
# 264 h; storm position errors 50 NM at 24 h, 300 NM at 120 h; bench/README.md): plans arrive 2.5 % of their hours
# ahead late on average, σ 1.1 h a day ahead and 6.3 h at 190 h; they burn 2 % more than claimed (σ 3.2 %); they
# realise 0.83 of the saving they claim (σ 0.37 points). A fleet's own verified plans replace it once there are
# MIN_PLANS of them.
DEFAULT = ErrorModel(eta_bias_share=0.025, eta_sd_h=PowerLaw(0.0707, 0.855), fuel_bias_share=0.020,
                     fuel_sd_share=PowerLaw(0.032, 0.038), skill=0.83, saving_sd_pts=PowerLaw(0.37, 0.0), n_plans=0,
                     source="default")


@dataclass(frozen=True)
class VerifiedErrors:
    """One verified plan's claim against what it realised (verification_errors)."""

    hours_ahead: float  # claimed passage, hours
    eta_error_h: float  # realised − claimed arrival, hours
    fuel_error_share: float  # (realised − claimed fuel) / claimed fuel
    claimed_savings_pct: float  # NaN: no baseline
    realised_savings_pct: float
    severity_m: float = math.nan  # route_hs_mean_m of the plan as made (NaN: unknown)


def route_hs_mean_m(legs: Iterable[dict]) -> float:
    """The forecast's severity along a plan's route: the mean significant wave height (m) its legs meet inside the
    forecast (legs sailed past the last valid time left out), weighted by each leg's hours; NaN with none."""
    h = hs = 0.0
    for g in legs:
        if g.get("beyond_forecast") or not math.isfinite(_finite(g.get("hs_m"))) \
                or not math.isfinite(_finite(g.get("hours"))):
            continue
        h += float(g["hours"])
        hs += float(g["hours"]) * float(g["hs_m"])
    return hs / h if h > 0 else math.nan


def _hours(a, b) -> float:
    return float((np.datetime64(b, "s") - np.datetime64(a, "s")) / np.timedelta64(1, "s")) / 3600.0


def _finite(x) -> float:
    try:
        x = float(x)
    except (TypeError, ValueError):
        return math.nan
    return x if math.isfinite(x) else math.nan


def verification_errors(rows: Iterable[dict]) -> list[VerifiedErrors]:
    """The errors of plan_verification rows (dicts with its columns) that are wholly verified (`coverage`
    'verified'; a row without the column counts as verified) and have a claimed and a realised arrival and fuel; the
    severity is the row's `route_hs_mean_m` (route_hs_mean_m of the plan's legs) when it has one."""
    out = []
    for r in rows:
        if r.get("coverage", "verified") != "verified":
            continue
        c_eta, r_eta = r.get("claimed_eta_utc"), r.get("realised_eta_utc")
        c_fuel, r_fuel, total = _finite(r.get("claimed_fuel_t")), _finite(r.get("realised_fuel_t")), \
            _finite(r.get("hours_total"))
        if c_eta is None or r_eta is None or c_eta != c_eta or r_eta != r_eta or not (c_fuel > 0) \
                or not math.isfinite(r_fuel) or not math.isfinite(total):
            continue
        e = _hours(c_eta, r_eta)
        ahead = total - e  # the realised passage less the arrival error: the passage as claimed
        if not ahead > 0:
            continue
        out.append(VerifiedErrors(ahead, e, (r_fuel - c_fuel) / c_fuel, _finite(r.get("claimed_savings_pct")),
                                  _finite(r.get("realised_savings_pct")), _finite(r.get("route_hs_mean_m"))))
    return out


def _power_law(hours: np.ndarray, resid: np.ndarray, default_b: float) -> PowerLaw:
    """σ(h) = a·h^b from residuals: b from a least-squares line through (mean ln h, ln RMS) of up to N_BINS bins of
    equal count by lead (within _B_RANGE; `default_b` when the leads or the bins do not tell), then a from the RMS of
    resid / h^b. RMS, not ln|resid|: plans that are exactly their claim (a plan that is its own baseline claims and
    realises a nil saving) must not pull σ to nothing."""
    h = np.maximum(np.asarray(hours, np.float64), MIN_HOURS)
    r = np.asarray(resid, np.float64)
    order = np.argsort(h)
    n_bins = min(N_BINS, h.size // 4)
    b = default_b
    if n_bins >= 2:
        bins = np.array_split(order, n_bins)
        x = np.array([np.mean(np.log(h[i])) for i in bins])
        rms = np.array([math.sqrt(float(np.mean(r[i] ** 2))) for i in bins])
        ok = rms > 0
        if ok.sum() >= 2 and np.ptp(x[ok]) > 0.1:
            b = float(np.clip(np.polyfit(x[ok], np.log(rms[ok]), 1)[0], *_B_RANGE))
    a = math.sqrt(float(np.mean((r / h ** b) ** 2))) if r.size else 0.0
    return PowerLaw(a, b)


def _fit_hours_only(errors: list[VerifiedErrors], min_plans: int, default: ErrorModel) -> ErrorModel:
    """The error model of these verified plans by the hours ahead alone."""
    if len(errors) < min_plans:
        return ErrorModel(**{**default.__dict__, "n_plans": len(errors), "source": "default"})
    h = np.array([e.hours_ahead for e in errors])
    eta = np.array([e.eta_error_h for e in errors])
    fuel = np.array([e.fuel_error_share for e in errors])
    beta = float(np.sum(eta * h) / np.sum(h * h))  # bias per hour ahead, through the origin
    fuel_bias = float(np.mean(fuel))
    sv = [(e.hours_ahead, e.claimed_savings_pct, e.realised_savings_pct) for e in errors
          if math.isfinite(e.claimed_savings_pct) and math.isfinite(e.realised_savings_pct)]
    if len(sv) >= min_plans:
        sh, sc, sr = (np.array(c) for c in zip(*sv))
        cc = float(np.sum(sc * sc))
        skill = float(np.clip(np.sum(sc * sr) / cc, 0.0, 1.0)) if cc > 0 else default.skill
        saving_sd = _power_law(sh, sr - skill * sc, 0.5)
    else:
        skill, saving_sd = default.skill, default.saving_sd_pts
    return ErrorModel(eta_bias_share=beta, eta_sd_h=_power_law(h, eta - beta * h, 1.0), fuel_bias_share=fuel_bias,
                      fuel_sd_share=_power_law(h, fuel - fuel_bias, 0.5), skill=skill, saving_sd_pts=saving_sd,
                      n_plans=len(errors), source="calibrated")


def eta_neg_log_likelihood(model: ErrorModel, errors: list[VerifiedErrors]) -> float:
    """−ln L of the plans' arrival errors under the model's normal (bias β·h, σ_eta(h)), the split's part per plan."""
    nll = 0.0
    for e in errors:
        m = model.given(e.severity_m)
        sd = max(m.eta_sd_h.at(e.hours_ahead), 1e-6)
        z = (e.eta_error_h - m.eta_bias_h(e.hours_ahead)) / sd
        nll += math.log(sd) + 0.5 * z * z + 0.5 * math.log(2.0 * math.pi)
    return nll


def fit_error_model(errors: list[VerifiedErrors], min_plans: int = MIN_PLANS,
                    default: ErrorModel = DEFAULT) -> ErrorModel:
    """The error model of these verified plans (verification_errors); `default` (saying how many there were) with
    fewer than `min_plans`. Split by the severity along the route (route_hs_mean_m) when both sides have `min_plans`
    plans and the split's likelihood of the arrival errors beats the hours alone by more than SPLIT_EXTRA_PARAMS
    (AIC); the parts then fall back to the whole where they lack plans (the saving's skill)."""
    whole = _fit_hours_only(errors, min_plans, default)
    known = [e for e in errors if math.isfinite(e.severity_m)]
    if whole.source != "calibrated" or len(known) < 2 * min_plans:
        return whole
    sev = np.array([e.severity_m for e in known])
    best, best_nll = None, eta_neg_log_likelihood(whole, known) - SPLIT_EXTRA_PARAMS
    for q in SPLIT_QUANTILES:
        cut = float(np.quantile(sev, q))
        calm = [e for e in known if e.severity_m < cut]
        stormy = [e for e in known if e.severity_m >= cut]
        if len(calm) < min_plans or len(stormy) < min_plans:
            continue
        split = replace(whole, severity_split_m=cut, calm=_fit_hours_only(calm, min_plans, whole),
                        stormy=_fit_hours_only(stormy, min_plans, whole))
        nll = eta_neg_log_likelihood(split, known)
        if nll < best_nll:
            best, best_nll = split, nll
    return best if best is not None else whole


def in_effect(model: ErrorModel | None, n_members: int) -> ErrorModel | None:
    """The model a plan uses: one calibrated from verified plans always; the stated default only with a lagged
    ensemble of two or more members (one forecast and no history: nothing to go by, the plan stays as made)."""
    if model is None:
        return None
    if model.source == "calibrated":
        return model
    return model if n_members >= 2 else None


def arrival_margin_h(model: ErrorModel, hours_ahead: float, k_sigma: float, max_share: float = 0.05,
                     horizon_h: float | None = None, reserve_h: float = math.inf) -> float:
    """Hours to aim before the RTA with `hours_ahead` to go: the mean lateness (bias, when late) plus k_sigma × σ_eta
    there, at most `max_share` of those hours; 0 with k_sigma ≤ 0. With `horizon_h`, only the error no later re-plan
    corrects: a voyage re-planned at sea on every new cycle makes up the error of the hours before its last re-plan
    by changing speed, as far as its speed reserve `reserve_h` (hours it could still gain at its top setting,
    robust.speed_reserve_h) allows; so the margin is the larger of the error of the last `horizon_h` hours and what of
    the whole passage's error the reserve cannot make up."""
    if k_sigma <= 0 or not hours_ahead > 0:
        return 0.0

    def error(h: float) -> float:
        return max(model.eta_bias_h(h), 0.0) + k_sigma * model.eta_sd_h.at(h)

    whole = error(hours_ahead)
    m = whole if horizon_h is None else max(error(margin_error_h(hours_ahead, horizon_h)), whole - max(reserve_h, 0.0))
    return float(min(m, max_share * hours_ahead))


def margin_error_h(hours_ahead: float, horizon_h: float | None) -> float:
    """The hours ahead whose arrival error a margin covers: all of them, or at most `horizon_h` (None: all)."""
    return float(hours_ahead) if horizon_h is None else float(min(hours_ahead, max(float(horizon_h), 0.0)))


def expected_saving_pct(model: ErrorModel, claimed_pct: float, hours_ahead: float,
                        margin_cost_pct: float = 0.0) -> tuple[float, float, float]:
    """The saving a plan can be expected to realise: (P10, P50, P90), P50 = skill × the claim, spread σ_saving(h).
    The claim of a plan aiming before the RTA contains the margin's cost (savings.with_margin_cost): that is the fuel of
    arriving earlier, not a forecast of the weather, so the skill discounts only the rest:
    P50 = skill × (claim + margin cost) − margin cost."""
    m = float(margin_cost_pct) if math.isfinite(_finite(margin_cost_pct)) else 0.0
    mid = model.skill * (float(claimed_pct) + m) - m
    sd = model.saving_sd_pts.at(hours_ahead)
    return mid - Z90 * sd, mid, mid + Z90 * sd


def p_on_time(model: ErrorModel, planned_h: float, allowed_h: float) -> float:
    """P(the realised passage ≤ allowed_h) for a plan of `planned_h` hours: normal with the model's bias and σ."""
    if not math.isfinite(planned_h):
        return 0.0
    mu = planned_h + model.eta_bias_h(planned_h)
    sd = model.eta_sd_h.at(planned_h)
    if sd <= 0:
        return float(mu <= allowed_h)
    return float(0.5 * math.erfc(-(allowed_h - mu) / (sd * math.sqrt(2.0))))


def fuel_range_t(model: ErrorModel, fuel_t: float, hours_ahead: float) -> tuple[float, float, float]:
    """(P10, P50, P90) of the fuel a plan claiming `fuel_t` realises."""
    mid = fuel_t * (1.0 + model.fuel_bias_share)
    sd = fuel_t * model.fuel_sd_share.at(hours_ahead)
    return mid - Z90 * sd, mid, mid + Z90 * sd


def calibrated_spread(plan, ens, model: ErrorModel):
    """The plan's spread (plan.Spread) from the error model instead of the members' disagreement: P(on time) of
    the plan and of its baseline, fuel and saving P10/P50/P90 around what the model expects it to realise (the saving's
    P50 is the claim × skill: the honest claim); a model split by severity uses its part for the plan's route
    (route_hs_mean_m). `ens` (the members' spread, or None) gives the member count."""
    from pipeline.routing.ensemble import ON_TIME_TOL_H  # noqa: PLC0415 (compiled kernels: routing only)
    from pipeline.routing.plan import Spread  # noqa: PLC0415

    if not plan.legs:
        return ens
    model = model.given(route_hs_mean_m(plan.legs))
    allowed_h = _hours(plan.depart_utc, plan.rta_utc) + ON_TIME_TOL_H
    planned_h = _hours(plan.depart_utc, plan.legs[-1]["eta_utc"])
    base = plan.baseline if plan.baseline is not None else plan
    base_h = _hours(base.depart_utc, base.legs[-1]["eta_utc"]) if base.legs else math.nan
    f10, f50, f90 = fuel_range_t(model, plan.fuel_t, planned_h)
    claimed = plan.savings.total_pct if plan.savings is not None else 0.0
    margin = plan.savings.margin_cost_pct if plan.savings is not None else 0.0
    s10, s50, s90 = expected_saving_pct(model, claimed, planned_h, margin)
    return Spread(ens.n_members if ens is not None else 0, p_on_time(model, planned_h, allowed_h),
                  p_on_time(model, base_h, allowed_h), f10, f50, f90, s10, s50, s90)
