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
would make (`dp_exact_nb`): that changes the legs sailed, never the labels kept. `DpOptions(slot_h=...)` selects the DP that needs no such assumption
(dp_grid.py): departures from nodes on a time grid and at the times of known wait-free plans, with waiting; exact
over that space, its plans wait. With `wait_free_first` (the product's default, options.DEFAULT_SOLVER_OPTIONS)
this DP's plan comes first and its times join the grid, so the grid DP's plan is never dearer than it.

ε-trimming (`DpOptions.gap` > 0): sorted by time, a label is kept only when its f − e·t is more than ε below
every earlier kept one's at its node, with ε = gap·LB / (lines − 1) and LB a certified lower bound on the
optimum's cost (`cost_lower_bound`); the plan returned then costs at most (1 + gap) × the optimum (proof in
`trim_eps`). This is what makes the 5,000 NM instance tractable: most labels at a node differ by grams.

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
The weather a leg can meet (`finish_bounds` with windows, reachable_weather.py): the grid cells its chord reads, at
the valid times between the earliest arrival at its start and the latest departure from its end (the RTA's, when U
is on time), narrowed to the times a plan burning no more than any plan the DP must keep can be there
(`fuel_windows`). Over them wind and Hs have lower bounds, and the wind, wave and current directions relative to the
leg's course ranges. The bounds on STW and fuel rate come from the performance model at the corners of those ranges
(speeds lo..hi, relative directions lo..hi): the thesis form is linear in each of them (with the corner just above
a calm, where it drops its direction terms), the physical form linear in Vw²·w(θw) and Hs²·w(θs) (w falling with
θ), each then clipped monotonically; so the corners give its extremes whatever the coefficients' signs, fouling
and the air-resistance allowance included (weather limits cap the range, since a leg beyond them is infeasible
anyway). Without windows (the engine-limits DP, the grid DP) the range is the node's: wind and Hs 0..the strongest
near it at any valid time, every direction, the strongest current. For the 5,000 NM bench voyages the windowed bound
is 0.87 (east) and 0.95 (west) of the optimum, against 0.80 and 0.75 for the node's range.

The compiled primitives these searches share (sailing a leg, the label stores, the bound structure `FinishBounds`
and the pruning rule `label_priced_out`) are in pipeline/routing/engine/; the tables are built here
(`label_bounds`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from pipeline.performance.features import FORM_PHYSICAL, FORM_THESIS, stw_kn_nb, fuel_tph_nb
from pipeline.routing import geodesy as geo
from pipeline.routing.contract import Found
from pipeline.routing.engine.bounds import FinishBounds, fuel_to_finish_lb, is_on_time, label_priced_out
from pipeline.routing.engine.labels import EXACT, bucketed, grow, prefix_min, put_min, time_span_nb
from pipeline.routing.engine_timing import time_price
from pipeline.routing.engine.leg import (CODE, FIX_FUEL, FIX_H, FIX_LAT0, FIX_LAT1, FIX_LON0, FIX_LON1, FIX_TOL_DEG, FUEL,
                                        H, N_LEG_OUT, OK, sail_leg_nb)
from pipeline.routing.objectives import LATE_STEP_T, OBJ_JIT, route_cost_nb
from pipeline.routing.reachable_weather import WINDOW_SLACK_H, earliest_arrival_nb, reachable_ranges_nb

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
                    # the leg at its least hours and fuel first: no sailing when even that prices the label out
                    t1 = t0 + d_nm * tau[i, a, s, r]
                    if on_time and t1 > ld[i + 1, a2]:
                        continue
                    if label_priced_out(o, fb, i + 1, a2, t1, f0 + d_nm * phi[i, a, s, r], upper, tol,
                                        on_time):
                        continue
                    if skip and tau[i, a, s, r] > 0.0 and phi[i, a, s, r] >= e * tau[i, a, s, r]:
                        g_lb = f0 - e * t0 + d_nm * (phi[i, a, s, r] - e * tau[i, a, s, r])
                        q = min(int((t1 - t_dep_h) / bin_h), PRUNE_BINS)  # bins 0..q − 1 end before t1
                        if q > 0 and prefix_min(made, a2, q) <= g_lb - 1e-12 * abs(g_lb):
                            continue  # a candidate made already will drop the one this leg makes
                    sail_leg_nb(lat[i, a], lon[i, a], lat[i + 1, a2], lon[i + 1, a2], t0, rpm_options[r], v, w, out)
                    n_legs += 1
                    if out[CODE] != OK:
                        continue
                    t1 = t0 + out[H]
                    if t1 - t_dep_h > max_hours:
                        continue
                    if on_time and t1 > ld[i + 1, a2]:
                        continue  # cannot reach the arrival by the RTA any more, even at full speed
                    f1 = f0 + out[FUEL]
                    if label_priced_out(o, fb, i + 1, a2, t1, f1, upper, tol, on_time):
                        continue
                    if n_c >= ct.shape[0]:
                        ct, cf = grow(ct, n_c + 1), grow(cf, n_c + 1)
                        cpar, cnode, cr = grow(cpar, n_c + 1), grow(cnode, n_c + 1), grow(cr, n_c + 1)
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
                    kt, kf = grow(kt, n_kept + 1), grow(kf, n_kept + 1)
                    kpar, knode, kr = grow(kpar, n_kept + 1), grow(knode, n_kept + 1), grow(kr, n_kept + 1)
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


# columns of the per-node weather ranges `_corner_bounds` takes (speeds in kn, relative directions folded 0..180°)
(WIND_LO, WIND_HI, WIND_REL_LO, WIND_REL_HI, HS_LO, HS_HI, WAVE_REL_LO, WAVE_REL_HI, CUR_HI) = range(9)


@numba.njit(cache=True)
def _corner_bounds(v, rng, tau, phi):
    """Per node n and engine setting r: hours per NM ≥ tau[n, r] and fuel per NM ≥ phi[n, r] on legs that meet
    weather within the ranges rng[n] (columns WIND_LO …, CUR_HI): the model at the corners of those ranges, where
    both forms take their extremes (linear in wind speed, Hs and the folded directions — thesis — or in
    Vw²·w(θw) and Hs²·w(θs), w falling with θ — physical). The thesis form drops a direction term in a calm, so a
    range down to a calm also gets the corner just above it (direction on, speed ~0)."""
    for n in range(rng.shape[0]):
        wk_hi = min(rng[n, WIND_HI], v.max_wind_kn)  # beyond a limit the leg is infeasible: no bound needed there
        h_hi = min(rng[n, HS_HI], v.max_hs_m)
        wk_lo, h_lo = min(rng[n, WIND_LO], wk_hi), min(rng[n, HS_LO], h_hi)
        winds = (wk_lo, max(wk_lo, 1e-12), wk_hi)
        waves = (h_lo, max(h_lo, 1e-12), h_hi)
        for r in range(v.rpm_options.shape[0]):
            rpm = v.rpm_options[r]
            stw, rate = 0.0, np.inf
            for wk in winds:
                for wr in (rng[n, WIND_REL_LO], rng[n, WIND_REL_HI]):
                    for h in waves:
                        for hr in (rng[n, WAVE_REL_LO], rng[n, WAVE_REL_HI]):
                            stw = max(stw, stw_kn_nb(v.form_id, v.speed_coef, rpm, v.draft_m, v.trim_m, wk, wr, h, hr,
                                                     v.months_dd))
                            rate = min(rate, fuel_tph_nb(v.form_id, v.fuel_coef, rpm, v.draft_m, v.trim_m, wk, wr, h,
                                                         hr, v.months_dd))
            sog = stw + rng[n, CUR_HI]
            # a little slack for rounding in the kernels' sums: the bounds must never cut an optimal plan
            tau[n, r] = (1.0 - 1e-9) / sog if sog > 0.0 else np.inf
            phi[n, r] = (1.0 - 1e-9) * rate / sog if sog > 0.0 else 0.0


@numba.njit(cache=True)
def _leg_prices(lat, lon, max_shift, i, a, b, tau_e, phi_e, lams, prices):
    """The leg (i, a) → (i + 1, b) relaxed: prices[k] = d·min_r(φ + λ_k·τ); returns its least hours d·min_r τ."""
    s = b - a + max_shift
    d = geo.gc_distance_nm(lat[i, a], lon[i, a], lat[i + 1, b], lon[i + 1, b]) * (1.0 - 1e-9)
    fastest = np.inf
    for r in range(tau_e.shape[3]):
        fastest = min(fastest, tau_e[i, a, s, r])
    for k in range(lams.shape[0]):
        best = np.inf
        for r in range(tau_e.shape[3]):
            best = min(best, phi_e[i, a, s, r] + lams[k] * tau_e[i, a, s, r])
        prices[k] = d * best
    return d * fastest


@numba.njit(cache=True)
def _backward_tables(lat, lon, edge_ok, max_shift, tau_e, phi_e, lams, m_lam, t_min):
    """m_lam[k, i, a] = least Σ d·min_r(φ + λ_k·τ) and t_min[i, a] = least Σ d·min_r τ from (i, a) to the arrival
    through feasible edges, with τ, φ (L+2, P, 2·max_shift + 1, R) of each leg (i, a) → (i + 1, a + s − max_shift);
    inf where the arrival cannot be reached."""
    L2, P = lat.shape
    prices = np.empty(lams.shape[0])
    m_lam[:] = np.inf
    t_min[:] = np.inf
    m_lam[:, L2 - 1, P // 2] = 0.0
    t_min[L2 - 1, P // 2] = 0.0
    for i in range(L2 - 2, -1, -1):
        for a in range(P):
            for b in range(max(0, a - max_shift), min(P, a + max_shift + 1)):
                if not edge_ok[i, a, b] or t_min[i + 1, b] == np.inf:
                    continue
                t_min[i, a] = min(t_min[i, a], t_min[i + 1, b] + _leg_prices(lat, lon, max_shift, i, a, b, tau_e, phi_e,
                                                                            lams, prices))
                for k in range(lams.shape[0]):
                    m_lam[k, i, a] = min(m_lam[k, i, a], m_lam[k, i + 1, b] + prices[k])


@numba.njit(cache=True)
def _arrival(lat0, lon0, lat1, lon1, t, v, w, rpms, out):
    """Earliest arrival at the leg's end leaving at t at any of the settings rpms (inf: no headway at any)."""
    best = np.inf
    for r in range(rpms.shape[0]):
        sail_leg_nb(lat0, lon0, lat1, lon1, t, rpms[r], v, w, out)
        if out[CODE] == OK:
            best = min(best, t + out[H])
    return best


@numba.njit(cache=True)
def latest_departure_nb(g, v, w, rpms, t_lo, deadline, ld):
    """ld[i, a] ≥ the latest time a ship can leave (i, a) and still reach the arrival by `deadline` (−inf: it
    cannot from t_lo on). Legs are sailed at the settings `rpms` (the fastest) with `v`'s weather limits lifted
    by the caller; first-in-first-out legs make the arrival time non-decreasing in the departure time, so the
    latest departure over a leg is found by iterating t = target − hours(t) and then checked from above. A leg
    with no headway at some departure time (a head current or gale that passes) says nothing about later ones:
    where the leg cannot be sailed at t_lo or during the iteration, the bound is the target itself (a ship never
    arrives before it leaves), which is safe."""
    lat, lon, edge_ok, max_shift = g.lat, g.lon, g.edge_ok, g.max_shift
    L2, P = lat.shape
    out = np.empty(N_LEG_OUT)
    ld[:] = -np.inf
    ld[L2 - 1, P // 2] = deadline
    for i in range(L2 - 2, -1, -1):
        for a in range(P):
            for b in range(max(0, a - max_shift), min(P, a + max_shift + 1)):
                target = ld[i + 1, b]
                if not edge_ok[i, a, b] or target == -np.inf:
                    continue
                arr = _arrival(lat[i, a], lon[i, a], lat[i + 1, b], lon[i + 1, b], t_lo, v, w, rpms, out)
                if arr == np.inf:  # no headway leaving at t_lo: a later departure may have it
                    ld[i, a] = max(ld[i, a], target)
                    continue
                if arr > target:
                    continue  # cannot make it even leaving at the earliest time, nor later (FIFO)
                t = target
                for _it in range(6):  # fixed point of t = target − hours(t): hours change slowly with t
                    arr = _arrival(lat[i, a], lon[i, a], lat[i + 1, b], lon[i + 1, b], t, v, w, rpms, out)
                    if arr == np.inf:
                        t = target  # no headway there: the departures between t_lo and target are not checked
                        break
                    t = t - (arr - target)
                # move up until leaving then arrives after the target: by FIFO the latest departure is below
                step = 1e-3
                while True:
                    arr = _arrival(lat[i, a], lon[i, a], lat[i + 1, b], lon[i + 1, b], t, v, w, rpms, out)
                    if arr == np.inf:
                        t = target  # no headway there, and maybe again later: not checked
                        break
                    if arr > target or t >= target:
                        break
                    t += step
                    step *= 2.0
                ld[i, a] = max(ld[i, a], min(t, target))


def _cell_index(grid, lat, lon) -> tuple[np.ndarray, np.ndarray]:
    """Grid row and column of the lower-left corner of the cell `sample_nb` reads at each (lat, lon)."""
    fy = np.clip((lat - grid.lat0) / grid.dlat, 0.0, grid.nlat - 1.0)
    iy = np.minimum(fy.astype(np.int64), grid.nlat - 2)
    if grid.wraps:
        ix = (((lon - grid.lon0) % 360.0) / grid.dlon).astype(np.int64) % grid.nlon
    else:
        x = grid.lon0 + ((lon - grid.lon0) % 360.0)
        x = np.where(x > grid.lon0 + grid.dlon * (grid.nlon - 1) + 0.5 * (360.0 - grid.dlon * (grid.nlon - 1)), x - 360.0, x)
        ix = np.minimum(np.clip((x - grid.lon0) / grid.dlon, 0.0, grid.nlon - 1.0).astype(np.int64), grid.nlon - 2)
    return iy, ix


def local_weather_max(inst, pad_cells: int = 2) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per node (L+2, P): the strongest wind (kn), highest Hs (m) and strongest current (kn) at any valid time in
    the grid cells around the legs leaving it (the cells `sample_nb` reads between the node and every node it
    can reach on the next line, padded by `pad_cells` for the legs' curvature)."""
    wf, sp = inst.weather, inst.space
    grid = wf.grid

    wind, hs, cur = wf.max_over_time
    L2, P = sp.lat.shape
    iy, ix = _cell_index(grid, sp.lat, sp.lon)
    out = np.zeros((3, L2, P))
    ms = sp.max_shift
    for i in range(L2):
        nxt = min(i + 1, L2 - 1)
        for a in range(P):
            lo, hi = max(0, a - ms), min(P, a + ms + 1)
            ys = np.concatenate(([iy[i, a]], iy[nxt, lo:hi]))
            xs = np.concatenate(([ix[i, a]], ix[nxt, lo:hi]))
            y0, y1 = max(0, ys.min() - pad_cells), min(grid.nlat, ys.max() + 2 + pad_cells)
            if grid.wraps:  # columns as offsets from the node's, so a box across 0° stays one box
                off = (xs - ix[i, a] + grid.nlon // 2) % grid.nlon - grid.nlon // 2
                cols = (ix[i, a] + np.arange(off.min() - pad_cells, off.max() + 2 + pad_cells)) % grid.nlon
            else:
                cols = np.arange(max(0, xs.min() - pad_cells), min(grid.nlon, xs.max() + 2 + pad_cells))
            for k, field in enumerate((wind, hs, cur)):
                out[k, i, a] = field[y0:y1][:, cols].max()
    return out[0], out[1], out[2]


def reachable_windows(inst, ld: np.ndarray, on_time: bool) -> tuple[np.ndarray, np.ndarray]:
    """(t_lo, t_hi) (L+2, P), hours after t_ref: a plan is at node (i, a) no earlier than t_lo and no later than
    t_hi. t_lo is the earliest arrival (reachable_weather), t_hi the latest departure `ld` when the plan must make
    the RTA (`on_time`), else the planning horizon; both widened by WINDOW_SLACK_H."""
    v, o, sp = inst.vessel, inst.objective, inst.space
    ea = np.empty(sp.lat.shape)
    earliest_arrival_nb(inst.graph, v._replace(max_hs_m=np.inf, max_wind_kn=np.inf), inst.wx,
                        np.ascontiguousarray(_fastest_settings(v)), o.t_dep_h, ea)
    t_hi = np.minimum(ld, o.t_dep_h + o.max_hours) if on_time else np.full(sp.lat.shape, o.t_dep_h + o.max_hours)
    return ea - WINDOW_SLACK_H, t_hi + WINDOW_SLACK_H


def reachable_weather_ranges(inst, windows) -> np.ndarray:
    """(L+2, P, 2·max_shift + 1, 9) `_corner_bounds` ranges (kn, deg, m) per leg (i, a) → (i + 1, a + s − max_shift):
    the weather it can meet while the ship is within the windows (`reachable_windows`); zeros where no edge, NaN
    where no plan within the windows sails the leg."""
    wf, sp = inst.weather, inst.space
    L2, P = sp.lat.shape
    t_lo, t_hi = windows
    rng = np.zeros((L2, P, 2 * sp.max_shift + 1, 9))
    reachable_ranges_nb(wf.cells, wf.times_h, wf.grid, np.ascontiguousarray(t_lo, dtype=np.float64),
                        np.ascontiguousarray(t_hi, dtype=np.float64),
                        sp.lat, sp.lon, sp.edge_ok, int(sp.max_shift), *wf.neutral_beyond, rng)
    rng[..., [WIND_LO, WIND_HI, CUR_HI]] *= geo.KN_PER_MS
    return rng


def finish_bounds(inst, windows=None, fuel_budget_t: float = math.inf, per_leg: bool = False, wide=None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(lams (K,), m_lam (K, L+2, P), t_min (L+2, P), tau, phi (L+2, P, R)): the fuel-to-finish bound tables of the
    exact DP and the least hours and fuel per NM they are built from (per node: on every leg leaving it). Without
    `windows` they hold for a ship at any node at any time, in any weather up to the strongest met near the node at
    any time; with windows (`reachable_windows`) only for ships within them, and the tables are built leg by leg
    from the weather each leg can meet then (`reachable_weather_ranges`), which is tighter. With a finite
    `fuel_budget_t` too they hold for the plans within the windows that burn at most that much: the windows are
    first narrowed to the times such a plan can be at each node (`fuel_windows`). With `per_leg`, tau and phi are
    those of each leg (L+2, P, 2·max_shift + 1, R), as dp_exact_nb takes them. `wide` (a list) receives the node
    tables of the windows before the fuel narrowing, which hold for plans that wait within the windows too."""
    v, sp = inst.vessel, inst.space
    L2, P = sp.lat.shape
    R = len(v.rpm_options)
    if v.form_id not in (FORM_THESIS, FORM_PHYSICAL):
        # no corner bounds for this model form (e.g. the MLP): zero hours and fuel to finish are still lower
        # bounds, so every search that uses these tables stays exact, it only prunes less
        zeros, rates = np.zeros((L2, P)), np.zeros((L2, P) + ((2 * sp.max_shift + 1,) if per_leg else ()) + (R,))
        return np.zeros(1), zeros[None].copy(), zeros, rates, rates.copy()
    tau_e, phi_e, tau, phi = _leg_bounds(inst, windows)
    # prices of time (t of fuel per hour) around the trade-offs between neighbouring engine settings
    t_med, f_med = np.median(tau.reshape(-1, R), axis=0), np.median(phi.reshape(-1, R), axis=0)
    slopes = [(f_med[r + 1] - f_med[r]) / (t_med[r] - t_med[r + 1]) for r in range(R - 1) if t_med[r] > t_med[r + 1]]
    lams = np.unique(np.array([0.0] + [s * m for s in slopes if np.isfinite(s) and s > 0
                                       for m in (0.5, 0.7, 0.85, 0.95, 1.0, 1.05, 1.15, 1.3, 1.6, 2.0)]))
    m_lam, t_min = np.empty((len(lams), L2, P)), np.empty((L2, P))
    _backward_tables(sp.lat, sp.lon, sp.edge_ok, int(sp.max_shift), tau_e, phi_e, lams, m_lam, t_min)
    if wide is not None:
        wide[:] = [lams, m_lam.copy(), t_min.copy(), tau_e, phi_e] if per_leg else [lams, m_lam.copy(), t_min.copy(),
                                                                                     tau, phi]
    if windows is not None and math.isfinite(fuel_budget_t):
        windows = fuel_windows(inst, windows, fuel_budget_t, lams, m_lam, t_min, tau_e, phi_e)
        tau_e, phi_e, tau, phi = _leg_bounds(inst, windows)
        _backward_tables(sp.lat, sp.lon, sp.edge_ok, int(sp.max_shift), tau_e, phi_e, lams, m_lam, t_min)
    if per_leg:  # inf on the legs no plan within the windows sails
        return lams, m_lam, t_min, tau_e, phi_e
    return lams, m_lam, t_min, tau, phi


def _leg_bounds(inst, windows) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(tau_e, phi_e (L+2, P, 2·max_shift + 1, R), tau, phi (L+2, P, R)): least hours and fuel per NM per leg and
    per node (its legs' least) in the weather of `finish_bounds`; inf on legs no plan within the windows sails."""
    v, sp = inst.vessel, inst.space
    L2, P = sp.lat.shape
    R = len(v.rpm_options)
    S = 2 * sp.max_shift + 1
    if windows is None:
        wind, hs, cur = local_weather_max(inst)
        rng = np.zeros((L2 * P, 9))
        rng[:, WIND_HI], rng[:, HS_HI], rng[:, CUR_HI] = wind.ravel(), hs.ravel(), cur.ravel()
        rng[:, WIND_REL_HI] = rng[:, WAVE_REL_HI] = 180.0
        tau, phi = np.empty((L2 * P, R)), np.empty((L2 * P, R))
        _corner_bounds(v, rng, tau, phi)
        tau, phi = tau.reshape(L2, P, R), phi.reshape(L2, P, R)
        tau_e, phi_e = np.repeat(tau[:, :, None, :], S, axis=2), np.repeat(phi[:, :, None, :], S, axis=2)
        _fixed_leg_rates(inst, tau_e, phi_e, tau, phi)
        return tau_e, phi_e, tau, phi
    rng = reachable_weather_ranges(inst, windows)
    closed = np.isnan(rng[..., WIND_LO])  # legs no plan within the windows sails
    tau_e, phi_e = np.empty((L2 * P * S, R)), np.empty((L2 * P * S, R))
    _corner_bounds(v, np.where(closed[..., None], 0.0, rng).reshape(-1, 9), tau_e, phi_e)
    tau_e, phi_e = tau_e.reshape(L2, P, S, R), phi_e.reshape(L2, P, S, R)
    tau_e[closed], phi_e[closed] = np.inf, np.inf
    ok = (_edge_mask(sp.edge_ok, L2, P, int(sp.max_shift)) & ~closed)[..., None]
    tau = np.where(ok, tau_e, np.inf).min(axis=2)  # a node's legs all take at least its least
    phi = np.where(ok, phi_e, np.inf).min(axis=2)
    tau[~np.isfinite(tau)], phi[~np.isfinite(phi)] = 0.0, 0.0  # no leg leaves: any bound holds
    _fixed_leg_rates(inst, tau_e, phi_e, tau, phi)
    return tau_e, phi_e, tau, phi


def _fixed_leg_rates(inst, tau_e, phi_e, tau, phi) -> None:
    """A canal's legs (engine.leg.Vessel.fixed_legs, canal_time.py) take their fixed hours and fuel at every setting
    and in any weather: their hours and fuel per NM are those, exactly, in place of the performance model's bounds
    (which would price the canal as open sea and prune nothing across it). A gate's node has that one leg, so its
    node bound is the leg's. Legs no plan within the windows sails (inf) stay closed."""
    fx = inst.vessel.fixed_legs
    if not fx.shape[0]:
        return
    sp = inst.space
    c, ms = sp.centre, int(sp.max_shift)
    for row in fx:
        d = geo.gc_distance_nm(row[FIX_LAT0], row[FIX_LON0], row[FIX_LAT1], row[FIX_LON1])
        if not d > 0.0:
            continue
        for i in range(sp.lat.shape[0] - 1):
            if (abs(sp.lat[i, c] - row[FIX_LAT0]) < FIX_TOL_DEG and abs(sp.lon[i, c] - row[FIX_LON0]) < FIX_TOL_DEG
                    and abs(sp.lat[i + 1, c] - row[FIX_LAT1]) < FIX_TOL_DEG
                    and abs(sp.lon[i + 1, c] - row[FIX_LON1]) < FIX_TOL_DEG):
                open_ = np.isfinite(tau_e[i, c, ms])
                tau_e[i, c, ms][open_] = row[FIX_H] / d
                phi_e[i, c, ms][open_] = row[FIX_FUEL] / d
                if sp.node_ok[i].sum() == 1:  # a gate (or a port): this is its only leg
                    tau[i, c] = np.where(open_, row[FIX_H] / d, tau[i, c])
                    phi[i, c] = np.where(open_, row[FIX_FUEL] / d, phi[i, c])


def fuel_windows(inst, windows, fuel_budget_t: float, lams, m_lam, t_min, tau_e, phi_e, step_h: float = 0.25):
    """`windows` narrowed to the times a plan burning at most `fuel_budget_t` and arriving by the RTA can be at each
    node: its fuel so far is at least the least fuel to reach the node in the hours since departure (the bound of
    `finish_bounds` run forwards, over the same legs' τ, φ) and the rest at least the fuel to finish in the hours
    left (m_lam, t_min); both bounds are convex in the time at the node, so the times where they sum within the
    budget are one interval, found on a grid of `step_h` and widened by a step and WINDOW_SLACK_H. A node whose
    interval the grid misses keeps its window."""
    o, sp = inst.objective, inst.space
    L2, P = sp.lat.shape
    m_f, t_f = np.empty_like(m_lam), np.empty_like(t_min)
    _forward_tables(sp.lat, sp.lon, sp.edge_ok, int(sp.max_shift), tau_e, phi_e, lams, m_f, t_f)
    t_lo, t_hi = (np.array(x, dtype=np.float64) for x in windows)
    _fuel_windows_nb(lams, m_f, t_f, m_lam, t_min, o.t_dep_h, o.t_dep_h + o.t_req_h, fuel_budget_t, step_h,
                     WINDOW_SLACK_H, t_lo, t_hi)
    return t_lo, t_hi


@numba.njit(cache=True)
def _fuel_windows_nb(lams, m_f, t_f, m_b, t_b, t_dep, deadline, budget, step, slack, t_lo, t_hi):
    """`fuel_windows` in place on t_lo, t_hi (L+2, P)."""
    L2, P = t_lo.shape
    for i in range(L2):
        for a in range(P):
            lo, hi = t_lo[i, a], t_hi[i, a]
            if not lo <= hi:
                continue
            first, last = np.inf, -np.inf
            n = int((hi - lo) / step) + 1
            for q in range(n + 1):
                t = min(lo + q * step, hi)
                f = fuel_to_finish_lb(m_f[:, i, a], lams, t_f[i, a], t - t_dep)
                f += fuel_to_finish_lb(m_b[:, i, a], lams, t_b[i, a], deadline - t)
                if f <= budget:
                    first, last = min(first, t), max(last, t)
            if first <= last:
                t_lo[i, a] = max(lo, first - step - slack)
                t_hi[i, a] = min(hi, last + step + slack)


@numba.njit(cache=True)
def _forward_tables(lat, lon, edge_ok, max_shift, tau_e, phi_e, lams, m_f, t_f):
    """`_backward_tables` from the departure: m_f[k, i, a] = least Σ d·min_r(φ + λ_k·τ) and t_f[i, a] = least Σ d·min_r τ
    from the departure to (i, a); inf where (i, a) cannot be reached."""
    L2, P = lat.shape
    prices = np.empty(lams.shape[0])
    m_f[:] = np.inf
    t_f[:] = np.inf
    m_f[:, 0, P // 2] = 0.0
    t_f[0, P // 2] = 0.0
    for i in range(L2 - 1):
        for a in range(P):
            if t_f[i, a] == np.inf:
                continue
            for b in range(max(0, a - max_shift), min(P, a + max_shift + 1)):
                if not edge_ok[i, a, b]:
                    continue
                t_f[i + 1, b] = min(t_f[i + 1, b], t_f[i, a] + _leg_prices(lat, lon, max_shift, i, a, b, tau_e, phi_e, lams,
                                                                          prices))
                for k in range(lams.shape[0]):
                    m_f[k, i + 1, b] = min(m_f[k, i + 1, b], m_f[k, i, a] + prices[k])


def _edge_mask(edge_ok, L2, P, max_shift) -> np.ndarray:
    """(L+2, P, 2·max_shift + 1): whether the leg (i, a) → (i + 1, a + s − max_shift) is an edge (False on the
    arrival line)."""
    mask = np.zeros((L2, P, 2 * max_shift + 1), bool)
    a = np.arange(P)
    for s in range(2 * max_shift + 1):
        b = a + s - max_shift
        inside = (b >= 0) & (b < P)
        mask[:-1, inside, s] = edge_ok[:, a[inside], b[inside]]
    return mask


def _fastest_settings(v) -> np.ndarray:
    """The settings that include the fastest in every condition: the top one when STW cannot fall with rpm in this
    model form (its rpm coefficient ≥ 0), else all of them."""
    rpm_coef = v.speed_coef[1] if v.form_id == FORM_PHYSICAL else v.speed_coef[2]
    return v.rpm_options[-1:] if rpm_coef >= 0.0 else v.rpm_options


def latest_departures(inst) -> np.ndarray:
    """(L+2, P) latest times (h after t_ref) to leave each node and still arrive by the RTA (see
    latest_departure_nb). Weather limits are lifted (a relaxation: the bound can only get later); the fastest
    setting alone is sailed when STW cannot fall with rpm in this model form (its rpm coefficient ≥ 0)."""
    v, o = inst.vessel, inst.objective
    rpms = _fastest_settings(v)
    free = v._replace(max_hs_m=np.inf, max_wind_kn=np.inf)
    ld = np.empty(inst.space.lat.shape)
    latest_departure_nb(inst.graph, free, inst.wx, np.ascontiguousarray(rpms), o.t_dep_h,
                        o.t_dep_h + o.t_req_h + 1e-9, ld)
    return ld


def _fuel_budget_t(o, upper: float, gap: float) -> float:
    """The most fuel (t) a plan can burn that the DP, pruning with the on-time incumbent cost `upper` and trimming
    within `gap`, must keep: its cost is at most upper + gap·upper (the DP's tolerance is gap·LB ≤ gap·optimum)."""
    cost = upper * (1.0 + gap) + 2e-9 * max(1.0, abs(upper))
    return cost if o.kind == OBJ_JIT else (cost - 0.85) * o.f_target / 3.0  # thesis: 0.85 + 3·F/F_target on time


def cost_lower_bound(inst, upper: float, lams, m_lam, t_min) -> float:
    """A certified lower bound on the optimum's cost: the least fuel to sail the whole voyage within the hours it
    may take (the RTA when `upper` is on time, else the planning horizon), priced by the objective."""
    o, sp = inst.objective, inst.space
    on_time = is_on_time(o, upper)
    hours = o.t_req_h if on_time else o.max_hours
    c = sp.lat.shape[1] // 2
    fuel_lb = float(fuel_to_finish_lb(m_lam[:, 0, c], lams, t_min[0, c], hours))
    if o.kind == OBJ_JIT:
        return fuel_lb  # jit prices a plan at least at its fuel
    return 0.85 + 3.0 * fuel_lb / o.f_target  # thesis: no plan below that (a late one costs over 9999.9)


def trim_eps(inst, gap: float, upper: float, lams, m_lam, t_min) -> float:
    """The fuel tolerance ε (t) of `dp_exact_nb` for a plan within `gap` of the optimum.

    Proof: let B_i be the optimal plan's label at line i. By induction some kept label A_i at B_i's node has
    t(A_i) ≤ t(B_i) and g(A_i) ≤ g(B_i) + i·ε (g = f − e·t): a label is dropped only when an earlier kept one
    has g at most ε above it, and sailing the optimum's next leg from A_i (not later, FIFO) keeps both relations.
    At the arrival A costs at most (lines − 1)·ε more fuel-equivalent than the optimum: that many t under jit,
    3·(lines − 1)·ε / F_target under thesis (late plans: none, an earlier arrival never costs more). With
    LB ≤ optimum (`cost_lower_bound`) and ε = gap·LB / (lines − 1) (jit; × F_target / 3 for thesis) the plan
    returned costs at most optimum + gap·LB ≤ (1 + gap)·optimum."""
    if gap <= 0.0:
        return 0.0
    lb = cost_lower_bound(inst, upper, lams, m_lam, t_min)
    if not math.isfinite(lb) or lb <= 0.0:
        return 0.0
    eps = gap * lb / (inst.space.lat.shape[0] - 1)
    return eps if inst.objective.kind == OBJ_JIT else eps * inst.objective.f_target / 3.0


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
    nodes, rpm_idx, cost, n_legs, _, note = _label_search(inst, options, upper, latest_departures(inst), baseline)
    if not math.isfinite(cost):  # nothing below the incumbents (where the dominance's assumption fails): the best
        nodes, rpm_idx = _cheapest(inst, known)  # plan known, never the baseline while a dearer plan... is known
    return Found(nodes, rpm_idx, n_fast + n_legs, note=note)


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


def label_bounds(inst, ld: np.ndarray, windows=None, fuel_budget_t: float = math.inf, wide=None) -> FinishBounds:
    """The FinishBounds of the label searches on `inst`'s graph: `finish_bounds` per leg (within `windows`, for the
    plans burning at most `fuel_budget_t`; `wide` as there) and the latest departures `ld` (`latest_departures`)."""
    lams, m_lam, t_min, tau, phi = finish_bounds(inst, windows, fuel_budget_t, per_leg=True, wide=wide)
    return FinishBounds(lams, m_lam, t_min, tau, phi, ld)


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
    from pipeline.routing.dp_grid import search_grid, wait_hours, wait_rate_tph

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
    note = "; ".join(x for x in (coarse, capped) if x) or None
    return Found(nodes, rpm_idx, n_first + n_legs, wait_h=waits, wait_tph=wait_rate_tph(inst, options.wait_tph),
                 note=note)


def grid_step_h(inst, options: DpOptions) -> float:
    """The grid DP's time step (h): `slot_h`, or with `slots_per_rta` the RTA's passage hours over that many slots
    rounded up to whole hours when that is longer: the grid DP's work grows with the slots a node can be left at,
    so a 40-day voyage gets a coarser grid than a 10-day one (its plan's reason then says which)."""
    step = float(options.slot_h)
    if options.slots_per_rta:
        step = max(step, float(math.ceil(inst.objective.t_req_h / float(options.slots_per_rta) - 1e-9)))
    return step
