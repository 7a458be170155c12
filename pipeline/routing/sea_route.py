"""A sea route over the whole ocean: the base route a voyage's node lines are laid along.

A `SeaRoute` is a polyline of waypoints from the departure to the arrival, clear of land by the voyage's
clearance except inside a passage's fairway, with the passages it goes through (canals and narrow straits) named
by the waypoints that open and close them. It is what the global sea-route layer returns and what the corridor
along the route is laid over; the planner takes its port-to-port distances from it too.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


class NoSeaRoute(ValueError):
    """Two points have no sea route between them; the message names what blocks them (land, an avoided passage)."""


@dataclass(frozen=True)
class PassageTransit:
    """One passage on a route: waypoints `start_index`..`end_index` (inclusive) of the route are its fairway.

    `transit_h` is the fixed time to sail a canal's fairway at its speed (None for a strait, sailed at the plan's
    own speed); `wait_h` the waiting allowance before a canal (0 for a strait)."""

    name: str
    kind: str  # "canal" | "strait"
    start_index: int
    end_index: int
    transit_h: float | None = None
    wait_h: float = 0.0


@dataclass(frozen=True)
class SeaRoute:
    """Waypoints in degrees (lon in -180..180; first the departure, last the arrival), the route's length in NM
    (great-circle legs between waypoints) and the passages it sails through, in order."""

    lat: np.ndarray
    lon: np.ndarray
    dist_nm: float
    passages: tuple[PassageTransit, ...] = ()


__all__ = ["NoSeaRoute", "PassageTransit", "SeaRoute"]
