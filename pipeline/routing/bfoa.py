"""Improved Bacterial Foraging Optimisation (BFOA) over the node graph, numba-compiled.

A bacterium's position is one node per line (lines 1..L; the ports are fixed) plus one engine
setting (index into the allowed rpm list) per leg. Every cycle each bacterium makes `n_chemo`
chemotactic moves:
  tumble   pick a direction vector V: +1 at line k; +1 at k, k+1; +1 at k..k+2; the same with −1;
           or +1 at k1 and −1 at k2 (single-line moves most likely, two-line next, the rest least).
           With probability `p_engine` the vector acts on the engine settings of legs instead. With
           probability `p_bend` k is a bend (a line where the route, or a leg where the engine plan,
           changes), else any line: on a smooth route a move at a bend shifts it instead of adding two.
  swim     S' = S + V·D, repeated while the judged cost keeps falling (at most `swim_max` times); only
           feasible improvements are accepted.
  engine re-set  every move also re-sets engine settings so the ship still arrives just inside the
           RTA: before sailing, random legs after the move are sped up (late) or slowed (early by more
           than a step) for the move's estimated arrival (a leg of h hours at rpm r takes h·r/r' at r',
           fuel ∝ rpm³); after sailing, the same corrects what the estimate missed (`retime_nb`).
  screen   (jit objective) a route move first sails only the legs it changes; the rest of the route
           is sailed only when their fuel change plus their time change priced at what the engine
           re-set pays per hour is below `screen` × cost (+ the move's repulsion credit);
           `screen_engine` ≥ 0 does the same for engine moves (off by default).
  step D   adaptive per bacterium: large (`d_large` × nodes per line, at least 3) → medium (2) → small
           (1) after `n_fail` consecutive failed moves at each size, and small → large again to escape
           local optima.
  repulsion  d(S1, S2) = sqrt(Σ (P1(i) − P2(i))²) over the lines; for neighbours closer than d_max,
           dQ(S) = Σ Q_exp·(1 − d_k/d_max) with Q_exp = repulsion × |Q(S)|. A move is judged on
           Q(S') + dQ(S') − dQ(S) (crowding is penalised, so bacteria spread and a crowded bacterium
           may step to a slightly dearer, less crowded position), unless S' beats S and every
           neighbour, when dQ = 0. The best plan ever met is kept apart and returned.
After the moves: sort by cost; reproduction replaces the `n_repro` worst *mature* bacteria
(≥ `steps_to_die` moves) with copies of the best; every `ed_every` cycles elimination/dispersal
re-initialises `n_disperse` random bacteria, never the current best.
Random initialisation is a safe random walk line by line that heads, one node at a time (chance
`walk_slope` per line), for a target offset drawn ~ N(0, `walk_spread` × nodes per line) and redrawn
`walk_turns` times per route on average, bending back to the destination in time: random routes are
smooth detours of every size rather than zig-zags. Each node tries the preferred node, then nodes
ever farther from it (R_max tries per node, K_max overall, backing up `backup` lines on failure); a
route that cannot be sailed (weather limits) is drawn again with twice the spread (up to 4 draws).
Its engine settings are aimed at the RTA: sailed at each constant setting, the two settings whose
arrivals bracket the RTA are mixed over random legs in the share that should arrive just in time,
then re-set as above. Bacterium 0 starts on the baseline route (with its constant rpm, or the aimed
settings where cheaper) so the result is never worse than it.

Everything random comes from numba's generator seeded with `seed`: same seed, same plan.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from pipeline.routing.leg_kernel import N_LEG_OUT
from pipeline.routing.objectives import OBJ_JIT
from pipeline.routing.engine_timing import (aim_engine_nb, cost_from_nb, plan_flips_nb, retime_nb, sail_span_nb,
                                              time_price_nb)
from pipeline.routing.random_route import random_walk_nb


@dataclass(frozen=True)
class BfoaParams:
    n_bacteria: int = 40
    n_chemo: int = 12
    n_cycles: int = 40
    n_repro: int = 4
    n_disperse: int = 2
    ed_every: int = 6
    n_fail: int = 3
    steps_to_die: int = 36
    swim_max: int = 6
    r_max: int = 12
    k_max: int = 4000
    backup: int = 2
    p_engine: float = 0.3
    repulsion: float = 0.002
    d_max: float | None = None  # None: 0.5·sqrt(L) + 1
    walk_spread: float = 0.1  # random routes: s.d. of a detour's target offset, as a share of the nodes per line
    walk_turns: float = 0.3  # random routes: new target offsets drawn per route (expected)
    walk_slope: float = 0.3  # random routes: chance per line of a one-node step towards the target
    screen: float = 0.002  # jit: skip sailing the rest of a route move estimated worse by > screen × cost
    screen_engine: float = -1.0  # the same for engine moves (negative: always sail them whole)
    d_large: float = 0.075  # the large swim length as a share of the nodes per line (at least 3; medium 2, small 1)
    plan_engine: bool = True  # re-set the engine for a move's estimated arrival before sailing it (else after)
    p_bend: float = 0.5  # chance a tumble is placed at a bend of the route (or engine plan) rather than anywhere

    def arrays(self, n_lines: int) -> tuple[np.ndarray, np.ndarray]:
        ip = np.array([self.n_bacteria, self.n_chemo, self.n_cycles, self.n_repro, self.n_disperse, self.ed_every,
                       self.n_fail, self.steps_to_die, self.swim_max, self.r_max, self.k_max, self.backup], dtype=np.int64)
        d_max = self.d_max if self.d_max is not None else 0.5 * np.sqrt(n_lines) + 1.0
        fp = np.array([self.p_engine, self.repulsion, d_max, self.walk_spread, self.walk_turns / max(n_lines, 1),
                       self.walk_slope, self.screen, self.p_bend, self.screen_engine,
                       1.0 if self.plan_engine else 0.0, self.d_large], dtype=np.float64)
        return ip, fp


@numba.njit(cache=True)
def _new_bacterium(nodes, rpm_idx, lat, lon, edge_ok, rpm_options, t_dep_h, max_hours, vp, sc, fc, wx, times_h, grid, obj,
                   t_req_h, window_h, f_target, early, late, ct, cf, keep_r, keep_t, keep_f, cnt, max_shift, r_max,
                   k_max, backup, sigma, p_new, p_step):
    """A random bacterium: a safe random walk with engine settings aimed at the RTA. A route that cannot be
    sailed (weather limits on the way) is drawn again with twice the spread, up to 4 draws. (placed?, cost)"""
    q = np.inf
    for attempt in range(4):
        if not random_walk_nb(nodes, edge_ok, max_shift, r_max, k_max, backup, sigma * 2.0 ** attempt, p_new, p_step):
            return False, np.inf
        q = aim_engine_nb(nodes, rpm_idx, lat, lon, edge_ok, rpm_options, t_dep_h, max_hours, vp, sc, fc, wx, times_h,
                        grid, obj, t_req_h, window_h, f_target, early, late, ct, cf, keep_r, keep_t, keep_f, cnt)
        if q < np.inf:
            break
    return True, q


@numba.njit(cache=True)
def _crowding(pos, i, cand, n_alive, d_max, q_exp):
    """dQ of `cand` (positions of bacterium i excluded) and the neighbour indices' count."""
    dq = 0.0
    for k in range(n_alive):
        if k == i:
            continue
        d2 = 0.0
        for j in range(1, cand.shape[0] - 1):
            e = cand[j] - pos[k, j]
            d2 += e * e
        d = np.sqrt(d2)
        if d < d_max:
            dq += q_exp * (1.0 - d / d_max)
    return dq


@numba.njit(cache=True)
def _beats_neighbours(pos, cost, i, cand, q_cand, d_max):
    for k in range(pos.shape[0]):
        if k == i:
            continue
        d2 = 0.0
        for j in range(1, cand.shape[0] - 1):
            e = cand[j] - pos[k, j]
            d2 += e * e
        if np.sqrt(d2) < d_max and q_cand >= cost[k]:
            return False
    return True


@numba.njit(cache=True)
def _bend(x, base, top):
    """A random index in base..top where x changes next to it (a bend of the route or of the engine plan); -1 if none."""
    m = 0
    for j in range(base, top + 1):
        if (j > 0 and x[j] != x[j - 1]) or (j + 1 < x.shape[0] and x[j] != x[j + 1]):
            m += 1
    if m == 0:
        return -1
    r = np.random.randint(0, m)
    for j in range(base, top + 1):
        if (j > 0 and x[j] != x[j - 1]) or (j + 1 < x.shape[0] and x[j] != x[j + 1]):
            if r == 0:
                return j
            r -= 1
    return -1


@numba.njit(cache=True)
def _tumble(L, n_legs, p_engine, p_bend, nodes, rpm_idx, vec, on_engine):
    """Fill vec (length L+2 for nodes or L+1 for legs) with a direction; return the first changed index (engine? in
    on_engine). With probability p_bend the vector is placed at a bend (a line where the route, or a leg where the
    engine plan, changes): there a move shifts the bend instead of adding two."""
    for j in range(vec.shape[0]):
        vec[j] = 0
    engine = np.random.random() < p_engine
    if engine:
        n = n_legs
        base = 0
    else:
        n = L
        base = 1
    u = np.random.random()
    sign = 1 if np.random.random() < 0.5 else -1
    top = base + n - 1
    k = -1
    if np.random.random() < p_bend:
        k = _bend(rpm_idx if engine else nodes, base, top)
        if k >= 0 and u >= 0.5 and u < 0.92 and np.random.random() < 0.5:
            k = max(base, k - (1 if u < 0.8 else 2))  # a block ending at the bend rather than starting there
    if k < 0:
        k = base + np.random.randint(0, n)
    if u < 0.5:
        vec[k] = sign
        first = k
    elif u < 0.8:
        vec[k] = sign
        if k + 1 <= top:
            vec[k + 1] = sign
        first = k
    elif u < 0.92:
        for j in range(k, min(k + 3, top + 1)):
            vec[j] = sign
        first = k
    else:
        k2 = base + np.random.randint(0, n)
        if k2 == k:
            k2 = base + (k - base + 1) % n
        vec[k] = 1
        vec[k2] = -1
        first = min(k, k2)
    on_engine[0] = engine
    return first


@numba.njit(cache=True)
def bfoa_nb(seed, ip, fp, base_nodes, base_rpm, lat, lon, edge_ok, rpm_options, t_dep_h, max_hours, vp, sc, fc, wx,
            times_h, grid, obj, t_req_h, window_h, f_target, early, late, max_shift):
    np.random.seed(seed)
    ns, n_chemo, n_cycles, n_repro, n_disp, ed_every, n_fail, to_die, swim_max, r_max, k_max, backup = (
        ip[0], ip[1], ip[2], ip[3], ip[4], ip[5], ip[6], ip[7], ip[8], ip[9], ip[10], ip[11])
    p_engine, repulsion, d_max = fp[0], fp[1], fp[2]
    sigma, p_new, p_step, screen, p_bend = max(2.0, fp[3] * lat.shape[1]), fp[4], fp[5], fp[6], fp[7]
    screen_engine, plan_flips, d_large = fp[8], fp[9], fp[10]
    L2, P = lat.shape
    L = L2 - 2
    n_rpm = rpm_options.shape[0]
    steps = np.array([max(3, min(max_shift, int(P * d_large))), 2, 1])
    pos = np.empty((ns, L2), np.int64)
    rpm = np.empty((ns, L2 - 1), np.int64)
    cum_t = np.empty((ns, L2))
    cum_f = np.empty((ns, L2))
    cost = np.empty(ns)
    moves = np.zeros(ns, np.int64)
    level = np.zeros(ns, np.int64)
    fails = np.zeros(ns, np.int64)
    history = np.empty(n_cycles)
    cnt = np.zeros(1, np.int64)  # routes (or route tails) sailed
    cand = np.empty(L2, np.int64)
    cand_r = np.empty(L2 - 1, np.int64)
    vec = np.empty(L2, np.int64)
    vec_r = np.empty(L2 - 1, np.int64)
    ct = np.empty(L2)
    cf = np.empty(L2)
    keep_r = np.empty(L2 - 1, np.int64)
    keep_t = np.empty(L2)
    keep_f = np.empty(L2)
    on_engine = np.zeros(1, np.bool_)
    for i in range(ns):
        placed = False
        if i > 0:
            placed, q = _new_bacterium(cand, cand_r, lat, lon, edge_ok, rpm_options, t_dep_h, max_hours, vp, sc, fc, wx,
                                       times_h, grid, obj, t_req_h, window_h, f_target, early, late, ct, cf, keep_r,
                                       keep_t, keep_f, cnt, max_shift, r_max, k_max, backup, sigma, p_new, p_step)
        if not placed:
            # the baseline route, with its constant rpm or engine settings aimed at the RTA, whichever is cheaper
            pos[i, :] = base_nodes
            rpm[i, :] = base_rpm
            cost[i] = cost_from_nb(pos[i], rpm[i], 0, lat, lon, edge_ok, rpm_options, t_dep_h, max_hours, vp, sc, fc, wx,
                                 times_h, grid, obj, t_req_h, window_h, f_target, early, late, cum_t[i], cum_f[i])
            cnt[0] += 1
            cand[:] = base_nodes
            q = aim_engine_nb(cand, cand_r, lat, lon, edge_ok, rpm_options, t_dep_h, max_hours, vp, sc, fc, wx, times_h,
                            grid, obj, t_req_h, window_h, f_target, early, late, ct, cf, keep_r, keep_t, keep_f, cnt)
        if placed or q < cost[i]:
            pos[i, :] = cand
            rpm[i, :] = cand_r
            cum_t[i, :] = ct
            cum_f[i, :] = cf
            cost[i] = q
    best_pos = pos[0].copy()
    best_rpm = rpm[0].copy()
    best_cost = cost[0]
    best_i = 0
    for i in range(ns):
        if cost[i] < best_cost:
            best_cost = cost[i]
            best_pos[:] = pos[i]
            best_rpm[:] = rpm[i]
            best_i = i
    # route moves are first judged on the legs they change, time priced at what the engine re-set would pay
    lam = time_price_nb(rpm[best_i], cum_t[best_i], cum_f[best_i], rpm_options) if best_cost < np.inf else 0.0
    do_screen = obj == OBJ_JIT and lam > 0.0
    do_plan = plan_flips > 0.0 and rpm_options.shape[0] > 1
    out = np.empty(N_LEG_OUT)
    for cyc in range(n_cycles):
        for i in range(ns):
            for _m in range(n_chemo):
                moves[i] += 1
                first = _tumble(L, L2 - 1, p_engine, p_bend, pos[i], rpm[i], vec, on_engine)
                engine = on_engine[0]
                if engine:
                    for j in range(L2 - 1):
                        vec_r[j] = vec[j]
                improved_any = False
                d = 1 if engine else steps[level[i]]
                for _s in range(swim_max):
                    cand[:] = pos[i]
                    cand_r[:] = rpm[i]
                    valid = True
                    last = first
                    if engine:
                        for j in range(L2 - 1):
                            if vec_r[j] != 0:
                                v = cand_r[j] + vec_r[j] * d
                                if v < 0 or v >= n_rpm:
                                    valid = False
                                    break
                                cand_r[j] = v
                                last = j
                        start = first
                    else:
                        for j in range(1, L2 - 1):
                            if vec[j] != 0:
                                v = cand[j] + vec[j] * d
                                if v < 0 or v >= P:
                                    valid = False
                                    break
                                cand[j] = v
                                last = j
                        start = first - 1
                    if not valid:
                        break
                    if cost[i] == np.inf:
                        start = 0  # the sums of an infeasible route are only valid up to where it failed
                    ct[: start + 1] = cum_t[i, : start + 1]
                    cf[: start + 1] = cum_f[i, : start + 1]
                    cnt[0] += 1
                    resume = start
                    # crowding of the current position: the most a move away from the crowd can be credited
                    q_exp = repulsion * abs(cost[i]) if cost[i] < np.inf else 0.0
                    dq_old = _crowding(pos, i, pos[i], ns, d_max, q_exp) if q_exp > 0.0 else 0.0
                    tol = screen_engine if engine else screen
                    if do_screen and tol >= 0.0 and cost[i] < np.inf:
                        # the changed legs only; the rest is sailed when their fuel and time look worth it
                        resume = last + 1
                        if not sail_span_nb(cand, cand_r, start, resume, lat, lon, edge_ok, rpm_options, vp, sc, fc, wx,
                                          times_h, grid, ct, cf, out):
                            break
                        est = cf[resume] - cum_f[i, resume] + lam * (ct[resume] - cum_t[i, resume])
                        if est > tol * cost[i] + dq_old:
                            break
                    if do_plan and cost[i] < np.inf:
                        # re-set the engine on the legs after the move for the estimated arrival, then sail once
                        if resume > start:  # the changed legs were sailed: the rest keeps its hours and fuel
                            t_est = ct[resume] + cum_t[i, L2 - 1] - cum_t[i, resume] - t_dep_h
                            f_est = cf[resume] + cum_f[i, L2 - 1] - cum_f[i, resume]
                            lo_flip = resume
                        else:
                            t_est = cum_t[i, L2 - 1] - t_dep_h
                            f_est = cum_f[i, L2 - 1]
                            for j in range(start, last + 1):
                                if cand_r[j] != rpm[i, j]:
                                    k_r = rpm_options[cand_r[j]] / rpm_options[rpm[i, j]]
                                    t_est += (cum_t[i, j + 1] - cum_t[i, j]) * (1.0 / k_r - 1.0)
                                    f_est += (cum_f[i, j + 1] - cum_f[i, j]) * (k_r * k_r - 1.0)
                            lo_flip = last + 1
                        if plan_flips_nb(cand_r, lo_flip, t_est, f_est, cost[i] + dq_old, cum_t[i], cum_f[i], rpm_options,
                                       t_req_h, obj) < 0:
                            break
                    q = cost_from_nb(cand, cand_r, resume, lat, lon, edge_ok, rpm_options, t_dep_h, max_hours, vp, sc,
                                   fc, wx, times_h, grid, obj, t_req_h, window_h, f_target, early, late, ct, cf)
                    # re-set the engine so the moved route still arrives just inside the RTA
                    q = retime_nb(cand, cand_r, start, q, cost[i] + dq_old, lat, lon, edge_ok, rpm_options, t_dep_h, max_hours, vp,
                                sc, fc, wx, times_h, grid, obj, t_req_h, window_h, f_target, early, late, ct, cf, keep_r,
                                keep_t, keep_f, cnt)
                    if q == np.inf:
                        break
                    # judged on Q(S') + dQ(S') − dQ(S), or on Q alone when S' beats S and every neighbour
                    if not (q < cost[i] and _beats_neighbours(pos, cost, i, cand, q, d_max)):
                        dq_new = _crowding(pos, i, cand, ns, d_max, q_exp) if q_exp > 0.0 else 0.0
                        if not (q + dq_new - dq_old < cost[i]):
                            break
                    pos[i, :] = cand
                    rpm[i, :] = cand_r
                    cum_t[i, :] = ct
                    cum_f[i, :] = cf
                    cost[i] = q
                    improved_any = True
                    if q < best_cost:
                        best_cost = q
                        best_pos[:] = cand
                        best_rpm[:] = cand_r
                if not engine:
                    if improved_any:
                        fails[i] = 0
                    else:
                        fails[i] += 1
                        if fails[i] >= n_fail:
                            fails[i] = 0
                            level[i] = (level[i] + 1) % 3
        order = np.argsort(cost)
        best_i = order[0]
        # reproduction: the worst mature bacteria become copies of the best
        replaced = 0
        for r in range(ns - 1, 0, -1):
            if replaced >= n_repro:
                break
            k = order[r]
            if moves[k] >= to_die and k != best_i:
                pos[k, :] = pos[best_i]
                rpm[k, :] = rpm[best_i]
                cum_t[k, :] = cum_t[best_i]
                cum_f[k, :] = cum_f[best_i]
                cost[k] = cost[best_i]
                moves[k] = 0
                level[k] = 0
                fails[k] = 0
                replaced += 1
        # elimination and dispersal: never the current best
        if (cyc + 1) % ed_every == 0:
            for _d in range(n_disp):
                k = np.random.randint(0, ns)
                if k == best_i:
                    continue
                # walk in scratch space: a failed walk must not leave bacterium k half-overwritten with stale sums
                placed, q = _new_bacterium(cand, cand_r, lat, lon, edge_ok, rpm_options, t_dep_h, max_hours, vp, sc, fc,
                                           wx, times_h, grid, obj, t_req_h, window_h, f_target, early, late, ct, cf,
                                           keep_r, keep_t, keep_f, cnt, max_shift, r_max, k_max, backup, sigma, p_new,
                                           p_step)
                if placed:
                    pos[k, :] = cand
                    rpm[k, :] = cand_r
                    cum_t[k, :] = ct
                    cum_f[k, :] = cf
                    cost[k] = q
                    moves[k] = 0
                    level[k] = 0
                    fails[k] = 0
        history[cyc] = best_cost
    return best_pos, best_rpm, best_cost, history, cnt[0]
