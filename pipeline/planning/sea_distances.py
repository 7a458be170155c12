"""Port-to-port sea distances: the length of the routing graph's shortest sea route (the baseline's route).

The graph is the one routing lays out for a voyage between the two ports (`search_space.build_search_space`:
the same lines, land clearance and port approaches), and the route is `baseline.shortest_route`, so a planned leg
is as long as the baseline routing later compares its plan with. A pair without a sea route through that graph
(or a port routing refuses, e.g. on land) gets NaN and the reason. Distances are symmetric: each unordered pair is
computed once. Computed pairs are kept in the `port_distances` table (storage.planning_store) and reused while
both ports keep their positions.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from pipeline.routing.baseline import shortest_route
from pipeline.routing.geodesy import gc_distance_nm
from pipeline.routing.search_space import VoyageGeometryError, build_search_space


@dataclass(frozen=True)
class PortDistance:
    port_a: str
    port_b: str
    lat_a: float
    lon_a: float
    lat_b: float
    lon_b: float
    dist_nm: float  # NaN: no sea route
    gc_nm: float  # great-circle distance, for comparison
    reason: str | None = None


def sea_distance(a: str, pos_a: tuple[float, float], b: str, pos_b: tuple[float, float]) -> PortDistance:
    """The shortest sea route's length between two ports ((lat, lon) degrees, at sea)."""
    gc = float(gc_distance_nm(pos_a[0], pos_a[1], pos_b[0], pos_b[1]))
    try:
        space = build_search_space(pos_a, pos_b, dep_name=f"port {a}", arr_name=f"port {b}")
    except VoyageGeometryError as exc:
        return PortDistance(a, b, *pos_a, *pos_b, math.nan, gc, str(exc))
    nodes = shortest_route(space)
    if nodes is None:
        return PortDistance(a, b, *pos_a, *pos_b, math.nan, gc,
                            f"no sea route from {a} to {b} through the routing graph (land or limits in the way)")
    lat = space.lat[np.arange(len(nodes)), nodes]
    lon = space.lon[np.arange(len(nodes)), nodes]
    dist = float(sum(gc_distance_nm(lat[i], lon[i], lat[i + 1], lon[i + 1]) for i in range(len(nodes) - 1)))
    return PortDistance(a, b, *pos_a, *pos_b, dist, gc)


def needed_pairs(ports: dict[str, tuple[float, float]], known: dict[tuple[str, str], PortDistance],
                 pairs: set[tuple[str, str]] | None = None) -> list[tuple[str, str]]:
    """Unordered pairs (sorted names) among `pairs` (default: all pairs of `ports`) that `known` lacks or holds for
    other positions."""
    todo = []
    wanted = pairs if pairs is not None else set(itertools.combinations(sorted(ports), 2))
    for a, b in sorted({tuple(sorted(p)) for p in wanted if p[0] != p[1]}):
        k = known.get((a, b))
        if k is None or (k.lat_a, k.lon_a, k.lat_b, k.lon_b) != (*ports[a], *ports[b]):
            todo.append((a, b))
    return todo


def distance_map(rows: list[PortDistance]) -> dict[tuple[str, str], float]:
    """(a, b) → NM both ways (NaN where no sea route), as the planner takes it."""
    out: dict[tuple[str, str], float] = {}
    for r in rows:
        out[(r.port_a, r.port_b)] = out[(r.port_b, r.port_a)] = r.dist_nm
    return out
