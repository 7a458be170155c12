"""Improved Bacterial Foraging Optimisation (BFOA) over the node graph, numba-compiled.

A bacterium's position is one node per line (lines 1..L; the ports are fixed) plus one engine
setting (index into the allowed rpm list) per leg. Every cycle each bacterium makes `n_chemo`
chemotactic moves:
  tumble   pick a direction vector V: +1 at line k; +1 at k, k+1; +1 at k..k+2; the same with −1;
           or +1 at k1 and −1 at k2 (single-line moves most likely, two-line next, the rest least).
           With probability `p_engine` the vector acts on the engine settings of legs instead.
  swim     S' = S + V·D, repeated while the cost keeps falling (at most `swim_max` times); only
           feasible improvements are accepted.
  step D   adaptive per bacterium: large → medium → small after `n_fail` consecutive failed moves at
           each size, and small → large again to escape local optima.
  repulsion  d(S1, S2) = sqrt(Σ (P1(i) − P2(i))²) over the lines; for neighbours closer than d_max,
           dQ(S) = Σ Q_exp·(1 − d_k/d_max) with Q_exp = repulsion × |Q(S)|. A move is judged on
           Q(S') + dQ(S') − dQ(S) (crowding is penalised, so bacteria spread), unless S' beats S
           and every neighbour, when dQ = 0.
After the moves: sort by cost; reproduction replaces the `n_repro` worst *mature* bacteria
(≥ `steps_to_die` moves) with copies of the best; every `ed_every` cycles elimination/dispersal
re-initialises `n_disperse` random bacteria, never the current best. Random initialisation walks
line by line choosing safe nodes (R_max tries per node, K_max overall, backing up `backup` lines
on failure). Bacterium 0 starts on the baseline route so the result is never worse than it.

Everything random comes from numba's generator seeded with `seed`: same seed, same plan.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from pipeline.routing.leg_kernel import OK, sail_route_nb
from pipeline.routing.objectives import route_cost_nb


@dataclass(frozen=True)
class BfoaParams:
    n_bacteria: int = 16
    n_chemo: int = 12
    n_cycles: int = 40
    n_repro: int = 4
    n_disperse: int = 2
    ed_every: int = 6
    n_fail: int = 3
    steps_to_die: int = 16
    swim_max: int = 6
    r_max: int = 12
    k_max: int = 4000
    backup: int = 2
    p_engine: float = 0.3
    repulsion: float = 0.002
    d_max: float | None = None  # None: 0.5·sqrt(L) + 1

    def arrays(self, n_lines: int) -> tuple[np.ndarray, np.ndarray]:
        ip = np.array([self.n_bacteria, self.n_chemo, self.n_cycles, self.n_repro, self.n_disperse, self.ed_every,
                       self.n_fail, self.steps_to_die, self.swim_max, self.r_max, self.k_max, self.backup], dtype=np.int64)
        d_max = self.d_max if self.d_max is not None else 0.5 * np.sqrt(n_lines) + 1.0
        fp = np.array([self.p_engine, self.repulsion, d_max], dtype=np.float64)
        return ip, fp


@numba.njit(cache=True)
def _cost_from(nodes, rpm_idx, start, inst_lat, inst_lon, edge_ok, rpm_options, t_dep_h, max_hours, vp, sc, fc, wx,
               times_h, grid, obj, t_req_h, window_h, f_target, early, late, cum_t, cum_f):
    code, _ = sail_route_nb(nodes, rpm_idx, start, inst_lat, inst_lon, edge_ok, rpm_options, t_dep_h, max_hours, vp, sc,
                            fc, wx, times_h, grid, cum_t, cum_f)
    if code != OK:
        return np.inf
    n = nodes.shape[0] - 1
    return route_cost_nb(obj, cum_t[n] - t_dep_h, cum_f[n], t_req_h, window_h, f_target, early, late)


@numba.njit(cache=True)
def _random_init(nodes, rpm_idx, edge_ok, n_rpm, max_shift, r_max, k_max, backup):
    L2 = nodes.shape[0]
    P = edge_ok.shape[1]
    c = P // 2
    L = L2 - 2
    nodes[0] = c
    nodes[L2 - 1] = c
    i, tries = 1, 0
    while i <= L:
        a = nodes[i - 1]
        left = L + 1 - i  # legs still to go after line i
        lo = max(0, a - max_shift, c - max_shift * left)
        hi = min(P - 1, a + max_shift, c + max_shift * left)
        placed = False
        if lo <= hi:
            for _ in range(r_max):
                b = np.random.randint(lo, hi + 1)
                if edge_ok[i - 1, a, b] and (i < L or edge_ok[L, b, c]):
                    nodes[i] = b
                    placed = True
                    break
        tries += 1
        if placed:
            i += 1
        else:
            i = max(1, i - backup)
        if tries > k_max:
            return False
    r0 = np.random.randint(0, n_rpm)
    for j in range(rpm_idx.shape[0]):
        rpm_idx[j] = r0 if np.random.random() < 0.8 else np.random.randint(0, n_rpm)
    return True


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
def _tumble(L, n_legs, p_engine, vec, on_engine):
    """Fill vec (length L+2 for nodes or L+1 for legs) with a direction; return (first changed index, engine?)."""
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
    k = base + np.random.randint(0, n)
    top = base + n - 1
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
    L2, P = lat.shape
    L = L2 - 2
    n_rpm = rpm_options.shape[0]
    steps = np.array([max(3, min(max_shift, P // 8)), 2, 1])
    pos = np.empty((ns, L2), np.int64)
    rpm = np.empty((ns, L2 - 1), np.int64)
    cum_t = np.empty((ns, L2))
    cum_f = np.empty((ns, L2))
    cost = np.empty(ns)
    moves = np.zeros(ns, np.int64)
    level = np.zeros(ns, np.int64)
    fails = np.zeros(ns, np.int64)
    history = np.empty(n_cycles)
    n_evals = 0
    for i in range(ns):
        if i == 0:
            pos[0, :] = base_nodes
            rpm[0, :] = base_rpm
        else:
            if not _random_init(pos[i], rpm[i], edge_ok, n_rpm, max_shift, r_max, k_max, backup):
                pos[i, :] = base_nodes
                rpm[i, :] = base_rpm
        cost[i] = _cost_from(pos[i], rpm[i], 0, lat, lon, edge_ok, rpm_options, t_dep_h, max_hours, vp, sc, fc, wx,
                             times_h, grid, obj, t_req_h, window_h, f_target, early, late, cum_t[i], cum_f[i])
        n_evals += 1
    cand = np.empty(L2, np.int64)
    cand_r = np.empty(L2 - 1, np.int64)
    vec = np.empty(L2, np.int64)
    vec_r = np.empty(L2 - 1, np.int64)
    ct = np.empty(L2)
    cf = np.empty(L2)
    on_engine = np.zeros(1, np.bool_)
    best_pos = pos[0].copy()
    best_rpm = rpm[0].copy()
    best_cost = cost[0]
    for i in range(ns):
        if cost[i] < best_cost:
            best_cost = cost[i]
            best_pos[:] = pos[i]
            best_rpm[:] = rpm[i]
    for cyc in range(n_cycles):
        for i in range(ns):
            for _m in range(n_chemo):
                moves[i] += 1
                first = _tumble(L, L2 - 1, p_engine, vec, on_engine)
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
                    if engine:
                        for j in range(L2 - 1):
                            if vec_r[j] != 0:
                                v = cand_r[j] + vec_r[j] * d
                                if v < 0 or v >= n_rpm:
                                    valid = False
                                    break
                                cand_r[j] = v
                        start = first
                    else:
                        for j in range(1, L2 - 1):
                            if vec[j] != 0:
                                v = cand[j] + vec[j] * d
                                if v < 0 or v >= P:
                                    valid = False
                                    break
                                cand[j] = v
                        start = first - 1
                    if not valid:
                        break
                    if cost[i] == np.inf:
                        start = 0  # the sums of an infeasible route are only valid up to where it failed
                    ct[: start + 1] = cum_t[i, : start + 1]
                    cf[: start + 1] = cum_f[i, : start + 1]
                    q = _cost_from(cand, cand_r, start, lat, lon, edge_ok, rpm_options, t_dep_h, max_hours, vp, sc,
                                   fc, wx, times_h, grid, obj, t_req_h, window_h, f_target, early, late, ct, cf)
                    n_evals += 1
                    if not (q < cost[i]):
                        break
                    if repulsion > 0.0 and not _beats_neighbours(pos, cost, i, cand, q, d_max):
                        q_exp = repulsion * abs(cost[i])
                        dq_new = _crowding(pos, i, cand, ns, d_max, q_exp)
                        dq_old = _crowding(pos, i, pos[i], ns, d_max, q_exp)
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
                if _random_init(cand, cand_r, edge_ok, n_rpm, max_shift, r_max, k_max, backup):
                    pos[k, :] = cand
                    rpm[k, :] = cand_r
                    cost[k] = _cost_from(pos[k], rpm[k], 0, lat, lon, edge_ok, rpm_options, t_dep_h, max_hours, vp, sc,
                                         fc, wx, times_h, grid, obj, t_req_h, window_h, f_target, early, late, cum_t[k],
                                         cum_f[k])
                    n_evals += 1
                    moves[k] = 0
                    level[k] = 0
                    fails[k] = 0
        history[cyc] = best_cost
    return best_pos, best_rpm, best_cost, history, n_evals
