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
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numba
import numpy as np

from pipeline.routing.engine import leg as lk
from pipeline.routing.bound_tables import finish_bounds, label_bounds, latest_departures, trim_eps
from pipeline.routing.engine.bounds import fuel_to_finish_lb
from pipeline.routing.engine.labels import bucketed, grow, time_span_nb
from pipeline.routing.engine.label_search import dp_exact_nb
from pipeline.routing.engine.leg import CODE, FUEL, H, N_LEG_OUT, OK, sail_leg_nb
from pipeline.routing.engine_timing import time_price
from pipeline.routing.objectives import LATE_STEP_T, OBJ_JIT, route_cost_nb


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


@numba.njit(cache=True)
def _route_latest_departures(lat, lon, nodes, v, w, fast_rpm, deadline, ld):
    """ld[i] ≥ the latest time the ship can leave line i on the route and still arrive by `deadline` at the
    fastest setting (first-in-first-out legs: fixed point of t = target − hours(t), then checked from above)."""
    out = np.empty(N_LEG_OUT)
    L2 = nodes.shape[0]
    ld[L2 - 1] = deadline
    for i in range(L2 - 2, -1, -1):
        a, b = nodes[i], nodes[i + 1]
        target = ld[i + 1]
        t = target
        ok = False
        for _it in range(8):
            sail_leg_nb(lat[i, a], lon[i, a], lat[i + 1, b], lon[i + 1, b], t, fast_rpm, v, w, out)
            if out[CODE] != OK:
                break
            ok = True
            t = target - out[H]
        if not ok:
            ld[i] = target  # a leg that cannot be sailed at full speed: no pruning before it
            continue
        step = 1e-3
        while t < target:  # move up until leaving then arrives after the target
            sail_leg_nb(lat[i, a], lon[i, a], lat[i + 1, b], lon[i + 1, b], t, fast_rpm, v, w, out)
            if out[CODE] != OK or t + out[H] > target:
                break
            t += step
            step *= 2.0
        ld[i] = min(t, target)


@numba.njit(cache=True)
def _sail_run_nb(lat, lon, nodes, v, w, rpm, i0, t0, f0, min_hold_h, to_end, out):
    """Sail the route from line i0 at time t0 (fuel f0) at `rpm` until the setting has been held `min_hold_h`
    hours, or to the arrival when `to_end`: (line reached, time, fuel, legs sailed, ok). ok is False when a leg
    cannot be sailed; the line reached is the last one when the arrival comes first."""
    L2 = nodes.shape[0]
    t, f = t0, f0
    i = i0
    n = 0
    while i < L2 - 1:
        a, b = nodes[i], nodes[i + 1]
        sail_leg_nb(lat[i, a], lon[i, a], lat[i + 1, b], lon[i + 1, b], t, rpm, v, w, out)
        n += 1
        if out[CODE] != OK:
            return i, t, f, n, False
        t += out[H]
        f += out[FUEL]
        i += 1
        if not to_end and t - t0 >= min_hold_h - 1e-9:
            break
    return i, t, f, n, True


@numba.njit(cache=True)
def _runs_to_sail_nb(kt, kf, kn, kr, lo, hi, R, change_cost_t, e):
    """Per kept label lo..hi of one line and setting r: whether its change to r is worth sailing (False for its own
    setting). A change of label B to r is dominated when an earlier label A of the line (t_A ≤ t_B) reaches r free
    at no greater cost: g_A + c·[A's setting ≠ r] ≤ g_B + c (g = f + c·n − e·t). A then sails on at r, or changes
    to it, and meets every line B's run meets no later and, in weather that does not change with time, dearer by
    no more, both free to change at its end: the DP's own dominance (module docstring) applied before the run is
    sailed instead of after, so the run's candidate, which the DP would drop, is not made."""
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


@numba.njit(cache=True)
def limited_plan_nb(lat, lon, nodes, v, w, o, min_hold_h, change_cost_t, ld, prune, upper, lams, m_route, t_min, eps,
                    buckets, lam_t):
    """(rpm index per leg, cost, fuel, changes, legs sailed) of the best plan on the route under the limits
    (cost inf: no plan can be sailed). `ld` (per line) prunes labels that cannot make the RTA when `prune`;
    under `jit`, labels whose fuel and change costs so far plus the least fuel to finish (engine.bounds.fuel_to_finish_lb
    with the route's tables m_route (K, lines), t_min (lines)) exceed `upper`, a known plan's cost, too. With
    eps > 0 (t) a label is also dropped when an earlier one comes within eps of dominating it.

    Labels are kept only where the ship is free to change setting (its setting held `min_hold_h`): from such a
    label it either sails one more leg at its setting, or changes and then sails the new setting until it has
    been held the hold (a run sailed in one go, no labels inside it). The first setting is such a run from the
    departure, which may also reach the arrival (a plan of one setting may be shorter than the hold); a changed
    setting whose run reaches the arrival before the hold is not a plan. Free labels at a line and setting differ
    only in time, fuel and changes, so the dominance is the DP's (dp.py): sorted by time, a label is kept when
    its f + c·n − e·t is below every earlier one's.

    With `buckets` > 0 the labels kept per line and setting are at most that many: the line's candidate times are
    cut into `buckets` equal spans and a span keeps its label of least f + c·n − e·t + lam_t·t, lam_t (t/h) the
    price of time (`time_price`). Approximate: the bucketed DP's cost grows with the lines, not with the lines
    times the spread of their arrival times."""
    rpm_options = v.rpm_options
    R = rpm_options.shape[0]
    L2 = nodes.shape[0]
    t_dep_h, max_hours = o.t_dep_h, o.max_hours
    e = o.early_t_per_h if o.kind == OBJ_JIT else 0.0
    deadline = t_dep_h + (o.t_req_h if upper < LATE_STEP_T else max_hours)
    tol = 1e-9 * max(1.0, abs(upper))
    tol += (L2 - 1) * eps  # the label standing for the best plan may be up to that much dearer: keep it (dp.py)
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
        i1, t1, f1, nl, ok = _sail_run_nb(lat, lon, nodes, v, w, rpm_options[r], 0, t_dep_h, 0.0, min_hold_h, True, out)
        n_legs += nl
        single_t[r], single_f[r] = t1, f1
        if ok and t1 - t_dep_h <= max_hours:
            q = route_cost_nb(o, t1 - t_dep_h, f1)
            if q < best:
                best, best_single = q, r
        # the same run, stopped where the hold is first met (its sailing is a prefix of the run above)
        i1, t1, f1, nl, ok = _sail_run_nb(lat, lon, nodes, v, w, rpm_options[r], 0, t_dep_h, 0.0, min_hold_h, False, out)
        n_legs += nl
        if not ok or i1 >= L2 - 1 or t1 - t_dep_h > max_hours or (prune and t1 > ld[i1]):
            continue
        if jit_bound and f1 + fuel_to_finish_lb(m_route[:, i1], lams, t_min[i1], deadline - t1) > upper + tol:
            continue
        if n_c >= ct.shape[0]:
            ct, cf = grow(ct, n_c + 1), grow(cf, n_c + 1)
            cn, cr, cpar, cstart, cnext = (grow(cn, n_c + 1), grow(cr, n_c + 1), grow(cpar, n_c + 1),
                                           grow(cstart, n_c + 1), grow(cnext, n_c + 1))
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
                kt, kf = grow(kt, n_kept + 1), grow(kf, n_kept + 1)
                kn, kr, kpar, kstart, kline = (grow(kn, n_kept + 1), grow(kr, n_kept + 1), grow(kpar, n_kept + 1),
                                               grow(kstart, n_kept + 1), grow(kline, n_kept + 1))
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
        # when an earlier label of the line reaches that setting free at no greater cost: _runs_to_sail_nb)
        sail = _runs_to_sail_nb(kt, kf, kn, kr, line_lo, n_kept, R, change_cost_t, e)
        for j in range(line_lo, n_kept):
            for r in range(R):
                change = r != kr[j]
                if change and not sail[j - line_lo, r]:
                    continue
                hold = min_hold_h if change else 0.0  # a held setting goes on one leg at a time
                i1, t1, f1, nl, ok = _sail_run_nb(lat, lon, nodes, v, w, rpm_options[r], i, kt[j], kf[j], hold, False,
                                                  out)
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
                    ct, cf = grow(ct, n_c + 1), grow(cf, n_c + 1)
                    cn, cr, cpar, cstart, cnext = (grow(cn, n_c + 1), grow(cr, n_c + 1), grow(cpar, n_c + 1),
                                                   grow(cstart, n_c + 1), grow(cnext, n_c + 1))
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


@dataclass(frozen=True)
class LimitedPlan:
    rpm_idx: np.ndarray  # per leg
    cost: float  # objective plus the change costs (inf: no plan under the limits)
    fuel_t: float
    n_changes: int
    legs_sailed: int


@numba.njit(cache=True)
def incumbent_cost_nb(nodes, g, v, w, o, min_hold_h, change_cost_t, one_change):
    """The cost of a plan obeying the limits, for pruning: the best of each setting held throughout and, with
    `one_change`, of one change from one setting to another at any line (inf when none can be sailed). A
    one-change plan shares its first part with the plan of its first setting throughout, so only its second part
    is sailed (still lines² legs: the bucketed DPs, whose labels are few anyway, go without it)."""
    L = nodes.shape[0] - 1
    R = v.rpm_options.shape[0]
    ct, cf = np.empty((R, L + 1)), np.empty((R, L + 1))
    sailed = np.zeros(R, np.int64)  # lines reached by the plan of each setting throughout
    rpm_idx = np.empty(L, np.int64)
    for r in range(R):
        rpm_idx[:] = r
        code, bad = lk.sail_route_nb(nodes, rpm_idx, 0, g, v, w, o, ct[r], cf[r])
        sailed[r] = L if code == OK else bad
    best = np.inf
    for r in range(R):
        if sailed[r] == L:
            best = min(best, route_cost_nb(o, ct[r, L] - o.t_dep_h, cf[r, L]))
    t2, f2 = np.empty(L + 1), np.empty(L + 1)
    for r0 in range(R if one_change else 0):
        for k in range(1, sailed[r0] + 1 if sailed[r0] < L else L):
            if ct[r0, k] - o.t_dep_h < min_hold_h - 1e-9:
                continue  # the first setting is not held long enough yet
            t2[:k + 1], f2[:k + 1] = ct[r0, :k + 1], cf[r0, :k + 1]
            for r1 in range(R):
                if r1 == r0:
                    continue
                rpm_idx[:k] = r0
                rpm_idx[k:] = r1
                code, _ = lk.sail_route_nb(nodes, rpm_idx, k, g, v, w, o, t2, f2)  # from line k on
                if code == OK and t2[L] - ct[r0, k] >= min_hold_h - 1e-9:
                    best = min(best, route_cost_nb(o, t2[L] - o.t_dep_h, f2[L]) + change_cost_t)
    return best


def incumbent_cost(inst, nodes: np.ndarray, limits: EngineLimits, one_change: bool = True) -> float:
    """incumbent_cost_nb for an instance."""
    return float(incumbent_cost_nb(np.ascontiguousarray(nodes, np.int64), inst.graph, inst.vessel, inst.wx,
                                   inst.objective, float(limits.min_hold_h), float(limits.change_cost_t), one_change))


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
    share of the best; with `buckets` > 0 at most that many labels per line (approximate, see limited_plan_nb).
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
    g, v, o = inst.graph, inst.vessel, inst.objective
    ld = np.full(len(nodes), np.inf)
    _route_latest_departures(g.lat, g.lon, nodes, v, inst.wx, float(v.rpm_options[-1]), o.t_dep_h + o.t_req_h + 1e-9,
                             ld)
    prune = bool(ld[0] >= o.t_dep_h)  # the RTA can be met at full speed: late labels cannot win
    upper = incumbent_cost(inst, nodes, limits, one_change=buckets == 0)
    lams, m_route, t_min = _route_finish_tables(inst, nodes)
    hold, cost_t = float(limits.min_hold_h), float(limits.change_cost_t)
    eps = gap * upper / (len(nodes) - 1) if gap > 0.0 and math.isfinite(upper) else 0.0
    lam_t = time_price(inst, nodes) if buckets > 0 else 0.0
    rpm_idx, cost, fuel, changes, n_legs = limited_plan_nb(g.lat, g.lon, nodes, v, inst.wx, o, hold, cost_t, ld, prune,
                                                           upper, lams, m_route, t_min, eps, int(buckets), lam_t)
    if not math.isfinite(cost):  # the hold makes the RTA unreachable: the least-late plan, without the bounds
        rpm_idx, cost, fuel, changes, n_legs2 = limited_plan_nb(g.lat, g.lon, nodes, v, inst.wx, o, hold, cost_t, ld,
                                                                False, np.inf, lams, m_route, t_min, 0.0, int(buckets),
                                                                lam_t)
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
