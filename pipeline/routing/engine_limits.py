"""Engine plans a master can sail: each rpm setting held for a minimum time, a small cost per change.

The solvers choose an rpm per leg freely, so their plans may switch setting every few hours. `limited_plan` is
an exact post-pass on a fixed route (the solver's): a dynamic programme over the route's legs choosing one rpm
setting per leg, each leg sailed with the same time-dependent kernel (`engine.leg.sail_leg_nb`) from the
label's exact time. A label is a partial plan at line i: its setting r, arrival time t, fuel f, number of
changes n and hours held since its last change (or since departure). The rules:

- a change of setting is allowed only after the current one has been held `min_hold_h` hours;
- the last setting must be held `min_hold_h` hours too (no exemption at the ends: every setting of the plan
  is held at least that long), except in a plan of one setting, which may be shorter than the hold;
- a plan costs its objective value (objectives.route_cost_nb) plus `change_cost_t` per change.

Per (line, setting) the labels are taken by arrival time and a label B is dropped when an earlier kept label A
has  f_A + c·n_A − e·t_A ≤ f_B + c·n_B − e·t_B  and held_A ≥ held_B (hours held capped at the hold), e being
the early rate of `jit` as in dp.py. Every continuation of B is then open to A at no greater cost, exactly in
weather that does not change with time (a continuation's legs take the same hours from either start); in
time-varying weather this is the same one assumption as the exact DP's (dp.py). A plan of one setting
throughout is always kept (it alone may end with less than the hold).

Bounds (as in dp.py; they never drop a label of an optimal plan): when the route can arrive by the RTA at its
fastest setting, labels that can no longer make it are dropped; under `jit`, a label whose fuel and change
costs so far plus the least fuel to finish in the time left (bound_tables.finish_bounds, on the route alone) exceed a
known plan's cost is dropped. The known plan: the best of one setting throughout and one change between two
settings at any line, among those obeying the limits.

The search is compiled in engine/hold_search.py (`hold_search_nb`); this module builds its bounds and runs it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from pipeline.routing.bound_tables import finish_bounds, label_bounds, latest_departures, trim_eps
from pipeline.routing.engine.hold_search import (Hold, RouteBounds, hold_search_nb, incumbent_cost_nb,
                                                  route_latest_departures_nb)
from pipeline.routing.engine.leg import OnRoute
from pipeline.routing.engine.label_search import dp_exact_nb
from pipeline.routing.engine.labels import bucketed
from pipeline.routing.engine.timing import time_price


PLAN_GAP = 1e-3  # the ε-trimming (share of a known plan's cost) of the plan under the limits in solve() and savings
PLAN_BUCKETS = 64  # and its labels per line and setting (bucketed: within 0.05 % of the ε-trimmed DP on the benches)
REFERENCE_BUCKETS = 256  # labels per line of the best plan without limits, the reference of what the limits cost


@dataclass(frozen=True)
class EngineLimits:
    """How often the engine setting may change: the least hours a setting is held, and a cost (t of fuel) per
    change that the plan's objective adds. Both zero: no limits."""

    min_hold_h: float = 12.0
    change_cost_t: float = 0.05

    @property
    def active(self) -> bool:
        return self.min_hold_h > 0.0 or self.change_cost_t > 0.0

    @property
    def hold(self) -> Hold:
        """The limits as the compiled hold search takes them."""
        return Hold(float(self.min_hold_h), float(self.change_cost_t))


@dataclass(frozen=True)
class LimitedPlan:
    rpm_idx: np.ndarray  # per leg
    cost: float  # objective plus the change costs (inf: no plan under the limits)
    fuel_t: float
    n_changes: int
    legs_sailed: int


def incumbent_cost(inst, nodes: np.ndarray, limits: EngineLimits, one_change: bool = True) -> float:
    """incumbent_cost_nb for an instance."""
    return float(incumbent_cost_nb(_on_route(inst, nodes), inst.objective, limits.hold, one_change))


def _on_route(inst, nodes: np.ndarray) -> OnRoute:
    """The route `nodes` of `inst`'s graph as the hold search sails it."""
    return OnRoute(inst.graph, np.ascontiguousarray(nodes, np.int64), inst.vessel, inst.wx)


def _route_instance(inst, nodes: np.ndarray):
    """The instance restricted to the route `nodes`: a graph of one node per line."""
    sp = inst.space
    lines = np.arange(len(nodes))
    legs = lines[:-1]
    route = replace(sp, lat=sp.lat[lines, nodes][:, None], lon=sp.lon[lines, nodes][:, None],
                    node_ok=sp.node_ok[lines, nodes][:, None],
                    edge_ok=sp.edge_ok[legs, nodes[:-1], nodes[1:]][:, None, None], max_shift=0)
    return replace(inst, space=route, graph=route.graph)


def _route_finish_tables(inst, nodes: np.ndarray):
    """bound_tables.finish_bounds on the route alone: (lams, m_route (K, lines), t_min (lines))."""
    lams, m_lam, t_min, _, _ = finish_bounds(_route_instance(inst, nodes))
    return lams, np.ascontiguousarray(m_lam[:, :, 0]), np.ascontiguousarray(t_min[:, 0])


def best_engine_plan(inst, nodes: np.ndarray, upper: float | None = None, gap: float = 0.0,
                     buckets: int = 0) -> tuple[np.ndarray, float, int]:
    """(rpm index per leg, cost, legs sailed) of the best engine plan without limits on the fixed route `nodes`:
    on time at the least fuel when the RTA can be met, else the least late. The exact DP on the route alone
    (engine.label_search.dp_exact_nb with its bounds), pruned by `upper` (default: the best plan of one setting throughout or one
    change, `incumbent_cost_nb` without a hold); with gap > 0 its labels are ε-trimmed so the plan is within that
    share of the best; with `buckets` > 0 at most that many labels per line (approximate, see engine/hold_search.py).
    Cost inf when no plan beats `upper` (or none can be sailed)."""
    nodes = np.ascontiguousarray(nodes, np.int64)
    if upper is None:
        upper = incumbent_cost(inst, nodes, EngineLimits(0.0, 0.0), one_change=buckets == 0)
        upper = upper * (1.0 + 1e-9) + 1e-12 if math.isfinite(upper) else math.inf  # that plan itself is kept
    sub = _route_instance(inst, nodes)
    fb = label_bounds(sub, latest_departures(sub))
    eps = trim_eps(sub, gap, upper, fb.lams, fb.m_lam, fb.t_min) if gap > 0.0 and math.isfinite(upper) else 0.0
    lam_t = time_price(inst, nodes) if buckets > 0 else 0.0
    _, rpm_idx, cost, n_legs, _ = dp_exact_nb(sub.graph, sub.vessel, sub.wx, sub.objective, upper, fb, eps,
                                              bucketed(buckets, lam_t))
    return rpm_idx, float(cost), int(n_legs)


def limited_plan(inst, nodes: np.ndarray, limits: EngineLimits, gap: float = 0.0, buckets: int = 0) -> LimitedPlan:
    """The best engine plan on the fixed route `nodes` under `limits` (see the module docstring); with gap > 0
    within that share of a known plan's cost of the optimum (faster). The hold itself keeps the labels few:
    without limits (EngineLimits(0, 0)) a long route takes far longer."""
    nodes = np.ascontiguousarray(nodes, np.int64)
    rt, o = _on_route(inst, nodes), inst.objective
    ld = np.full(len(nodes), np.inf)
    route_latest_departures_nb(rt, float(inst.vessel.rpm_options[-1]), o.t_dep_h + o.t_req_h + 1e-9, ld)
    prune = bool(ld[0] >= o.t_dep_h)  # the RTA can be met at full speed: late labels cannot win
    upper = incumbent_cost(inst, nodes, limits, one_change=buckets == 0)
    lams, m_route, t_min = _route_finish_tables(inst, nodes)
    eps = gap * upper / (len(nodes) - 1) if gap > 0.0 and math.isfinite(upper) else 0.0
    mode = bucketed(buckets, time_price(inst, nodes) if buckets > 0 else 0.0)
    rb = RouteBounds(ld, prune, upper, lams, m_route, t_min, eps)
    rpm_idx, cost, fuel, changes, n_legs = hold_search_nb(rt, o, limits.hold, rb, mode)
    if not math.isfinite(cost):  # the hold makes the RTA unreachable: the least-late plan, without the bounds
        rb = rb._replace(prune=False, upper=np.inf, eps=0.0)
        rpm_idx, cost, fuel, changes, n_legs2 = hold_search_nb(rt, o, limits.hold, rb, mode)
        n_legs += n_legs2
    return LimitedPlan(rpm_idx, float(cost), float(fuel), int(changes), int(n_legs))


def settings_held_h(legs: list[dict]) -> list[tuple[float, float]]:
    """(rpm, hours held) of each run of equal settings along a plan's legs, in order."""
    runs: list[tuple[float, float]] = []
    for leg in legs:
        if runs and runs[-1][0] == leg["rpm"]:
            runs[-1] = (leg["rpm"], runs[-1][1] + leg["hours"])
        else:
            runs.append((leg["rpm"], leg["hours"]))
    return runs
