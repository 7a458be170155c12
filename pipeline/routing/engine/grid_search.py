"""The grid DP's search (compiled): labels at (line, node, departure slot), one per state (the least fuel), so exact
over the space of nodes, settings and departure times on each line's grid with waits; `grid_sail_nb` sails one
plan of that space. The space, its bounds and why they are certified: pipeline/routing/dp_grid.py, the strategy
that builds the grid and runs this search.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from pipeline.routing import geodesy as geo
from pipeline.routing.engine.bounds import label_priced_out
from pipeline.routing.engine.labels import grow_store
from pipeline.routing.engine.leg import CODE, FUEL, H, N_LEG_OUT, NO_EDGE, OK, TOO_LONG, sail_leg_nb
from pipeline.routing.engine.relax import Relax, leg_priced_out, sail_label_leg
from pipeline.routing.objectives import LATE_STEP_T, OBJ_JIT, route_cost_nb

EARLY_SLOT = -1  # grid_sail_nb: a departure slot before the ship reaches the node


@numba.njit(cache=True)
def first_slot(times_i, t_h):
    """The first slot k of a line (departure times_i[k]) at or after t_h; 1e-9 h of rounding is forgiven.
    times_i.shape[0] when the line has none left (its padding is inf)."""
    return np.searchsorted(times_i, t_h - 1e-9)


@numba.njit(cache=True)
def grid_sail_nb(vy, nodes, rpm_idx, slots, times, wait_tph):
    """(code, hours, fuel) of a plan of the grid space: leave line i's node at times[i, slots[i]] and sail its leg
    at rpm_idx[i]; code is an engine.leg code, or EARLY_SLOT when a slot is before the ship is there. slots[i] < 0:
    the first slot after arriving (no extra wait). `slots` is filled with the slots used."""
    g, v, w, o = vy
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
def dp_grid_nb(vy, upper, prune_at, fb, times, max_wait_h, wait_tph):
    """(nodes, rpm indexes, departure slots, cost, legs sailed, labels kept) of the best plan of the grid space
    costing less than `upper` (cost inf when there is none); labels whose lower bound is above `prune_at`
    (≤ upper; upper / (1 + gap) for a certified gap) are dropped. `fb`: the FinishBounds, as label_search.dp_exact_nb's."""
    g, v, w, o = vy
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
                            ck, cf, cpar, cnode, cr = grow_store(n_c + 1, ck, cf, cpar, cnode, cr)
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
                kk, kf, kpar, knode, kr = grow_store(n_kept + 1, kk, kf, kpar, knode, kr)
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
