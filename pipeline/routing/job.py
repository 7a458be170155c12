"""One voyage to route: the typed job a fleet run sends to a worker, and the plan made from it.

`RouteJob` carries plain rows (voyage, vessel, active model as JSON) so it pickles cheaply to any
worker; `RoutingOptions` holds the solver settings of the run. `plan_voyage` is the whole per-voyage
science: problem → search space → its weather (only the window of the forecast it can meet) → solve.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from pipeline.performance.model import PerformanceModel
from pipeline.routing import weather_field as wf
from pipeline.routing.base_route import with_base_route
from pipeline.routing.options import RoutingOptions
from pipeline.routing.plan import Plan
from pipeline.routing.problem import RoutingInputError, RoutingProblem
from pipeline.routing.search_space import SearchSpace
from pipeline.routing.solve import solve, solver_spec
from pipeline.routing.voyage import problem_from_voyage


@dataclass(frozen=True)
class RouteJob:
    """A voyage of a run: warehouse rows as plain dicts, the vessel's active model as JSON (None: no model; then
    `model_note` says why, e.g. a model stored by an older form definition)."""

    voyage: dict
    vessel: dict
    model: dict | None
    run_id: str
    cycle: str | None  # ISO cycle of the cube, None for calm water
    exports: bool = True
    options: RoutingOptions = field(default_factory=RoutingOptions)
    cycle_version: int | None = None  # the cycle's content version when the run started (storage.cube.cycle_versions)
    model_note: str | None = None  # why there is no usable model (None: the vessel has none)
    debug_plots: bool = False  # export the developer's diagnostics too (the BFOA convergence plot)

    @property
    def voyage_id(self) -> str:
        return str(self.voyage.get("voyage_id"))


def routing_problem(job: RouteJob) -> RoutingProblem:
    """The voyage as a routing problem; RoutingInputError (naming the voyage) when it cannot be routed as given."""
    o = job.options
    if job.model is None:
        raise RoutingInputError(f"voyage {job.voyage_id}: " + (job.model_note or f"vessel {job.voyage.get('imo')} has no active "
                                "performance model; import its noon reports and run `jitroute refit` first"))
    model = PerformanceModel.from_json(job.model)
    problem = problem_from_voyage(job.voyage, model, rpm_max=job.vessel.get("rpm_max"), objective=o.objective,
                                  base=solver_spec(o.solver).base,
                                  window_h=o.arrival_window_h, n_lines=o.n_lines, n_points=o.n_points,
                                  d_point_nm=o.d_point_nm, land_clearance_nm=o.land_clearance_nm,
                                  port_approach_nm=o.port_approach_nm, barred_rpm=job.vessel.get("barred_rpm"))
    return with_base_route(problem, o)  # the one place a voyage's base route is decided (base_route.py)


def calm_weather(problem: RoutingProblem) -> wf.WeatherField:
    """Calm water and no current over the voyage's whole time span (and well beyond its RTA)."""
    return wf.uniform(problem.depart_utc - np.timedelta64(1, "h"), 2.0 * problem.t_req_h + 240.0)


WeatherFor = Callable[[RoutingProblem, SearchSpace], wf.WeatherField]  # the weather of a voyage, given its search space


def plan_voyage(job: RouteJob, weather_for: WeatherFor | None) -> tuple[Plan, wf.WeatherField]:
    """Solve the job in the weather `weather_for(problem, space)` gives (None: calm water). Returns (plan, the
    weather it was planned in).

    Raises RoutingInputError / VoyageGeometryError / KeyError for voyages that cannot be routed as given.
    """
    problem = routing_problem(job)
    space = problem.search_space()
    weather = calm_weather(problem) if weather_for is None else weather_for(problem, space)
    o = job.options
    options = solver_spec(o.solver).make_options(o.solver_overrides())
    # the same function and, unless the run's settings say otherwise, the same values as solve()'s defaults
    plan = solve(problem, weather, solver=o.solver, seed=o.seed, options=options, space=space, limits=o.limits,
                 savings=True, continuous=o.continuous_speed)
    for note in (problem.rpm_note, problem.model.envelope_note(plan.legs, problem.draft_m)):
        if note:
            plan.reason = f"{plan.reason}; {note}" if plan.reason else note
    return plan, weather
