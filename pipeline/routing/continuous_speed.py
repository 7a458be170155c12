"""Speed as a continuous decision: each run of a plan's engine setting gets its own rpm, anywhere between the
lowest and the highest allowed rpm outside the engine's barred ranges, not only one of the listed settings.

The solvers search routes and a few settings per leg (the voyage's listed settings plus the constant rpm that
meets the RTA, solve.py); `refine_rpm` then refines the speeds of a plan on its fixed route. Its runs of one
setting are the variables (a run held longer than 1.5 pieces is cut into pieces of about two holds first, so a
voyage held at one rpm can still vary its speed). Each step measures, for every run, what one rpm more costs the
whole voyage in fuel and hours (`run_slopes_nb`: the run sailed faster and the rest of the voyage from the
times that gives, with the time-dependent leg kernel of the other solvers), moves the runs along the direction
that burns less fuel at the same hours (the fuel slope projected off the hours slope), brings the voyage back to
the RTA with one rpm offset on every leg when the move made it late, and keeps the step only when the plan so
sailed costs less under the objective, change costs included, and still holds every setting `min_hold_h`. So a
refined plan is never dearer than the plan it refines, and a plan on time stays on time. The result is a local
optimum over the runs' rpm (a descent, not an exhaustive search).

Barred ranges (`barred_rpm`: open intervals (lo, hi) of rpm the engine must not be held in, e.g. a torsional-
vibration range) are never chosen: a run moved into one is put on its nearer edge.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numba
import numpy as np

from pipeline.routing.engine.leg import CODE, FUEL, H, N_LEG_OUT, OK, OnRoute, sail_leg_nb
from pipeline.routing.objectives import route_cost_nb

_ITERATIONS = 12  # descent steps at most
_DELTA_RPM = 0.25  # the rpm step of the slopes
_FIRST_STEP_RPM = 4.0  # the largest change of a run's rpm in one step
_LAST_STEP_RPM = 0.125  # below this step the descent stops
_RETIMES = 8  # secant steps bringing a plan that became late back to the RTA
_MERGE_RPM = 1.0  # neighbouring runs closer than this are tried at one rpm


@dataclass(frozen=True)
class Refined:
    """A plan's rpm per leg after refining, its objective value (change costs included), fuel, hours, changes."""

    rpm: np.ndarray
    cost: float
    fuel_t: float
    hours: float
    n_changes: int


def runs_of(rpm_per_leg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(first leg, one past the last leg) of each run of equal rpm along the legs."""
    rpm_per_leg = np.asarray(rpm_per_leg)
    change = np.flatnonzero(rpm_per_leg[1:] != rpm_per_leg[:-1]) + 1
    starts = np.concatenate(([0], change)).astype(np.int64)
    ends = np.concatenate((change, [rpm_per_leg.size])).astype(np.int64)
    return starts, ends


@numba.njit(cache=True)
def sail_from_nb(rt, rpm, i0, cum_t, cum_f):
    """Sail the route `rt` (engine.leg.OnRoute) from line i0 (cum_t[i0], cum_f[i0] given) at rpm[i] on leg i, filling
    cum_t/cum_f after it. Returns the engine.leg code."""
    out = np.empty(N_LEG_OUT)
    lat, lon, nodes = rt.g.lat, rt.g.lon, rt.nodes
    for i in range(i0, nodes.shape[0] - 1):
        a, b = nodes[i], nodes[i + 1]
        sail_leg_nb(lat[i, a], lon[i, a], lat[i + 1, b], lon[i + 1, b], cum_t[i], rpm[i], rt.v, rt.w, out)
        if out[CODE] != OK:
            return int(out[CODE])
        cum_t[i + 1] = cum_t[i] + out[H]
        cum_f[i + 1] = cum_f[i] + out[FUEL]
    return OK


class SlopeStep(NamedTuple):
    """How `run_slopes_nb` measures a slope: `delta` rpm more on a run (less when that passes `hi`; none below `lo`)."""

    delta: float
    lo: float
    hi: float


@numba.njit(cache=True)
def run_slopes_nb(rt, rpm, starts, ends, step, cum_t, cum_f, d_fuel, d_hours):
    """Per run j: the change of the voyage's fuel (t) and hours per rpm when run j alone sails `step.delta` rpm faster
    (slower at the top of the range), the rest of the voyage sailed from the times that gives; inf when a leg then
    cannot be sailed. cum_t/cum_f: the plan as sailed (left unchanged)."""
    delta, lo, hi = step.delta, step.lo, step.hi
    L2 = rt.nodes.shape[0]
    t2, f2 = np.empty(L2), np.empty(L2)
    r2 = rpm.copy()
    for j in range(starts.shape[0]):
        d = delta if rpm[starts[j]] + delta <= hi else -delta
        if rpm[starts[j]] + d < lo:
            d_fuel[j], d_hours[j] = np.inf, np.inf
            continue
        for i in range(starts[j], ends[j]):
            r2[i] = rpm[i] + d
        t2[starts[j]], f2[starts[j]] = cum_t[starts[j]], cum_f[starts[j]]
        code = sail_from_nb(rt, r2, starts[j], t2, f2)
        for i in range(starts[j], ends[j]):
            r2[i] = rpm[i]
        if code != OK:
            d_fuel[j], d_hours[j] = np.inf, np.inf
            continue
        d_fuel[j] = (f2[L2 - 1] - cum_f[L2 - 1]) / d
        d_hours[j] = (t2[L2 - 1] - cum_t[L2 - 1]) / d


class _Route:
    """The fixed route of a refinement and what sailing it at given rpm per leg costs."""

    def __init__(self, inst, nodes, change_cost_t: float, min_hold_h: float):
        self.inst = inst
        self.nodes = np.ascontiguousarray(nodes, np.int64)
        self.rt = OnRoute(inst.graph, self.nodes, inst.vessel, inst.wx)
        self.o = inst.objective
        self.change_cost_t, self.min_hold_h = change_cost_t, min_hold_h
        self.n_sails = 0

    def sail(self, rpm: np.ndarray):
        """(cost, hours, fuel, cum_t, cum_f) of the route at rpm[i] on leg i; cost inf when it cannot be sailed,
        passes the planning horizon or does not hold its settings."""
        L2 = len(self.nodes)
        ct, cf = np.empty(L2), np.empty(L2)
        ct[0], cf[0] = self.o.t_dep_h, 0.0
        code = sail_from_nb(self.rt, np.ascontiguousarray(rpm, np.float64), 0, ct, cf)
        self.n_sails += 1
        hours, fuel = float(ct[-1] - self.o.t_dep_h), float(cf[-1])
        if code != OK or hours > self.o.max_hours or not _holds(rpm, ct, self.min_hold_h):
            return math.inf, hours, fuel, ct, cf
        return route_cost_nb(self.o, hours, fuel) + self.change_cost_t * _changes(rpm), hours, fuel, ct, cf


def _changes(rpm: np.ndarray) -> int:
    return int(np.sum(rpm[1:] != rpm[:-1]))


def _holds(rpm: np.ndarray, cum_t: np.ndarray, min_hold_h: float) -> bool:
    """Whether every run of the legs' rpm is held at least `min_hold_h` (a plan of one setting always is)."""
    starts, ends = runs_of(rpm)
    if len(starts) == 1 or min_hold_h <= 0.0:
        return True
    return bool(np.all(cum_t[ends] - cum_t[starts] >= min_hold_h - 1e-9))


def split_runs(rpm_per_leg: np.ndarray, cum_t: np.ndarray, piece_h: float) -> tuple[np.ndarray, np.ndarray]:
    """The plan's runs, each longer than 1.5 pieces cut into pieces of about `piece_h` hours (at its legs'
    boundaries), so one setting held long can become several."""
    starts, ends = runs_of(rpm_per_leg)
    out_s, out_e = [], []
    for a, b in zip(starts, ends):
        span = cum_t[b] - cum_t[a]
        n = min(int(round(span / piece_h)), int(b - a)) if math.isfinite(piece_h) and span > 1.5 * piece_h else 1
        cuts = [int(a)]
        for piece in range(1, n):
            i = int(np.searchsorted(cum_t[a:b + 1], cum_t[a] + piece * span / n)) + int(a)
            if cuts[-1] < i < b:
                cuts.append(i)
        cuts.append(int(b))
        out_s.extend(cuts[:-1])
        out_e.extend(cuts[1:])
    return np.asarray(out_s, np.int64), np.asarray(out_e, np.int64)


def _allowed(rpm: np.ndarray, lo: float, hi: float, barred_rpm) -> np.ndarray:
    """rpm clipped to lo..hi and moved out of each barred open interval to its nearer edge."""
    rpm = np.clip(rpm, lo, hi)
    for b_lo, b_hi in barred_rpm:
        inside = (rpm > b_lo) & (rpm < b_hi)
        rpm = np.where(inside, np.where(rpm - b_lo < b_hi - rpm, b_lo, b_hi), rpm)
    return rpm


def refine_rpm(inst, nodes, rpm_per_leg, *, min_hold_h: float = 0.0, change_cost_t: float = 0.0, barred_rpm=(),
               iterations: int = _ITERATIONS) -> Refined | None:
    """The plan (route `nodes`, rpm per leg) with its speeds refined continuously (module docstring), or None when
    nothing cheaper is found under the objective plus `change_cost_t` per change, each setting held `min_hold_h`.
    The descent runs twice: on the plan's own runs, and on them cut into pieces of two holds (12 h without a
    hold); the cheaper result is returned."""
    best = None
    for piece_h in (math.inf, 2.0 * min_hold_h if min_hold_h > 0.0 else 12.0):
        found = _descend(inst, nodes, rpm_per_leg, min_hold_h, change_cost_t, barred_rpm, piece_h, iterations)
        if found is not None and (best is None or found.cost < best.cost):
            best = found
    return best


def _descend(inst, nodes, rpm_per_leg, min_hold_h: float, change_cost_t: float, barred_rpm, piece_h: float,
             iterations: int) -> Refined | None:
    """refine_rpm's descent over the plan's runs, each longer than 1.5 × `piece_h` cut into pieces of about it."""
    rpm = np.asarray(rpm_per_leg, np.float64).copy()
    lo, hi = float(inst.rpm_options[0]), float(inst.rpm_options[-1])
    route = _Route(inst, nodes, change_cost_t, min_hold_h)
    cost0, hours, fuel, ct, cf = route.sail(rpm)
    if not math.isfinite(cost0):
        return None
    starts, ends = split_runs(rpm, ct, piece_h)
    leg_run = np.repeat(np.arange(len(starts)), ends - starts)
    t_req = inst.objective.t_req_h
    cost, best = cost0, None
    d_fuel, d_hours = np.empty(len(starts)), np.empty(len(starts))
    slope_step = SlopeStep(_DELTA_RPM, lo, hi)
    step = _FIRST_STEP_RPM
    for _it in range(iterations):
        run_slopes_nb(route.rt, rpm, starts, ends, slope_step, ct, cf, d_fuel, d_hours)
        run_rpm = rpm[starts]
        # a run held barely its hold cannot go faster (it would be held less), nor one at the top
        pinned = _pinned(rpm, ct, starts, min_hold_h)
        d = _descent(d_fuel, d_hours, run_rpm, lo, hi, pinned)
        if d is None:
            break
        shift = ~pinned[leg_run]
        improved = False
        while step >= _LAST_STEP_RPM:
            trial = _allowed(run_rpm + step * d, lo, hi, barred_rpm)[leg_run]
            result = _on_time(route, trial, t_req, lo, hi, barred_rpm, hours, float(d_hours[~pinned].sum()), shift)
            if result[0] < cost * (1.0 - 1e-9) - 1e-12:
                cost, hours, fuel, ct, cf, rpm = result
                best = Refined(rpm.copy(), float(cost), float(fuel), float(hours), _changes(rpm))
                improved = True
                step = min(2.0 * step, _FIRST_STEP_RPM)
                break
            step *= 0.5
        if not improved:
            break
    if best is not None and change_cost_t > 0.0:
        best = _merge_close_runs(route, best, t_req, lo, hi, barred_rpm)
    return best


def _pinned(rpm: np.ndarray, cum_t: np.ndarray, starts: np.ndarray, min_hold_h: float) -> np.ndarray:
    """Per variable run (`starts`): whether it lies in a run of the plan held less than 1.25 holds, which a faster
    rpm would leave held too short."""
    pinned = np.zeros(len(starts), bool)
    if min_hold_h <= 0.0:
        return pinned
    r_s, r_e = runs_of(rpm)
    if len(r_s) == 1:
        return pinned
    short = cum_t[r_e] - cum_t[r_s] < 1.25 * min_hold_h
    which = np.searchsorted(r_s, starts, side="right") - 1
    return short[which]


def _descent(d_fuel, d_hours, run_rpm, lo, hi, pinned) -> np.ndarray | None:
    """The direction of the runs' rpm (largest component 1) that lowers the fuel at the same hours to first order:
    the fuel slope projected off the hours slope over the runs that may move that way (not below lo, not above hi,
    not faster when pinned); None when no run can move."""
    movable = np.isfinite(d_fuel) & np.isfinite(d_hours)
    for _ in range(4):
        if not np.any(movable):
            return None
        g, h = d_fuel[movable], d_hours[movable]
        # math.fsum, not `g @ h`: BLAS's ddot sums in an order that follows the CPU's kernel (AVX-512, AVX2, SSE3),
        # so a plan's last bits would depend on the machine; a correctly rounded sum does not
        gh, hh = math.fsum(g * h), math.fsum(h * h)
        mu = gh / hh if hh > 0.0 else 0.0
        d = np.zeros(len(run_rpm))
        d[movable] = -(g - mu * h)
        blocked = ((d < 0.0) & (run_rpm <= lo)) | ((d > 0.0) & ((run_rpm >= hi) | pinned))
        if not np.any(blocked):
            break
        movable &= ~blocked
    else:
        return None
    top = np.abs(d).max()
    return d / top if top > 0.0 else None


def _merge_close_runs(route: _Route, best: Refined, t_req_h: float, lo: float, hi: float, barred_rpm) -> Refined:
    """`best` with neighbouring runs less than `_MERGE_RPM` apart sailed at one rpm (their time-weighted mean,
    the voyage brought back to the RTA if that makes it late), each merge kept when it costs less: a change of
    setting costs more than the fuel such a small difference saves."""
    rpm, cost = best.rpm.copy(), best.cost
    tried = set()
    for _ in range(len(rpm)):
        _, hours, _, ct, _ = route.sail(rpm)
        r_s, r_e = runs_of(rpm)
        gaps = np.abs(np.diff(rpm[r_s]))
        order = [k for k in np.argsort(gaps) if gaps[k] < _MERGE_RPM and float(rpm[r_s[k]]) not in tried]
        if not order:
            break
        k = order[0]
        tried.add(float(rpm[r_s[k]]))
        span = slice(r_s[k], r_e[k + 1])
        w = np.diff(ct)[span]
        trial = rpm.copy()
        trial[span] = float(np.sum(rpm[span] * w) / np.sum(w))
        result = _on_time(route, _allowed(trial, lo, hi, barred_rpm), t_req_h, lo, hi, barred_rpm, hours,
                          -float(np.sum(np.diff(ct))) / max(float(np.mean(rpm)), 1.0), np.ones(len(rpm), bool))
        if result[0] < cost:
            cost, rpm = result[0], result[5]
            tried.clear()
    if cost >= best.cost:
        return best
    _, hours, fuel, _, _ = route.sail(rpm)
    return Refined(rpm, float(cost), float(fuel), float(hours), _changes(rpm))


def _on_time(route: _Route, rpm: np.ndarray, t_req_h: float, lo: float, hi: float, barred_rpm, hours_before: float,
             hours_per_rpm: float, shift: np.ndarray):
    """The plan `rpm` sailed, and when it then arrives after the RTA (while the plan before it did not), with every
    leg where `shift` is set shifted by one rpm offset that brings it in by the RTA again (regula falsi from the first guess that the
    voyage's hours per rpm `hours_per_rpm` < 0 gives): (cost, hours, fuel, cum_t, cum_f, rpm); cost inf when no
    offset tried is on time."""
    cost, hours, fuel, ct, cf = route.sail(rpm)
    if not (hours > t_req_h >= hours_before) or not math.isfinite(hours):
        return cost, hours, fuel, ct, cf, rpm
    late_c, late_h = 0.0, hours
    early = None  # (offset, result) of the on-time offset nearest the RTA so far
    c = (t_req_h - hours) / hours_per_rpm if hours_per_rpm < 0.0 else 0.25
    for _ in range(_RETIMES):
        c = max(c * 1.02, 1e-3)
        r = _allowed(rpm + c * shift, lo, hi, barred_rpm)
        res = route.sail(r)
        if not math.isfinite(res[1]):
            break
        if res[1] <= t_req_h:
            early = (c, res + (r,))
            if t_req_h - res[1] <= 1e-3 * max(1.0, t_req_h - hours_before):
                break
            early_c, early_h = c, res[1]
        else:
            late_c, late_h = c, res[1]
        if early is None:
            c = c + (t_req_h - res[1]) / hours_per_rpm if hours_per_rpm < 0.0 else 2.0 * c
        else:  # regula falsi between the late and the on-time offset, aiming just inside the RTA
            c = late_c + (early_c - late_c) * (late_h - t_req_h) / (late_h - early_h)
            c = min(max(c, late_c), early_c) / 1.02
    if early is None:
        return math.inf, hours, fuel, ct, cf, rpm
    return early[1]


def as_settings(inst, rpm_per_leg: np.ndarray):
    """(the instance with the legs' rpm among its settings, the rpm index of each leg): how a plan with rpm of
    its own is handed to code that takes settings."""
    rpm = np.asarray(rpm_per_leg, np.float64)
    options = np.union1d(np.asarray(inst.rpm_options, np.float64), rpm)
    inst2 = inst.with_rpm_options(options)
    return inst2, np.searchsorted(inst2.rpm_options, rpm).astype(np.int64)


__all__ = ["Refined", "refine_rpm", "runs_of", "split_runs", "as_settings"]
