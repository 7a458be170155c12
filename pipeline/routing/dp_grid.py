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
              `grid_sail_nb`). With `gap` > 0, a label is dropped when even its lower bound is above
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

import numba
import numpy as np

from pipeline.routing import geodesy as geo
from pipeline.routing.bound_tables import label_bounds, reachable_windows
from pipeline.routing.engine.bounds import is_on_time, label_priced_out
from pipeline.routing.engine.labels import grow
from pipeline.routing.engine.relax import Relax, leg_priced_out, sail_label_leg
from pipeline.routing.engine.leg import CODE, FUEL, H, N_LEG_OUT, NO_EDGE, OK, TOO_LONG, sail_leg_nb, sail_route_nb
from pipeline.routing.objectives import LATE_STEP_T, OBJ_JIT, route_cost_nb

EARLY_SLOT = -1  # grid_sail_nb: a departure slot before the ship reaches the node


@numba.njit(cache=True)
def first_slot(times_i, t_h):
    """The first slot k of a line (departure times_i[k]) at or after t_h; 1e-9 h of rounding is forgiven.
    times_i.shape[0] when the line has none left (its padding is inf)."""
    return np.searchsorted(times_i, t_h - 1e-9)


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


@numba.njit(cache=True)
def grid_sail_nb(nodes, rpm_idx, slots, g, v, w, o, times, wait_tph):
    """(code, hours, fuel) of a plan of the grid space: leave line i's node at times[i, slots[i]] and sail its leg
    at rpm_idx[i]; code is an engine.leg code, or EARLY_SLOT when a slot is before the ship is there. slots[i] < 0:
    the first slot after arriving (no extra wait). `slots` is filled with the slots used."""
    lat, lon = g.lat, g.lon
    out = np.empty(N_LEG_OUT)
    t, fuel = o.t_dep_h, 0.0
    L2 = nodes.shape[0]
    for i in range(L2 - 1):
        k0 = first_slot(times[i], t)
        k = k0 if slots[i] < 0 else slots[i]
        if k < k0:
            return EARLY_SLOT, math.nan, math.nan
        if k >= times.shape[1] or not times[i, k] < math.inf:
            return TOO_LONG, math.nan, math.nan
        slots[i] = k
        td = times[i, k]
        fuel += wait_tph * (td - t)
        a, b = nodes[i], nodes[i + 1]
        if not g.edge_ok[i, a, b]:
            return NO_EDGE, math.nan, math.nan
        sail_leg_nb(lat[i, a], lon[i, a], lat[i + 1, b], lon[i + 1, b], td, v.rpm_options[rpm_idx[i]], v, w, out)
        if out[CODE] != OK:
            return int(out[CODE]), math.nan, math.nan
        t = td + out[H]
        fuel += out[FUEL]
        if t - o.t_dep_h > o.max_hours:
            return TOO_LONG, math.nan, math.nan
    return OK, t - o.t_dep_h, fuel


@numba.njit(cache=True)
def dp_grid_nb(g, v, w, o, upper, prune_at, fb, times, max_wait_h, wait_tph):
    """(nodes, rpm indexes, departure slots, cost, legs sailed, labels kept) of the best plan of the grid space
    costing less than `upper` (cost inf when there is none); labels whose lower bound is above `prune_at`
    (≤ upper; upper / (1 + gap) for a certified gap) are dropped. `fb`: the FinishBounds, as dp.dp_exact_nb's."""
    lat, lon, edge_ok, max_shift, ld = g.lat, g.lon, g.edge_ok, g.max_shift, fb.ld
    t_dep_h, max_hours = o.t_dep_h, o.max_hours
    L2, P = lat.shape
    R = v.rpm_options.shape[0]
    c = P // 2
    on_time = upper < (LATE_STEP_T if o.kind == OBJ_JIT else 9999.9)
    tol = 1e-9 * max(1.0, abs(prune_at))
    x = Relax(g, v, w, o, fb, prune_at, tol, on_time)
    # kept labels of every line: node, departure slot, fuel at departure, parent label, setting of the leg to it
    cap = 1024
    kk, kf = np.empty(cap, np.int64), np.empty(cap)
    kpar, knode, kr = np.empty(cap, np.int64), np.empty(cap, np.int64), np.empty(cap, np.int64)
    n_kept = 0
    K = times.shape[1]
    for q in range(K):  # leave at once, or wait at the departure node
        td = times[0, q]
        if td > t_dep_h + max_wait_h + 1e-9 or (on_time and td > ld[0, c]):
            break
        kk[n_kept], kf[n_kept], kpar[n_kept], knode[n_kept], kr[n_kept] = q, wait_tph * (td - t_dep_h), -1, c, -1
        n_kept += 1
    line_lo, line_hi = 0, n_kept
    ccap = 1024
    ck, cf = np.empty(ccap, np.int64), np.empty(ccap)
    cpar, cnode, cr = np.empty(ccap, np.int64), np.empty(ccap, np.int64), np.empty(ccap, np.int64)
    out = np.empty(N_LEG_OUT)
    n_legs = 0
    best, best_par, best_r = upper, -1, -1
    for i in range(L2 - 1):
        last = i + 1 == L2 - 1
        n_c = 0
        for j in range(line_lo, line_hi):
            a, f0 = knode[j], kf[j]
            t0 = times[i, kk[j]]
            for a2 in range(max(0, a - max_shift), min(P, a + max_shift + 1)):
                if not edge_ok[i, a, a2]:
                    continue
                d_nm = geo.gc_distance_nm(lat[i, a], lon[i, a], lat[i + 1, a2], lon[i + 1, a2]) * (1.0 - 1e-9)
                s = a2 - a + max_shift
                for r in range(R):
                    if leg_priced_out(x, i, a, a2, s, r, d_nm, t0, f0):
                        continue
                    t1 = sail_label_leg(x, i, a, a2, r, t0, out)
                    n_legs += 1
                    if t1 == np.inf:
                        continue
                    f1 = f0 + out[FUEL]
                    if last:
                        q = route_cost_nb(o, t1 - t_dep_h, f1)
                        if q < best:
                            best, best_par, best_r = q, j, r
                        continue
                    k1 = first_slot(times[i + 1], t1)
                    for k in range(k1, K):
                        td = times[i + 1, k]
                        if td > times[i + 1, k1] + max_wait_h + 1e-9 or td - t_dep_h > max_hours or (
                                on_time and td > ld[i + 1, a2]):
                            break
                        fw = f1 + wait_tph * (td - t1)
                        if label_priced_out(o, fb, i + 1, a2, td, fw, prune_at, tol, on_time):
                            break  # a later slot burns no less and has fewer hours left
                        if n_c >= ck.shape[0]:
                            ck, cf = grow(ck, n_c + 1), grow(cf, n_c + 1)
                            cpar, cnode, cr = grow(cpar, n_c + 1), grow(cnode, n_c + 1), grow(cr, n_c + 1)
                        ck[n_c], cf[n_c], cpar[n_c], cnode[n_c], cr[n_c] = k, fw, j, a2, r
                        n_c += 1
        if last or n_c == 0:
            break
        # one label per (node, slot): the least fuel (the first of equals, in the order generated)
        k_lo, k_hi = ck[:n_c].min(), ck[:n_c].max()
        span = k_hi - k_lo + 1
        pick = np.full(P * span, -1, np.int64)
        for q in range(n_c):
            s = cnode[q] * span + ck[q] - k_lo
            if pick[s] < 0 or cf[q] < cf[pick[s]]:
                pick[s] = q
        line_lo = n_kept
        for s in range(P * span):
            q = pick[s]
            if q < 0:
                continue
            if n_kept >= kk.shape[0]:
                kk, kf = grow(kk, n_kept + 1), grow(kf, n_kept + 1)
                kpar, knode, kr = grow(kpar, n_kept + 1), grow(knode, n_kept + 1), grow(kr, n_kept + 1)
            kk[n_kept], kf[n_kept], kpar[n_kept], knode[n_kept], kr[n_kept] = ck[q], cf[q], cpar[q], cnode[q], cr[q]
            n_kept += 1
        line_hi = n_kept
    nodes = np.full(L2, c, np.int64)
    rpm_idx = np.zeros(L2 - 1, np.int64)
    slots = np.zeros(L2 - 1, np.int64)
    if best_par < 0:
        return nodes, rpm_idx, slots, np.inf, n_legs, n_kept
    rpm_idx[L2 - 2] = best_r
    j = best_par
    for i in range(L2 - 2, -1, -1):
        nodes[i] = knode[j]
        slots[i] = kk[j]
        if i > 0:
            rpm_idx[i - 1] = kr[j]
        j = kpar[j]
    return nodes, rpm_idx, slots, best, n_legs, n_kept


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
    code, hours, fuel = grid_sail_nb(np.asarray(nodes, np.int64), np.asarray(rpm_idx, np.int64), s, inst.graph,
                                     inst.vessel, inst.wx, inst.objective, times, float(wait_tph))
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
    nodes, rpm_idx, slots, cost, n_legs, _ = dp_grid_nb(inst.graph, inst.vessel, inst.wx, inst.objective, upper,
                                                        prune_at, bounds, times, float(max_wait_h), rate)
    if math.isfinite(cost) and cost < inc_cost:
        return nodes, rpm_idx, slots, float(cost), n_legs, times
    if inc is None:
        return None, None, None, math.inf, n_legs, times
    return inc[0], inc[1], inc[2], inc_cost, n_legs, times
