"""The bound tables every label search prunes with (the searches: dp.py, dp_grid.py, engine_limits.py): the least
hours and fuel per NM of each leg in the weather it can meet, the fuel-to-finish tables built from them, the latest
departures that still make the RTA, the windows of times a plan can be at each node, and the `FinishBounds` they
make together (engine/bounds.py holds the structure and the pruning rule; why each bound is certified:
docs/search-methods.md, "The exact DP", Bounds).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from pipeline.performance.features import FORM_PHYSICAL, FORM_THESIS, stw_kn_nb, fuel_tph_nb
from pipeline.routing import geodesy as geo
from pipeline.routing.engine.bounds import FinishBounds, fuel_to_finish_lb, is_on_time
from pipeline.routing.engine.leg import (CODE, FIX_FUEL, FIX_H, FIX_LAT0, FIX_LAT1, FIX_LON0, FIX_LON1, FIX_TOL_DEG, H,
                                         N_LEG_OUT, OK, sail_leg_nb)
from pipeline.routing.objectives import OBJ_JIT
from pipeline.routing.reachable_weather import WINDOW_SLACK_H, earliest_arrival_nb, reachable_ranges_nb


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


@numba.njit(cache=True, inline="always")  # in the tables' inner loops
def _leg_prices(g, i, a, b, rates, prices):
    """The leg (i, a) → (i + 1, b) of the graph `g` relaxed at the `rates` (τ, φ per leg and setting, the prices λ):
    prices[k] = d·min_r(φ + λ_k·τ); returns its least hours d·min_r τ."""
    lat, lon, tau_e, phi_e, lams = g.lat, g.lon, rates[0], rates[1], rates[2]
    s = b - a + g.max_shift
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
def _backward_tables(g, rates, m_lam, t_min):
    """m_lam[k, i, a] = least Σ d·min_r(φ + λ_k·τ) and t_min[i, a] = least Σ d·min_r τ from (i, a) to the arrival
    through the feasible edges of the graph `g`, with the `rates` (τ, φ (L+2, P, 2·max_shift + 1, R) of each leg
    (i, a) → (i + 1, a + s − max_shift), the prices λ); inf where the arrival cannot be reached."""
    edge_ok, max_shift, lams = g.edge_ok, g.max_shift, rates[2]
    L2, P = g.lat.shape
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
                t_min[i, a] = min(t_min[i, a], t_min[i + 1, b] + _leg_prices(g, i, a, b, rates, prices))
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
    sp = inst.space
    L2, P = sp.lat.shape
    t_lo, t_hi = windows
    rng = np.zeros((L2, P, 2 * sp.max_shift + 1, 9))
    reachable_ranges_nb(inst.wx, inst.graph, np.ascontiguousarray(t_lo, dtype=np.float64),
                        np.ascontiguousarray(t_hi, dtype=np.float64), rng)
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
    _backward_tables(sp.graph, (tau_e, phi_e, lams), m_lam, t_min)
    if wide is not None:
        wide[:] = [lams, m_lam.copy(), t_min.copy(), tau_e, phi_e] if per_leg else [lams, m_lam.copy(), t_min.copy(),
                                                                                     tau, phi]
    if windows is not None and math.isfinite(fuel_budget_t):
        windows = fuel_windows(inst, windows, fuel_budget_t, lams, m_lam, t_min, tau_e, phi_e)
        tau_e, phi_e, tau, phi = _leg_bounds(inst, windows)
        _backward_tables(sp.graph, (tau_e, phi_e, lams), m_lam, t_min)
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
    _forward_tables(sp.graph, (tau_e, phi_e, lams), m_f, t_f)
    t_lo, t_hi = (np.array(x, dtype=np.float64) for x in windows)
    _fuel_windows_nb(lams, (m_f, t_f), (m_lam, t_min), (o.t_dep_h, o.t_dep_h + o.t_req_h), fuel_budget_t, step_h,
                     WINDOW_SLACK_H, (t_lo, t_hi))
    return t_lo, t_hi


@numba.njit(cache=True)
def _fuel_windows_nb(lams, forward, backward, span, budget, step, slack, windows):
    """`fuel_windows` in place on windows = (t_lo, t_hi) (L+2, P): the tables from the departure (m_f, t_f) and to the
    arrival (m_b, t_b), span = (departure, deadline) (h)."""
    (m_f, t_f), (m_b, t_b), (t_dep, deadline), (t_lo, t_hi) = forward, backward, span, windows
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
def _forward_tables(g, rates, m_f, t_f):
    """`_backward_tables` from the departure: m_f[k, i, a] = least Σ d·min_r(φ + λ_k·τ) and t_f[i, a] = least Σ d·min_r τ
    from the departure to (i, a); inf where (i, a) cannot be reached."""
    edge_ok, max_shift, lams = g.edge_ok, g.max_shift, rates[2]
    L2, P = g.lat.shape
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
                t_f[i + 1, b] = min(t_f[i + 1, b], t_f[i, a] + _leg_prices(g, i, a, b, rates, prices))
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


def label_bounds(inst, ld: np.ndarray, windows=None, fuel_budget_t: float = math.inf, wide=None) -> FinishBounds:
    """The FinishBounds of the label searches on `inst`'s graph: `finish_bounds` per leg (within `windows`, for the
    plans burning at most `fuel_budget_t`; `wide` as there) and the latest departures `ld` (`latest_departures`)."""
    lams, m_lam, t_min, tau, phi = finish_bounds(inst, windows, fuel_budget_t, per_leg=True, wide=wide)
    return FinishBounds(lams, m_lam, t_min, tau, phi, ld)


def fuel_budget_t(o, upper: float, gap: float) -> float:
    """The most fuel (t) a plan can burn that the DP, pruning with the on-time incumbent cost `upper` and trimming
    within `gap`, must keep: its cost is at most upper + gap·upper (the DP's tolerance is gap·LB ≤ gap·optimum)."""
    cost = upper * (1.0 + gap) + 2e-9 * max(1.0, abs(upper))
    return cost if o.kind == OBJ_JIT else (cost - 0.85) * o.f_target / 3.0  # thesis: 0.85 + 3·F/F_target on time
