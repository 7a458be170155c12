"""Robust decisions: act on a plan only as far as the forecasts agree with it (issue 41, item 3).

A plan made on one forecast cycle is sailed through the members of a lagged ensemble (ensemble.py: the cycle
routed on and the ones before it, valid at the same times). Three rules use what the members say; each is off
with its option at 0, and none can act with fewer than two members that could sail the plan (one forecast has
no spread), so plans made on a single cycle are those of the solver:

- **arrival margin** (`arrival_margin_h`): the plan aims `k · σ` hours before the RTA, σ the standard deviation
  (n − 1) of its arrival across the members, at most `max_share` of the passage, so that a plan sailed as made is
  on time in weather that differs from the forecast as the forecasts differ among themselves;
- **win across the ensemble** (`wins_across`): a plan is preferred to its constant-speed baseline only when it
  burns less than the baseline in at least `min_share` of the members and is not late where the baseline is on
  time; otherwise the baseline is kept (`baseline_kept`, which says so in the plan's reason);
- **no new detour at sea for a gain smaller than its spread** (`replan_decision`): a plan re-made at sea replaces
  the current one (its legs ahead of the ship) only when its expected fuel gain across the members exceeds
  `k` standard deviations of that gain (and MIN_GAIN_SHARE of the fuel), or when it is on time in more members
  than the current plan.

Times are hours, fuel tonnes; legs are plan leg dicts (lat0, lon0, lat1, lon1, rpm, wait_h, wait_fuel_t).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from pipeline.routing.engine import leg as lk
from pipeline.routing.ensemble import ON_TIME_TOL_H, sail_plan, spread
from pipeline.routing.plan import Plan
from pipeline.routing.savings import with_margin_cost
from pipeline.routing.weather_field import WeatherField

MIN_GAIN_SHARE = 1e-3  # a re-plan gaining less than this share of the current plan's fuel is noise: never taken


def sailed(legs: list[dict], depart_utc, members: list[WeatherField], vessel: lk.Vessel) -> np.ndarray:
    """(n_members, 2): hours and fuel (t) of the legs sailed through each member from `depart_utc` (inf, nan where
    they cannot be sailed)."""
    return np.array([sail_plan(legs, depart_utc, m, vessel) for m in members], dtype=np.float64).reshape(-1, 2)


def _hours_between(a, b) -> float:
    return float((np.datetime64(b, "s") - np.datetime64(a, "s")) / np.timedelta64(1, "s")) / 3600.0


def arrival_margin_h(plan: Plan, members: list[WeatherField], vessel: lk.Vessel, k_sigma: float,
                     max_share: float = 0.05) -> float:
    """Hours to aim before the RTA: k_sigma × the standard deviation (n − 1) of the plan's arrival across the members
    where it can be sailed, at most `max_share` of the passage; 0 with k_sigma ≤ 0 or fewer than two such members."""
    if k_sigma <= 0 or not plan.legs or len(members) < 2:
        return 0.0
    hours = sailed(plan.legs, plan.depart_utc, members, vessel)[:, 0]
    hours = hours[np.isfinite(hours)]
    if hours.size < 2:
        return 0.0
    passage_h = _hours_between(plan.depart_utc, plan.rta_utc)
    return float(min(k_sigma * np.std(hours, ddof=1), max_share * passage_h))


def speed_reserve_h(plan: Plan, weather: WeatherField, vessel: lk.Vessel) -> float:
    """Hours the plan's route could still be sailed faster: its passage less the same legs sailed without waits at the
    vessel's top setting in `weather` (0 when that cannot be sailed): what a later re-plan can make up by speeding up."""
    if not plan.legs:
        return 0.0
    top = float(np.max(vessel.rpm_options))
    fast = [{**leg, "rpm": top, "wait_h": 0.0, "wait_fuel_t": 0.0} for leg in plan.legs]
    hours, _ = sail_plan(fast, plan.depart_utc, weather, vessel)
    return float(max(plan.hours - hours, 0.0)) if np.isfinite(hours) else 0.0


def aim_reached(aimed: Plan, rta_utc) -> bool:
    """Whether a plan made for an aim before the RTA (an arrival margin) is the one to sail: it has legs and meets
    that aim, or, late for it, still arrives by the RTA (the earliest the ship can make it, still earlier than a plan
    for the RTA)."""
    if not aimed.legs:
        return False
    return aimed.status == "ok" or np.datetime64(aimed.legs[-1]["eta_utc"], "s") <= np.datetime64(rta_utc, "s")


def margin_charged(aimed: Plan, at_rta: Plan) -> Plan:
    """The plan made to arrive before the RTA (`aimed`, by an arrival margin) as the plan for the voyage's RTA: it keeps
    the RTA, its constant-speed baseline becomes the one arriving at the RTA itself (`at_rta.baseline`, the voyage a
    master aiming at the RTA sails; verification re-sails that one) and its saving is claimed against that baseline,
    so it contains what the margin costs, which is its own figure (savings.with_margin_cost, `margin_cost_pct`)."""
    rta = np.datetime64(at_rta.rta_utc, "s")
    aimed.rta_utc = rta
    if aimed.savings is not None and at_rta.savings is not None:
        aimed.savings = with_margin_cost(aimed.savings, at_rta.savings)
        s = aimed.savings
        note = (f"saving claimed against the constant speed arriving at the RTA: {s.total_pct:.2f} %, after the "
                f"margin's cost of {s.margin_cost_pct:.2f} %")
        aimed.add_reason(note)
    if at_rta.baseline is not None and at_rta.baseline.legs:
        aimed.baseline = at_rta.baseline
    elif aimed.baseline is not None:
        aimed.baseline.rta_utc = rta
    return aimed


@dataclass(frozen=True)
class Wins:
    n_members: int  # members where both the plan and its baseline can be sailed
    n_wins: int  # of those, where the plan burns no more and is not late where the baseline is on time

    def preferred(self, min_share: float) -> bool:
        """Whether the plan is preferred to its baseline (True with fewer than two members: nothing to go by)."""
        return self.n_members < 2 or self.n_wins >= min_share * self.n_members - 1e-9


def wins_across(plan: Plan, members: list[WeatherField], vessel: lk.Vessel) -> Wins:
    """In how many members the plan beats its constant-speed baseline (`Plan.baseline`), both sailed as made."""
    base = plan.baseline
    if base is None or not base.legs or not plan.legs or not members:
        return Wins(0, 0)
    allowed_h = _hours_between(plan.depart_utc, plan.rta_utc) + ON_TIME_TOL_H
    p = sailed(plan.legs, plan.depart_utc, members, vessel)
    b = sailed(base.legs, base.depart_utc, members, vessel)
    ok = np.isfinite(p[:, 0]) & np.isfinite(b[:, 0])
    on_time_p, on_time_b = p[:, 0] <= allowed_h, b[:, 0] <= allowed_h
    # a tie is a win: a plan that is its baseline (never-worse kept it) gives way to nothing
    wins = ok & (p[:, 1] <= b[:, 1] * (1.0 + 1e-12)) & (on_time_p | ~on_time_b)
    return Wins(int(ok.sum()), int(wins.sum()))


def baseline_kept(plan: Plan, wins: Wins, min_share: float, members: list[WeatherField] | None = None,
                  vessel: lk.Vessel | None = None) -> Plan:
    """The plan's constant-speed baseline in its place, saying why: the plan won in only `wins.n_wins` of
    `wins.n_members` forecasts (fewer than `min_share`). Its saving is nil (it is its own baseline); with `members`
    its spread is computed again."""
    base = plan.baseline
    if base is None:
        raise ValueError(f"{plan.solver} plan has no constant-speed baseline to keep in its place")
    kept = replace(base, solver=plan.solver, seed=plan.seed, baseline=base, history=plan.history,
                   n_evals=plan.n_evals, model_version=plan.model_version, cycle=plan.cycle, spread=None,
                   runtime_s=plan.runtime_s)
    kept.limits = plan.limits
    kept.unlimited_fuel_t = base.fuel_t if plan.limits is not None else math.nan  # one setting: the limits cost nothing
    s = plan.savings
    if s is not None:
        kept.savings = replace(s, plan_fuel_t=s.baseline_fuel_t, route_pct=-s.speed_profile_pct, total_pct=0.0,
                               plan_fuel_beyond_t=s.baseline_fuel_beyond_t,
                               forecast_pct=0.0 if math.isfinite(s.forecast_pct) else s.forecast_pct,
                               beyond_forecast_pct=0.0 if math.isfinite(s.beyond_forecast_pct) else s.beyond_forecast_pct)
    note = (f"the {plan.solver} plan ({plan.fuel_t:.1f} t) beat its constant-speed baseline in only {wins.n_wins} of "
            f"{wins.n_members} forecasts (fewer than {100 * min_share:.0f} %): kept the baseline")
    kept.add_reason(note)  # kept carries its baseline's reason
    if members is not None and vessel is not None:
        kept.spread = spread(kept, members, vessel)
    return kept


def legs_ahead(legs: list[dict], at_utc, lat: float, lon: float) -> list[dict]:
    """The legs of a plan still to sail for a ship at (lat, lon) at `at_utc`: the leg it is on (by the plan's
    times) from that position, then the rest. Legs need etd_utc and eta_utc; a leg not yet begun keeps its wait."""
    at = np.datetime64(at_utc, "s")
    ahead: list[dict] = []
    for g in sorted(legs, key=lambda g: np.datetime64(g["etd_utc"], "s")):
        if np.datetime64(g["eta_utc"], "s") <= at:
            continue
        if not ahead:
            begun = np.datetime64(g["etd_utc"], "s") <= at
            g = {**g, "lat0": float(lat), "lon0": float(lon)}
            if begun or g.get("wait_h"):
                g.update(wait_h=0.0, wait_fuel_t=0.0)
        ahead.append(g)
    return ahead


@dataclass(frozen=True)
class ReplanDecision:
    take_new: bool
    n_members: int  # members where both could be sailed
    gain_mean_t: float  # current plan's fuel − new plan's, mean over those members
    gain_sd_t: float  # its standard deviation (n − 1)
    on_time_current: int  # members where each arrives by the RTA (+ ON_TIME_TOL_H)
    on_time_new: int
    reason: str


def replan_decision(current_legs: list[dict], new_plan: Plan, members: list[WeatherField], vessel: lk.Vessel,
                    k_sigma: float = 1.0) -> ReplanDecision:
    """Whether a plan re-made at sea (`new_plan`, starting at the ship's position and time) should replace the current
    plan's legs ahead of the ship (`current_legs`, from the same position; legs_ahead). Both are sailed through each
    member from the new plan's departure: the new plan is taken when it is on time in more members, or, on time in
    as many, when its mean fuel gain exceeds k_sigma standard deviations of the gain and MIN_GAIN_SHARE of the current
    plan's fuel. With fewer
    than two members, or nothing current to keep, the new plan is taken."""
    if not current_legs or not new_plan.legs or len(members) < 2:
        return ReplanDecision(True, 0, math.nan, math.nan, 0, 0, "new plan taken: nothing to weigh it against")
    allowed_h = _hours_between(new_plan.depart_utc, new_plan.rta_utc) + ON_TIME_TOL_H
    c = sailed(current_legs, new_plan.depart_utc, members, vessel)
    n = sailed(new_plan.legs, new_plan.depart_utc, members, vessel)
    ok = np.isfinite(c[:, 0]) & np.isfinite(n[:, 0])
    on_c = int(np.sum(np.isfinite(c[:, 0]) & (c[:, 0] <= allowed_h)))
    on_n = int(np.sum(np.isfinite(n[:, 0]) & (n[:, 0] <= allowed_h)))
    if ok.sum() < 2:
        take = on_n >= on_c
        return ReplanDecision(take, int(ok.sum()), math.nan, math.nan, on_c, on_n,
                              "new plan taken: the current one cannot be sailed in the forecasts" if take
                              else "current plan kept: the new one cannot be sailed in the forecasts")
    gain = c[ok, 1] - n[ok, 1]
    mean, sd = float(np.mean(gain)), float(np.std(gain, ddof=1))
    if on_n > on_c:
        take, why = True, f"new plan taken: on time in {on_n} of {len(members)} forecasts, the current one in {on_c}"
    elif on_n < on_c:
        take, why = False, f"current plan kept: on time in {on_c} of {len(members)} forecasts, the new one in {on_n}"
    elif mean > max(k_sigma * sd, MIN_GAIN_SHARE * float(np.mean(c[ok, 1]))):
        take, why = True, f"new plan taken: saves {mean:.1f} ± {sd:.1f} t across {int(ok.sum())} forecasts"
    else:
        take, why = False, (f"current plan kept: the new one would save {mean:.1f} ± {sd:.1f} t across "
                            f"{int(ok.sum())} forecasts, not more than {k_sigma:g} × its spread (nor "
                            f"{100 * MIN_GAIN_SHARE:g} % of the fuel)")
    return ReplanDecision(take, int(ok.sum()), mean, sd, on_c, on_n, why)


def retimed(legs: list[dict], depart_utc, rta_utc, weather: WeatherField, vessel: lk.Vessel) -> list[dict]:
    """The legs with every rpm scaled by one factor (each kept within the vessel's lowest and highest setting) so
    that, sailed in `weather` from `depart_utc`, they arrive at `rta_utc`: the current route kept, the ship re-timed
    (bisection; the slowest when even that is early, the fastest when none is in time). Waits are kept."""
    if not legs:
        return legs
    lo_rpm, hi_rpm = float(vessel.rpm_options[0]), float(vessel.rpm_options[-1])
    need_h = _hours_between(depart_utc, rta_utc)
    rpm0 = np.array([float(g["rpm"]) for g in legs])

    def at(f):
        return [{**g, "rpm": float(min(max(r * f, lo_rpm), hi_rpm))} for g, r in zip(legs, rpm0)]

    lo, hi = lo_rpm / rpm0.max(), hi_rpm / rpm0.min()
    if sail_plan(at(lo), depart_utc, weather, vessel)[0] <= need_h:
        return at(lo)
    if not sail_plan(at(hi), depart_utc, weather, vessel)[0] <= need_h:
        return at(hi)
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        if sail_plan(at(mid), depart_utc, weather, vessel)[0] <= need_h:
            hi = mid
        else:
            lo = mid
    return at(hi)


def current_plan_kept(new_plan: Plan, ahead: list[dict], weather: WeatherField, vessel: lk.Vessel,
                      why: str) -> Plan | None:
    """The current plan's legs ahead of the ship (`ahead`, legs_ahead) as the plan of this run in place of
    `new_plan` (same voyage, start, baseline): each leg at its rpm, after its wait, sailed in `weather` from the new
    plan's departure, its saving against the new plan's baseline, `why` as its reason. None when a leg cannot be
    sailed in `weather` (the new plan then stands)."""
    from pipeline.routing.plan import leg_record  # noqa: PLC0415 (plan imports nothing of this module: no cycle)

    t = weather.hours_after_ref(new_plan.depart_utc)
    legs = []
    for i, g in enumerate(ahead):
        wait = float(g.get("wait_h") or 0.0)
        wait_tph = float(g.get("wait_fuel_t") or 0.0) / wait if wait > 0 else 0.0
        t += wait
        o = lk.sail_leg(g["lat0"], g["lon0"], g["lat1"], g["lon1"], t, float(g["rpm"]), vessel, weather)
        if o[lk.CODE] != lk.OK:
            return None
        legs.append(leg_record(i, (g["lat0"], g["lon0"], g["lat1"], g["lon1"]), float(g["rpm"]), o, t, wait,
                               wait_tph, weather))
        t += o[lk.H]
    kept = replace(new_plan, legs=legs, reason=why, cost=math.inf, spread=None, history=None)
    late = _hours_between(new_plan.rta_utc, kept.legs[-1]["eta_utc"]) > 0.0
    kept.status = "late" if late else "ok"
    kept.unlimited_fuel_t = kept.fuel_t if kept.limits is not None else math.nan
    s = new_plan.savings
    if s is not None:
        f, f_beyond = kept.fuel_t, kept.fuel_beyond_forecast_t
        total = 100.0 * (s.baseline_fuel_t - f) / s.baseline_fuel_t
        beyond = 100.0 * (s.baseline_fuel_beyond_t - f_beyond) / s.baseline_fuel_t
        kept.savings = replace(s, plan_fuel_t=f, route_pct=total - s.speed_profile_pct + s.margin_cost_pct, total_pct=total,
                               plan_fuel_beyond_t=f_beyond, forecast_pct=total - beyond, beyond_forecast_pct=beyond)
    return kept
