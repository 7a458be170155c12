"""A plan searched again on a graph finer across the lines round its route (refine_graph.py): the corridor keeps the
coarse graph's nodes and legs, its new nodes lie between them and keep its rules, and the refined plan is never
dearer than the graph's, keeps the clearance from land, and says what it gained."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.routing.geodesy import gc_distance_nm
from pipeline.routing.refine_graph import corridor_space, refine_route
from pipeline.routing.savings import solver_instance
from pipeline.routing.solve import solve
from routing_cases import FAST, field, moving_storm, problem, wavy


def _route(space):
    """A route that wanders across the graph: the base route bent to ±2 nodes."""
    L2 = space.lat.shape[0]
    nodes = space.base_route().copy()
    nodes[1:-1] += np.round(2 * np.sin(np.linspace(0, np.pi, L2))[1:-1]).astype(np.int64)
    return nodes


def test_the_corridor_holds_the_route_the_coarse_nodes_and_legs_and_points_between_them():
    pr = problem((30.0, -160.0), (33.0, -146.0), 110.0, n_lines=8, n_points=9)
    space = pr.search_space()
    nodes = _route(space)
    split, width = 3, 3
    fine_space, fine = corridor_space(space, split * nodes, width, split)
    L2, n = fine.shape
    assert n == 2 * width + 1 and fine_space.lat.shape == (L2, n)
    assert (fine[:, width] == split * nodes).all()  # the route is node `width` of every line
    for i in range(L2):
        for k in range(n):
            j, r = divmod(int(fine[i, k]), split)
            if r == 0:  # one of the coarse graph's nodes: the same point, usable as there
                assert (fine_space.lat[i, k], fine_space.lon[i, k]) == (space.lat[i, j], space.lon[i, j])
                assert fine_space.node_ok[i, k] == space.node_ok[i, j]
            elif fine_space.node_ok[i, k]:  # between nodes j and j + 1, r/split of the way
                a = gc_distance_nm(space.lat[i, j], space.lon[i, j], fine_space.lat[i, k], fine_space.lon[i, k])
                b = gc_distance_nm(space.lat[i, j], space.lon[i, j], space.lat[i, j + 1], space.lon[i, j + 1])
                assert a == pytest.approx(b * r / split, rel=1e-6)
    # the ports keep their one node; a leg between two coarse nodes is the coarse graph's
    assert fine_space.node_ok[0].sum() == 1 and fine_space.node_ok[-1].sum() == 1
    for i in range(L2 - 1):
        for ka in range(n):
            for kb in range(n):
                fa, fb = int(fine[i, ka]), int(fine[i + 1, kb])
                if fa % split == 0 and fb % split == 0 and fine_space.node_ok[i, ka] and fine_space.node_ok[i + 1, kb]:
                    assert fine_space.edge_ok[i, ka, kb] == space.edge_ok[i, fa // split, fb // split]
                if abs(fb - fa) > split * space.max_shift:
                    assert not fine_space.edge_ok[i, ka, kb]


def test_a_drift_limit_keeps_every_leg_within_that_many_fine_steps_of_the_routes_own():
    pr = problem((30.0, -160.0), (33.0, -146.0), 110.0, n_lines=8, n_points=9)
    space = pr.search_space()
    nodes = _route(space)
    free, _ = corridor_space(space, 3 * nodes, 3, 3)
    held, _ = corridor_space(space, 3 * nodes, 3, 3, max_drift=2)
    k = np.arange(free.lat.shape[1])
    drift = np.abs(k[None, :] - k[:, None])[None]
    assert not held.edge_ok[np.broadcast_to(drift > 2, held.edge_ok.shape)].any()
    near = np.broadcast_to(drift <= 2, held.edge_ok.shape)
    assert (held.edge_ok[near] == free.edge_ok[near]).all()  # the rest as without the limit
    assert free.edge_ok[np.broadcast_to(drift > 2, free.edge_ok.shape)].any()  # so the limit did remove legs


@pytest.mark.slow  # six whole solves in a moving storm (about 2.7 s)
def test_refining_never_costs_more_and_leaves_the_graph_between_its_nodes():
    pr = problem((30.0, -160.0), (35.0, -130.0), 150.0, n_lines=10, n_points=11)
    storm = field(moving_storm(3, 32.0, 210.0), step_h=3)
    space = pr.search_space()
    for solver in ("bfoa", "dp", "astar"):
        coarse = solve(pr, storm, solver=solver, seed=1, params=FAST if solver == "bfoa" else None, space=space,
                       refine_split=1)
        fine = solve(pr, storm, solver=solver, seed=1, params=FAST if solver == "bfoa" else None, space=space,
                     refine_split=3)
        assert coarse.status == fine.status == "ok", (solver, coarse.reason, fine.reason)
        assert fine.cost <= coarse.cost + 1e-9, solver
        assert fine.hours <= pr.t_req_h + 1e-9
        if fine.cost < coarse.cost:
            assert "3× finer across the lines" in fine.reason, fine.reason
            on_a_node = [min(gc_distance_nm(la, lo, a, o) for a, o in zip(space.lat[i], space.lon[i])) < 1e-6
                         for i, (la, lo) in enumerate(fine.waypoints)]
            assert not all(on_a_node), solver  # some waypoint lies between two of the graph's nodes


def test_refine_route_gives_nothing_without_a_finer_split_or_a_plan_that_can_be_sailed():
    pr = problem((30.0, -160.0), (33.0, -146.0), 110.0, n_lines=8, n_points=9)
    space = pr.search_space()
    inst, base = solver_instance(pr, space, field(wavy(2)))
    rpm = np.full(len(base) - 1, 1, np.int64)
    assert refine_route(inst, base, rpm, 1) is None  # split 1: the graph itself
    found = refine_route(inst, base, rpm, 3)
    assert found is not None and found.cost < found.from_cost and found.gain_pct > 0  # the middle setting: beaten
    assert 1 <= found.rounds <= 3 and found.legs_sailed > 0
    off = base.copy()
    off[1:-1] = 0  # the graph's edge lines, 4 nodes a leg from the ports: beyond the widest shift
    assert refine_route(inst, off, rpm, 3) is None
