"""Savings against an honest baseline, split into what the speed profile and what the route contribute.

A baseline that must hold one of the voyage's listed rpm settings usually arrives hours before the RTA;
slowing down to arrive on time then looks like "weather-routing savings". The honest baseline is the base
route (the great circle, or the shortest sea route when the great circle crosses land) sailed at the one
constant rpm, anywhere between the lowest and the highest allowed setting, that arrives at the RTA in the same
weather and model (the slowest setting when even that arrives early; the fastest, late, when none arrives in
time; baseline.constant_rpm_for_rta). solve.py adds that rpm to the settings every solver may use, so it is
the plan's `baseline` too. Against its fuel F_b:

    speed profile  (F_b − F_p) / F_b   F_p: the best engine plan on the base route, its speeds refined continuously
                                       (continuous_speed.py; under the same engine-change limits as the plan, when
                                       it has them); ≥ 0, as the constant-speed voyage is one of those plans
    route          (F_p − F) / F_b     F: the plan's fuel
    total          (F_b − F) / F_b     = speed profile + route

and, by when the fuel is burnt, into what the forecast covers and what it does not (F' and F_b': the fuel each
burns after the weather's last valid time, where they sail in the neutral weather of engine.leg, not a forecast):

    forecast       ((F_b − F_b') − (F − F')) / F_b    burnt within the forecast's valid times: backed by it
    beyond         (F_b' − F') / F_b                  burnt past them: an assumption, not a forecast
    total          = forecast + beyond

Both voyages leave at the same time, so the forecast's last valid time cuts both at the same instant.

A plan that aims before the RTA (an arrival margin, job.robust_plan) is compared with the baseline that arrives at
the RTA itself, the voyage a master aiming at the RTA sails (`with_margin_cost`), not with the constant-speed voyage
arriving as early as the plan: F_b is then the RTA baseline's fuel, F_b'' the early baseline's, F_p'' the best engine
plan on the base route for the early arrival, and

    speed profile  (F_b'' − F_p'') / F_b
    route          (F_p'' − F) / F_b
    margin cost    (F_b'' − F_b) / F_b     the fuel of arriving early at constant speed: what the margin costs
    total          (F_b − F) / F_b         = speed profile + route − margin cost
"""

from __future__ import annotations

import math

import numpy as np

from pipeline.routing.engine import leg as lk
from pipeline.routing.baseline import constant_rpm_for_rta, evaluate, shortest_route, with_setting
from pipeline.routing.continuous_speed import as_settings
from pipeline.routing.engine_limits import EngineLimits
from pipeline.routing.plan import Plan, SavingsSplit
from pipeline.routing.problem import Instance
from pipeline.routing.route_speeds import RouteSpeeds, best_speeds


def with_margin_cost(aimed: SavingsSplit, at_rta: SavingsSplit) -> SavingsSplit:
    """The split of a plan made to arrive before the RTA (`aimed`: against the constant-speed voyage arriving as early)
    against the baseline that arrives at the RTA itself (`at_rta`: the split of the plan made for the RTA, in the same
    cycle): the saving then contains the margin's cost, and that cost is its own figure (`margin_cost_pct`)."""
    f_b, f_early, f = at_rta.baseline_fuel_t, aimed.baseline_fuel_t, aimed.plan_fuel_t
    total = 100.0 * (f_b - f) / f_b
    beyond = 100.0 * (at_rta.baseline_fuel_beyond_t - aimed.plan_fuel_beyond_t) / f_b
    return SavingsSplit(baseline_rpm=at_rta.baseline_rpm, baseline_fuel_t=f_b, baseline_hours=at_rta.baseline_hours,
                        profile_fuel_t=aimed.profile_fuel_t, plan_fuel_t=f,
                        speed_profile_pct=100.0 * (f_early - aimed.profile_fuel_t) / f_b,
                        route_pct=100.0 * (aimed.profile_fuel_t - f) / f_b, total_pct=total,
                        baseline_fuel_beyond_t=at_rta.baseline_fuel_beyond_t,
                        plan_fuel_beyond_t=aimed.plan_fuel_beyond_t, forecast_pct=total - beyond,
                        beyond_forecast_pct=beyond, margin_cost_pct=100.0 * (f_early - f_b) / f_b)


def fuel_of(inst: Instance, nodes: np.ndarray, rpm_per_leg: np.ndarray) -> float:
    """Fuel (t) of the route sailed at rpm_per_leg[i] on leg i."""
    at, rpm_idx = as_settings(inst, rpm_per_leg)
    return float(evaluate(at, nodes, rpm_idx)[2])


def fuel_beyond_forecast_t(inst: Instance, nodes: np.ndarray, rpm_per_leg: np.ndarray) -> float:
    """Fuel (t) the route sailed at rpm_per_leg[i] on leg i burns after the weather's last valid time (NaN when a
    leg cannot be sailed)."""
    out = np.empty(lk.N_LEG_OUT)
    lat, lon, t = inst.space.lat, inst.space.lon, inst.t_dep_h
    beyond = 0.0
    for i in range(len(nodes) - 1):
        a, b = int(nodes[i]), int(nodes[i + 1])
        lk.sail_leg_nb(lat[i, a], lon[i, a], lat[i + 1, b], lon[i + 1, b], t, float(rpm_per_leg[i]), inst.vessel,
                       inst.wx, out)
        if out[lk.CODE] != lk.OK:
            return math.nan
        t += out[lk.H]
        beyond += out[lk.FUEL_BEYOND]
    return float(beyond)


def split_of(inst: Instance, base_nodes: np.ndarray, plan_fuel_t: float, limits: EngineLimits | None = None,
             profile: RouteSpeeds | None = None, plan_fuel_beyond_t: float = math.nan
             ) -> SavingsSplit | None:
    """The split for a plan burning `plan_fuel_t`, `plan_fuel_beyond_t` of it past the forecast's last valid time
    (NaN: unknown, no forecast/beyond split), in the instance whose base route is `base_nodes` (None: no baseline
    can be sailed). With engine-change limits the speed-profile plan obeys them too (engine_limits); `profile`,
    when known, is that plan (route_speeds.best_speeds on the base route)."""
    if base_nodes is None or not math.isfinite(plan_fuel_t):
        return None
    base = constant_rpm_for_rta(inst, base_nodes)
    if base is None:
        return None
    rpm, hours, f_b = base
    profile = profile if profile is not None else best_speeds(inst, base_nodes, limits)
    if not math.isfinite(profile.cost):
        return None
    f_p = fuel_of(inst, base_nodes, profile.rpm)
    f = plan_fuel_t
    total = 100.0 * (f_b - f) / f_b
    f_b_beyond = fuel_beyond_forecast_t(inst, base_nodes, np.full(len(base_nodes) - 1, rpm))
    beyond = 100.0 * (f_b_beyond - plan_fuel_beyond_t) / f_b
    return SavingsSplit(rpm, f_b, hours, f_p, f, 100.0 * (f_b - f_p) / f_b, 100.0 * (f_p - f) / f_b, total,
                        f_b_beyond, plan_fuel_beyond_t, total - beyond, beyond)


def savings_split(problem, weather, plan: Plan, space=None, limits: EngineLimits | None = None) -> SavingsSplit | None:
    """The plan's savings against the honest baseline of its voyage, split (None: no baseline can be sailed)."""
    space = space if space is not None else problem.search_space()
    inst, base_nodes = solver_instance(problem, space, weather)
    if plan.baseline is not None and plan.baseline.legs:
        inst.f_target = max(plan.baseline.fuel_t, 1e-6)  # as solve() sets it (the thesis objective's scale)
    return split_of(inst, base_nodes, plan.fuel_t if plan.legs else math.nan, limits,
                    plan_fuel_beyond_t=plan.fuel_beyond_forecast_t if plan.legs else math.nan)


def solver_instance(problem, space, weather) -> tuple[Instance, np.ndarray | None]:
    """(the instance the solvers search, the base route's nodes or None): the voyage's listed settings plus the
    constant rpm at which the base route arrives at the RTA (`with_constant_speed`)."""
    base_nodes = shortest_route(space)
    return with_constant_speed(Instance.build(problem, space, weather), base_nodes), base_nodes


def with_constant_speed(inst: Instance, base_nodes: np.ndarray | None) -> Instance:
    """The instance whose settings include the constant rpm that brings the base route in at the RTA (the honest
    baseline's), so that voyage is a plan of every solver's space; unchanged when the base route cannot be
    sailed at the extremes."""
    if base_nodes is None:
        return inst
    const = constant_rpm_for_rta(inst, base_nodes)
    if const is None:
        return inst
    return inst.with_rpm_options(with_setting(inst.rpm_options, const[0]))
