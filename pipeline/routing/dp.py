"""The exact reference (`--solver dp`): dynamic programming over (line, node) with an engine setting per leg.

A label is a partial plan reaching (line, node) at time t with fuel f; at each node a label is dropped when an earlier
one has no more f − e·t (e: the early-arrival rate of `jit`), which is exact over the wait-free plans of weather that
holds still. With `DpOptions.gap` > 0 the labels are ε-trimmed and the plan is certified within (1 + gap) × the
optimum; its work is paced by legs sailed (`max_label_legs`, then at most `capped_labels` per node, said in the
reason). With `slot_h` the grid DP of dp_grid.py follows: departures on a time grid and at the wait-free plans' times,
with waits, exact over that space (the product's default, with `wait_free_first`).

This module is the strategy: the bounds and incumbents it prunes with, the legs budget, and the grid DP after it. The
search is compiled in engine/ (`label_search.dp_exact_nb`, with the leg, the label stores, `FinishBounds`,
`label_priced_out` and the relaxation of relax.py); the bound tables come from bound_tables.py (`label_bounds`). Why
the dominance is exact and where it is not, the ε-trimming's certificate, and every bound: docs/search-methods.md,
"The exact DP".
"""

from __future__ import annotations

import math

import numpy as np

from pipeline.routing.bound_tables import fuel_budget_t, label_bounds, latest_departures, reachable_windows, trim_eps
from pipeline.routing.contract import Found
from pipeline.routing.dp_grid import search_grid, wait_hours, wait_rate_tph
from pipeline.routing.engine.bounds import FinishBounds, is_on_time
from pipeline.routing.engine.label_search import dp_exact_nb
from pipeline.routing.engine.labels import EXACT, bucketed
from pipeline.routing.engine.timing import time_price
from pipeline.routing.fastest_plan import cheapest_known, fastest_incumbent
from pipeline.routing.objectives import OBJ_JIT
from pipeline.routing.options import DpOptions


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
        upper, n_fast = fastest_incumbent(inst, upper, known)
    if options.slot_h is not None:
        found = _grid_search(inst, baseline, options, upper, known)
        found.n_evals += n_fast
        return found
    nodes, rpm_idx, cost, n_legs, _, capped = _label_search(inst, options, upper, latest_departures(inst), baseline)
    if not math.isfinite(cost):  # nothing below the incumbents (where the dominance's assumption fails): the best
        nodes, rpm_idx = cheapest_known(inst, known)  # plan known, never the baseline while a dearer plan... is known
    space = (f"dp: {_within(options.gap)} the best wait-free plan of the graph, in weather that holds still, before "
             "engine limits and continuous speed"
             if capped is None else None)  # capped: the search was approximate, and the note says how
    return Found(nodes, rpm_idx, n_fast + n_legs, note="; ".join(x for x in (space, capped) if x))


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
                      fuel_budget_t(inst.objective, upper, gap) if on_time else math.inf, wide=wide)
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
