"""The label DP's search (compiled): labels at (line, node) kept by time–fuel dominance (every one not dominated, or
at most a number per node in time spans), each leg relaxed by the one step of engine/relax.py. Why the dominance is
exact, the bounds it prunes with and the ε-trimming: docs/search-methods.md, "The exact DP"; the strategy that runs it
is pipeline/routing/dp.py (also the BFOA's polish and the engine plans of a fixed route, engine_limits.py).
"""

from __future__ import annotations

import numba
import numpy as np

from pipeline.routing import geodesy as geo
from pipeline.routing.engine.bounds import label_priced_out
from pipeline.routing.engine.labels import grow_store, prefix_min, put_min, time_span_nb
from pipeline.routing.engine.leg import FUEL, N_LEG_OUT
from pipeline.routing.engine.relax import Relax, leg_priced_out, sail_label_leg
from pipeline.routing.objectives import LATE_STEP_T, OBJ_JIT, route_cost_nb

PRUNE_BINS = 16384  # time bins of dp_exact_nb's look-up of the candidates made (up to the deadline)


@numba.njit(cache=True)
def dp_exact_nb(g, v, w, o, upper, fb, eps, mode):
    """(nodes, rpm indexes, cost, legs sailed, labels kept) of an optimal plan; see the module docstring.

    `upper` bounds the optimum from above (inf: none); `fb` is a FinishBounds (`label_bounds`): the fuel bound
    tables m_lam, t_min for the prices lams, the least hours and fuel per NM tau, phi on each leg (a leg is priced at
    them before it is sailed, and not sailed when even that cannot beat `upper` or make the RTA) and the latest
    departures ld that can still make the RTA (`latest_departure_nb`), used when `upper` is on time. With eps > 0 (t) a label is also dropped when an
    earlier one is within eps of dominating it: the plan returned then costs at most (lines − 1)·eps more than
    the optimum (see `trim_eps`; the incumbent bound is widened by as much, so that plan is not cut).

    `mode` (engine.labels.LabelMode) says which labels are kept: every one not dominated (`EXACT`), or with
    `mode.buckets` > 0 (approximate: bfoa's polish, the engine plans of a fixed route, the wait-free search of a
    voyage too long for every label) at most that many per node: the line's candidate times are cut into `buckets`
    equal spans and a span keeps its label of least f − e·t + lam_t·t, lam_t (t/h) the price of time. With
    `mode.max_legs` > 0 the search stops once it has sailed more legs than that and returns no plan (cost inf; the
    legs sailed tell the caller why).

    Without buckets (and with `mode.skip_dropped`) a leg is not sailed either when the candidate B it would make is sure
    to be dropped: when a candidate A made before it at the same node arrives before B can (before t0 + d·τ) with
    g_A = f − e·t no more than B can have, g0 + d·(φ − e·τ) (the fuel rate is at least φ/τ, so fuel − e·hours ≥
    (φ/τ − e)·hours ≥ d·(φ − e·τ) when φ ≥ e·τ). B is then dropped by the keep rule below whether A is kept (g_B ≥
    g_A ≥ the least kept g before B) or not (a label kept before A has g ≤ g_A + eps ≤ g_B + eps), and a dropped
    candidate changes nothing else: the labels kept, so the plan, are the same, only fewer legs are sailed. The
    candidates made so far are looked up per node in a prefix-minimum tree over time bins (`PRUNE_BINS` up to the
    deadline), counting only bins wholly before t0 + d·τ; the line's labels are expanded in time order, so that the
    earlier candidates, the ones that can drop others, are mostly made first."""
    lat, lon, edge_ok, rpm_options, max_shift = g.lat, g.lon, g.edge_ok, v.rpm_options, g.max_shift
    tau, phi, ld = fb.tau, fb.phi, fb.ld
    t_dep_h, max_hours = o.t_dep_h, o.max_hours
    L2, P = lat.shape
    R = rpm_options.shape[0]
    c = P // 2
    e = o.early_t_per_h if o.kind == OBJ_JIT else 0.0
    # an on-time incumbent: late plans cannot win, so every label must still be able to arrive by the RTA
    on_time = upper < (LATE_STEP_T if o.kind == OBJ_JIT else 9999.9)
    deadline = t_dep_h + (o.t_req_h if on_time else max_hours)
    tol = 1e-9 * max(1.0, abs(upper))
    # with eps, the label that stands for the optimal plan may cost up to (lines − 1)·eps more: keep it
    tol += (L2 - 1) * eps * (1.0 if o.kind == OBJ_JIT else 3.0 / o.f_target)
    x = Relax(g, v, w, o, fb, upper, tol, on_time)
    # kept labels of every line, for the way back
    cap = 1024
    kt, kf = np.empty(cap), np.empty(cap)
    kpar, knode, kr = np.empty(cap, np.int64), np.empty(cap, np.int64), np.empty(cap, np.int64)
    kt[0], kf[0], kpar[0], knode[0], kr[0] = t_dep_h, 0.0, -1, c, -1
    n_kept = 1
    line_lo, line_hi = 0, 1
    # candidates for the next line
    ccap = 1024
    ct, cf = np.empty(ccap), np.empty(ccap)
    cpar, cnode, cr = np.empty(ccap, np.int64), np.empty(ccap, np.int64), np.empty(ccap, np.int64)
    out = np.empty(N_LEG_OUT)
    n_legs = 0
    buckets, lam_t, max_legs = mode.buckets, mode.lam_t, mode.max_legs
    skip = mode.skip_dropped and buckets == 0
    nodes = np.full(L2, c, np.int64)
    rpm_idx = np.zeros(L2 - 1, np.int64)
    made = np.empty((P if skip else 0, PRUNE_BINS + 1))  # per node, the least g made so far per time bin
    bin_h = max(deadline - t_dep_h, 1e-6) / PRUNE_BINS
    S = 2 * max_shift + 1
    leg_nm, leg_tau, leg_phi = np.empty((P, S)), np.empty((P, S)), np.empty((P, S))
    for i in range(L2 - 1):
        n_c = 0
        made[:] = np.inf
        # the line's labels by time, all nodes together (see skip_dropped)
        by_time = np.argsort(kt[line_lo:line_hi], kind="mergesort") + line_lo
        # the line's legs once: length, least hours and least fuel per NM over the settings
        for a in range(P):
            for a2 in range(max(0, a - max_shift), min(P, a + max_shift + 1)):
                s = a2 - a + max_shift
                leg_nm[a, s] = geo.gc_distance_nm(lat[i, a], lon[i, a], lat[i + 1, a2], lon[i + 1, a2]) * (1.0 - 1e-9)
                leg_tau[a, s], leg_phi[a, s] = tau[i, a, s].min(), phi[i, a, s].min()
        for j in by_time:
            if max_legs > 0 and n_legs > max_legs:
                return nodes, rpm_idx, np.inf, n_legs, n_kept  # its work spent: no plan
            a, t0, f0 = knode[j], kt[j], kf[j]
            for a2 in range(max(0, a - max_shift), min(P, a + max_shift + 1)):
                if not edge_ok[i, a, a2]:
                    continue
                s = a2 - a + max_shift
                d_nm = leg_nm[a, s]
                # every setting at once first: at their least hours and fuel (the bound only grows as hours shrink)
                t1 = t0 + d_nm * leg_tau[a, s]
                if label_priced_out(o, fb, i + 1, a2, t1, f0 + d_nm * leg_phi[a, s], upper, tol, on_time):
                    continue
                for r in range(R):
                    if leg_priced_out(x, i, a, a2, s, r, d_nm, t0, f0):
                        continue
                    if skip and tau[i, a, s, r] > 0.0 and phi[i, a, s, r] >= e * tau[i, a, s, r]:
                        g_lb = f0 - e * t0 + d_nm * (phi[i, a, s, r] - e * tau[i, a, s, r])
                        # bins 0..q − 1 end before the leg's earliest arrival
                        q = min(int((t0 + d_nm * tau[i, a, s, r] - t_dep_h) / bin_h), PRUNE_BINS)
                        if q > 0 and prefix_min(made, a2, q) <= g_lb - 1e-12 * abs(g_lb):
                            continue  # a candidate made already will drop the one this leg makes
                    t1 = sail_label_leg(x, i, a, a2, r, t0, out)
                    n_legs += 1
                    if t1 == np.inf:
                        continue
                    if on_time and t1 > ld[i + 1, a2]:
                        continue  # cannot reach the arrival by the RTA any more, even at full speed
                    f1 = f0 + out[FUEL]
                    if label_priced_out(o, fb, i + 1, a2, t1, f1, upper, tol, on_time):
                        continue
                    if n_c >= ct.shape[0]:
                        ct, cf, cpar, cnode, cr = grow_store(n_c + 1, ct, cf, cpar, cnode, cr)
                    ct[n_c], cf[n_c], cpar[n_c], cnode[n_c], cr[n_c] = t1, f1, j, a2, r
                    n_c += 1
                    q = int((t1 - t_dep_h) / bin_h)
                    if skip and 0 <= q < PRUNE_BINS:
                        put_min(made, a2, q + 1, f1 - e * t1)
        # per node, by arrival time: keep a label only when it beats every earlier one on f − e·t
        order = np.argsort(ct[:n_c], kind="mergesort")
        by_node = np.argsort(cnode[:n_c][order], kind="mergesort")  # stable: time order kept inside each node
        line_lo = n_kept
        gmin = np.inf
        prev = -1
        last_b, last_val = -1, np.inf
        if n_c > 0:
            t_lo, t_span = ct[order[0]], ct[order[n_c - 1]] - ct[order[0]]
        for q in range(n_c):
            k = order[by_node[q]]
            if cnode[k] != prev:
                prev = cnode[k]
                gmin = np.inf
                last_b = -1
            gk = cf[k] - e * ct[k]
            if gk < gmin - eps:
                gmin = gk
                if buckets > 0:
                    b = time_span_nb(ct[k], t_lo, t_span, buckets)
                    val = gk + lam_t * ct[k]
                    if b == last_b:  # the span has a label at this node: keep the better one
                        if val < last_val:
                            s_ = n_kept - 1
                            kt[s_], kf[s_], kpar[s_], kr[s_] = ct[k], cf[k], cpar[k], cr[k]
                            last_val = val
                        continue
                    last_b, last_val = b, val
                if n_kept >= kt.shape[0]:
                    kt, kf, kpar, knode, kr = grow_store(n_kept + 1, kt, kf, kpar, knode, kr)
                kt[n_kept], kf[n_kept], kpar[n_kept], knode[n_kept], kr[n_kept] = ct[k], cf[k], cpar[k], cnode[k], cr[k]
                n_kept += 1
        line_hi = n_kept
    best, best_j = np.inf, -1
    for j in range(line_lo, line_hi):
        if knode[j] == c:
            q = route_cost_nb(o, kt[j] - t_dep_h, kf[j])
            if q < best:
                best, best_j = q, j
    if best_j < 0:
        return nodes, rpm_idx, np.inf, n_legs, n_kept
    j = best_j
    for i in range(L2 - 1, 0, -1):
        nodes[i] = knode[j]
        rpm_idx[i - 1] = kr[j]
        j = kpar[j]
    return nodes, rpm_idx, best, n_legs, n_kept
