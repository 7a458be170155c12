"""How a plan fares across forecasts: each member of an ensemble sails the plan and its constant-speed baseline.

A plan is made on one forecast. A lagged ensemble (the newest cycle and the previous ones, valid at the same times)
is the cheapest honest view of how far that forecast can be trusted: the plan as the master executes it (its
waypoints, the rpm of each leg and its waits, leaving at its departure) and its baseline (`Plan.baseline`, the base
route at constant speed) are sailed through every member with the same leg kernel, and the spread of their arrival
and fuel is the plan's uncertainty: P(on time) (arrival by the RTA plus `ON_TIME_TOL_H`), fuel P10/P50/P90 and the
saving's P10/P50/P90. Past a member's last step its neutral weather applies (engine.leg), as in planning.
"""

from __future__ import annotations

import math

import numpy as np

from pipeline.routing.engine import leg as lk
from pipeline.routing.plan import Plan, Spread
from pipeline.routing.weather_field import WeatherField

ON_TIME_TOL_H = 0.5  # an arrival this late still counts as on time (the hindcast's rule in issue 41)


def sail_plan(legs: list[dict], depart_utc, field: WeatherField, vessel: lk.Vessel) -> tuple[float, float]:
    """(hours, fuel t) of the legs (their waypoints, rpm and waits before them) sailed in `field` leaving at
    `depart_utc`; (inf, nan) when a leg cannot be sailed there (weather limits, no headway)."""
    t = field.hours_after_ref(depart_utc)
    t0, fuel = t, 0.0
    for leg in legs:
        wait = float(leg.get("wait_h", 0.0) or 0.0)
        t += wait
        fuel += float(leg.get("wait_fuel_t", 0.0) or 0.0)
        o = lk.sail_leg(leg["lat0"], leg["lon0"], leg["lat1"], leg["lon1"], t, leg["rpm"], vessel, field)
        if o[lk.CODE] != lk.OK:
            return math.inf, math.nan
        t += o[lk.H]
        fuel += o[lk.FUEL]
    return t - t0, fuel


def spread(plan: Plan, members: list[WeatherField], vessel: lk.Vessel) -> Spread | None:
    """The plan and its baseline sailed through each member (None: no plan, or no member where both can be sailed).
    A plan without a baseline is the constant-speed voyage itself (the gc and rhumb solvers): its own baseline."""
    base = plan.baseline if plan.baseline is not None else plan
    if not plan.legs or not base.legs or not members:
        return None
    allowed_h = float((np.datetime64(plan.rta_utc, "s") - np.datetime64(plan.depart_utc, "s")) / np.timedelta64(1, "s"))
    allowed_h = allowed_h / 3600.0 + ON_TIME_TOL_H
    hours, fuel, base_hours, saving = [], [], [], []
    for m in members:
        h, f = sail_plan(plan.legs, plan.depart_utc, m, vessel)
        bh, bf = sail_plan(base.legs, base.depart_utc, m, vessel)
        if not (math.isfinite(h) and math.isfinite(bh) and bf > 0):
            continue
        hours.append(h)
        fuel.append(f)
        base_hours.append(bh)
        saving.append(100.0 * (bf - f) / bf)
    if not fuel:
        return None
    f10, f50, f90 = np.percentile(fuel, [10, 50, 90])
    s10, s50, s90 = np.percentile(saving, [10, 50, 90])
    return Spread(len(fuel), float(np.mean(np.asarray(hours) <= allowed_h)),
                  float(np.mean(np.asarray(base_hours) <= allowed_h)), float(f10), float(f50), float(f90),
                  float(s10), float(s50), float(s90))


def describe(s: Spread | None) -> str:
    """One line for people."""
    if s is None:
        return "ensemble: n/a"
    return (f"across {s.n_members} forecast{'s' if s.n_members != 1 else ''}: on time {100 * s.p_on_time:.0f} % "
            f"(baseline {100 * s.baseline_p_on_time:.0f} %), fuel P10/P50/P90 {s.fuel_p10_t:.1f}/{s.fuel_p50_t:.1f}/"
            f"{s.fuel_p90_t:.1f} t, saving P10/P50/P90 {s.savings_p10_pct:.1f}/{s.savings_p50_pct:.1f}/"
            f"{s.savings_p90_pct:.1f} %")
