"""Port-to-port sea distances: the length of the shortest sea route of the global sea-route layer.

The route is `global_routes.sea_route`'s (the product's land mask and clearance, round capes and through the
straits and canals of routing/passages.py), so a planned leg is as long as the base route routing later lays its
corridor along. A pair without a sea route (a port on land or enclosed, an unconnected sea) gets NaN and the reason.
A route through a canal carries the canal's time: `canal_nm` of its length is the canals' fairways, sailed in
`canal_h` hours (transit and waiting allowance, passages.py) instead of at the vessel's speed
(`hours`). Distances are taken as symmetric: each unordered pair is computed once, from the port first in name
order. Only the one-way lanes of a traffic separation scheme (passages.py) make the two directions differ, by
the lanes' offset (Lisbon–Rotterdam 1,081 NM, back 1,094 NM). Computed pairs are kept in the
`port_distances` table (storage.planning_store) and reused while both ports keep their positions.

The table holds the shortest routes with no passage avoided. A fleet that avoids passages (the setting
`routing.avoid_passages`, env JITROUTE_AVOID_PASSAGES, which its voyages are routed with) plans with
`avoiding`: a stored route that sails none of them is also the shortest without them and is kept; the others are
computed again without those passages (round the Cape instead of through Suez), so a plan's schedule and the
routes its voyages then get agree.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

from pipeline.routing.geodesy import gc_distance_nm
from pipeline.routing.global_routes import NoSeaRoute, sea_route


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
    passages: str | None = None  # the passages sailed, in order from port_a, ';'-separated
    canal_nm: float = 0.0  # length of the canals' fairways in dist_nm
    canal_h: float = 0.0  # hours through those canals, waiting included


def sea_distance(a: str, pos_a: tuple[float, float], b: str, pos_b: tuple[float, float], *,
                 avoid=frozenset()) -> PortDistance:
    """The shortest sea route's length between two ports ((lat, lon) degrees, at sea), avoiding the passages named
    in `avoid`."""
    gc = float(gc_distance_nm(pos_a[0], pos_a[1], pos_b[0], pos_b[1]))
    try:
        route = sea_route(pos_a, pos_b, avoid=avoid, dep_name=f"port {a}", arr_name=f"port {b}")
    except NoSeaRoute as exc:
        return PortDistance(a, b, *pos_a, *pos_b, math.nan, gc, str(exc))
    canal_nm = canal_h = 0.0
    for p in route.passages:
        if p.transit_h is not None:
            canal_nm += float(sum(gc_distance_nm(route.lat[k], route.lon[k], route.lat[k + 1], route.lon[k + 1])
                                  for k in range(p.start_index, p.end_index)))
            canal_h += p.transit_h + p.wait_h
    return PortDistance(a, b, *pos_a, *pos_b, route.dist_nm, gc, None,
                        ";".join(p.name for p in route.passages) or None, canal_nm, canal_h)


def avoiding(rows: list[PortDistance], avoid) -> list[PortDistance]:
    """`rows` (computed with no passage avoided) as they are when the passages named in `avoid` are closed: those
    whose route sails one of them computed again without them (NaN and the reason when nothing else joins them)."""
    avoid = frozenset(avoid or ())
    out = []
    for r in rows:
        sailed = set((r.passages or "").split(";")) - {""}
        if avoid and sailed & avoid:
            r = sea_distance(r.port_a, (r.lat_a, r.lon_a), r.port_b, (r.lat_b, r.lon_b), avoid=avoid)
        out.append(r)
    return out


def hours(dist_nm: float, speed_kn: float, canal: tuple[float, float] = (0.0, 0.0)) -> float:
    """Hours to sail `dist_nm` at `speed_kn` when `canal` = (NM, hours) of it goes through canals at their own pace."""
    canal_nm, canal_h = canal
    return (dist_nm - canal_nm) / speed_kn + canal_h


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


def canal_map(rows: list[PortDistance]) -> dict[tuple[str, str], tuple[float, float]]:
    """(a, b) → (canal NM, canal hours) both ways, for the pairs whose route goes through a canal."""
    out: dict[tuple[str, str], tuple[float, float]] = {}
    for r in rows:
        if r.canal_h and math.isfinite(r.dist_nm):
            out[(r.port_a, r.port_b)] = out[(r.port_b, r.port_a)] = (float(r.canal_nm), float(r.canal_h))
    return out
