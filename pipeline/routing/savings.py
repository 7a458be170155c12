"""Savings against an honest baseline, split into what the speed profile and what the route contribute.

The baseline every plan carries (baseline.py) must hold one of the voyage's discrete rpm settings, so it
usually arrives hours before the RTA; slowing down to arrive on time then looks like "weather-routing
savings". The honest baseline is the same base route (the great circle, or the shortest sea route when the
great circle crosses land) sailed at the one constant rpm, anywhere between the lowest and the highest
allowed setting, that arrives at the RTA in the same weather and model (the slowest setting when even
that arrives early; the fastest, late, when none arrives in time). Against its fuel F_b:

    speed profile  (F_b − F_p) / F_b   F_p: the best engine plan over the allowed settings on the base route
                                       (under the same engine-change limits as the plan, when it has them)
    route          (F_p − F) / F_b     F: the plan's fuel
    total          (F_b − F) / F_b     = speed profile + route
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from pipeline.routing import leg_kernel as lk
from pipeline.routing.baseline import evaluate, shortest_route
from pipeline.routing.engine_limits import EngineLimits, best_engine_plan, limited_plan
from pipeline.routing.problem import Instance

if TYPE_CHECKING:
    from pipeline.routing.plan import Plan


@dataclass(frozen=True)
class SavingsSplit:
    baseline_rpm: float  # the constant rpm of the honest baseline
    baseline_fuel_t: float
    baseline_hours: float
    profile_fuel_t: float  # the best engine plan on the base route
    plan_fuel_t: float
    speed_profile_pct: float
    route_pct: float
    total_pct: float


def _sail_constant(inst: Instance, nodes: np.ndarray, rpm: float) -> tuple[float, float]:
    """(hours, fuel) of the route at a constant rpm (inf hours when a leg cannot be sailed)."""
    v = inst.vessel._replace(rpm_options=np.array([rpm]))
    L2 = len(nodes)
    ct, cf = np.empty(L2), np.empty(L2)
    code, _ = lk.sail_route_nb(nodes, np.zeros(L2 - 1, np.int64), 0, inst.graph, v, inst.wx, inst.objective, ct, cf)
    return (ct[-1] - inst.t_dep_h, cf[-1]) if code == lk.OK else (math.inf, math.nan)


def constant_rpm_for_rta(inst: Instance, nodes: np.ndarray, tol_h: float = 1e-3) -> tuple[float, float, float] | None:
    """(rpm, hours, fuel) of the one constant rpm between the allowed extremes that arrives at the RTA on `nodes`
    (bisection: hours fall as rpm rises); None when the route cannot be sailed at the extremes."""
    lo, hi = float(inst.rpm_options[0]), float(inst.rpm_options[-1])
    t_req = inst.problem.t_req_h
    h_lo, f_lo = _sail_constant(inst, nodes, lo)
    if h_lo <= t_req:
        return lo, h_lo, f_lo
    h_hi, f_hi = _sail_constant(inst, nodes, hi)
    if not math.isfinite(h_hi) or h_hi >= t_req:
        return (hi, h_hi, f_hi) if math.isfinite(h_hi) else None
    for _ in range(60):  # keep the on-time end: its plan arrives by the RTA
        mid = 0.5 * (lo + hi)
        h, f = _sail_constant(inst, nodes, mid)
        if h <= t_req:
            hi, h_hi, f_hi = mid, h, f
        else:
            lo = mid
        if t_req - h_hi <= tol_h:
            break
    return hi, h_hi, f_hi


def split_of(inst: Instance, base_nodes: np.ndarray, plan_fuel_t: float,
             limits: EngineLimits | None = None) -> SavingsSplit | None:
    """The split for a plan burning `plan_fuel_t` in the instance whose base route is `base_nodes` (None: no
    baseline can be sailed). With engine-change limits the speed-profile plan obeys them too (engine_limits)."""
    if base_nodes is None or not math.isfinite(plan_fuel_t):
        return None
    base = constant_rpm_for_rta(inst, base_nodes)
    if base is None:
        return None
    rpm, hours, f_b = base
    if limits is not None and limits.active:
        best = limited_plan(inst, base_nodes, limits)
        rpm_idx, cost = best.rpm_idx, best.cost
    else:
        rpm_idx, cost, _ = best_engine_plan(inst, base_nodes)
    if not math.isfinite(cost):
        return None
    f_p = evaluate(inst, base_nodes, rpm_idx)[2]
    f = plan_fuel_t
    return SavingsSplit(rpm, f_b, hours, f_p, f, 100.0 * (f_b - f_p) / f_b, 100.0 * (f_p - f) / f_b,
                        100.0 * (f_b - f) / f_b)


def savings_split(problem, weather, plan: Plan, space=None, limits: EngineLimits | None = None) -> SavingsSplit | None:
    """The plan's savings against the honest baseline of its voyage, split (None: no baseline can be sailed)."""
    space = space if space is not None else problem.search_space()
    inst = Instance.build(problem, space, weather)
    if plan.baseline is not None and plan.baseline.legs:
        inst.f_target = max(plan.baseline.fuel_t, 1e-6)  # as solve() sets it (the thesis objective's scale)
    return split_of(inst, shortest_route(space), plan.fuel_t if plan.legs else math.nan, limits)
