"""The search for engine plans on a fixed route under a hold (compiled): labels only where the ship is free to change
setting, a change sailed as one run until the new setting has been held. The rules, the dominance and the bounds:
pipeline/routing/engine_limits.py, the strategy that builds the bounds and runs it (`limited_plan`).
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from pipeline.routing.engine.bounds import fuel_to_finish_lb
from pipeline.routing.engine.labels import grow, grow_store, time_span_nb
from pipeline.routing.engine.leg import CODE, FUEL, H, N_LEG_OUT, OK, sail_leg_nb, sail_route_nb
from pipeline.routing.objectives import LATE_STEP_T, OBJ_JIT, route_cost_nb


class Hold(NamedTuple):
    """The engine-change limits as the kernels see them: the least hours a setting is held, and the cost (t) the
    objective adds per change."""

    min_h: float
    change_cost_t: float


class RouteBounds(NamedTuple):
    """What the hold search prunes with: the latest departure from each line that still makes the RTA at full speed
    (`ld`, used when `prune`), a known plan's cost `upper`, the route's fuel-to-finish tables (prices `lams`, m_route
    (K, lines), t_min (lines); engine.bounds.fuel_to_finish_lb) and the ε-trimming `eps` (t)."""

    ld: np.ndarray
    prune: bool
    upper: float
    lams: np.ndarray
    m_route: np.ndarray
    t_min: np.ndarray
    eps: float


@numba.njit(cache=True)
def route_latest_departures_nb(rt, fast_rpm, deadline, ld):
    """ld[i] ≥ the latest time the ship can leave line i on the route and still arrive by `deadline` at the
    fastest setting (first-in-first-out legs: fixed point of t = target − hours(t), then checked from above)."""
    out = np.empty(N_LEG_OUT)
    lat, lon, nodes = rt.g.lat, rt.g.lon, rt.nodes
    L2 = nodes.shape[0]
    ld[L2 - 1] = deadline
    for i in range(L2 - 2, -1, -1):
        a, b = nodes[i], nodes[i + 1]
        target = ld[i + 1]
        t = target
        ok = False
        for _it in range(8):
            sail_leg_nb(lat[i, a], lon[i, a], lat[i + 1, b], lon[i + 1, b], t, fast_rpm, rt.v, rt.w, out)
            if out[CODE] != OK:
                break
            ok = True
            t = target - out[H]
        if not ok:
            ld[i] = target  # a leg that cannot be sailed at full speed: no pruning before it
            continue
        step = 1e-3
        while t < target:  # move up until leaving then arrives after the target
            sail_leg_nb(lat[i, a], lon[i, a], lat[i + 1, b], lon[i + 1, b], t, fast_rpm, rt.v, rt.w, out)
            if out[CODE] != OK or t + out[H] > target:
                break
            t += step
            step *= 2.0
        ld[i] = min(t, target)


@numba.njit(cache=True, inline="always")  # in the search's inner loop
def sail_run_nb(rt, rpm, i0, t0, f0, hold_h, to_end, out):
    """Sail the route from line i0 at time t0 (fuel f0) at `rpm` until the setting has been held `hold_h` hours, or
    to the arrival when `to_end`: (line reached, time, fuel, legs sailed, ok). ok is False when a leg cannot be
    sailed; the line reached is the last one when the arrival comes first."""
    lat, lon, nodes = rt.g.lat, rt.g.lon, rt.nodes
    L2 = nodes.shape[0]
    t, f = t0, f0
    i = i0
    n = 0
    while i < L2 - 1:
        a, b = nodes[i], nodes[i + 1]
        sail_leg_nb(lat[i, a], lon[i, a], lat[i + 1, b], lon[i + 1, b], t, rpm, rt.v, rt.w, out)
        n += 1
        if out[CODE] != OK:
            return i, t, f, n, False
        t += out[H]
        f += out[FUEL]
        i += 1
        if not to_end and t - t0 >= hold_h - 1e-9:
            break
    return i, t, f, n, True


@numba.njit(cache=True)
def runs_to_sail_nb(kt, kf, kn, kr, lo, hi, R, change_cost_t, e):
    """Per kept label lo..hi of one line and setting r: whether its change to r is worth sailing (False for its own
    setting). A change of label B to r is dominated when an earlier label A of the line (t_A ≤ t_B) reaches r free
    at no greater cost: g_A + c·[A's setting ≠ r] ≤ g_B + c (g = f + c·n − e·t). A then sails on at r, or changes
    to it, and meets every line B's run meets no later and, in weather that does not change with time, dearer by
    no more, both free to change at its end: the search's own dominance applied before the run is sailed instead
    of after, so the run's candidate, which the search would drop, is not made."""
    m = hi - lo
    sail = np.zeros((m, R), np.bool_)
    order = np.argsort(kt[lo:hi], kind="mergesort")
    least = np.full(R, np.inf)  # the least g + c·[setting ≠ r] of the labels so far in time order, per setting r
    for q in range(m):
        j = lo + order[q]
        g = kf[j] + change_cost_t * kn[j] - e * kt[j]
        for r in range(R):
            if r == kr[j]:
                least[r] = min(least[r], g)
                continue
            gc = g + change_cost_t
            sail[order[q], r] = gc < least[r]
            least[r] = min(least[r], gc)
    return sail


@numba.njit(cache=True, inline="always")
def _grow_runs(n, t, f, changes, setting, parent, start, more):
    """The seven parallel arrays of the hold search's label stores (time, fuel, changes, setting, parent, line its
    run began, and a line or a link), each with room for at least n labels."""
    t, f, changes, setting, parent = grow_store(n, t, f, changes, setting, parent)
    return t, f, changes, setting, parent, grow(start, n), grow(more, n)


@numba.njit(cache=True)
def hold_search_nb(rt, o, hold, rb, mode):
    """(rpm index per leg, cost, fuel, changes, legs sailed) of the best plan on the route `rt` (engine.leg.OnRoute) under
    the `hold` (a `Hold`), cost inf when no plan can be sailed. `rb` (a `RouteBounds`): labels that cannot make the RTA
    are dropped when rb.prune, and under `jit` those whose fuel and change costs so far plus the least fuel to finish
    exceed rb.upper; with rb.eps > 0 (t) a label is also dropped when an earlier one comes within eps of dominating
    it. `mode` (engine.labels.LabelMode): with mode.buckets > 0 at most that many labels per line and setting, the
    line's candidate times cut into equal spans, a span keeping its label of least f + c·n − e·t + lam_t·t."""
    rpm_options = rt.v.rpm_options
    R = rpm_options.shape[0]
    L2 = rt.nodes.shape[0]
    min_hold_h, change_cost_t = hold.min_h, hold.change_cost_t
    ld, prune, upper, lams, m_route, t_min, eps = rb.ld, rb.prune, rb.upper, rb.lams, rb.m_route, rb.t_min, rb.eps
    buckets, lam_t = mode.buckets, mode.lam_t
    t_dep_h, max_hours = o.t_dep_h, o.max_hours
    e = o.early_t_per_h if o.kind == OBJ_JIT else 0.0
    deadline = t_dep_h + (o.t_req_h if upper < LATE_STEP_T else max_hours)
    tol = 1e-9 * max(1.0, abs(upper))
    tol += (L2 - 1) * eps  # the label standing for the best plan may be up to that much dearer: keep it
    jit_bound = o.kind == OBJ_JIT and upper < np.inf
    # candidates: a label waiting to be judged at its line (per-line linked lists)
    ccap = 1024
    ct, cf = np.empty(ccap), np.empty(ccap)
    cn, cr, cpar, cstart, cnext = (np.empty(ccap, np.int64), np.empty(ccap, np.int64), np.empty(ccap, np.int64),
                                   np.empty(ccap, np.int64), np.empty(ccap, np.int64))
    head = np.full(L2, -1, np.int64)
    n_c = 0
    # kept labels: (time, fuel, changes, setting, parent kept label, line where its last run began, line)
    cap = 1024
    kt, kf = np.empty(cap), np.empty(cap)
    kn, kr, kpar, kstart, kline = (np.empty(cap, np.int64), np.empty(cap, np.int64), np.empty(cap, np.int64),
                                   np.empty(cap, np.int64), np.empty(cap, np.int64))
    n_kept = 0
    out = np.empty(N_LEG_OUT)
    n_legs = 0
    best, best_j, best_single = np.inf, -1, -1
    single_t, single_f = np.empty(R), np.empty(R)
    # the first setting: a run from the departure (to the arrival too: a plan of one setting)
    for r in range(R):
        i1, t1, f1, nl, ok = sail_run_nb(rt, rpm_options[r], 0, t_dep_h, 0.0, min_hold_h, True, out)
        n_legs += nl
        single_t[r], single_f[r] = t1, f1
        if ok and t1 - t_dep_h <= max_hours:
            q = route_cost_nb(o, t1 - t_dep_h, f1)
            if q < best:
                best, best_single = q, r
        # the same run, stopped where the hold is first met (its sailing is a prefix of the run above)
        i1, t1, f1, nl, ok = sail_run_nb(rt, rpm_options[r], 0, t_dep_h, 0.0, min_hold_h, False, out)
        n_legs += nl
        if not ok or i1 >= L2 - 1 or t1 - t_dep_h > max_hours or (prune and t1 > ld[i1]):
            continue
        if jit_bound and f1 + fuel_to_finish_lb(m_route[:, i1], lams, t_min[i1], deadline - t1) > upper + tol:
            continue
        if n_c >= ct.shape[0]:
            ct, cf, cn, cr, cpar, cstart, cnext = _grow_runs(n_c + 1, ct, cf, cn, cr, cpar, cstart, cnext)
        ct[n_c], cf[n_c], cn[n_c], cr[n_c], cpar[n_c], cstart[n_c] = t1, f1, 0, r, -1, 0
        cnext[n_c] = head[i1]
        head[i1] = n_c
        n_c += 1
    gmin = np.empty(R)
    last_slot, last_bucket, last_val = np.empty(R, np.int64), np.empty(R, np.int64), np.empty(R)
    for i in range(1, L2):
        # judge this line's candidates: per setting, by time, kept when f + c·n − e·t beats every earlier one
        m = 0
        k = head[i]
        while k >= 0:
            m += 1
            k = cnext[k]
        idx = np.empty(m, np.int64)
        k = head[i]
        q = 0
        while k >= 0:
            idx[q] = k
            q += 1
            k = cnext[k]
        order = idx[np.argsort(ct[idx], kind="mergesort")]
        gmin[:] = np.inf
        line_lo = n_kept
        last_slot[:] = -1
        if m > 0:
            t_lo, t_span = ct[order[0]], ct[order[m - 1]] - ct[order[0]]
        for q in range(m):
            k = order[q]
            r = cr[k]
            g = cf[k] + change_cost_t * cn[k] - e * ct[k]
            if not g < gmin[r] - eps:
                continue
            gmin[r] = g
            if buckets > 0:
                b = time_span_nb(ct[k], t_lo, t_span, buckets)
                val = g + lam_t * ct[k]
                if last_slot[r] >= 0 and last_bucket[r] == b:  # the span has a label: keep the better one
                    if val < last_val[r]:
                        s_ = last_slot[r]
                        kt[s_], kf[s_], kn[s_] = ct[k], cf[k], cn[k]
                        kpar[s_], kstart[s_] = cpar[k], cstart[k]
                        last_val[r] = val
                    continue
                last_bucket[r], last_slot[r], last_val[r] = b, n_kept, val
            if n_kept >= kt.shape[0]:
                kt, kf, kn, kr, kpar, kstart, kline = _grow_runs(n_kept + 1, kt, kf, kn, kr, kpar, kstart, kline)
            kt[n_kept], kf[n_kept], kn[n_kept], kr[n_kept] = ct[k], cf[k], cn[k], r
            kpar[n_kept], kstart[n_kept], kline[n_kept] = cpar[k], cstart[k], i
            n_kept += 1
        if i == L2 - 1:
            for j in range(line_lo, n_kept):
                qc = route_cost_nb(o, kt[j] - t_dep_h, kf[j]) + change_cost_t * kn[j]
                if qc < best:
                    best, best_j, best_single = qc, j, -1
            break
        # expand: one more leg at the label's setting, or a change and a run that holds the new setting (not sailed
        # when an earlier label of the line reaches that setting free at no greater cost: runs_to_sail_nb)
        sail = runs_to_sail_nb(kt, kf, kn, kr, line_lo, n_kept, R, change_cost_t, e)
        for j in range(line_lo, n_kept):
            for r in range(R):
                change = r != kr[j]
                if change and not sail[j - line_lo, r]:
                    continue
                run_h = min_hold_h if change else 0.0  # a held setting goes on one leg at a time
                i1, t1, f1, nl, ok = sail_run_nb(rt, rpm_options[r], i, kt[j], kf[j], run_h, False, out)
                n_legs += nl
                if not ok or t1 - t_dep_h > max_hours or (prune and t1 > ld[i1]):
                    continue
                n1 = kn[j] + (1 if change else 0)
                if change and t1 - kt[j] < min_hold_h - 1e-9:
                    continue  # the arrival came before the new setting was held: not a plan
                if jit_bound and (f1 + change_cost_t * n1
                                  + fuel_to_finish_lb(m_route[:, i1], lams, t_min[i1], deadline - t1)) > upper + tol:
                    continue
                if n_c >= ct.shape[0]:
                    ct, cf, cn, cr, cpar, cstart, cnext = _grow_runs(n_c + 1, ct, cf, cn, cr, cpar, cstart, cnext)
                ct[n_c], cf[n_c], cn[n_c], cr[n_c], cpar[n_c], cstart[n_c] = t1, f1, n1, r, j, i
                cnext[n_c] = head[i1]
                head[i1] = n_c
                n_c += 1
    rpm_idx = np.zeros(L2 - 1, np.int64)
    if best_single >= 0:
        rpm_idx[:] = best_single
        return rpm_idx, best, single_f[best_single], 0, n_legs
    if best_j < 0:
        return rpm_idx, np.inf, np.nan, 0, n_legs
    fuel, changes = kf[best_j], kn[best_j]
    j = best_j
    end = L2 - 1
    while j >= 0:
        rpm_idx[kstart[j]:end] = kr[j]
        end = kstart[j]
        j = kpar[j]
    return rpm_idx, best, fuel, changes, n_legs


@numba.njit(cache=True)
def incumbent_cost_nb(rt, o, hold, one_change):
    """The cost of a plan obeying the `hold`, for pruning: the best of each setting held throughout and, with
    `one_change`, of one change from one setting to another at any line (inf when none can be sailed). A
    one-change plan shares its first part with the plan of its first setting throughout, so only its second part
    is sailed (still lines² legs: the bucketed searches, whose labels are few anyway, go without it)."""
    nodes, g, v, w = rt.nodes, rt.g, rt.v, rt.w
    L = nodes.shape[0] - 1
    R = v.rpm_options.shape[0]
    ct, cf = np.empty((R, L + 1)), np.empty((R, L + 1))
    sailed = np.zeros(R, np.int64)  # lines reached by the plan of each setting throughout
    rpm_idx = np.empty(L, np.int64)
    for r in range(R):
        rpm_idx[:] = r
        code, bad = sail_route_nb(nodes, rpm_idx, 0, g, v, w, o, ct[r], cf[r])
        sailed[r] = L if code == OK else bad
    best = np.inf
    for r in range(R):
        if sailed[r] == L:
            best = min(best, route_cost_nb(o, ct[r, L] - o.t_dep_h, cf[r, L]))
    t2, f2 = np.empty(L + 1), np.empty(L + 1)
    for r0 in range(R if one_change else 0):
        for k in range(1, sailed[r0] + 1 if sailed[r0] < L else L):
            if ct[r0, k] - o.t_dep_h < hold.min_h - 1e-9:
                continue  # the first setting is not held long enough yet
            t2[:k + 1], f2[:k + 1] = ct[r0, :k + 1], cf[r0, :k + 1]
            for r1 in range(R):
                if r1 == r0:
                    continue
                rpm_idx[:k] = r0
                rpm_idx[k:] = r1
                code, _ = sail_route_nb(nodes, rpm_idx, k, g, v, w, o, t2, f2)  # from line k on
                if code == OK and t2[L] - ct[r0, k] >= hold.min_h - 1e-9:
                    best = min(best, route_cost_nb(o, t2[L] - o.t_dep_h, f2[L]) + hold.change_cost_t)
    return best
