"""One voyage to route: the typed job a fleet run sends to a worker, and the plan made from it.

`RouteJob` carries plain rows (voyage, vessel, active model as JSON) so it pickles cheaply to any
worker; `RoutingOptions` holds the solver settings of the run. `plan_voyage` is the whole per-voyage
science: problem → search space → its weather (only the window of the forecast it can meet) → solve.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from pipeline.performance.model import PerformanceModel
from pipeline.routing import calibration, robust
from pipeline.routing import weather_field as wf
from pipeline.routing.base_route import with_base_route
from pipeline.routing.options import RoutingOptions
from pipeline.routing.plan import Plan
from pipeline.routing.problem import RoutingInputError, RoutingProblem
from pipeline.routing.search_space import SearchSpace
from pipeline.routing.solve import solve
from pipeline.routing.solvers import solver_spec
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
    # a voyage at sea: its current plan's legs (lat0, lon0, lat1, lon1, rpm, wait_h, wait_fuel_t, etd_utc, eta_utc),
    # which a re-plan replaces only when it gains more than its spread (options.replan_gain_sigmas; kept_or_replanned)
    current_legs: tuple = ()
    # how far plans realised from their claims (calibration.fit_error_model over plan_verification; None: not read):
    # sizes the arrival margin by the hours ahead and the plan's spread (calibration.in_effect says when it applies)
    error_model: calibration.ErrorModel | None = None

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
                 savings=True, continuous=o.continuous_speed, refine_split=o.refine_split)
    for note in (problem.rpm_note, problem.model.envelope_note(plan.legs, problem.draft_m)):
        if note:
            plan.add_reason(note)
    return plan, weather


def robust_plan(job: RouteJob, plan: Plan, weather: wf.WeatherField, weather_for: WeatherFor | None,
                members: list[wf.WeatherField]) -> tuple[Plan, wf.WeatherField]:
    """The plan after the robust decisions the job's options ask for (robust.py), over the lagged ensemble `members`:
    re-planned to arrive `arrival_margin_sigmas` standard deviations before the RTA (the plan keeps the voyage's RTA and
    says what it aims at; kept as it was when the earlier arrival cannot be met), then replaced by its constant-speed
    baseline unless it beats it in `min_win_share` of the members. σ is that of the arrival error by the hours ahead
    (calibration.py: `job.error_model` where calibration.in_effect allows it, saying which model in the reason), else
    that of the plan's arrival across the members. A plan aiming before the RTA claims its saving against the
    constant speed arriving at the RTA (robust.margin_charged: the margin's cost in `margin_cost_pct`). With fewer
    than two members and no error model calibrated from verified plans, or the options at 0, the plan is returned as
    it is."""
    o = job.options
    model = calibration.in_effect(job.error_model, len(members))
    if not plan.legs or not (o.arrival_margin_sigmas > 0 or o.min_win_share > 0) or (len(members) < 2 and model is None):
        return plan, weather
    vessel = routing_problem(job).kernel_vessel()
    if model is not None:  # split by the forecast's severity: the part for this route (the plan made for the RTA)
        model = model.given(calibration.route_hs_mean_m(plan.legs))
    rta = np.datetime64(plan.rta_utc, "s")
    ahead_h = float((rta - np.datetime64(plan.depart_utc, "s")) / np.timedelta64(1, "s")) / 3600.0
    if model is not None:
        reserve_h = robust.speed_reserve_h(plan, weather, vessel) if o.arrival_margin_horizon_h is not None else 0.0
        margin_h = calibration.arrival_margin_h(model, ahead_h, o.arrival_margin_sigmas, o.arrival_margin_max_share,
                                                o.arrival_margin_horizon_h, reserve_h)
        error_h = calibration.margin_error_h(ahead_h, o.arrival_margin_horizon_h)
        bias_h = max(model.eta_bias_h(error_h), 0.0)
        why = ((f"its mean lateness {bias_h:.1f} h + " if bias_h >= 0.05 else "")
               + f"{o.arrival_margin_sigmas:g} × σ {model.eta_sd_h.at(error_h):.1f} h of the arrival error "
               f"{error_h:.0f} h ahead; {model.note()}")
        if o.arrival_margin_horizon_h is not None:
            why = (f"{why}; or what of the whole passage's error its speed reserve of {reserve_h:.1f} h cannot make "
                   "up, whichever is more")
    else:
        margin_h = robust.arrival_margin_h(plan, members, vessel, o.arrival_margin_sigmas, o.arrival_margin_max_share)
        why = f"{o.arrival_margin_sigmas:g} × the spread of its arrival across {len(members)} forecasts"
    at_rta = None  # the plan made for the RTA, whose baseline the claim is made against when the plan aims earlier
    if margin_h >= 1.0 / 60.0:
        aim = rta - np.timedelta64(int(round(margin_h * 3600.0)), "s")
        aimed, aimed_weather = plan_voyage(replace(job, voyage={**job.voyage, "rta_utc": aim}), weather_for)
        note = f"aims {margin_h:.1f} h before the RTA ({why})"
        if robust.aim_reached(aimed, rta):
            if aimed.status != "ok":  # the earliest it can make: still before the RTA
                early_h = float((rta - np.datetime64(aimed.legs[-1]["eta_utc"], "s")) / np.timedelta64(1, "s")) / 3600
                note += f"; can arrive only {early_h:.1f} h before it"
            for p in (aimed, aimed.baseline):  # on time means by the RTA, in the members too
                if p is not None:
                    p.rta_utc = rta
            aimed.status = "ok"
            aimed.add_reason(note)
            at_rta, plan, weather = plan, aimed, aimed_weather
        else:
            note = f"could not aim {margin_h:.1f} h before the RTA ({aimed.status}): planned for the RTA itself"
            plan.add_reason(note)
    if o.min_win_share > 0 and len(members) >= 2:  # against the constant speed arriving when the plan aims
        wins = robust.wins_across(plan, members, vessel)
        if not wins.preferred(o.min_win_share) and plan.baseline is not None and plan.baseline.legs:
            plan = robust.baseline_kept(plan, wins, o.min_win_share)
    if at_rta is not None:
        plan = robust.margin_charged(plan, at_rta)
    return plan, weather


def plan_spread(job: RouteJob, plan: Plan, members: list[wf.WeatherField]):
    """The plan's spread (plan.Spread): across the members, or, where the job's error model is in effect
    (calibration.in_effect), from that model around what it expects the plan to realise (calibration.calibrated_spread;
    the plan's reason then says which model and the expected saving). None without either."""
    from pipeline.routing.ensemble import spread  # noqa: PLC0415

    ens = spread(plan, members, routing_problem(job).kernel_vessel()) if members else None
    model = calibration.in_effect(job.error_model, len(members))
    if model is None or not plan.legs:
        return ens
    model = model.given(calibration.route_hs_mean_m(plan.legs))
    s = calibration.calibrated_spread(plan, ens, model)
    note = (f"expected to realise a saving of {s.savings_p50_pct:.1f} % (P10–P90 {s.savings_p10_pct:.1f} to "
            f"{s.savings_p90_pct:.1f} %; {model.note()})")
    if note not in (plan.reason or ""):
        plan.add_reason(note)
    return s


def kept_or_replanned(job: RouteJob, plan: Plan, weather: wf.WeatherField, members: list[wf.WeatherField]) -> Plan:
    """For a voyage re-planned at sea with a current plan (`job.current_legs`) and `replan_gain_sigmas` > 0: the new
    plan when it is on time in more members of the lagged ensemble than the current plan's legs ahead of the ship,
    or gains more fuel than that many standard deviations of its gain across them (robust.replan_decision); else
    the current plan's route ahead, re-timed to the RTA in this cycle's weather (robust.retimed), saying why.
    Otherwise the plan as it is."""
    k = job.options.replan_gain_sigmas
    if k <= 0 or not job.current_legs or job.voyage.get("start_kind") in (None, "port") or not plan.legs \
            or len(members) < 2:
        return plan
    vessel = routing_problem(job).kernel_vessel()
    ahead = robust.legs_ahead(list(job.current_legs), plan.depart_utc, plan.legs[0]["lat0"], plan.legs[0]["lon0"])
    ahead = robust.retimed(ahead, plan.depart_utc, plan.rta_utc, weather, vessel)  # its route, re-timed to the RTA
    decision = robust.replan_decision(ahead, plan, members, vessel, k)
    if decision.take_new:
        plan.add_reason(decision.reason)
        return plan
    kept = robust.current_plan_kept(plan, ahead, weather, vessel, decision.reason) if ahead else None
    return kept if kept is not None else plan
