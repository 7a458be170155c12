"""Which base route a voyage's node lines are laid along: the one place that decides it.

Today the great circle (or rhumb line) between the ports (`None`): `search_space.lay_out_lines` lays its lines
across it. A `SeaRoute` (sea_route.py) from the global sea-route layer lays them along that route instead
(corridor.py), round capes and through straits and canals; plugging that layer in is the one marked line below.
"""

from __future__ import annotations

from dataclasses import replace

from pipeline.routing.options import RoutingOptions
from pipeline.routing.problem import RoutingProblem
from pipeline.routing.sea_route import SeaRoute
from pipeline.routing.solve import solver_spec


def base_route_for(dep: tuple[float, float], arr: tuple[float, float], options: RoutingOptions) -> SeaRoute | None:
    """The sea route from `dep` to `arr` ((lat, lon) degrees) the voyage is routed along, or None for the great
    circle (rhumb line). A solver whose base is the rhumb line always gets None: it sails across the open sea."""
    if solver_spec(options.solver).base != "gc":
        return None
    return None  # the global sea-route layer: return sea_route(dep, arr, ...) here


def with_base_route(problem: RoutingProblem, options: RoutingOptions) -> RoutingProblem:
    """The problem laid along `base_route_for` its ports (unchanged when that is the great circle)."""
    route = base_route_for(problem.dep, problem.arr, options)
    return problem if route is None else replace(problem, base_route=route)


__all__ = ["base_route_for", "with_base_route"]
