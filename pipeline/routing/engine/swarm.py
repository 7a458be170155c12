"""The swarm of the improved BFOA (compiled): bacteria that are routes with an engine setting per leg, their
chemotaxis (tumbles of route blocks, bends and engine settings, swims while a move pays), reproduction and
elimination–dispersal, and the best plan met. The algorithm, its parameters and what each step is for:
docs/search-methods.md, "The default search"; pipeline/routing/bfoa.py is the strategy that runs the swarm and then
polishes its best plan.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from pipeline.routing.engine.leg import Voyage
from pipeline.routing.engine.timing import (aim_engine_nb, cost_from_nb, plan_flips_nb, retime_nb, sail_span_nb,
                                            time_price_nb)
from pipeline.routing.objectives import OBJ_JIT
from pipeline.routing.engine.random_walk import Walk, random_walk_nb


class Knobs(NamedTuple):
    """`BfoaParams` as the kernel sees them, with the values that depend on the graph worked out."""

    n_bacteria: int
    n_chemo: int
    n_cycles: int
    n_repro: int
    n_disperse: int
    ed_every: int
    n_fail: int
    steps_to_die: int
    swim_max: int
    r_max: int
    k_max: int
    backup: int
    p_engine: float
    repulsion: float
    d_max: float
    sigma: float  # random routes: s.d. of a detour's target offset, in nodes
    p_new: float  # random routes: chance per line of a new target offset
    p_step: float  # random routes: chance per line of a step towards the target
    screen: float
    screen_engine: float
    plan_engine: bool
    p_bend: float
    step_large: int  # the large swim length in nodes (medium 2, small 1)
    p_block: float
    n_offset: int  # bacteria 1..n_offset start on offset routes spread over the graph's width
    stall: int  # stop after this many cycles without a gain of stall_tol × cost (0: run every cycle)
    stall_tol: float


class Swarm(NamedTuple):
    """The bacteria (Ns of them over L+2 lines) and the best plan met so far."""

    pos: np.ndarray  # (Ns, L+2) int64 node per line
    rpm: np.ndarray  # (Ns, L+1) int64 engine setting per leg
    cum_t: np.ndarray  # (Ns, L+2) hours after t_ref on reaching each line
    cum_f: np.ndarray  # (Ns, L+2) fuel so far on reaching each line
    cost: np.ndarray  # (Ns,)
    moves: np.ndarray  # (Ns,) int64 chemotactic moves since birth
    level: np.ndarray  # (Ns,) int64 swim length: 0 large, 1 medium, 2 small
    fails: np.ndarray  # (Ns,) int64 consecutive failed route moves at this length
    best_pos: np.ndarray  # (L+2,) int64
    best_rpm: np.ndarray  # (L+1,) int64
    best_cost: np.ndarray  # (1,)


class Work(NamedTuple):
    """A move's candidate position and direction vectors."""

    cand: np.ndarray  # (L+2,) int64
    cand_r: np.ndarray  # (L+1,) int64
    vec: np.ndarray  # (L+2,) int64
    vec_r: np.ndarray  # (L+1,) int64
    on_engine: np.ndarray  # (1,) bool: the tumble acts on engine settings


class SwarmRun(NamedTuple):
    """What the swarm's kernels read: the voyage (engine.leg.Voyage: graph, vessel, weather, objective), the sailing
    scratch (engine.timing.scratch), the knobs and the work arrays of a move."""

    vy: Voyage
    s: object
    k: Knobs
    wk: Work


class Screening(NamedTuple):
    """How a swim judges a move before sailing it whole: `on`, its changed legs first, time priced at `lam` (t/h,
    what the engine re-set would pay); `plan`, the engine re-set for the move's estimated arrival first."""

    lam: float
    on: bool
    plan: bool


def swarm(n_bacteria: int, n_lines_total: int) -> Swarm:
    ns, n = n_bacteria, n_lines_total
    return Swarm(np.empty((ns, n), np.int64), np.empty((ns, n - 1), np.int64), np.empty((ns, n)), np.empty((ns, n)),
                 np.empty(ns), np.zeros(ns, np.int64), np.zeros(ns, np.int64), np.zeros(ns, np.int64),
                 np.empty(n, np.int64), np.empty(n - 1, np.int64), np.full(1, np.inf))


def work(n_lines_total: int) -> Work:
    n = n_lines_total
    return Work(np.empty(n, np.int64), np.empty(n - 1, np.int64), np.empty(n, np.int64), np.empty(n - 1, np.int64),
                np.zeros(1, np.bool_))


@numba.njit(cache=True)
def _new_bacterium(nodes, rpm_idx, run, rng):
    """A random bacterium: a safe random walk with engine settings aimed at the RTA. A route that cannot be
    sailed (weather limits on the way) is drawn again with twice the spread, up to 4 draws. (placed?, cost)"""
    vy, s, k = run.vy, run.s, run.k
    g = vy.g
    q = np.inf
    for attempt in range(4):
        if not random_walk_nb(nodes, g.edge_ok, g.max_shift,
                              Walk(k.r_max, k.k_max, k.backup, k.sigma * 2.0 ** attempt, k.p_new, k.p_step), 0, rng):
            return False, np.inf
        q = aim_engine_nb(vy, nodes, rpm_idx, s, rng)
        if q < np.inf:
            break
    return True, q


@numba.njit(cache=True)
def _offset_bacterium(j, nodes, rpm_idx, run, rng):
    """Offset route j of k.n_offset (offsets spread evenly from one side of the graph to the other): out one node
    a line, along the offset, back in time; engine settings aimed at the RTA. A random bacterium when it cannot
    be walked or sailed. (placed?, cost)"""
    g, s, k = run.vy.g, run.s, run.k
    c = g.lat.shape[1] // 2
    offset = int(np.round(-c + 2.0 * c * j / max(k.n_offset - 1, 1)))
    if random_walk_nb(nodes, g.edge_ok, g.max_shift, Walk(k.r_max, k.k_max, k.backup, 0.0, 0.0, 1.0), offset, rng):
        q = aim_engine_nb(run.vy, nodes, rpm_idx, s, rng)
        if q < np.inf:
            return True, q
    return _new_bacterium(nodes, rpm_idx, run, rng)


@numba.njit(cache=True, inline="always")
def _distance(cand, pos, k):
    """d(S1, S2) of the route `cand` and bacterium k's: sqrt(Σ (P1(i) − P2(i))²) over the lines (ports excluded)."""
    d2 = 0.0
    for j in range(1, cand.shape[0] - 1):
        e = cand[j] - pos[k, j]
        d2 += e * e
    return np.sqrt(d2)


@numba.njit(cache=True)
def _crowding(pos, i, cand, n_alive, d_max, q_exp):
    """dQ of `cand` (positions of bacterium i excluded) and the neighbour indices' count."""
    dq = 0.0
    for k in range(n_alive):
        if k == i:
            continue
        d = _distance(cand, pos, k)
        if d < d_max:
            dq += q_exp * (1.0 - d / d_max)
    return dq


@numba.njit(cache=True)
def _beats_neighbours(pos, cost, i, cand, q_cand, d_max):
    for k in range(pos.shape[0]):
        if k == i:
            continue
        if _distance(cand, pos, k) < d_max and q_cand >= cost[k]:
            return False
    return True


@numba.njit(cache=True)
def _bend(x, base, top, rng):
    """A random index in base..top where x changes next to it (a bend of the route or of the engine plan); -1 if none."""
    m = 0
    for j in range(base, top + 1):
        if (j > 0 and x[j] != x[j - 1]) or (j + 1 < x.shape[0] and x[j] != x[j + 1]):
            m += 1
    if m == 0:
        return -1
    r = rng.integers(0, m)
    for j in range(base, top + 1):
        if (j > 0 and x[j] != x[j - 1]) or (j + 1 < x.shape[0] and x[j] != x[j + 1]):
            if r == 0:
                return j
            r -= 1
    return -1


@numba.njit(cache=True)
def _block(L, nodes, vec, rng):
    """A block shift: +1 or −1 on every line of the plateau (lines on one node) around a random line, or, when
    that plateau is shorter than 4 lines, on 4..L/2 lines from it. Returns the first line of the block."""
    k = 1 + rng.integers(0, L)
    lo, hi = k, k
    while lo > 1 and nodes[lo - 1] == nodes[k]:
        lo -= 1
    while hi < L and nodes[hi + 1] == nodes[k]:
        hi += 1
    if hi - lo < 3:
        lo, hi = k, min(L, k + 3 + rng.integers(0, max(1, L // 2 - 3)))
    sign = 1 if rng.random() < 0.5 else -1
    for j in range(lo, hi + 1):
        vec[j] = sign
    return lo


@numba.njit(cache=True)
def _tumble(kn, L, n_legs, nodes, rpm_idx, wk, rng):
    """Fill wk.vec (length L+2 for nodes or L+1 for legs) with a direction; return the first changed index (engine? in
    wk.on_engine). With probability kn.p_bend the vector is placed at a bend (a line where the route, or a leg where
    the engine plan, changes): there a move shifts the bend instead of adding two."""
    p_engine, p_bend, p_block, vec, on_engine = kn.p_engine, kn.p_bend, kn.p_block, wk.vec, wk.on_engine
    for j in range(vec.shape[0]):
        vec[j] = 0
    engine = rng.random() < p_engine
    on_engine[0] = engine
    if not engine and rng.random() < p_block:
        return _block(L, nodes, vec, rng)
    if engine:
        n = n_legs
        base = 0
    else:
        n = L
        base = 1
    u = rng.random()
    sign = 1 if rng.random() < 0.5 else -1
    top = base + n - 1
    k = -1
    if rng.random() < p_bend:
        k = _bend(rpm_idx if engine else nodes, base, top, rng)
        if k >= 0 and u >= 0.5 and u < 0.92 and rng.random() < 0.5:
            k = max(base, k - (1 if u < 0.8 else 2))  # a block ending at the bend rather than starting there
    if k < 0:
        k = base + rng.integers(0, n)
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
        k2 = base + rng.integers(0, n)
        if k2 == k:
            k2 = base + (k - base + 1) % n
        vec[k] = 1
        vec[k2] = -1
        first = min(k, k2)
    return first


@numba.njit(cache=True)
def _adopt(sw, i, cand, cand_r, ct, cf, q):
    sw.pos[i, :] = cand
    sw.rpm[i, :] = cand_r
    sw.cum_t[i, :] = ct
    sw.cum_f[i, :] = cf
    sw.cost[i] = q


@numba.njit(cache=True)
def init_swarm_nb(sw, base_nodes, base_rpm, branches, run, rng):
    """Initial bacteria: bacterium 0 (and any whose walk fails) starts on the baseline route, with its constant rpm
    or engine settings aimed at the RTA, whichever is cheaper; bacteria 1..n_offset on the offset routes; the last
    ones on the routes in `branches` (one per row, engine settings aimed at the RTA); the rest random. Returns the
    best one's index."""
    vy, s, k = run.vy, run.s, run.k
    cand, cand_r = run.wk.cand, run.wk.cand_r
    q = np.inf
    n_branch = min(branches.shape[0], k.n_bacteria - 1 - k.n_offset)
    for i in range(k.n_bacteria):
        placed = False
        if i >= k.n_bacteria - n_branch:
            cand[:] = branches[k.n_bacteria - 1 - i]
            q = aim_engine_nb(vy, cand, cand_r, s, rng)
            placed = q < np.inf
        elif 0 < i <= k.n_offset:
            placed, q = _offset_bacterium(i - 1, cand, cand_r, run, rng)
        elif i > 0:
            placed, q = _new_bacterium(cand, cand_r, run, rng)
        if not placed:
            sw.pos[i, :] = base_nodes
            sw.rpm[i, :] = base_rpm
            sw.cost[i] = cost_from_nb(vy, sw.pos[i], sw.rpm[i], 0, sw.cum_t[i], sw.cum_f[i])
            s.cnt[0] += 1
            cand[:] = base_nodes
            q = aim_engine_nb(vy, cand, cand_r, s, rng)
        if placed or q < sw.cost[i]:
            _adopt(sw, i, cand, cand_r, s.ct, s.cf, q)
    sw.best_pos[:] = sw.pos[0]
    sw.best_rpm[:] = sw.rpm[0]
    sw.best_cost[0] = sw.cost[0]
    best_i = 0
    for i in range(k.n_bacteria):
        if sw.cost[i] < sw.best_cost[0]:
            sw.best_cost[0] = sw.cost[i]
            sw.best_pos[:] = sw.pos[i]
            sw.best_rpm[:] = sw.rpm[i]
            best_i = i
    return best_i


@numba.njit(cache=True, inline="always")
def _shift(cand, vec, lo, hi, d, top, last):
    """A swim step: cand[j] += vec[j]·d for j in lo..hi − 1 where vec[j] ≠ 0 (nodes or engine settings). Returns
    (False, last) when a shifted value would leave 0..top − 1 (the step is not taken), else (True, the last index
    shifted, or `last` when none)."""
    for j in range(lo, hi):
        if vec[j] != 0:
            x = cand[j] + vec[j] * d
            if x < 0 or x >= top:
                return False, last
            cand[j] = x
            last = j
    return True, last


@numba.njit(cache=True)
def swim_nb(sw, i, first, engine, d, screen, run, rng):
    """Swim bacterium i along the tumbled direction (wk.vec, or wk.vec_r for engine moves) in steps of `d`, while
    the judged cost keeps falling (at most `swim_max` steps), each move judged as `screen` (Screening) says. Returns
    True when at least one step was taken."""
    vy, s, k, wk = run.vy, run.s, run.k, run.wk
    g, v, o = vy.g, vy.v, vy.o
    lam, do_screen, do_plan = screen.lam, screen.on, screen.plan
    pos, rpm, cum_t, cum_f, cost = sw.pos, sw.rpm, sw.cum_t, sw.cum_f, sw.cost
    cand, cand_r, vec, vec_r = wk.cand, wk.cand_r, wk.vec, wk.vec_r
    ct, cf = s.ct, s.cf
    L2, P = g.lat.shape
    n_rpm = v.rpm_options.shape[0]
    t_dep_h = o.t_dep_h
    ns = k.n_bacteria
    improved_any = False
    for _s in range(k.swim_max):
        cand[:] = pos[i]
        cand_r[:] = rpm[i]
        if engine:
            valid, last = _shift(cand_r, vec_r, 0, L2 - 1, d, n_rpm, first)
            start = first
        else:
            valid, last = _shift(cand, vec, 1, L2 - 1, d, P, first)
            start = first - 1
        if not valid:
            break
        if cost[i] == np.inf:
            start = 0  # the sums of an infeasible route are only valid up to where it failed
        ct[: start + 1] = cum_t[i, : start + 1]
        cf[: start + 1] = cum_f[i, : start + 1]
        s.cnt[0] += 1
        resume = start
        # crowding of the current position: the most a move away from the crowd can be credited
        q_exp = k.repulsion * abs(cost[i]) if cost[i] < np.inf else 0.0
        dq_old = _crowding(pos, i, pos[i], ns, k.d_max, q_exp) if q_exp > 0.0 else 0.0
        tol = k.screen_engine if engine else k.screen
        if do_screen and tol >= 0.0 and cost[i] < np.inf:
            # the changed legs only; the rest is sailed when their fuel and time look worth it
            resume = last + 1
            if not sail_span_nb(vy, cand, cand_r, start, resume, ct, cf, s.out):
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
                        k_r = v.rpm_options[cand_r[j]] / v.rpm_options[rpm[i, j]]
                        t_est += (cum_t[i, j + 1] - cum_t[i, j]) * (1.0 / k_r - 1.0)
                        f_est += (cum_f[i, j + 1] - cum_f[i, j]) * (k_r * k_r - 1.0)
                lo_flip = last + 1
            if plan_flips_nb(cand_r, lo_flip, (t_est, f_est), cost[i] + dq_old, (cum_t[i], cum_f[i]), v.rpm_options,
                             o, rng) < 0:
                break
        q = cost_from_nb(vy, cand, cand_r, resume, ct, cf)
        # re-set the engine so the moved route still arrives just inside the RTA
        q = retime_nb(vy, cand, cand_r, start, q, cost[i] + dq_old, s, rng)
        if q == np.inf:
            break
        # judged on Q(S') + dQ(S') − dQ(S), or on Q alone when S' beats S and every neighbour
        if not (q < cost[i] and _beats_neighbours(pos, cost, i, cand, q, k.d_max)):
            dq_new = _crowding(pos, i, cand, ns, k.d_max, q_exp) if q_exp > 0.0 else 0.0
            if not (q + dq_new - dq_old < cost[i]):
                break
        _adopt(sw, i, cand, cand_r, ct, cf, q)
        improved_any = True
        if q < sw.best_cost[0]:
            sw.best_cost[0] = q
            sw.best_pos[:] = cand
            sw.best_rpm[:] = cand_r
    return improved_any


@numba.njit(cache=True)
def chemotaxis_nb(sw, i, screen, run, rng):
    """Bacterium i's `n_chemo` chemotactic moves: tumble, swim; the swim length adapts after `n_fail` failed route
    moves at each size (large → medium → small → large)."""
    k, wk = run.k, run.wk
    L2 = run.vy.g.lat.shape[0]
    for _m in range(k.n_chemo):
        sw.moves[i] += 1
        first = _tumble(k, L2 - 2, L2 - 1, sw.pos[i], sw.rpm[i], wk, rng)
        engine = wk.on_engine[0]
        if engine:
            for j in range(L2 - 1):
                wk.vec_r[j] = wk.vec[j]
        if engine:
            d = 1
        elif sw.level[i] == 0:
            d = k.step_large
        else:
            d = 3 - sw.level[i]
        improved_any = swim_nb(sw, i, first, engine, d, screen, run, rng)
        if not engine:
            if improved_any:
                sw.fails[i] = 0
            else:
                sw.fails[i] += 1
                if sw.fails[i] >= k.n_fail:
                    sw.fails[i] = 0
                    sw.level[i] = (sw.level[i] + 1) % 3


@numba.njit(cache=True)
def _reborn(sw, i):
    sw.moves[i] = 0
    sw.level[i] = 0
    sw.fails[i] = 0


@numba.njit(cache=True)
def reproduce_nb(sw, order, k):
    """The `n_repro` worst mature bacteria (≥ steps_to_die moves) become copies of the best (order[0])."""
    best_i = order[0]
    replaced = 0
    for r in range(k.n_bacteria - 1, 0, -1):
        if replaced >= k.n_repro:
            break
        j = order[r]
        if sw.moves[j] >= k.steps_to_die and j != best_i:
            _adopt(sw, j, sw.pos[best_i], sw.rpm[best_i], sw.cum_t[best_i], sw.cum_f[best_i], sw.cost[best_i])
            _reborn(sw, j)
            replaced += 1


@numba.njit(cache=True)
def disperse_nb(sw, best_i, run, rng):
    """Elimination and dispersal: `n_disperse` random bacteria, never the current best, start again at random."""
    k, wk = run.k, run.wk
    for _d in range(k.n_disperse):
        j = rng.integers(0, k.n_bacteria)
        if j == best_i:
            continue
        # walk in scratch space: a failed walk must not leave bacterium j half-overwritten with stale sums
        placed, q = _new_bacterium(wk.cand, wk.cand_r, run, rng)
        if placed:
            _adopt(sw, j, wk.cand, wk.cand_r, run.s.ct, run.s.cf, q)
            _reborn(sw, j)


@numba.njit(cache=True)
def bfoa_nb(rng, run, base_nodes, base_rpm, branches, sw, history):
    """Run the improved BFOA (`run`: SwarmRun) drawing from the generator `rng`, some bacteria starting on the routes
    in `branches`; the best plan ends in sw.best_pos / best_rpm / best_cost, the best cost after each cycle in
    `history`. Stops early after `stall` cycles that lower the best cost by no more than `stall_tol` of it. Returns
    (routes or route tails sailed, cycles run)."""
    k, v, o = run.k, run.vy.v, run.vy.o
    best_i = init_swarm_nb(sw, base_nodes, base_rpm, branches, run, rng)
    # route moves are first judged on the legs they change, time priced at what the engine re-set would pay
    lam = (time_price_nb(sw.rpm[best_i], sw.cum_t[best_i], sw.cum_f[best_i], v.rpm_options)
           if sw.best_cost[0] < np.inf else 0.0)
    do_screen = o.kind == OBJ_JIT and lam > 0.0
    do_plan = k.plan_engine and v.rpm_options.shape[0] > 1
    screen = Screening(lam, do_screen, do_plan)
    ref, last_gain, n_run = sw.best_cost[0], 0, 0
    for cyc in range(k.n_cycles):
        for i in range(k.n_bacteria):
            chemotaxis_nb(sw, i, screen, run, rng)
        order = np.argsort(sw.cost)
        reproduce_nb(sw, order, k)
        if (cyc + 1) % k.ed_every == 0:
            disperse_nb(sw, order[0], run, rng)
        history[cyc] = sw.best_cost[0]
        n_run = cyc + 1
        if sw.best_cost[0] < ref - k.stall_tol * abs(ref) or (ref == np.inf and sw.best_cost[0] < np.inf):
            ref, last_gain = sw.best_cost[0], n_run
        elif k.stall > 0 and ref < np.inf and n_run - last_gain >= k.stall:
            break
    return run.s.cnt[0], n_run
