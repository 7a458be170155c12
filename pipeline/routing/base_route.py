"""Which base route a voyage's node lines are laid along: the one place that decides it.

The great circle (or rhumb line) between the ports (`None`) when its leg is clear of land: `search_space.lay_out_lines`
lays its lines across it, as for every open-ocean passage. Otherwise the global sea-route layer's `SeaRoute`
(global_routes.py): the lines are laid along it (corridor.py), round capes and through straits and canals, keeping
out of the passages the run avoids (`RoutingOptions.avoid_passages`).
"""

from __future__ import annotations

from dataclasses import replace

from pipeline.routing.options import RoutingOptions
from pipeline.routing.global_routes import sea_route
from pipeline.routing.problem import RoutingProblem, place_name
from pipeline.routing.sea_route import NoSeaRoute, SeaRoute
from pipeline.routing.search_space import VoyageGeometryError
from pipeline.routing.solvers import solver_spec


def base_route_for(dep: tuple[float, float], arr: tuple[float, float], options: RoutingOptions, *,
                   dep_name: str = "departure", arr_name: str = "arrival") -> SeaRoute | None:
    """The sea route from `dep` to `arr` ((lat, lon) degrees) the voyage is routed along, or None for the great
    circle (rhumb line). A solver whose base is the rhumb line always gets None: it sails across the open sea."""
    if solver_spec(options.solver).base != "gc":
        return None
    route = sea_route(dep, arr, avoid=frozenset(options.avoid_passages), clearance_nm=options.land_clearance_nm,
                      approach_nm=options.port_approach_nm, dep_name=dep_name, arr_name=arr_name)
    if len(route.lat) == 2 and not route.passages:
        return None  # the great circle's leg is clear: the lines across it, as for any open-ocean voyage
    return route


def with_base_route(problem: RoutingProblem, options: RoutingOptions) -> RoutingProblem:
    """The problem laid along `base_route_for` its ports (unchanged when that is the great circle)."""
    who = f"voyage {problem.voyage_id}: "
    try:
        route = base_route_for(problem.dep, problem.arr, options, dep_name=who + place_name("departure", problem.dep_name),
                               arr_name=who + place_name("destination", problem.arr_name))
    except NoSeaRoute as exc:
        raise VoyageGeometryError(str(exc)) from None
    return problem if route is None else replace(problem, base_route=route)


__all__ = ["base_route_for", "with_base_route"]
