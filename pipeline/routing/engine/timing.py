"""Engine settings per leg that make a route arrive just inside the RTA (numba, used by the BFOA).

cost_from_nb    sail a route from line `start` on and price it with the objective
sail_span_nb    sail legs start..stop only (a move's changed legs), for screening a route move
time_price_nb   what the engine re-set pays in fuel per hour gained or lost along a route
plan_flips_nb   before sailing: which legs to speed up (late) or slow down (early by more than a step) for
                a move's estimated arrival (a leg of h hours at rpm r takes h·r/r' at r', fuel ∝ rpm³)
retime_nb       after sailing: the same flips, judged on the sailed route, until arrival is in the window
aim_engine_nb   a new route's settings: of the constant settings, the two whose arrivals bracket the RTA
                mixed over random legs in the share that should arrive just in time, then re-timed

Kernels take the voyage as one `engine.leg.Voyage`: the graph `g` (search_space.Graph), the vessel `v`
(engine.leg.Vessel), the weather `w` (weather_field.Weather) and the objective `o` (objectives.Objective); `s` is a
`Scratch` of work arrays and `rng` the random generator (a numpy Generator; numba draws from it the same numbers numpy would, so the
interpreted kernels reproduce the compiled ones).
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from pipeline.routing.engine.leg import CODE, FUEL, H, N_LEG_OUT, OK, sail_leg_nb, sail_route_nb
from pipeline.routing.objectives import OBJ_JIT, route_cost_nb


class Scratch(NamedTuple):
    """Work arrays for one route being sailed and re-timed (L+2 lines, L+1 legs) and a counter of sails."""

    ct: np.ndarray  # (L+2,) hours after t_ref on reaching each line
    cf: np.ndarray  # (L+2,) fuel (t) so far on reaching each line
    keep_r: np.ndarray  # (L+1,) int64: rpm indexes to restore when a re-time does not pay
    keep_t: np.ndarray  # (L+2,)
    keep_f: np.ndarray  # (L+2,)
    cnt: np.ndarray  # (1,) int64: routes (or route tails) sailed
    out: np.ndarray  # (N_LEG_OUT,) one leg's results


def scratch(n_lines_total: int) -> Scratch:
    """Scratch for routes over `n_lines_total` lines (L+2, ports included)."""
    n = n_lines_total
    return Scratch(np.empty(n), np.empty(n), np.empty(n - 1, np.int64), np.empty(n), np.empty(n),
                   np.zeros(1, np.int64), np.empty(N_LEG_OUT))


@numba.njit(cache=True)
def cost_from_nb(vy, nodes, rpm_idx, start, cum_t, cum_f):
    """Sail the route from line `start` on (cum_t, cum_f valid there) and price it with the objective (inf: it
    cannot be sailed)."""
    o = vy.o
    code, _ = sail_route_nb(nodes, rpm_idx, start, vy.g, vy.v, vy.w, o, cum_t, cum_f)
    if code != OK:
        return np.inf
    n = nodes.shape[0] - 1
    return route_cost_nb(o, cum_t[n] - o.t_dep_h, cum_f[n])


@numba.njit(cache=True)
def sail_span_nb(vy, nodes, rpm_idx, start, stop, ct, cf, out):
    """Sail legs start..stop-1 only (ct/cf valid at line `start`); False as soon as one is infeasible."""
    g, v, w = vy.g, vy.v, vy.w
    lat, lon, edge_ok, rpm_options = g.lat, g.lon, g.edge_ok, v.rpm_options
    for i in range(start, stop):
        a, b = nodes[i], nodes[i + 1]
        if not edge_ok[i, a, b]:
            return False
        sail_leg_nb(lat[i, a], lon[i, a], lat[i + 1, b], lon[i + 1, b], ct[i], rpm_options[rpm_idx[i]], v, w, out)
        if out[CODE] != OK:
            return False
        ct[i + 1] = ct[i] + out[H]
        cf[i + 1] = cf[i] + out[FUEL]
    return True


@numba.njit(cache=True)
def time_price_nb(rpm_idx, ct, cf, rpm_options):
    """Estimated fuel (t) per hour gained by raising the slowest setting one step on this plan; 0 with one setting."""
    if rpm_options.shape[0] < 2:
        return 0.0
    h, f = 0.0, 0.0
    for j in range(rpm_idx.shape[0]):
        if rpm_idx[j] == 0:
            h += ct[j + 1] - ct[j]
            f += cf[j + 1] - cf[j]
    n = rpm_idx.shape[0]
    if h <= 0.0:
        h, f = ct[n] - ct[0], cf[n] - cf[0]
    if h <= 0.0:
        return 0.0
    k = rpm_options[1] / rpm_options[0]
    return (f / h) * (k * k - 1.0) / (1.0 - 1.0 / k)


@numba.njit(cache=True)
def speed_up_nb(rpm_idx, lo, need_h, fuel, ct, cf, rpm_options, rng):
    """Raise the rpm of random legs ≥ lo (the slower of two draws) one step at a time until the estimated hours
    saved cover `need_h` (a leg of h hours at rpm r takes h·r/r' at r', burns (r'/r)² its fuel), with the legs'
    hours and fuel from ct/cf. Returns (first leg changed, n when none; `fuel` plus the estimated extra fuel)."""
    n = rpm_idx.shape[0]
    n_rpm = rpm_options.shape[0]
    first = n
    for _t in range(4 * (n - lo)):
        if need_h <= 0.0:
            break
        j = lo + rng.integers(0, n - lo)
        j2 = lo + rng.integers(0, n - lo)
        if rpm_idx[j2] < rpm_idx[j]:
            j = j2
        r = rpm_idx[j]
        if r >= n_rpm - 1:
            continue
        ratio = rpm_options[r + 1] / rpm_options[r]
        need_h -= (ct[j + 1] - ct[j]) * (1.0 - 1.0 / ratio)
        fuel += (cf[j + 1] - cf[j]) * (ratio * ratio - 1.0)
        rpm_idx[j] = r + 1
        first = min(first, j)
    return first, fuel


@numba.njit(cache=True)
def slow_down_nb(rpm_idx, lo, slack_h, ct, rpm_options, stop_when_spent, rng):
    """Lower the rpm of random legs ≥ lo (the faster of two draws) one step at a time while the estimated extra
    hours fit in `slack_h`; `stop_when_spent` ends the draws once the slack is used up (otherwise all 2·(n − lo)
    draws are made). Returns the first leg changed (n when none)."""
    n = rpm_idx.shape[0]
    first = n
    for _t in range(2 * (n - lo)):
        if stop_when_spent and slack_h <= 0.0:
            break
        j = lo + rng.integers(0, n - lo)
        j2 = lo + rng.integers(0, n - lo)
        if rpm_idx[j2] > rpm_idx[j]:
            j = j2
        r = rpm_idx[j]
        if r == 0:
            continue
        add = (ct[j + 1] - ct[j]) * (rpm_options[r] / rpm_options[r - 1] - 1.0)
        if add > slack_h:
            continue
        slack_h -= add
        rpm_idx[j] = r - 1
        first = min(first, j)
    return first


@numba.njit(cache=True)
def plan_flips_nb(rpm_idx, lo, est, bar, ref, rpm_options, o, rng):
    """Engine settings re-set before a move is sailed: from the estimated arrival and fuel est = (T_est hours, F_est)
    of the moved route, raise (late) or lower (early by more than a step) the rpm of random legs ≥ lo, priced with
    the legs' hours and fuel in ref = (ct_ref, cf_ref) (the legs are unchanged by the move). Returns the first leg
    re-set (n when none), or -1 when, under the jit objective, the estimated fuel reaches `bar`."""
    (T_est, F_est), (ct_ref, cf_ref) = est, ref
    n = rpm_idx.shape[0]
    if lo >= n:
        return n
    t_req_h = o.t_req_h
    margin = 0.05 * t_req_h / n
    if T_est > t_req_h:
        first, F_est = speed_up_nb(rpm_idx, lo, T_est - t_req_h + margin, F_est, ct_ref, cf_ref, rpm_options, rng)
        if o.kind == OBJ_JIT and F_est >= bar:
            return -1
        return first
    return slow_down_nb(rpm_idx, lo, t_req_h - T_est - margin, ct_ref, rpm_options, True, rng)


@numba.njit(cache=True)
def retime_nb(vy, nodes, rpm_idx, lo, q, bar, s, rng):
    """Engine re-adjustment after a move, so the arrival stays just inside the RTA; returns the new cost.

    `nodes`/`rpm_idx` were sailed whole into s.ct/s.cf with cost q. Only legs ≥ `lo` are re-set. A leg of h hours
    at rpm r is estimated to take h·r/r' at r' and burn (r'/r)² times its fuel (fuel rate ∝ rpm³).
      late   raise the rpm of random legs (the slower of two draws) until the estimated saving covers the
             delay, sail again; at most two rounds. With the jit objective the re-sail is skipped (cost +inf)
             when the estimated fuel already reaches `bar`, the cost the move has to beat.
      early  by more than one step's worth: lower the rpm of random legs while the estimated arrival stays
             before the RTA, sail again, and keep it only if it is on time and cheaper; at most two rounds.
    """
    n = rpm_idx.shape[0]
    if q == np.inf or lo >= n:
        return q
    v, o = vy.v, vy.o
    ct, cf, rpm_options, t_dep_h, t_req_h = s.ct, s.cf, v.rpm_options, o.t_dep_h, o.t_req_h
    margin = 0.05 * t_req_h / n  # about 5 % of a leg's hours: room for the estimate's error
    for _round in range(2):
        T = ct[n] - t_dep_h
        if T <= t_req_h + 1e-9:
            break
        first, extra_f = speed_up_nb(rpm_idx, lo, T - t_req_h + margin, 0.0, ct, cf, rpm_options, rng)
        if first == n:
            return q
        if o.kind == OBJ_JIT and cf[n] + extra_f >= bar:
            return np.inf
        q = cost_from_nb(vy, nodes, rpm_idx, first, ct, cf)
        s.cnt[0] += 1
        if q == np.inf:
            return q
    for _round in range(2):
        T = ct[n] - t_dep_h
        slack = t_req_h - T - margin
        if T > t_req_h + 1e-9 or slack <= 0.0:
            return q
        s.keep_r[:] = rpm_idx
        first = slow_down_nb(rpm_idx, lo, slack, ct, rpm_options, False, rng)
        if first == n:
            return q
        s.keep_t[:] = ct
        s.keep_f[:] = cf
        q2 = cost_from_nb(vy, nodes, rpm_idx, first, ct, cf)
        s.cnt[0] += 1
        if not (q2 < q and ct[n] - t_dep_h <= t_req_h + 1e-9):
            rpm_idx[:] = s.keep_r
            ct[:] = s.keep_t
            cf[:] = s.keep_f
            return q
        q = q2
    return q


@numba.njit(cache=True)
def aim_engine_nb(vy, nodes, rpm_idx, s, rng):
    """Engine settings aimed at the RTA for a route: sail it at every constant setting, take the two settings
    whose arrivals bracket the RTA and put the share of legs on the faster one that should arrive just in
    time (random legs), then re-time. The sailed route is left in s.ct/s.cf. Returns the cost."""
    g, v, w, o = vy.g, vy.v, vy.w, vy.o
    n = rpm_idx.shape[0]
    R = v.rpm_options.shape[0]
    ct, cf, t_dep_h, t_req_h = s.ct, s.cf, o.t_dep_h, o.t_req_h
    hours = np.empty(R)
    for r in range(R):
        rpm_idx[:] = r
        code, _ = sail_route_nb(nodes, rpm_idx, 0, g, v, w, o, ct, cf)
        hours[r] = ct[n] - t_dep_h if code == OK else np.inf
        s.cnt[0] += 1
    fast = -1
    for r in range(R):
        if hours[r] <= t_req_h:
            fast = r
            break
    if fast <= 0:  # the slowest setting is in time, or none is: one constant setting
        rpm_idx[:] = 0 if fast == 0 else R - 1
        for r in range(R - 1, -1, -1):
            if fast < 0 and hours[r] < np.inf:
                rpm_idx[:] = r  # the fastest feasible one: the least late
                break
    else:
        slow = fast - 1
        rpm_idx[:] = fast
        if hours[slow] < np.inf:
            share = (hours[slow] - t_req_h) / (hours[slow] - hours[fast])
            k = int(share * n + rng.random())
            rpm_idx[:] = slow
            perm = rng.permutation(n)
            for j in range(min(k, n)):
                rpm_idx[perm[j]] = fast
    q = cost_from_nb(vy, nodes, rpm_idx, 0, ct, cf)
    s.cnt[0] += 1
    return retime_nb(vy, nodes, rpm_idx, 0, q, np.inf, s, rng)


def time_price(inst, nodes: np.ndarray) -> float:
    """The fuel (t) the route pays per hour gained around its RTA: the slope between the two settings held
    throughout whose arrivals bracket the RTA (0 when none do). The price at which the bucketed DPs compare
    labels of one time span."""
    o = inst.objective
    deadline = o.t_dep_h + o.t_req_h
    hours, fuel = [], []
    for r in range(len(inst.rpm_options)):
        ok, t, f = _sail_held(inst, nodes, r)
        hours.append(t if ok else np.inf)
        fuel.append(f)
    for r in range(len(hours) - 1):
        if hours[r] > deadline >= hours[r + 1]:
            return max(0.0, (fuel[r + 1] - fuel[r]) / (hours[r] - hours[r + 1]))
    return 0.0


def _sail_held(inst, nodes: np.ndarray, r: int):
    """The route at setting r throughout: (sailed ok, arrival time h, fuel t)."""
    L2 = len(nodes)
    ct, cf = np.empty(L2), np.empty(L2)
    code, _ = sail_route_nb(nodes, np.full(L2 - 1, r, np.int64), 0, inst.graph, inst.vessel, inst.wx, inst.objective,
                            ct, cf)
    return code == OK, float(ct[-1]), float(cf[-1])
