"""Exact DP when the weather changes in time: departures from every node on a time grid, waiting allowed.

Why: the label DP of dp.py drops a label B when an earlier label A has no more fuel. That is exact only when the
rest of the voyage costs the same from either start time. Under a passing storm it does not. A weather limit
(Hs or wind over the vessel's) can block a leg started at 116.7 h and leave it open at 118.7 h, and a later
start behind a storm can burn less. Here no such assumption is made.

Decision space: a node per line and an engine setting per leg, as everywhere, plus **when the ship leaves each
node**. A line's departure times are the grid t_dep + k·`slot_h` and the times the known wait-free plans leave it
(`line_times`: the baseline, the incumbent solver's plan and, with `DpOptions.wait_free_first`, the label DP's
plan; so each of those is a plan of the space as it is). A ship that reaches a node between two of its line's
times waits (heaves to, drifting at `wait_tph` t/h) until the next one. It may also wait up to `max_wait_h` more
there (waiting in front of a storm). Waiting at the departure node is allowed the same way. The arrival at the
last line is not rounded: the voyage ends when the ship gets there.

Exact: a state is (line, node, departure time). Two partial plans in the same state have the same futures:
same place, same departure time, and the fuel so far is all that differs. So the DP keeps one label per state
(the least fuel) and drops nothing else. The optimum over this space is found; `tests/test_routing_grid_exact.py`
checks it against exhaustive enumeration of the same space (every route × setting × wait), on the grid alone and
on the grid with the label DP's plan. The price is that no two departure times are merged: the work grows with
the number of times a node can be left at. What `jitroute route --solver dp` runs by default is the second: the
label DP's wait-free plan first, then this DP, so its plan is never dearer than the wait-free one and it heaves to
where waiting for the weather wins.

Bounds (certified; they never drop a label of an optimal plan, as in dp.py):
  incumbent   `upper`: the cost of a known plan of this space (a wait-free plan sailed with the rounding waits,
              `engine.grid_search.grid_sail_nb`). With `gap` > 0, a label is dropped when even its lower bound is above
              upper / (1 + gap). The plan returned (the DP's or the incumbent) is then within (1 + gap) of the
              optimum.
  deadline    with an on-time incumbent, a label must be able to leave its node by the node's latest departure
              that still makes the RTA (bound_tables.latest_departures; waiting only delays).
  fuel        bound_tables.finish_bounds: fuel so far + the least fuel to finish in the hours left (the hours left start at
              the departure slot; waiting burns ≥ 0), priced leg by leg in the weather of the times a plan can be
              at each node (from the earliest arrival to the latest departure: waiting keeps a plan inside them).
              After the label DP found a plan on time, its own tables: its windows narrowed to the times a plan
              within the incumbent's cost can be at a node (bound_tables.fuel_windows), which hold for a plan that waits too
              (while it waits, the fuel it needed to get there and the fuel it needs to finish only grow).
  lateness    with no plan on time, the lateness of the earliest arrival a label can still make (engine.bounds.cost_lb_nb).

The grid's step (dp.grid_step_h): `slot_h`, or with `DpOptions.slots_per_rta` (the product's: 240) the RTA's
passage hours over that many slots in whole hours when that is longer: a 40-day voyage waits on a 5 h grid, whose
plan's reason then says "waits on a 5 h grid". The work grows with the slots a node can be left at.
"""

from __future__ import annotations

import math

import numpy as np

from pipeline.routing.bound_tables import label_bounds, reachable_windows
from pipeline.routing.engine.bounds import is_on_time
from pipeline.routing.engine.grid_search import dp_grid_nb, grid_sail_nb
from pipeline.routing.engine.leg import CODE, FUEL, H, N_LEG_OUT, OK, sail_leg_nb, sail_route_nb
from pipeline.routing.objectives import route_cost_nb



def line_times(inst, plans, slot_h: float) -> np.ndarray:
    """(lines − 1, K) departure times (h, sorted, inf-padded) a ship may leave each line's nodes at: the grid
    t_dep + k·slot_h up to the voyage's longest hours, and each wait-free plan's own departure time from that
    line (`plans`: (nodes, rpm_idx); one that cannot be sailed adds nothing). So the plans given are plans of the
    grid space as they are, without rounding waits, and the grid DP's optimum is never dearer than theirs."""
    g, v, w, o = inst.graph, inst.vessel, inst.wx, inst.objective
    L2 = g.lat.shape[0]
    grid = o.t_dep_h + slot_h * np.arange(int(math.floor(o.max_hours / slot_h + 1e-9)) + 1)
    extra = [[] for _ in range(L2 - 1)]
    ct, cf = np.empty(L2), np.empty(L2)
    for nodes, rpm_idx in plans:
        if nodes is None:
            continue
        code, _ = sail_route_nb(np.asarray(nodes, np.int64), np.asarray(rpm_idx, np.int64), 0, g, v, w, o, ct, cf)
        if code != OK:
            continue
        for i in range(1, L2 - 1):
            extra[i].append(float(ct[i]))
    rows = [np.unique(np.concatenate([grid, np.asarray(e, float)])) for e in extra]
    times = np.full((L2 - 1, max(len(r) for r in rows)), np.inf)
    for i, r in enumerate(rows):
        times[i, :len(r)] = r
    return times


def wait_rate_tph(inst, wait_tph: float | None) -> float:
    """The fuel rate while waiting (t/h): as given, else the model's calm-water rate at the lowest setting (a ship
    hove to keeps steerage way at its slowest engine order)."""
    if wait_tph is not None:
        return float(wait_tph)
    p = inst.problem
    return float(p.model.fuel_tph(float(inst.rpm_options[0]), p.draft_m, p.trim_m))


def grid_plan_cost(inst, nodes, rpm_idx, times, wait_tph: float, slots=None) -> tuple[float, np.ndarray]:
    """(cost, slots) of a plan in the grid space; `slots` None: each node left at the first slot after arriving
    (how a wait-free plan becomes a plan of this space). Cost inf when it cannot be sailed so."""
    L2 = len(nodes)
    s = np.full(L2 - 1, -1, np.int64) if slots is None else np.array(slots, np.int64)
    code, hours, fuel = grid_sail_nb(inst.voyage, np.asarray(nodes, np.int64), np.asarray(rpm_idx, np.int64), s, times,
                                     float(wait_tph))
    if code != OK:
        return math.inf, s
    return float(route_cost_nb(inst.objective, hours, fuel)), s


def wait_hours(inst, nodes, rpm_idx, slots, times) -> np.ndarray:
    """Hours waited at each line's node before its leg (line 0: at the departure), for the plan's slots."""
    g, v, w, o = inst.graph, inst.vessel, inst.wx, inst.objective
    out = np.empty(N_LEG_OUT)
    t = o.t_dep_h
    waits = np.zeros(len(nodes) - 1)
    for i in range(len(nodes) - 1):
        td = float(times[i, int(slots[i])])
        waits[i] = td - t
        a, b = int(nodes[i]), int(nodes[i + 1])
        sail_leg_nb(g.lat[i, a], g.lon[i, a], g.lat[i + 1, b], g.lon[i + 1, b], td,
                    v.rpm_options[int(rpm_idx[i])], v, w, out)
        t = td + out[H]
    return waits


def waited_plan_cost(inst, nodes, rpm_idx, wait_h, wait_tph: float) -> float:
    """Cost of a plan that waits wait_h[i] (h) at line i's node, burning wait_tph, before sailing its leg."""
    g, v, w, o = inst.graph, inst.vessel, inst.wx, inst.objective
    out = np.empty(N_LEG_OUT)
    t, fuel = o.t_dep_h, 0.0
    for i in range(len(nodes) - 1):
        t += float(wait_h[i])
        fuel += wait_tph * float(wait_h[i])
        a, b = int(nodes[i]), int(nodes[i + 1])
        sail_leg_nb(g.lat[i, a], g.lon[i, a], g.lat[i + 1, b], g.lon[i + 1, b], t, v.rpm_options[int(rpm_idx[i])], v,
                    w, out)
        if out[CODE] != OK:
            return math.inf
        t += out[H]
        fuel += out[FUEL]
    return float(route_cost_nb(o, t - o.t_dep_h, fuel))


def _incumbents(plans, n_settings: int):
    """The wait-free plans given, and on each of their routes every setting held throughout and the given settings
    one step faster: the rounding waits make a plan that was just on time late, and a late incumbent prunes
    next to nothing, so one that still makes the RTA is worth a few more sails."""
    for nodes, rpm_idx in plans:
        if nodes is None:
            continue
        nodes, rpm_idx = np.asarray(nodes, np.int64), np.asarray(rpm_idx, np.int64)
        yield nodes, rpm_idx
        yield nodes, np.minimum(rpm_idx + 1, n_settings - 1)
        for r in range(n_settings):
            yield nodes, np.full(len(rpm_idx), r, np.int64)


def search_grid(inst, plans, *, slot_h: float, max_wait_h: float, wait_tph: float | None, gap: float, ld,
                bounds=None):
    """(nodes, rpm_idx, slots, cost, legs sailed, times) of the best plan of the grid space, within (1 + gap) of
    its optimum; `plans` are known wait-free plans (nodes, rpm_idx): their departure times join the grid
    (`line_times`, returned as `times`; a plan's slots index its rows), so each is a plan of the space as it is,
    and each, its settings one step faster and every setting held throughout are sailed with the rounding waits
    as the incumbent; `ld` = bound_tables.latest_departures(inst). The fuel-to-finish bound is bound_tables.finish_bounds in the
    weather of the times a plan can be at each node (reachable_windows), per leg: waits keep a plan within them;
    `bounds`, when given, is a FinishBounds that holds for every plan the grid must keep (dp._grid_search: the label
    DP's, narrowed to the times a plan within its incumbent's cost can be at each node, when its plan is on time)."""
    rate = wait_rate_tph(inst, wait_tph)
    times = line_times(inst, plans, slot_h)
    inc_cost, inc = math.inf, None
    for nodes, rpm_idx in _incumbents(plans, len(inst.rpm_options)):
        q, s = grid_plan_cost(inst, nodes, rpm_idx, times, rate)
        if q < inc_cost:
            inc_cost, inc = q, (np.asarray(nodes, np.int64), np.asarray(rpm_idx, np.int64), s)
    on_time = math.isfinite(inc_cost) and is_on_time(inst.objective, inc_cost)
    if bounds is None:
        bounds = label_bounds(inst, ld, reachable_windows(inst, ld, on_time))
    upper = inc_cost * (1.0 + 1e-12) + 1e-12 if math.isfinite(inc_cost) else math.inf
    prune_at = upper / (1.0 + gap) if gap > 0.0 else upper
    nodes, rpm_idx, slots, cost, n_legs, _ = dp_grid_nb(inst.voyage, upper, prune_at, bounds, times, float(max_wait_h),
                                                        rate)
    if math.isfinite(cost) and cost < inc_cost:
        return nodes, rpm_idx, slots, float(cost), n_legs, times
    if inc is None:
        return None, None, None, math.inf, n_legs, times
    return inc[0], inc[1], inc[2], inc_cost, n_legs, times
