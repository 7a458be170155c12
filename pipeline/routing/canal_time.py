"""A canal is sailed on its fixed fairway at its own pace: the legs of a search space inside a canal, with their
fixed hours and fuel.

A route through a canal (sea_route.PassageTransit with a `transit_h`) has one gate line per fairway waypoint
(corridor.py). The legs between consecutive gates of one canal take the canal's `transit_h`, shared in proportion to
their length, and the first of them also the canal's waiting allowance `wait_h` (the ship waits for its convoy or
slot before entering). Those hours and their fuel are fixed: the leg kernel (engine.leg.Vessel.fixed_legs) gives
them whatever rpm a solver picks and whatever the weather, so every solver and the constant-speed baseline spend
them alike and savings compare like with like. Weather routing applies outside the canal.

Fuel assumption: the ship burns, in the canal and while waiting for it, the calm-water fuel rate of its lowest
allowed setting (the rate a ship hove to burns in the grid DP's waits, dp_grid.wait_rate_tph): canal speeds
(Suez about 7.5 kn over its 104 NM in 14 h, Panama and Kiel slower) are below a merchant ship's slowest sea
setting, so its engine runs at that order or stops; the auxiliaries' consumption is not modelled anywhere.
These are the same `transit_h` and `wait_h` the fleet planner's schedule adds (planning/sea_distances.py).
"""

from __future__ import annotations

import numpy as np

from pipeline.routing import geodesy as geo
from pipeline.routing.engine.leg import NO_FIXED_LEGS

MATCH_NM = 0.01  # a gate line's node is a fairway waypoint when it lies this close to it


def canal_lines(space) -> list[tuple[str, float, float, list[int]]]:
    """(canal name, transit_h, wait_h, its lines in order) for each canal of the space's sea route whose fairway
    waypoints are gate lines of the space (a canal cut by the voyage's ends keeps the part it sails)."""
    route = getattr(space, "sea_route", None)
    if route is None or space.gate is None:
        return []
    c = space.centre
    out = []
    for p in route.passages:
        if p.transit_h is None:
            continue
        wlat = np.asarray(route.lat[p.start_index:p.end_index + 1], np.float64)
        wlon = np.asarray(route.lon[p.start_index:p.end_index + 1], np.float64)
        lines = []
        for i in range(space.lat.shape[0]):
            if not (space.gate[i] or i in (0, space.lat.shape[0] - 1)):
                continue
            la, lo = float(space.lat[i, c]), float(space.lon[i, c])
            if min(geo.gc_distance_nm(la, lo, float(a), float(b)) for a, b in zip(wlat, wlon)) < MATCH_NM:
                lines.append(i)
        # the canal's legs join consecutive lines; keep the longest run of them
        runs: list[list[int]] = []
        run: list[int] = []
        for i in lines:
            if run and i != run[-1] + 1:
                runs.append(run)
                run = []
            run.append(i)
        if run:
            runs.append(run)
        best = max(runs, key=len, default=[])
        if len(best) >= 2:
            out.append((p.name, float(p.transit_h), float(p.wait_h), best))
    return out


def canal_fixed_legs(space, fuel_tph: float) -> np.ndarray:
    """(n, 6) legs of the space sailed in fixed hours and fuel (engine.leg FIX_* columns), burning `fuel_tph`
    (t/h) in the canal and while waiting for it; none when the space crosses no canal."""
    rows = []
    c = space.centre
    for _, transit_h, wait_h, lines in canal_lines(space):
        ends = [(float(space.lat[i, c]), float(space.lon[i, c]), float(space.lat[j, c]), float(space.lon[j, c]))
                for i, j in zip(lines[:-1], lines[1:])]
        dist = np.array([geo.gc_distance_nm(*e) for e in ends])
        if not dist.sum() > 0.0:
            continue
        for k, (e, d) in enumerate(zip(ends, dist)):
            hours = transit_h * d / dist.sum() + (wait_h if k == 0 else 0.0)
            if hours > 0.0:
                rows.append((*e, hours, hours * float(fuel_tph)))
    return np.array(rows, np.float64).reshape(-1, 6) if rows else NO_FIXED_LEGS


def passages_note(space) -> str | None:
    """What a plan says about the passages it sails: their names, and for canals the fixed hours counted."""
    route = getattr(space, "sea_route", None)
    if route is None or not route.passages:
        return None
    canals = {name: (t, w) for name, t, w, _ in canal_lines(space)}
    parts = [f"{p.name}{'' if 'canal' in p.name.lower() else ' canal'} ({canals[p.name][0]:g} h transit + "
             f"{canals[p.name][1]:g} h waiting, at the lowest setting's calm-water fuel rate)" if p.name in canals
             else p.name for p in route.passages]
    return "through " + ", ".join(parts)


__all__ = ["canal_lines", "canal_fixed_legs", "passages_note"]
