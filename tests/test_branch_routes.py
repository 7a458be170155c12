"""The BFOA's branch routes (pipeline/routing/branch_routes.py): the fastest route at one constant rpm through each
side of the graph. Checked against every route of a small graph sailed one by one, and round a storm that closes
the middle of the graph."""

from __future__ import annotations

import itertools
import math

import numpy as np

from pipeline.routing.engine import leg as lk
from pipeline.routing.branch_routes import branch_routes, fastest_route_nb
from pipeline.routing.problem import Instance
from routing_cases import field, problem

DEP, ARR = (30.0, -160.0), (35.0, -130.0)


def _hours(inst, nodes, r):
    """Hours of `nodes` sailed at constant rpm index r, inf when a leg cannot be sailed."""
    ct, cf = np.empty(len(nodes)), np.empty(len(nodes))
    rpm_idx = np.full(len(nodes) - 1, r, np.int64)
    code, _ = lk.sail_route_nb(np.asarray(nodes, np.int64), rpm_idx, 0, inst.graph, inst.vessel, inst.wx,
                               inst.objective, ct, cf)
    return ct[-1] - inst.t_dep_h if code == lk.OK else math.inf


def _current_band(LA, LO):
    """A head current (westward 1.2 m/s) north of 32.2 N and a following one (eastward 0.6 m/s) south of 31.5 N: the
    fastest route on each side bends to its own side, by as much as it pays."""
    return dict(uo=np.where(LA > 32.2, -1.2, np.where(LA < 31.5, 0.6, 0.0)))


def test_fastest_route_of_each_side_is_the_fastest_of_every_route_there():
    pr = problem(DEP, ARR, 200, n_lines=4, n_points=5)
    space = pr.search_space()
    inst = Instance.build(pr, space, field(_current_band))
    L2, P = space.lat.shape
    c = P // 2
    r = 1
    for lo, hi in ((0, c), (c, P - 1)):
        nodes = np.empty(L2, np.int64)
        fastest_route_nb(inst.graph, inst.vessel, inst.wx, inst.objective, r, lo, hi, 1, nodes)
        best = math.inf
        for mid in itertools.product(range(lo, hi + 1), repeat=L2 - 2):
            route = (c, *mid, c)
            if max(abs(a - b) for a, b in zip(route, route[1:])) <= 1:
                best = min(best, _hours(inst, route, r))
        assert math.isfinite(best)
        assert np.all((nodes[1:-1] >= lo) & (nodes[1:-1] <= hi)) and nodes[0] == nodes[-1] == c
        assert np.max(np.abs(np.diff(nodes))) <= 1
        assert _hours(inst, nodes, r) == best  # weather that does not change in time: earliest arrival is exact


def test_branch_routes_go_round_a_storm_on_both_sides():
    """Waves above the ship's limit close the middle of the graph: one route passes it on each side, both sailable
    at the rpm asked for, each the fastest of its side (hence distinct)."""
    mid_lat, mid_lon = 32.6, 215.0  # near the middle of the great circle DEP → ARR (0..360 east)

    def storm(LA, LO):
        d_nm = 60.0 * np.hypot(LA - mid_lat, (LO - mid_lon) * np.cos(np.radians(mid_lat)))
        return dict(swh=np.where(d_nm < 120.0, 9.0, 1.0), mwd_deg=np.full(LA.shape, 90.0))

    pr = problem(DEP, ARR, 150, n_lines=10, n_points=11, max_hs_m=6.0)
    space = pr.search_space()
    inst = Instance.build(pr, space, field(storm))
    c = space.centre
    assert _hours(inst, np.full(space.lat.shape[0], c), 1) == math.inf  # the base route is closed
    routes, n_legs = branch_routes(inst.graph, inst.vessel, inst.wx, inst.objective, 1)
    assert routes.shape == (2, space.lat.shape[0]) and n_legs > 0
    sides = sorted(int(np.sign((rt - c)[np.argmax(np.abs(rt - c))])) for rt in routes)
    assert sides == [-1, 1]
    for rt in routes:
        assert math.isfinite(_hours(inst, rt, 1))
