"""What a routing solve takes (`RoutingProblem`) and what the numba solvers see (`Instance`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pipeline.performance.model import PerformanceModel
from pipeline.routing.leg_kernel import vessel_params
from pipeline.routing.objectives import OBJECTIVES
from pipeline.routing.search_space import SearchSpace, build_search_space
from pipeline.routing.weather_field import WeatherField


class RoutingInputError(ValueError):
    """The voyage cannot be routed as given (the message names the voyage and the problem)."""


MAX_VOYAGE_H = 90 * 24.0  # longer is a typing mistake in the RTA, not a voyage (same limit as the voyages import)


def _place(role: str, name: str) -> str:
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
        if self.objective not in OBJECTIVES:
            raise RoutingInputError(f"voyage {self.voyage_id}: unknown objective {self.objective!r}; use one of {sorted(OBJECTIVES)}")

    @property
    def t_req_h(self) -> float:
        return float((self.rta_utc - self.depart_utc) / np.timedelta64(1, "s")) / 3600.0

    def search_space(self) -> SearchSpace:
        return build_search_space(self.dep, self.arr, n_lines=self.n_lines, n_points=self.n_points,
                                  d_point_nm=self.d_point_nm, base=self.base, max_shift=self.max_shift,
                                  lat_limits=self.lat_limits, limit_lines=list(self.limit_lines),
                                  dep_name=f"voyage {self.voyage_id}: {_place('departure', self.dep_name)}",
                                  arr_name=f"voyage {self.voyage_id}: {_place('destination', self.arr_name)}")

    def lat_band_deg(self, space: SearchSpace, margin_deg: float = 1.0) -> tuple[float, float]:
        ok = space.lat[space.node_ok]
        return float(np.min(space.lat) - margin_deg), float(np.max(space.lat) + margin_deg)


@dataclass
class Instance:
    """Plain arrays for the compiled solvers: graph, vessel, weather and objective."""

    problem: RoutingProblem
    space: SearchSpace
    weather: WeatherField
    rpm_options: np.ndarray
    vp: np.ndarray
    speed_coef: np.ndarray
    fuel_coef: np.ndarray
    t_dep_h: float
    max_hours: float
    obj: int
    f_target: float = 1.0

    @classmethod
    def build(cls, problem: RoutingProblem, space: SearchSpace, weather: WeatherField) -> "Instance":
        m = problem.model
        vp = vessel_params(m.form_id, problem.draft_m, problem.trim_m, m.months_dd, problem.max_hs_m,
                           problem.max_wind_kn, problem.max_step_h)
        slow = float(m.stw_kn(problem.rpm_options[0], problem.draft_m, problem.trim_m))
        if slow < 1.0:
            raise RoutingInputError(
                f"voyage {problem.voyage_id}: the performance model of vessel {problem.imo} gives {slow:.2f} kn at "
                f"{problem.rpm_options[0]:g} rpm in calm water; refit the model or check the allowed rpm settings")
        _check_coverage(problem, space, weather)
        max_hours = max(1.6 * problem.t_req_h, 1.6 * space.base_distance_nm / slow)
        return cls(problem=problem, space=space, weather=weather, rpm_options=np.array(problem.rpm_options),
                   vp=vp, speed_coef=m.speed_coef, fuel_coef=m.fuel_coef,
                   t_dep_h=weather.hours_after_ref(problem.depart_utc), max_hours=float(max_hours),
                   obj=OBJECTIVES[problem.objective])

    def numba_weather(self) -> tuple:
        return self.weather.values, self.weather.times_h, self.weather.grid

    def numba_args(self) -> tuple:
        """(lat, lon, edge_ok, rpm_options, t_dep_h, max_hours, vp, sc, fc, wx, times, grid, obj, t_req, window, f_target, early, late)."""
        p = self.problem
        return (self.space.lat, self.space.lon, self.space.edge_ok, self.rpm_options, self.t_dep_h, self.max_hours,
                self.vp, self.speed_coef, self.fuel_coef, *self.numba_weather(), self.obj, p.t_req_h, p.window_h,
                self.f_target, p.early_t_per_h, p.late_t_per_h)


def _check_coverage(problem: RoutingProblem, space: SearchSpace, weather: WeatherField) -> None:
    """The weather must cover every usable node (a regional field must not be silently extrapolated)."""
    lat = space.lat[space.node_ok]
    lon = space.lon[space.node_ok]
    lo, hi = weather.lat_range_deg
    tol = weather.grid[1]
    if lat.min() < lo - tol or lat.max() > hi + tol:
        raise RoutingInputError(
            f"voyage {problem.voyage_id}: its search area spans latitudes {lat.min():.1f}..{lat.max():.1f} but the "
            f"weather covers only {lo:.1f}..{hi:.1f}")
    if weather.grid[6] < 0.5:
        lon0, dlon, nlon = weather.grid[3], weather.grid[4], int(weather.grid[5])
        rel = (lon - lon0) % 360.0
        if np.any(rel > dlon * (nlon - 1) + dlon):
            raise RoutingInputError(
                f"voyage {problem.voyage_id}: its search area leaves the weather's longitudes "
                f"{lon0:.1f}..{lon0 + dlon * (nlon - 1):.1f}")
