"""Exact reference: dynamic programming over (line, node) with an engine setting per leg.

Every leg is sailed with the same time-dependent kernel as the other solvers, from the label's exact
arrival time. A label is a partial plan reaching (line i, node a) at time t with fuel f. At each node the
labels are sorted by time and a label B is dropped when an earlier label A has

    t_A ≤ t_B  and  f_A − e·t_A ≤ f_B − e·t_B          (e = the early-arrival rate of `jit`, 0 for `thesis`)

Every continuation of A then arrives no later than the same continuation of B (legs are first-in
first-out), so no later penalty, at most e per hour more early penalty, and no more fuel **as long as the
rest of the voyage costs the same fuel from either start time**. That holds exactly in weather that does not
change with time; in time-varying weather it is the one assumption of this solver (a later start through a
passing storm can be cheaper, and a weather limit can block a leg started at 116.7 h that is open at 118.7 h),
so it is exact only over the wait-free plans of weather that holds still; tests/test_routing_exact.py checks it
against exhaustive enumeration on small graphs with moving storms, where it happens to hold. There is no merging
of labels into time buckets. A leg is not sailed when a label already made at its end is sure to drop the one it
would make (`engine.label_search.dp_exact_nb`): that changes the legs sailed, never the labels kept. `DpOptions(slot_h=...)` selects the DP that needs no such assumption
(dp_grid.py): departures from nodes on a time grid and at the times of known wait-free plans, with waiting; exact
over that space, its plans wait. With `wait_free_first` (the product's default, options.DEFAULT_SOLVER_OPTIONS)
this DP's plan comes first and its times join the grid, so the grid DP's plan is never dearer than it.

ε-trimming (`DpOptions.gap` > 0): sorted by time, a label is kept only when its f − e·t is more than ε below
every earlier kept one's at its node, with ε = gap·LB / (lines − 1) and LB a certified lower bound on the
optimum's cost (`bound_tables.cost_lower_bound`); the plan returned then costs at most (1 + gap) × the optimum (proof in
`bound_tables.trim_eps`). This is what makes the 5,000 NM instance tractable: most labels at a node differ by grams.

Work paced by legs sailed (`DpOptions.max_label_legs`, the product's 3,000,000): the number of labels grows with the
voyage's length twice over (more lines, and ε shrinks as 1 / lines), so a 10,000 NM voyage would sail about 93 million
legs. Past the budget the search is given up and run again keeping at most `capped_labels` per node
(`engine.labels.LabelMode`: time spans, a span's label chosen at the base route's price of time), which is
approximate and said in the plan's reason; the grid DP that follows (dp_grid.py) certifies the plan over its space
either way.

Bounds (certified: they never drop a label of an optimal plan):
  incumbent   any known plan's cost is an upper bound U on the optimum: the baseline's, and by default a
              BFOA plan's (`DpOptions.incumbent`); the answer does not depend on it, only the time taken.
  deadline    when U is on time (jit: below the 1000 t late step; thesis: below 9999.9), a plan arriving after
              the RTA cannot win, so a label must still be able to arrive by the RTA.
  lateness    when no plan known is on time, a label is priced with the lateness of the earliest arrival it can
              still make (its time plus the least hours to finish, t_min below; `engine.bounds.cost_lb_nb`), and the fastest
              wait-free plan (fastest_plan.py) joins the incumbents: on a voyage whose RTA cannot be met the
              optimum is the least-late plan (10 t per minute late under jit), and every label that cannot arrive
              within minutes of the fastest is dropped. Without it such a voyage kept every label to the horizon.
  fuel        for each leg and engine setting r: the least hours per NM τ (best STW in the weather the leg can
              meet, plus the strongest current along its course there) and the least fuel per NM φ. For any λ ≥ 0
              a backward pass gives M_λ = the least Σ d·(φ + λ·τ) to the arrival, and a completion sailed within
              H hours burns at least max_λ (M_λ − λ·H) (it cannot arrive at all below the least Σ d·τ). A label
              whose fuel so far plus that bound prices it above U is dropped; each leg is first priced at its
              own least hours and fuel (d·τ, d·φ) and sailed only when that label could survive.
The weather a leg can meet (`bound_tables.finish_bounds` with windows, reachable_weather.py): the grid cells its chord reads, at
the valid times between the earliest arrival at its start and the latest departure from its end (the RTA's, when U
is on time), narrowed to the times a plan burning no more than any plan the DP must keep can be there
(`bound_tables.fuel_windows`). Over them wind and Hs have lower bounds, and the wind, wave and current directions relative to the
leg's course ranges. The bounds on STW and fuel rate come from the performance model at the corners of those ranges
(speeds lo..hi, relative directions lo..hi): the thesis form is linear in each of them (with the corner just above
a calm, where it drops its direction terms), the physical form linear in Vw²·w(θw) and Hs²·w(θs) (w falling with
θ), each then clipped monotonically; so the corners give its extremes whatever the coefficients' signs, fouling
and the air-resistance allowance included (weather limits cap the range, since a leg beyond them is infeasible
anyway). Without windows (the engine-limits DP, the grid DP) the range is the node's: wind and Hs 0..the strongest
near it at any valid time, every direction, the strongest current. For the 5,000 NM bench voyages the windowed bound
is 0.87 (east) and 0.95 (west) of the optimum, against 0.80 and 0.75 for the node's range.

The search itself is compiled in pipeline/routing/engine/ (`label_search.dp_exact_nb`, with what the searches share:
sailing a leg, the label stores, the bound structure `FinishBounds`, the pruning rule `label_priced_out` and the one
relaxation step of `relax.py`); the tables are built by pipeline/routing/bound_tables.py (`label_bounds`). This
module is the strategy: the bounds, the incumbents, the legs budget, and the grid DP after it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pipeline.routing.bound_tables import label_bounds, latest_departures, reachable_windows, trim_eps
from pipeline.routing.contract import Found
from pipeline.routing.dp_grid import search_grid, wait_hours, wait_rate_tph
from pipeline.routing.engine.bounds import FinishBounds, is_on_time
from pipeline.routing.engine.label_search import dp_exact_nb
from pipeline.routing.engine.labels import EXACT, bucketed
from pipeline.routing.engine_timing import time_price
from pipeline.routing.objectives import OBJ_JIT



def _fuel_budget_t(o, upper: float, gap: float) -> float:
    """The most fuel (t) a plan can burn that the DP, pruning with the on-time incumbent cost `upper` and trimming
    within `gap`, must keep: its cost is at most upper + gap·upper (the DP's tolerance is gap·LB ≤ gap·optimum)."""
    cost = upper * (1.0 + gap) + 2e-9 * max(1.0, abs(upper))
    return cost if o.kind == OBJ_JIT else (cost - 0.85) * o.f_target / 3.0  # thesis: 0.85 + 3·F/F_target on time


@dataclass(frozen=True)
class DpOptions:
    upper_bound: float | None = None  # a known plan's cost, to prune with (the baseline's is always used)
    incumbent: str | None = "bfoa"  # also prune with this solver's plan (seed 1, default options); None: no
    gap: float = 0.0  # > 0: the plan costs at most (1 + gap) × the optimum. Labels: ε-trimming (see `trim_eps`),
    #                   certified under the dominance's assumption; grid (slot_h): pruning, certified outright
    slot_h: float | None = None  # a number: the exact DP of dp_grid.py, departures from nodes on this time grid
    #                              (h) with waits; the plan's legs then carry their waits (wait_h, wait_fuel_t)
    max_wait_h: float = 0.0  # grid: a ship may wait this long beyond the first slot after arriving at a node
    wait_tph: float | None = None  # grid: fuel rate while waiting (t/h); None: calm water at the lowest setting
    wait_free_first: bool = False  # grid: first the label DP (same gap); its plan's times join the grid
    slots_per_rta: float | None = None  # grid: a step of at least the RTA's passage hours / this, in whole hours
    max_label_legs: int | None = None  # the label DP gives up after sailing this many legs (None: never) and
    #                                     searches again keeping at most `capped_labels` labels per node (approximate;
    #                                     the plan's reason says so): its work paced by legs sailed, not the clock
    capped_labels: int = 64

    def __post_init__(self):
        legs, cap = self.max_label_legs, self.capped_labels
        if legs is not None:
            if isinstance(legs, bool) or not isinstance(legs, (int, float)) or not legs >= 1:
                raise ValueError(f"dp option max_label_legs must be a number of legs ≥ 1 or none, got {legs!r}")
            object.__setattr__(self, "max_label_legs", int(legs))
        if isinstance(cap, bool) or not isinstance(cap, (int, float)) or not cap >= 1 or int(cap) != cap:
            raise ValueError(f"dp option capped_labels must be a whole number of labels per node ≥ 1, got {cap!r}")
        object.__setattr__(self, "capped_labels", int(cap))


def search(inst, baseline, *, seed: int, options: DpOptions, upper: float = math.inf, incumbent=None):
    """The solver contract (contract.py); `seed` is not used, `upper` is a known plan's cost to prune with and
    `incumbent` that plan (nodes, rpm_idx) when known (the registry passes its incumbent solver's, solvers._dp).
    The grid DP (options.slot_h) searches the departure times of the grid and of the wait-free plans it knows:
    the baseline, `incumbent` and, with `wait_free_first`, the label DP's plan, found first; its Found carries the
    waits (Found.wait_h, Found.wait_tph), which solve() puts on the plan's legs."""
    from pipeline.routing.baseline import evaluate

    if options.upper_bound is not None:
        upper = min(upper, float(options.upper_bound))
    if baseline.ok:
        upper = min(upper, evaluate(inst, baseline.nodes, baseline.rpm_idx)[0])
    known = [incumbent] if incumbent is not None else []
    n_fast = 0
    if not is_on_time(inst.objective, upper):  # no plan known on time: maybe none is; the fastest prices lateness
        upper, n_fast = _with_fastest_plan(inst, upper, known)
    if options.slot_h is not None:
        found = _grid_search(inst, baseline, options, upper, known)
        found.n_evals += n_fast
        return found
    nodes, rpm_idx, cost, n_legs, _, capped = _label_search(inst, options, upper, latest_departures(inst), baseline)
    if not math.isfinite(cost):  # nothing below the incumbents (where the dominance's assumption fails): the best
        nodes, rpm_idx = _cheapest(inst, known)  # plan known, never the baseline while a dearer plan... is known
    space = (f"dp: {_within(options.gap)} the best wait-free plan of the graph, in weather that holds still, before "
             "engine limits and continuous speed"
             if capped is None else None)  # capped: the search was approximate, and the note says how
    return Found(nodes, rpm_idx, n_fast + n_legs, note="; ".join(x for x in (space, capped) if x))


def _cheapest(inst, plans) -> tuple:
    """(nodes, rpm_idx) of the cheapest of `plans` that can be sailed; (None, None) when none can."""
    from pipeline.routing.baseline import evaluate

    best, pick = math.inf, (None, None)
    for nodes, rpm_idx in plans:
        cost = evaluate(inst, nodes, rpm_idx)[0]
        if cost < best:
            best, pick = cost, (nodes, rpm_idx)
    return pick


def _with_fastest_plan(inst, upper: float, known: list) -> tuple[float, int]:
    """(upper, legs sailed): `upper` lowered to the cost of the fastest wait-free plan (fastest_plan.py) when that is
    cheaper, the plan appended to `known`. Worth its few legs only when no plan known is on time: then either none
    is (and the optimum is within minutes of the fastest, which the lateness in the DP's bound then shows) or the
    fastest is, and it is an on-time incumbent."""
    from pipeline.routing.baseline import evaluate
    from pipeline.routing.fastest_plan import fastest_plan

    nodes, rpm_idx, _, n_legs = fastest_plan(inst)
    if nodes is not None:
        cost = evaluate(inst, nodes, rpm_idx)[0]
        if cost < upper:
            upper = cost
            known.append((nodes, rpm_idx))
    return upper, n_legs


def _label_search(inst, options: DpOptions, upper: float, ld: np.ndarray, baseline, wide=None):
    """(nodes, rpm_idx, cost, legs sailed, bounds, note) of dp_exact_nb, pruned by `upper` and trimmed to
    options.gap; `wide` as in finish_bounds (per leg); `bounds` the FinishBounds the DP ran with. With
    options.max_label_legs, a search that sails more legs than that is given up and run again keeping at most
    options.capped_labels labels per node (spans compared at the baseline route's price of time); `note` then says
    so (else None)."""
    # the bounds in the weather of the times a plan can be at each node (an on-time incumbent: by the RTA, and
    # burning no more fuel than a plan the DP keeps: within the incumbent's cost and the gap)
    gap = options.gap
    on_time = is_on_time(inst.objective, upper)
    fb = label_bounds(inst, ld, reachable_windows(inst, ld, on_time),
                      _fuel_budget_t(inst.objective, upper, gap) if on_time else math.inf, wide=wide)
    eps = trim_eps(inst, gap, upper, fb.lams, fb.m_lam, fb.t_min)
    budget = options.max_label_legs or 0  # 0: no limit (LabelMode.max_legs)
    nodes, rpm_idx, cost, n_legs, _ = dp_exact_nb(inst.graph, inst.vessel, inst.wx, inst.objective, upper, fb, eps,
                                                  EXACT._replace(max_legs=budget))
    if budget <= 0 or n_legs <= budget:
        return nodes, rpm_idx, cost, n_legs, fb, None
    route = baseline.nodes if baseline.ok else inst.space.base_route()
    mode = bucketed(options.capped_labels, time_price(inst, route) if inst.objective.kind == OBJ_JIT else 0.0)
    nodes, rpm_idx, cost, n_capped, _ = dp_exact_nb(inst.graph, inst.vessel, inst.wx, inst.objective, upper, fb, eps,
                                                    mode)
    note = (f"the wait-free label search kept at most {options.capped_labels} labels per node: keeping every label "
            f"would sail over {budget:,} legs (solver option max_label_legs)")
    return nodes, rpm_idx, cost, n_legs + n_capped, fb, note


def _grid_search(inst, baseline, options: DpOptions, upper: float, known: list) -> Found:
    """The grid DP (dp_grid.py) over the grid and the wait-free plans known (see `search`; `known`: (nodes, rpm_idx)
    of the incumbent solver's plan and the fastest plan, when found)."""
    if not options.slot_h > 0.0 or not options.max_wait_h >= 0.0 or not (options.wait_tph or 0.0) >= 0.0:
        raise ValueError(f"dp options slot_h must be > 0 h and max_wait_h, wait_tph ≥ 0, got {options.slot_h}, "
                         f"{options.max_wait_h} and {options.wait_tph}")
    plans = ([(baseline.nodes, baseline.rpm_idx)] if baseline.ok else []) + list(known)
    ld = latest_departures(inst)
    n_first, bounds, capped = 0, None, None
    if options.wait_free_first:
        wide: list = []
        nodes, rpm_idx, cost, n_first, narrow, capped = _label_search(inst, options, upper, ld, baseline, wide)
        if math.isfinite(cost):
            plans.append((nodes, rpm_idx))
        # which of its bound tables hold for the grid's plans: with its plan on time (a plan of the grid, so the
        # grid's incumbent is on time and costs no more) the tables it ran with, whose windows are narrowed to the
        # times a plan within its incumbent's cost and the gap can be at each node: a plan that waits is at a node
        # from its arrival to its departure, and both bounds (fuel to get there, fuel to finish) only tighten while
        # it waits, so it is inside them too. With no plan known on time, its windows before the fuel narrowing when
        # they reach to the horizon; an `upper_bound` on time with no plan known on time: the grid builds its own
        if math.isfinite(cost) and is_on_time(inst.objective, cost):
            bounds = narrow
        elif not is_on_time(inst.objective, upper):
            bounds = FinishBounds(*wide, ld)
    slot_h = grid_step_h(inst, options)
    nodes, rpm_idx, slots, cost, n_legs, times = search_grid(
        inst, plans, slot_h=slot_h, max_wait_h=float(options.max_wait_h), wait_tph=options.wait_tph,
        gap=float(options.gap), ld=ld, bounds=bounds)
    if nodes is None:
        return Found(None, None, n_first + n_legs)
    waits = wait_hours(inst, nodes, rpm_idx, slots, times)
    coarse = f"waits on a {slot_h:g} h grid" if np.any(waits > 1.0 / 3600.0) and slot_h > options.slot_h else None
    space = (f"dp: {_within(options.gap)} the best plan of the graph leaving each node on a {slot_h:g} h grid or at the "
             f"wait-free plans' times (waits up to {options.max_wait_h:g} h), before engine limits and continuous speed")
    note = "; ".join(x for x in (space, coarse, capped) if x)
    return Found(nodes, rpm_idx, n_first + n_legs, wait_h=waits, wait_tph=wait_rate_tph(inst, options.wait_tph),
                 note=note)


def _within(gap: float) -> str:
    """How close the plan is certified to be to the best of its space (`DpOptions.gap`)."""
    return f"certified within {100.0 * gap:g} % of" if gap > 0.0 else "certified as"


def grid_step_h(inst, options: DpOptions) -> float:
    """The grid DP's time step (h): `slot_h`, or with `slots_per_rta` the RTA's passage hours over that many slots
    rounded up to whole hours when that is longer: the grid DP's work grows with the slots a node can be left at,
    so a 40-day voyage gets a coarser grid than a 10-day one (its plan's reason then says which)."""
    step = float(options.slot_h)
    if options.slots_per_rta:
        step = max(step, float(math.ceil(inst.objective.t_req_h / float(options.slots_per_rta) - 1e-9)))
    return step
