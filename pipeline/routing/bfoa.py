"""Improved Bacterial Foraging Optimisation (BFOA) over the node graph: the default search (`--solver bfoa`).

A bacterium is a route (one node per line; the ports fixed) and an engine setting per leg. Every cycle each makes
chemotactic moves (tumble, swim while the cost falls, the engine re-set for the RTA, adaptive step, repulsion between
neighbours); then reproduction, and elimination/dispersal every few cycles. The swarm starts on the baseline route, on
offset routes across the graph, on the fastest routes round either side (branch_routes.py) and on random detours, and
stops after `stall_cycles` cycles without gain. Its best plan is then polished by the label DP in a corridor of
±`polish_width` nodes round it (`polish`), again while a round gains. Same seed, same plan (one numpy generator,
PCG64, passed to every kernel that draws).

This module is the strategy: the settings (`BfoaParams`), the run and the polish. The swarm is compiled in
engine/swarm.py, the DP in engine/label_search.py. Every move, its probabilities and why each addition to the thesis's
method is there: docs/search-methods.md, "The default search".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.routing.branch_routes import branch_routes
from pipeline.routing.engine.timing import scratch, time_price_nb
from pipeline.routing.engine.bounds import FinishBounds
from pipeline.routing.engine.label_search import dp_exact_nb
from pipeline.routing.engine.labels import bucketed
from pipeline.routing.engine.swarm import Knobs, SwarmRun, bfoa_nb, swarm, work
from pipeline.routing.engine.leg import Voyage, sail_route_nb
from pipeline.routing.objectives import OBJ_JIT


@dataclass(frozen=True)
class BfoaParams:
    n_bacteria: int = 40
    n_chemo: int = 10
    n_cycles: int = 20
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
    polish_width: int = 1  # the best plan is polished by the DP in a corridor of ± this many nodes (−1: not)
    polish_gap: float = 0.002  # the polish's ε-trimming of its labels, as a share of the plan's cost
    polish_window_h: float = 4.0  # the polish keeps partial plans within this many hours of the plan's
    polish_fuel: float = 0.02  # and within this share of its cost in fuel so far
    polish_rounds: int = 6  # polish the polished plan again while a round gains more than stall_tol × cost
    polish_buckets: int = 16  # > 0: the polish keeps at most this many labels per node (time spans of the line; ×4 thesis)
    p_block: float = 0.15  # chance a route tumble shifts a whole block of lines (a plateau of the route)
    offset_routes: int = 8  # bacteria that start on offset routes spread evenly over the graph's width
    branch_routes: bool = True  # the last bacteria start on the fastest routes round either side (branch_routes.py)
    stall_cycles: int = 2  # stop after this many cycles without a gain of stall_tol × cost (0: never)
    stall_tol: float = 1e-4

    def knobs(self, n_lines: int, n_points: int, max_shift: int) -> Knobs:
        """The settings for a graph of `n_lines` lines (ports excluded) × `n_points` nodes."""
        d_max = self.d_max if self.d_max is not None else 0.5 * np.sqrt(n_lines) + 1.0
        return Knobs(int(self.n_bacteria), int(self.n_chemo), int(self.n_cycles), int(self.n_repro),
                     int(self.n_disperse), int(self.ed_every), int(self.n_fail), int(self.steps_to_die),
                     int(self.swim_max), int(self.r_max), int(self.k_max), int(self.backup), float(self.p_engine),
                     float(self.repulsion), float(d_max), max(2.0, float(self.walk_spread) * n_points),
                     float(self.walk_turns / max(n_lines, 1)), float(self.walk_slope), float(self.screen),
                     float(self.screen_engine), bool(self.plan_engine), float(self.p_bend),
                     int(max(3, min(max_shift, int(n_points * self.d_large)))), float(self.p_block),
                     int(min(self.offset_routes, self.n_bacteria - 1, n_points)), int(self.stall_cycles),
                     float(self.stall_tol))


def run_bfoa(seed: int, params: BfoaParams, base_nodes, base_rpm, g, v, w, o):
    """(best nodes, best rpm indexes, best cost, history of the best cost per cycle, routes sailed)."""
    n = g.lat.shape[0]
    k = params.knobs(n - 2, g.lat.shape[1], g.max_shift)
    sw, s, wk = swarm(k.n_bacteria, n), scratch(n), work(n)
    history = np.empty(k.n_cycles)
    rng = np.random.default_rng(int(seed))
    base_rpm = np.asarray(base_rpm, np.int64)
    branches, n_legs = np.empty((0, n), np.int64), 0
    if params.branch_routes and base_rpm.shape[0] > 0 and k.n_bacteria - 1 - k.n_offset > 0:  # room for them
        branches, n_legs = branch_routes(g, v, w, o, int(base_rpm[0]))  # at the baseline's constant rpm
    run = SwarmRun(Voyage(g, v, w, o), s, k, wk)
    n_evals, n_run = bfoa_nb(rng, run, np.asarray(base_nodes, np.int64), base_rpm, branches, sw, history)
    n_evals += n_legs // max(n - 1, 1)  # legs sailed, counted as whole routes
    history = history[:n_run]
    nodes, rpm_idx, cost = sw.best_pos, sw.best_rpm, float(sw.best_cost[0])
    for _round in range(params.polish_rounds if params.polish_width >= 0 and np.isfinite(cost) else 0):
        before = cost
        nodes, rpm_idx, cost, n_legs = polish(nodes, rpm_idx, cost, params, g, v, w, o)
        n_evals += n_legs // max(n - 1, 1)  # legs sailed, counted as whole routes
        if not cost < before - params.stall_tol * abs(before):
            break
    return nodes, rpm_idx, cost, history, int(n_evals)


def polish(nodes, rpm_idx, cost: float, params: BfoaParams, g, v, w, o):
    """(nodes, rpm indexes, cost, legs sailed): the best plan the DP finds near this one, or this one.

    Near: routes inside the corridor of ±`polish_width` nodes around it, every engine setting per leg, and
    partial plans that stay within `polish_window_h` hours of it and burn at most `polish_fuel` × cost more
    fuel than it at each line (a heuristic window, which keeps the DP's labels few; only the dominance and the
    ε-trimming of `polish_gap` × cost act inside it)."""
    L2, P = g.lat.shape
    inside = np.zeros((L2, P), np.bool_)
    for i in range(L2):
        inside[i, max(0, nodes[i] - params.polish_width):min(P, nodes[i] + params.polish_width + 1)] = True
    corridor = g._replace(edge_ok=g.edge_ok & inside[:-1, :, None] & inside[1:, None, :])
    cum_t, cum_f = np.empty(L2), np.empty(L2)
    sail_route_nb(np.asarray(nodes, np.int64), np.asarray(rpm_idx, np.int64), 0, g, v, w, o, cum_t, cum_f)
    # the window as the DP's bound tables: no later than the plan + window at each line (the DP applies it as
    # the latest departure when the plan is on time), and fuel so far ≤ the plan's + slack (as a fuel-to-finish
    # bound at price 0 that prices a label out above the plan's cost)
    slack_t = params.polish_fuel * cost if o.kind == OBJ_JIT else params.polish_fuel * cost * o.f_target / 3.0
    latest = np.repeat((cum_t + params.polish_window_h)[:, None], P, axis=1)
    to_finish = np.maximum(cum_f[-1] - cum_f - slack_t, 0.0)
    m_lam = np.repeat(to_finish[None, :, None], P, axis=2)
    no_rate = np.zeros((L2, P, 2 * g.max_shift + 1, v.rpm_options.shape[0]))
    eps = params.polish_gap * cost / (L2 - 1) * (1.0 if o.kind == OBJ_JIT else o.f_target / 3.0)
    lam_t = (time_price_nb(np.asarray(rpm_idx, np.int64), cum_t, cum_f, v.rpm_options)
             if params.polish_buckets > 0 and o.kind == OBJ_JIT else 0.0)
    # thesis: a span keeps its label of least fuel, time unpriced, so it needs spans four times finer to keep the
    # label that wins on T/T_req (with 16 the suite's storm-limit stalled 0.58 % above the optimum, with 64 at it)
    buckets = params.polish_buckets * (1 if o.kind == OBJ_JIT else 4)
    bounds = FinishBounds(np.zeros(1), m_lam, np.zeros((L2, P)), no_rate, no_rate, latest)
    new_nodes, new_rpm, new_cost, n_legs, _ = dp_exact_nb(corridor, v, w, o, cost, bounds, eps,
                                                          bucketed(buckets, lam_t))
    if np.isfinite(new_cost) and new_cost < cost:
        return new_nodes, new_rpm, float(new_cost), int(n_legs)
    return nodes, rpm_idx, cost, int(n_legs)
