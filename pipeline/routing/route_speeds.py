"""The best speeds on a fixed route: the one step every plan takes after its search.

solve() asks it for four routes' speeds: the base route's best engine plan (the speed profile of the savings split,
and a contender in never-worse), the solver's route under the engine-change limits, the solver's route without them
(its own settings refined continuously), and the best plan of a route without limits (what the limits cost is
measured against it). Each is the same two stages:

  settings    the best engine plan over the listed settings, sailed in the weather it meets:
              - under active limits, the bucketed DP that holds each setting `min_hold_h` and charges each change
                (engine_limits.limited_plan, ε-trimmed by PLAN_GAP, PLAN_BUCKETS labels per line and setting);
              - without them, the DP over the settings on the route (engine_limits.best_engine_plan: exact by
                default, or ε-trimmed by `gap` and bucketed by `buckets`), pruned by `start` when one is given;
              - `search=False`: `start` itself (a solver's plan, already its search's best on its route).
              A `start` the DP does not beat is kept.
  continuous  that plan's speeds refined continuously between the lowest and the highest allowed rpm, outside
              barred ranges, holding and charging as the limits say (continuous_speed.refine_rpm); kept only when
              cheaper.

`known` (a dict, one per instance and graph: a route is its node per line) keeps each answer under active limits by
route: the base route's profile and a solver's plan on the same route are then planned once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pipeline.routing.baseline import evaluate
from pipeline.routing.continuous_speed import as_settings, refine_rpm
from pipeline.routing.engine_limits import PLAN_BUCKETS, PLAN_GAP, EngineLimits, LimitedPlan, best_engine_plan, limited_plan
from pipeline.routing.problem import Instance


@dataclass(frozen=True)
class Start:
    """A plan of the route known before the step: rpm per leg, its cost (objective, change costs included) and fuel
    (NaN: not known)."""

    rpm: np.ndarray
    cost: float
    fuel_t: float = math.nan


@dataclass(frozen=True)
class RouteSpeeds:
    """The best speeds found on one route."""

    rpm: np.ndarray  # rpm per leg: the settings plan's, or its continuous refinement's when that is cheaper
    cost: float  # objective plus change costs (inf: no plan can be sailed)
    fuel_t: float  # NaN when not known (a start without fuel that nothing beat)
    settings_idx: np.ndarray | None  # the settings plan: rpm index per leg among the instance's settings (None: a
    # start of continuous speeds)
    settings_cost: float
    refined: bool  # the continuous refinement was cheaper
    held: LimitedPlan | None = None  # under active limits, the settings plan as the DP holding each setting found it
    legs_sailed: int = 0  # by the settings DP

    def as_plan_settings(self, inst: Instance) -> tuple[Instance, np.ndarray]:
        """(the instance with the plan's rpm among its settings, rpm index per leg): the instance itself when the
        plan uses only its settings."""
        if self.refined or self.settings_idx is None:
            return as_settings(inst, self.rpm)
        return inst, self.settings_idx


def best_speeds(inst: Instance, nodes: np.ndarray, limits: EngineLimits | None = None, continuous: bool = True, *,
                start: Start | None = None, search: bool = True, gap: float = 0.0, buckets: int = 0,
                known: dict | None = None) -> RouteSpeeds:
    """The best speeds on the route `nodes` (module docstring)."""
    nodes = np.ascontiguousarray(nodes, np.int64)
    active = limits if limits is not None and limits.active else None  # the limits that act
    key = (nodes.tobytes(), limits, bool(continuous))
    if active is not None and known is not None and key in known:
        return known[key]
    held, legs = None, 0
    if not search:
        if start is None:
            raise ValueError("best_speeds without a search needs a start")
        rpm, idx, cost, fuel = start.rpm, _indexes(inst, start.rpm), float(start.cost), float(start.fuel_t)
    elif active is not None:
        held = limited_plan(inst, nodes, active, gap=PLAN_GAP, buckets=PLAN_BUCKETS)
        idx, cost, fuel, legs = held.rpm_idx, float(held.cost), float(held.fuel_t), held.legs_sailed
        rpm = inst.rpm_options[idx]
    else:
        upper = start.cost * (1.0 + 1e-9) + 1e-12 if start is not None else None
        idx, cost, legs = best_engine_plan(inst, nodes, upper, gap=gap, buckets=buckets)
        if start is not None and not cost < start.cost:
            rpm, idx, cost, fuel = start.rpm, _indexes(inst, start.rpm), float(start.cost), float(start.fuel_t)
        else:
            rpm = inst.rpm_options[idx]
            fuel = float(evaluate(inst, nodes, idx)[2]) if math.isfinite(cost) else math.nan
    out = RouteSpeeds(np.asarray(rpm, np.float64), cost, fuel, idx, cost, False, held, int(legs))
    if continuous and math.isfinite(cost):
        hold, change = (active.min_hold_h, active.change_cost_t) if active is not None else (0.0, 0.0)
        refined = refine_rpm(inst, nodes, out.rpm, min_hold_h=hold, change_cost_t=change,
                             barred_rpm=inst.problem.barred_rpm)
        if refined is not None and refined.cost < cost:
            out = RouteSpeeds(refined.rpm, float(refined.cost), float(refined.fuel_t), idx, cost, True, held,
                              int(legs))
    if active is not None and known is not None:
        known[key] = out
    return out


def _indexes(inst: Instance, rpm: np.ndarray) -> np.ndarray | None:
    """rpm index per leg of a plan sailed at the instance's settings (None: some leg's rpm is not one of them)."""
    idx = np.searchsorted(inst.rpm_options, rpm)
    idx = np.minimum(idx, inst.rpm_options.shape[0] - 1)
    return idx.astype(np.int64) if np.allclose(inst.rpm_options[idx], rpm, rtol=0.0, atol=1e-9) else None


__all__ = ["Start", "RouteSpeeds", "best_speeds"]
