"""Routes round either side of what lies across a voyage, for the BFOA's start (numba).

A storm across the base route splits the cheap routes into branches, one round each side of it; a swarm that
starts near the base route finds the near branch and can stall there, or on a detour beside the cheapest one
(bench/routing_suite.py: `storm-head-on`, `southern-indian`). `branch_routes` gives the swarm one route on each
side from the start: the fastest route at one constant rpm (the baseline's, the rpm that meets the RTA on the base
route) through the nodes on one side of the base route (the centre line included) and through those on the other.
Each is a time-dependent label search over the lines with one label per node, the earliest arrival, over legs
that shift at most one node a line (smooth routes; a graph that needs wider shifts near a port gives no route,
and the swarm starts as it did without them). At one rpm the fuel rate changes little with the route, so the
fastest route is close to the least-fuel one at that rpm; the two searches sail each of the graph's
one-node-shift legs about once, ~3·P·L legs, fewer than the swarm's first cycle. Earliest arrival is exact only
where a later start never arrives sooner (first in, first out): the routes are starting points that the swarm
and its polish improve, not plans.
"""

from __future__ import annotations

import numba
import numpy as np

from pipeline.routing.engine.leg import CODE, H, N_LEG_OUT, OK, sail_leg_nb


@numba.njit(cache=True)
def fastest_route_nb(g, v, w, o, r, lo, hi, max_shift, nodes):
    """The earliest-arriving route at constant rpm index `r` through nodes lo..hi of every inner line, its legs
    shifting at most `max_shift` nodes (and the graph's), into `nodes` (L+2,); nodes[0] = −1 when no route arrives
    within the planning horizon. Returns the legs sailed."""
    lat, lon, edge_ok, ms = g.lat, g.lon, g.edge_ok, min(g.max_shift, max_shift)
    L2, P = lat.shape
    c = P // 2
    t = np.full((L2, P), np.inf)
    parent = np.full((L2, P), -1, np.int64)
    t[0, c] = o.t_dep_h
    out = np.empty(N_LEG_OUT)
    rpm = v.rpm_options[r]
    n_legs = 0
    for i in range(L2 - 1):
        b_lo, b_hi = (c, c) if i == L2 - 2 else (lo, hi)  # the last leg ends at the port
        for a in range(P):
            t0 = t[i, a]
            if t0 == np.inf:
                continue
            for b in range(max(b_lo, a - ms), min(b_hi, a + ms) + 1):
                if not edge_ok[i, a, b]:
                    continue
                sail_leg_nb(lat[i, a], lon[i, a], lat[i + 1, b], lon[i + 1, b], t0, rpm, v, w, out)
                n_legs += 1
                if out[CODE] != OK:  # weather limits, or the weather's end
                    continue
                t1 = t0 + out[H]
                if t1 < t[i + 1, b] and t1 - o.t_dep_h <= o.max_hours:
                    t[i + 1, b] = t1
                    parent[i + 1, b] = a
    if t[L2 - 1, c] == np.inf:
        nodes[0] = -1
        return n_legs
    nodes[L2 - 1] = c
    for i in range(L2 - 1, 0, -1):
        nodes[i - 1] = parent[i, nodes[i]]
    return n_legs


def branch_routes(g, v, w, o, r: int, max_shift: int = 1) -> tuple[np.ndarray, int]:
    """((k, L+2) int64 routes, legs sailed): the distinct fastest routes at rpm index `r` through the nodes on one
    side of the centre line (the base route) and through those on the other, legs shifting at most `max_shift`
    nodes (k ≤ 2; 0 when none arrives)."""
    L2, P = g.lat.shape
    c = P // 2
    found: list[np.ndarray] = []
    n_legs = 0
    for lo, hi in ((0, c), (c, P - 1)):
        nodes = np.empty(L2, np.int64)
        n_legs += fastest_route_nb(g, v, w, o, int(r), lo, hi, int(max_shift), nodes)
        if nodes[0] >= 0 and not any(np.array_equal(nodes, x) for x in found):
            found.append(nodes)
    return np.array(found, np.int64).reshape(len(found), L2), n_legs
