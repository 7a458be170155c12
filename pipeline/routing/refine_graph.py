"""A finer graph around a route: the same lines, with nodes at a fraction of the spacing in a corridor round it.

The solvers search a graph of lines across the voyage, each with its nodes d NM apart. Between two nodes lies water
no route of the graph can use, and a search with finer isochrones can find a cheaper passage there. `corridor_space`
lays, on every line of a search space, 2·width + 1 nodes centred on a route's node at 1/`split` of the line's
spacing: the line's own nodes within width/split of the route's, and the points between them on the great circle
from one node to the next. The corridor keeps everything the coarse graph keeps:
- a node between two usable nodes is usable only when it is at sea, clear of land by the space's rule
  (clearance.py) and within the latitude limits; the ports and a passage's gates keep their one node;
- a leg between two of the coarse graph's own nodes is the coarse graph's leg (usable or not as there); any other is
  usable only when both its nodes are, it shifts at most the coarse graph's widest shift (in the finer spacing, split
  times as many nodes), it keeps the clearance from land, and it crosses no limit line;
- with `max_drift`, a leg moves at most that many fine steps sideways from the route's own leg (a leg from corridor
  node k to k' has |k' − k| ≤ max_drift), the coarse graph's legs included;
- the lines are the same, so a canal's fixed legs (canal_time.py) and the weather are the same.
The route itself is a route of the corridor (node `width` of every line), so a search started from it can only gain.

`refine_route` searches the corridor of a plan (±1 coarse node, at 1/split of the spacing, each leg drifting at most one
coarse spacing from the route's: on the routing suite the same gains as any drift, for 74 % of the CPU,
bench/README.md) with the polish of the
default search (bfoa.polish: the DP over the corridor, every engine setting per leg, partial plans within 4 h and 2 %
of fuel of the plan's own, at most `REFINE_BUCKETS` labels per node), and again round the plan it finds, while that gains more than 0.01 % (at most
`REFINE_ROUNDS` corridors): a route may walk sideways a node a round. The plan found is a plan of the finer graph,
sailed with the same legs' kernel in the same weather; it is kept only when cheaper.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from pipeline.routing import geodesy as geo
from pipeline.routing.baseline import evaluate
from pipeline.routing.bfoa import BfoaParams, polish
from pipeline.routing.clearance import edges_clear, lat_band, nodes_clear
from pipeline.routing.land import land_grid
from pipeline.routing.problem import Instance
from pipeline.routing.search_space import SearchSpace, forbid_crossing

REFINE_ROUNDS = 3  # corridors searched at most, each round the plan the last one found
REFINE_GAIN = 1e-4  # a round that gains less than this share of the cost ends the refinement
# labels per node the corridor's DP keeps (the polish's 16 halved: on six suite instances half the CPU, 0.02–0.33
# points of gain less; bench/README.md)
REFINE_BUCKETS = 8


def corridor_space(space: SearchSpace, centre: np.ndarray, width: int, split: int = 2,
                   lat_limits: tuple[float, float] = (-75.0, 75.0),
                   limit_lines=(), max_drift: int | None = None) -> tuple[SearchSpace, np.ndarray]:
    """(the corridor's search space, each of its nodes' position along its line in steps of 1/`split` of the coarse
    spacing (L+2, 2·width + 1)) round the route whose node on line i is at position centre[i] in those steps (split ×
    the coarse node of a route of `space`): that route is node `width` of every line of the corridor."""
    centre = np.asarray(centre, np.int64)
    L2, P = space.lat.shape
    n = 2 * width + 1
    lat, lon = np.empty((L2, n)), np.empty((L2, n))
    node_ok = np.zeros((L2, n), np.bool_)
    fine = np.empty((L2, n), np.int64)  # position along the line in fine steps (split per coarse spacing)
    new = np.zeros((L2, n), np.bool_)  # a node between two coarse nodes: its clearance is checked here
    for i in range(L2):
        for k in range(n):
            f = int(centre[i]) - width + k
            fine[i, k] = f
            j, r = divmod(f, split)
            if f < 0 or j >= P - (1 if r else 0):
                lat[i, k], lon[i, k] = space.lat[i, P // 2], space.lon[i, P // 2]
                continue
            if r == 0:
                lat[i, k], lon[i, k], node_ok[i, k] = space.lat[i, j], space.lon[i, j], space.node_ok[i, j]
                continue
            lat[i, k], lon[i, k] = geo.gc_interpolate(space.lat[i, j], space.lon[i, j], space.lat[i, j + 1],
                                                      space.lon[i, j + 1], r / split)
            gate = space.gate is not None and bool(space.gate[i])
            node_ok[i, k] = (bool(space.node_ok[i, j] and space.node_ok[i, j + 1]) and not gate and 0 < i < L2 - 1
                             and lat_limits[0] <= lat[i, k] <= lat_limits[1])
            new[i, k] = node_ok[i, k]
    edge_ok = np.zeros((L2 - 1, n, n), np.bool_)
    if space.clearance is not None:
        grid = land_grid()
        clear = new.copy()
        nodes_clear(grid, space.clearance, lat, lon, clear)
        node_ok = np.where(new, clear, node_ok)
        # only the legs the drift limit keeps: the others are dropped below whatever their clearance
        reach = n - 1 if max_drift is None else min(n - 1, int(max_drift))
        edges_clear(grid, space.clearance, lat, lon, node_ok, reach, lat_band(lat_limits), edge_ok)
    else:
        edge_ok[:] = node_ok[:-1, :, None] & node_ok[1:, None, :]
    shift = np.abs(fine[1:, None, :] - fine[:-1, :, None])
    edge_ok &= shift <= split * int(space.max_shift)
    # a leg between two of the coarse graph's own nodes is exactly the coarse graph's
    coarse_a, coarse_b = ~_between(fine[:-1], split), ~_between(fine[1:], split)
    both = coarse_a[:, :, None] & coarse_b[:, None, :] & node_ok[:-1, :, None] & node_ok[1:, None, :]
    ja, jb = np.clip(fine[:-1] // split, 0, P - 1), np.clip(fine[1:] // split, 0, P - 1)
    lines = np.arange(L2 - 1)[:, None, None]
    edge_ok = np.where(both, space.edge_ok[lines, ja[:, :, None], jb[:, None, :]], edge_ok)
    if max_drift is not None:
        k = np.arange(n)
        edge_ok &= (np.abs(k[None, :] - k[:, None]) <= max_drift)[None]
    for line in limit_lines or []:
        forbid_crossing(lat, lon, edge_ok, line)
    d_line = space.line_d_point_nm / split if space.line_d_point_nm is not None else None
    fine_space = replace(space, lat=lat, lon=lon, node_ok=node_ok, edge_ok=edge_ok, d_point_nm=space.d_point_nm / split,
                         max_shift=n - 1, line_d_point_nm=d_line)
    return fine_space, fine


@dataclass(frozen=True)
class RefinedRoute:
    """A plan of a corridor graph round a route (`corridor_space`): its instance (the corridor's graph), nodes and
    engine settings in it, cost, the cost of the route it was refined from, the rounds searched, the legs sailed."""

    inst: Instance
    nodes: np.ndarray
    rpm_idx: np.ndarray
    cost: float
    from_cost: float
    rounds: int
    legs_sailed: int

    @property
    def gain_pct(self) -> float:
        return 100.0 * (self.from_cost - self.cost) / self.from_cost


def refine_route(inst: Instance, nodes: np.ndarray, rpm_idx: np.ndarray, split: int) -> RefinedRoute | None:
    """The plan (route `nodes` of `inst`'s graph, settings `rpm_idx`) searched again on corridors `split` times finer
    round it, as the module says; None when that finds nothing cheaper, the plan cannot be sailed, or split < 2."""
    if split < 2:
        return None
    problem = inst.problem
    params = BfoaParams(polish_width=split, polish_buckets=REFINE_BUCKETS)
    centre = split * np.asarray(nodes, np.int64)
    rpm_idx = np.asarray(rpm_idx, np.int64)
    from_cost = cost = float(evaluate(inst, nodes, rpm_idx)[0])
    if not np.isfinite(cost):
        return None
    best, legs, rounds = None, 0, 0
    for rounds in range(1, REFINE_ROUNDS + 1):
        space, fine = corridor_space(inst.space, centre, split, split, problem.lat_limits, list(problem.limit_lines),
                                     max_drift=split)
        sub = replace(inst, space=space, graph=space.graph)
        start = np.full(fine.shape[0], split, np.int64)  # the route itself: the same legs, the same cost
        n2, r2, c2, n_legs = polish(start, rpm_idx, cost, params, sub.graph, sub.vessel, sub.wx, sub.objective)
        legs += int(n_legs)
        if not c2 < cost - REFINE_GAIN * abs(cost):
            break
        best = (sub, np.asarray(n2, np.int64), np.asarray(r2, np.int64), float(c2))
        centre, rpm_idx, cost = fine[np.arange(fine.shape[0]), n2], best[2], best[3]
    if best is None:
        return None
    return RefinedRoute(best[0], best[1], best[2], best[3], from_cost, rounds, legs)


def _between(fine: np.ndarray, split: int) -> np.ndarray:
    """Whether each corridor node lies between two coarse nodes (not on one)."""
    return fine % split != 0


__all__ = ["corridor_space", "refine_route", "RefinedRoute", "REFINE_ROUNDS"]
