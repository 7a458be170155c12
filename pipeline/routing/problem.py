"""What a routing solve takes (`RoutingProblem`) and what the numba solvers see (`Instance`: the graph, vessel,
weather and objective as named structures)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np

from pipeline.performance.model import PerformanceModel
from pipeline.routing.canal_time import canal_fixed_legs
from pipeline.routing.engine.leg import Vessel, Voyage, vessel
from pipeline.routing.objectives import OBJECTIVES, Objective, objective
from pipeline.routing.sea_route import SeaRoute
from pipeline.routing.search_space import Graph, SearchSpace, build_search_space
from pipeline.routing.weather_field import Weather, WeatherField


class RoutingInputError(ValueError):
    """The voyage cannot be routed as given (the message names the voyage and the problem)."""


MAX_VOYAGE_H = 90 * 24.0  # longer is a typing mistake in the RTA, not a voyage (same limit as the voyages import)


class WeatherWindow(NamedTuple):
    """The part of a forecast a voyage can meet: valid times from its departure to the end of its planning
    horizon, and the box of its search space (degrees; `lon_deg` = (west, east) in degrees east with east ≥ west,
    west in 0..360, so a box across 180° is e.g. (170, 200))."""

    from_utc: np.datetime64
    to_utc: np.datetime64
    lat_deg: tuple[float, float]
    lon_deg: tuple[float, float]


def lon_span_deg(lon_deg) -> tuple[float, float]:
    """The shortest arc of longitude holding every given longitude: (west, east), west in 0..360, east ≥ west."""
    x = np.unique(np.asarray(lon_deg, dtype=np.float64) % 360.0)
    gaps = np.diff(np.append(x, x[0] + 360.0))  # gap after each longitude, going east
    k = int(np.argmax(gaps))
    west = float(x[(k + 1) % x.size])
    return west, west + 360.0 - float(gaps[k])


def place_name(role: str, name: str) -> str:
    """'departure Yokohama', or just 'departure' when the voyage names no port (never 'departure departure')."""
    name = (name or "").strip()
    return role if not name or name.lower() == role else f"{role} {name}"


@dataclass(frozen=True)
class RoutingProblem:
    dep: tuple[float, float]  # (lat, lon) degrees, at sea
    arr: tuple[float, float]
    depart_utc: np.datetime64
    rta_utc: np.datetime64
    model: PerformanceModel
    rpm_options: tuple[float, ...]
    draft_m: float = 10.0
    trim_m: float = 0.0
    max_hs_m: float | None = None
    max_wind_kn: float | None = None
    objective: str = "jit"
    window_h: float = 6.0
    early_t_per_h: float = 0.2
    late_t_per_h: float = 1.0e4
    voyage_id: str = "adhoc"
    imo: int | None = None
    dep_name: str = "departure"
    arr_name: str = "destination"
    n_lines: int | None = None
    n_points: int = 21
    d_point_nm: float | None = None
    max_shift: int | None = None
    base: str = "gc"
    lat_limits: tuple[float, float] = (-75.0, 75.0)
    limit_lines: tuple = field(default=())
    max_step_h: float = 1.0
    land_clearance_nm: float = 2.0  # legs keep this far from land, except within port_approach_nm of a port
    port_approach_nm: float = 10.0
    rpm_note: str | None = None  # why allowed rpm settings were clipped to the model's range (said on the plan)
    # the engine's barred speed ranges: open intervals (lo, hi) of rpm it must not be held in (continuous_speed.py)
    barred_rpm: tuple = ()
    # the sea route the node lines are laid along (corridor.py); None: across the great circle or rhumb line (`base`)
    base_route: SeaRoute | None = field(default=None, compare=False)

    def __post_init__(self):
        object.__setattr__(self, "depart_utc", np.datetime64(self.depart_utc, "s"))
        object.__setattr__(self, "rta_utc", np.datetime64(self.rta_utc, "s"))
        rpm = tuple(sorted(float(r) for r in self.rpm_options))
        object.__setattr__(self, "rpm_options", rpm)
        if not rpm or any(not np.isfinite(r) or r <= 0 for r in rpm):
            raise RoutingInputError(f"voyage {self.voyage_id}: allowed rpm settings must be positive numbers, got {self.rpm_options}")
        if self.rta_utc <= self.depart_utc:
            raise RoutingInputError(f"voyage {self.voyage_id}: RTA {self.rta_utc} is not after departure {self.depart_utc}")
        if self.t_req_h > MAX_VOYAGE_H:
            raise RoutingInputError(f"voyage {self.voyage_id}: RTA {self.rta_utc} is {self.t_req_h / 24:.0f} days after departure "
                                    f"{self.depart_utc}, more than the {MAX_VOYAGE_H / 24:.0f} days a voyage can plausibly take; "
                                    "check the RTA (its year)")
        barred = tuple(sorted((float(lo), float(hi)) for lo, hi in self.barred_rpm))
        if any(not (np.isfinite(lo) and np.isfinite(hi) and 0.0 <= lo < hi) for lo, hi in barred):
            raise RoutingInputError(f"voyage {self.voyage_id}: barred rpm ranges must be (low, high) with 0 ≤ low < high, "
                                    f"got {self.barred_rpm}")
        object.__setattr__(self, "barred_rpm", barred)
        inside = [r for r in rpm if any(lo < r < hi for lo, hi in barred)]
        if inside:
            raise RoutingInputError(f"voyage {self.voyage_id}: allowed rpm setting(s) {', '.join(f'{r:g}' for r in inside)} "
                                    f"lie in the engine's barred range(s) "
                                    f"{', '.join(f'{lo:g}-{hi:g}' for lo, hi in barred)}")
        if self.objective not in OBJECTIVES:
            raise RoutingInputError(f"voyage {self.voyage_id}: unknown objective {self.objective!r}; use one of {sorted(OBJECTIVES)}")

    @property
    def t_req_h(self) -> float:
        return float((self.rta_utc - self.depart_utc) / np.timedelta64(1, "s")) / 3600.0

    def search_space(self) -> SearchSpace:
        if self.base_route is not None and self.base != "gc":
            raise RoutingInputError(f"voyage {self.voyage_id}: its lines are laid along a sea route of great-circle legs; "
                                    f"the {self.base} base route applies only across the open sea (route it with base 'gc')")
        return build_search_space(self.dep, self.arr, n_lines=self.n_lines, n_points=self.n_points,
                                  d_point_nm=self.d_point_nm, base=self.base, max_shift=self.max_shift,
                                  lat_limits=self.lat_limits, limit_lines=list(self.limit_lines),
                                  clearance_nm=self.land_clearance_nm, approach_nm=self.port_approach_nm,
                                  dep_name=f"voyage {self.voyage_id}: {place_name('departure', self.dep_name)}",
                                  arr_name=f"voyage {self.voyage_id}: {place_name('destination', self.arr_name)}",
                                  base_route=self.base_route)

    def slowest_kn(self) -> float:
        """Calm-water speed at the lowest allowed rpm; RoutingInputError when the model gives next to nothing."""
        m = self.model
        slow = float(m.stw_kn(self.rpm_options[0], self.draft_m, self.trim_m))
        if slow < 1.0:
            raise RoutingInputError(
                f"voyage {self.voyage_id}: the performance model of vessel {self.imo} gives {slow:.2f} kn at "
                f"{self.rpm_options[0]:g} rpm in calm water; refit the model or check the allowed rpm settings")
        return slow

    def planning_horizon_h(self, space: SearchSpace) -> float:
        """The longest passage the solvers consider (hours after departure); longer ones are refused."""
        return max(1.6 * self.t_req_h, 1.6 * space.base_distance_nm / self.slowest_kn())

    def kernel_vessel(self) -> Vessel:
        """The ship as the leg kernel sees it: the model at this voyage's loading, its weather limits and settings."""
        return vessel(self.model, draft_m=self.draft_m, trim_m=self.trim_m, max_hs_m=self.max_hs_m,
                      max_wind_kn=self.max_wind_kn, max_step_h=self.max_step_h, rpm_options=self.rpm_options)

    def weather_window(self, space: SearchSpace) -> WeatherWindow:
        """The weather this voyage can meet: departure .. departure + planning horizon, over its search space."""
        end = self.depart_utc + np.timedelta64(int(np.ceil(self.planning_horizon_h(space) * 3600.0)), "s")
        return WeatherWindow(self.depart_utc, end, (float(space.lat.min()), float(space.lat.max())),
                             lon_span_deg(space.lon))


@dataclass
class Instance:
    """A voyage ready for the compiled solvers: the problem, its search space and weather, and the named
    structures the kernels take (`graph`, `vessel`, `wx` the weather, `objective`)."""

    problem: RoutingProblem
    space: SearchSpace
    weather: WeatherField
    graph: Graph
    vessel: Vessel
    wx: Weather
    objective: Objective

    @classmethod
    def build(cls, problem: RoutingProblem, space: SearchSpace, weather: WeatherField) -> "Instance":
        problem.slowest_kn()  # refuses a model that barely moves the ship, before the weather is looked at
        _check_coverage(problem, space, weather)
        max_hours = problem.planning_horizon_h(space)
        ves = problem.kernel_vessel()
        fixed = canal_fixed_legs(space, problem.model.fuel_tph(problem.rpm_options[0], problem.draft_m, problem.trim_m))
        if fixed.shape[0]:  # a canal is sailed in its fixed hours at the lowest setting's calm-water rate
            ves = ves._replace(fixed_legs=fixed)
        obj = objective(problem.objective, t_dep_h=weather.hours_after_ref(problem.depart_utc), max_hours=max_hours,
                        t_req_h=problem.t_req_h, window_h=problem.window_h, early_t_per_h=problem.early_t_per_h,
                        late_t_per_h=problem.late_t_per_h)
        return cls(problem=problem, space=space, weather=weather, graph=space.graph, vessel=ves, wx=weather.kernel,
                   objective=obj)

    @property
    def voyage(self) -> Voyage:
        """The voyage as the kernels take it in one piece (graph, vessel, weather, objective)."""
        return Voyage(self.graph, self.vessel, self.wx, self.objective)

    @property
    def rpm_options(self) -> np.ndarray:
        """The engine settings the solvers choose from (the voyage's, plus what solve.py adds)."""
        return self.vessel.rpm_options

    def with_rpm_options(self, rpm_options) -> "Instance":
        """The same voyage with other engine settings (sorted, rpm)."""
        rpm = np.ascontiguousarray(np.sort(np.asarray(rpm_options, np.float64)))
        return replace(self, vessel=self.vessel._replace(rpm_options=rpm))

    @property
    def t_dep_h(self) -> float:
        return self.objective.t_dep_h

    @property
    def max_hours(self) -> float:
        return self.objective.max_hours

    @property
    def f_target(self) -> float:
        return self.objective.f_target

    @f_target.setter
    def f_target(self, value: float) -> None:
        """The thesis objective's fuel scale (t): the baseline's fuel, once it is known."""
        self.objective = self.objective._replace(f_target=float(value))


def _check_coverage(problem: RoutingProblem, space: SearchSpace, weather: WeatherField) -> None:
    """The weather must cover every usable node (a regional field must not be silently extrapolated)."""
    lat = space.lat[space.node_ok]
    lon = space.lon[space.node_ok]
    lo, hi = weather.lat_range_deg
    tol = weather.grid.dlat
    if lat.min() < lo - tol or lat.max() > hi + tol:
        raise RoutingInputError(
            f"voyage {problem.voyage_id}: its search area spans latitudes {lat.min():.1f}..{lat.max():.1f} but the "
            f"weather covers only {lo:.1f}..{hi:.1f}")
    if not weather.grid.wraps:
        lon0, dlon, nlon = weather.grid.lon0, weather.grid.dlon, weather.grid.nlon
        rel = (lon - lon0) % 360.0
        if np.any(rel > dlon * (nlon - 1) + dlon):
            raise RoutingInputError(
                f"voyage {problem.voyage_id}: its search area leaves the weather's longitudes "
                f"{lon0:.1f}..{lon0 + dlon * (nlon - 1):.1f}")
