"""One entry point for every solver: `solve(problem, weather, solver=…, seed=…)` → `Plan`.

Solvers (the registry in solvers.py, the contract in contract.py): `bfoa` (default, improved BFOA), `dp`
(dynamic programming on the same graph), `astar` (A* with the α sweep), `gc` and `rhumb` (the constant-speed
voyage: the shortest sea route along the great-circle / rhumb-line graph at the one constant rpm that meets the
RTA).

Speed is a decision between the lowest and the highest allowed rpm, not only the listed settings: the solvers
choose per leg from the listed settings plus the constant rpm at which the base route arrives at the RTA
(baseline.constant_rpm_for_rta), so a voyage too short to change setting sails one well-chosen rpm. That
constant-speed voyage is every plan's `baseline`, and it is a plan of every solver's space: a solver whose plan
(with its engine-change limits, engine_limits.py) costs more than it, or than the best engine plan on the base
route, returns that plan instead and says so, so no plan on time burns more than the ship would at constant
speed. With engine-change limits the solver's route is re-planned so every setting is held; `unlimited_fuel_t`
is the best engine plan on the same route without them, for what the limits cost. The savings against the
constant-speed voyage are split into speed profile and route (savings.py).

A solver whose plans wait at nodes (`dp` with `slot_h`, the grid DP that is exact when the weather changes in time,
dp_grid.py) hands its waits over in Found.wait_h: the plan's legs carry them (wait_h, wait_fuel_t, etd after the
wait) and its hours, fuel and cost include them; `_waiting_plan_limits` says what the engine-change limits do to it.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from pipeline.routing.engine import leg as lk
from pipeline.routing.base_route import with_base_route
from pipeline.routing.baseline import Baseline, baseline as find_baseline, constant_rpm_route, evaluate, shortest_route
from pipeline.routing.bfoa import BfoaParams
from pipeline.routing.canal_time import passages_note
from pipeline.routing.clearance import least_clearance_outside_nm, widest_corridor_nm
from pipeline.routing.options import DpOptions
from pipeline.routing.continuous_speed import as_settings
from pipeline.routing.engine_limits import PLAN_GAP, REFERENCE_BUCKETS, EngineLimits, settings_held_h
from pipeline.routing.objectives import route_cost_nb
from pipeline.routing.options import RoutingOptions
from pipeline.routing.plan import Plan, legs_of_route
from pipeline.routing.problem import Instance, RoutingInputError, RoutingProblem
from pipeline.routing.refine_graph import refine_route
from pipeline.routing.route_speeds import Start, best_speeds
from pipeline.routing.savings import solver_instance, split_of
from pipeline.routing.search_space import SearchSpace, VoyageGeometryError, reachable
from pipeline.routing.solvers import solver_spec
from pipeline.routing.weather_field import WeatherField

# the product's defaults (options.RoutingOptions and options.DEFAULT_SOLVER_OPTIONS): what `jitroute route`,
# route-fleet and the dask workers plan with (job.plan_voyage), and what solve() plans with when not told otherwise
PRODUCT = RoutingOptions()
_evaluate = evaluate  # the name tests and scripts have used


def _plan(inst: Instance, solver: str, nodes, rpm_idx, *, seed=None, t0=0.0, history=None, n_evals=0,
          reason_if_infeasible: str | None = None, clearance_nm: float | None = None, wait_h=None,
          wait_tph: float = 0.0) -> Plan:
    """The plan of a route and its engine settings, waiting wait_h[i] hours at line i's node before leg i when
    given (burning `wait_tph`); `clearance_nm`, when known (the same route planned before), is taken as its least
    distance to land instead of tracing the legs again."""
    p = inst.problem
    plan = Plan(voyage_id=p.voyage_id, imo=p.imo, solver=solver, objective=p.objective, status="infeasible",
                reason=reason_if_infeasible, depart_utc=p.depart_utc, rta_utc=p.rta_utc, seed=seed, history=history,
                n_evals=n_evals, model_version=p.model.version, cycle=inst.weather.cycle)
    if nodes is not None:
        legs, code, bad_leg = legs_of_route(inst, nodes, rpm_idx, wait_h, wait_tph)
        if code == lk.OK:
            plan.legs = legs
            if clearance_nm is not None:
                plan.min_land_clearance_nm = clearance_nm
            elif inst.space.clearance is not None:
                plan.min_land_clearance_nm = least_clearance_outside_nm(plan.waypoints, inst.space.clearance,
                                                                        inst.space.gate)
            if wait_h is None:
                plan.cost, _, _, _ = evaluate(inst, nodes, rpm_idx)
            else:  # the legs as sailed after their waits, and the waits' fuel
                plan.cost = float(route_cost_nb(inst.objective, plan.hours, plan.fuel_t))
            late_h = plan.hours - p.t_req_h
            if late_h > 1e-6:
                plan.status = "late"
                plan.reason = f"RTA cannot be met: arrives {late_h:.1f} h late at the fastest feasible plan"
            else:
                plan.status = "ok"
                early_h = p.t_req_h - p.window_h - plan.hours
                plan.reason = f"arrives {early_h:.1f} h before the arrival window" if early_h > 1e-6 else None
            notes = []
            through = passages_note(inst.space)
            if through:
                notes.append(through)
            if plan.wait_h > 1e-9:
                waited = [(leg["leg"], leg["wait_h"]) for leg in plan.legs if leg["wait_h"] > 1e-9]
                where = ", ".join(f"{h:.1f} h before leg {i}" for i, h in waited[:5]) + (", …" if len(waited) > 5 else "")
                notes.append(f"waits {plan.wait_h:.1f} h hove to ({where}; {sum(leg['wait_fuel_t'] for leg in plan.legs):.2f} t)")
            if plan.hours_beyond_forecast > 1e-9:
                n = plan.n_beyond_forecast
                notes.append(f"{plan.hours_beyond_forecast:.1f} h of the voyage ({n} leg{'s' if n != 1 else ''}) beyond "
                             f"the forecast horizon {inst.weather.horizon_utc} (sailed in the region's mean wind and waves from "
                             "near the beam, the same for every route)")
            no_wind = [leg["leg"] for leg in plan.legs if leg.get("hours_without_wind", 0.0) > 1e-9]
            if no_wind:
                hours = sum(leg.get("hours_without_wind", 0.0) for leg in plan.legs)
                notes.append(f"weather missing: no wind data for {hours:.1f} h on leg{'s' if len(no_wind) != 1 else ''} "
                             f"{', '.join(map(str, no_wind))} (a hole in cycle {inst.weather.cycle}, sailed as calm; "
                             "re-ingest the cycle)")
            if plan.hours_before_cycle > 1e-9:
                notes.append(f"{plan.hours_before_cycle:.1f} h of the voyage before the forecast cycle "
                             f"{inst.weather.cycle} (its first step used)")
            if notes:
                note = "; ".join(notes)
                plan.add_reason(note)
        else:
            plan.reason = f"leg {bad_leg}: {lk.REASONS[code]}"
    plan.runtime_s = time.perf_counter() - t0
    return plan


def _infeasible_reason(base: Baseline | None, space: SearchSpace) -> str:
    if base is None or base.nodes is None:
        reason = "no route at sea between the ports inside the search corridor and limits"
        rule = space.clearance
        widest = widest_corridor_nm(rule) if rule is not None and rule.clearance_nm > 0.0 else None
        if widest is not None and widest < rule.clearance_nm:
            reason += (f": the widest corridor at sea between them keeps about {widest:.1f} NM from land, less than "
                       f"the {rule.clearance_nm:g} NM asked (routing.land_clearance_nm; a strait narrower than twice "
                       "the clearance is closed); route it with a smaller clearance if its fairway allows")
        return reason
    return f"every route is blocked; the shortest sea route fails: {lk.REASONS.get(base.code, 'unknown')}"


def _check_forecast(problem: RoutingProblem, weather: WeatherField) -> None:
    """Refuse a departure after the forecast's last valid time: every leg would sail on persisted weather."""
    if problem.depart_utc > weather.horizon_utc:
        cycle = weather.cycle if weather.cycle is not None else weather.t_ref
        late_h = float((problem.depart_utc - weather.horizon_utc) / np.timedelta64(1, "s")) / 3600.0
        raise RoutingInputError(
            f"voyage {problem.voyage_id}: departs {problem.depart_utc}, {late_h:.1f} h after the last valid time "
            f"{weather.horizon_utc} of the forecast cycle {cycle}; route it with a later cycle")


def product_options(solver: str, refine_split: int = PRODUCT.refine_split):
    """The solver's own options as the product runs them: its options class's defaults with the product's
    (options.DEFAULT_SOLVER_OPTIONS, and REFINED_SOLVER_OPTIONS with `refine_split` > 1) over them, e.g. `dp`
    certified within 0.1 % over plans that may wait."""
    return solver_spec(solver).make_options(RoutingOptions(solver=solver, refine_split=refine_split).solver_overrides())


def _options(spec, options, params: BfoaParams | None, refine_split: int):
    """The solver's options: `options` as given, else the shorthand `params` (BfoaParams) when they are of this
    solver's kind, else the product's for that refinement (product_options)."""
    if options is None:
        if params is not None and isinstance(params, spec.options):
            options = params
        else:
            options = product_options(spec.name, refine_split)
    if not isinstance(options, spec.options):
        raise RoutingInputError(f"solver {spec.name!r} takes {spec.options.__name__} options, not {type(options).__name__}")
    return options


def _unlimited_fuel_t(inst: Instance, nodes, known: list[Start], continuous: bool) -> float:
    """Fuel of the best engine plan on the route without limits: the route's bucketed DP over the settings, pruned by
    the cheapest `known` plan of that route (its cost without change costs; it is the answer when nothing beats it),
    with `continuous` its speeds refined (route_speeds.best_speeds, no hold, no change cost)."""
    start = min(known, key=lambda k: k.cost)
    return best_speeds(inst, nodes, None, continuous, start=start, gap=PLAN_GAP, buckets=REFERENCE_BUCKETS).fuel_t


def _with_limits(inst: Instance, plan: Plan, nodes, limits: EngineLimits, continuous: bool = True,
                 known: dict | None = None) -> Plan:
    """The plan re-planned on its own route so each engine setting is held (route_speeds.best_speeds: within 0.1 % of the
    best such plan over the settings and never dearer than a setting held throughout; `known` as there), its speeds
    then refined continuously (`continuous`). For what the limits cost, `unlimited_fuel_t` is the best engine plan on
    the route without limits, so the limits never seem to save fuel and are not blamed for what the solver left on
    its route."""
    best = best_speeds(inst, nodes, limits, continuous, known=known)
    held = best.held
    if held is None or not np.isfinite(held.cost):
        return plan  # no plan of the route holds its settings (a leg cannot be sailed at some setting)
    (at, rpm_idx), cost = best.as_plan_settings(inst), best.cost
    limited = _plan(at, plan.solver, nodes, rpm_idx, seed=plan.seed, history=plan.history,
                    n_evals=plan.n_evals + held.legs_sailed, clearance_nm=plan.min_land_clearance_nm)
    limited.cost = cost
    limited.limits = limits
    rpm_of = lambda p: np.array([leg["rpm"] for leg in p.legs])  # noqa: E731
    known = [Start(inst.rpm_options[held.rpm_idx], held.cost - limits.change_cost_t * held.n_changes, held.fuel_t),
             Start(rpm_of(limited), cost - limits.change_cost_t * limited.n_engine_changes, limited.fuel_t)]
    if plan.legs:
        known.append(Start(rpm_of(plan), plan.cost, plan.fuel_t))
    limited.unlimited_fuel_t = _unlimited_fuel_t(inst, nodes, known, continuous)
    if limited.status == "late" and plan.status == "ok":
        limited.reason = (f"RTA cannot be met holding each engine setting {limits.min_hold_h:g} h: arrives "
                          f"{limited.hours - inst.problem.t_req_h:.1f} h late (without the limits on time, "
                          f"{plan.fuel_t:.1f} t)")
    return limited


def _waiting_plan_limits(inst: Instance, plan: Plan, nodes, limits: EngineLimits | None, continuous: bool) -> Plan:
    """A plan that waits at nodes (the grid DP's) under the engine-change limits. Its waits are kept when its
    settings are already held: a wait is sailed as a pause of the setting around it (hove to, the order is not
    changed), so holds count the hours sailed; the change cost is added per change. Otherwise its route is
    re-planned wait-free with the limits as any solver's (_with_limits), and the plan says the waits were given up.
    Where a storm blocks every wait-free plan of the route that holds, the waiting plan is kept without the limits
    (`limits` None) and says which hold it breaks. Speeds are not refined continuously on a plan that waits (the
    refinement sails wait-free)."""
    if limits is None or not limits.active:
        return plan
    runs = settings_held_h(plan.legs)
    shortest = min(h for _, h in runs)
    if len(runs) == 1 or shortest >= limits.min_hold_h - 1e-9:  # a voyage of one setting always holds it
        plan.limits = limits
        plan.unlimited_fuel_t = plan.fuel_t  # the waiting plan is the solver's own optimum: the limits cost nothing
        plan.cost += limits.change_cost_t * plan.n_engine_changes
        return plan
    note = (f"the {plan.solver} plan waits {plan.wait_h:.1f} h ({plan.fuel_t:.1f} t) but changes setting within "
            f"{limits.min_hold_h:g} h: re-planned wait-free holding each setting")
    # the wait-free re-plan is compared with nothing of the waiting plan's (its fuel is not a plan of that route)
    held = _with_limits(inst, replace(plan, legs=[], status="infeasible"), nodes, limits, continuous)
    if not held.legs:  # no wait-free plan of the route holds its settings (a storm blocks it): the waiting plan stays
        note = (f"holds a setting only {shortest:.1f} h (less than the {limits.min_hold_h:g} h asked): no wait-free "
                "plan of its route holds each setting")
        plan.add_reason(note)
        return plan
    held.add_reason(note)
    return held


def _never_worse(inst: Instance, plan: Plan, baseline: Plan, base: Baseline, limits: EngineLimits | None, profile,
                 t0: float, continuous: bool = True) -> Plan:
    """The solver's plan, or the constant-speed voyage `baseline` (or `profile`, (rpm per leg, cost) of the best
    engine plan on the base route under the limits) when that costs less: both are plans of every solver's space,
    so no plan burns more than sailing at constant speed. The plan kept says so in its reason."""
    if not base.ok or not baseline.legs:
        return plan
    const_rpm = baseline.legs[0]["rpm"]
    candidates = [(f"the base route at constant {const_rpm:.1f} rpm", inst.rpm_options[base.rpm_idx], baseline.cost)]
    if profile is not None and np.isfinite(profile.cost):
        candidates.append(("the best engine plan on the base route", profile.rpm, profile.cost))
    what, rpm, cost = min(candidates, key=lambda c: c[2])
    if plan.legs and plan.cost <= cost * (1.0 + 1e-9) + 1e-12:
        return plan
    at, rpm_idx = as_settings(inst, rpm)
    # the base route's clearance is the baseline's: the legs are not traced against the land again
    kept = _plan(at, plan.solver, base.nodes, rpm_idx, seed=plan.seed, t0=t0, history=plan.history,
                 n_evals=plan.n_evals, clearance_nm=baseline.min_land_clearance_nm)
    if not kept.legs:
        return plan
    if limits is not None and limits.active:
        n_changes = kept.n_engine_changes
        kept.limits = limits
        kept.unlimited_fuel_t = _unlimited_fuel_t(
            inst, base.nodes, [Start(rpm, kept.cost, kept.fuel_t),
                               Start(rpm, cost - limits.change_cost_t * n_changes, kept.fuel_t)], continuous)
        kept.cost = cost if n_changes else kept.cost
    found = (f"the {plan.solver} plan ({plan.fuel_t:.1f} t, {plan.status}) cost more" if plan.legs
             else f"the {plan.solver} search found no plan ({plan.reason})")
    note = f"{found}: kept {what}"
    kept.add_reason(note)
    return kept


def solve(problem: RoutingProblem, weather: WeatherField, *, solver: str = PRODUCT.solver, seed: int = PRODUCT.seed,
          options=None, params: BfoaParams | None = None, space: SearchSpace | None = None,
          limits: EngineLimits | None = PRODUCT.limits, savings: bool = True,
          continuous: bool = PRODUCT.continuous_speed, refine_split: int = PRODUCT.refine_split) -> Plan:
    """Route one voyage. Never raises for a voyage that simply cannot be sailed: the plan says why.

    Every default is the product's (`PRODUCT`, options.RoutingOptions): `solve(problem, weather, solver="dp")` gives
    the plan `jitroute route --solver dp`, route-fleet and the workers give (job.plan_voyage calls this with the
    run's options). `options` are the solver's own (solvers.SOLVERS[solver].options; default product_options);
    `params` (BfoaParams, for bfoa) are a shorthand for them. With `limits`
    (engine_limits.EngineLimits; None: none) the solver's route gets the best engine plan holding each setting;
    `savings` adds the split against the constant-speed voyage (savings.py) to the plan and lets the best engine
    plan on the base route compete in never-worse. A `space` laid along another base route than the solver's
    (`rhumb`) is refused; without a `space`, the problem's lines are laid along the global sea route when its great
    circle crosses land (base_route.py), as for every voyage the CLI and the fleet runs route. With `continuous` the speeds of the solver's plan and of the best engine plan on the base
    route are refined continuously between the lowest and the highest allowed rpm (continuous_speed.py); without it
    plans use only the settings. With `refine_split` > 1 the solver's route (unless its plan waits at nodes) is first
    searched again on corridors that many times finer across the lines round it (refine_graph.py), and the plan is
    the cheaper of the two; 1: the graph's plan. The bare search (the solver's options class's defaults, no limits,
    no savings, the graph itself) is `solve(..., options=SOLVERS[solver].options(), limits=None, savings=False,
    refine_split=1)`.
    """
    spec = solver_spec(solver)
    opts = _options(spec, options, params, refine_split)
    _check_forecast(problem, weather)
    t0 = time.perf_counter()
    if space is None:
        if problem.base_route is None and spec.base == "gc":  # the base route every entry point decides alike
            try:
                problem = with_base_route(problem, replace(PRODUCT, solver=solver,
                                                           land_clearance_nm=problem.land_clearance_nm,
                                                           port_approach_nm=problem.port_approach_nm))
            except VoyageGeometryError:  # no sea route: the great circle's lines, whose plan then says why not
                pass
        space = (replace(problem, base=spec.base) if spec.base != problem.base else problem).search_space()
    elif space.base != spec.base:
        raise RoutingInputError(f"voyage {problem.voyage_id}: solver {solver!r} routes along the {spec.base} base route, "
                                f"but the search space given is laid along the {space.base}")
    inst, base_nodes = solver_instance(problem, space, weather)
    base = find_baseline(inst, base_nodes) if base_nodes is not None else Baseline(None, None, lk.NO_EDGE)
    if base.ok:
        inst.f_target = max(float(evaluate(inst, base.nodes, base.rpm_idx)[2]), 1e-6)
    why_not = _infeasible_reason(base, space)  # what a plan that cannot be sailed says
    baseline = _plan(inst, space.base, base.nodes, base.rpm_idx, t0=t0, reason_if_infeasible=why_not)
    known: dict = {}  # the routes planned under the limits (route_speeds.best_speeds): the base route's once
    profile = best_speeds(inst, base.nodes, limits, continuous, known=known) if savings and base.ok else None
    if spec.is_baseline:  # the constant-speed voyage itself: the plan just made, compared with nothing
        plan = baseline
        plan.solver = solver
    elif not reachable(space):
        plan = _plan(inst, solver, None, None, seed=seed, t0=t0, reason_if_infeasible=why_not)
    else:
        found = spec.search(inst, base, seed=int(seed), options=opts)
        waits = found.waits
        at, nodes, rpm_idx, n_evals = inst, found.nodes, found.rpm_idx, found.n_evals  # the plan's graph and route
        refined = None
        if refine_split > 1 and not waits and nodes is not None and rpm_idx is not None:
            refined = refine_route(inst, nodes, rpm_idx, refine_split)
            if refined is not None:
                at, nodes, rpm_idx = refined.inst, refined.nodes, refined.rpm_idx
                n_evals += refined.legs_sailed // max(len(nodes) - 1, 1)  # legs sailed, counted as whole routes
        plan = _plan(at, solver, nodes, rpm_idx, seed=seed if spec.seeded else None, t0=t0,
                     history=found.history, n_evals=n_evals, reason_if_infeasible=why_not,
                     wait_h=found.wait_h if waits else None, wait_tph=found.wait_tph)
        if waits and plan.legs and found.note:  # what the solver's space is, e.g. the grid its waits are on
            plan.add_reason(found.note)
        if waits and plan.legs:
            plan = _waiting_plan_limits(inst, plan, nodes, limits, continuous)
        elif limits is not None and limits.active and plan.legs:  # `known` holds routes of the graph, not a corridor's
            plan = _with_limits(at, plan, nodes, limits, continuous, known if refined is None else None)
        elif continuous and plan.legs:
            own = Start(at.rpm_options[rpm_idx], plan.cost, plan.fuel_t)
            best = best_speeds(at, nodes, None, continuous, start=own, search=False)
            if best.cost < plan.cost:
                at2, idx2 = best.as_plan_settings(at)
                plan = _plan(at2, solver, nodes, idx2, seed=plan.seed, t0=t0, history=plan.history,
                             n_evals=plan.n_evals, clearance_nm=plan.min_land_clearance_nm)
        if not waits and plan.legs and found.note:  # e.g. how the search was narrowed (dp's capped label search)
            plan.add_reason(found.note)
        if refined is not None and plan.legs:
            n = refined.rounds
            plan.add_reason(f"then searched again on {n} corridor{'s' if n > 1 else ''} {refine_split}× finer across the "
                            f"lines round its route: {refined.gain_pct:.2f} % cheaper than the graph's plan over the "
                            "settings")
        plan = _never_worse(inst, plan, baseline, base, limits, profile, t0, continuous)
    plan.baseline = None if spec.is_baseline else baseline
    if savings and plan.legs and base.ok:
        plan.savings = split_of(inst, base.nodes, plan.fuel_t, plan.limits, profile,
                                plan_fuel_beyond_t=plan.fuel_beyond_forecast_t)
    plan.runtime_s = time.perf_counter() - t0
    return plan


__all__ = ["solve", "product_options", "PRODUCT", "solver_spec", "RoutingProblem", "RoutingInputError", "VoyageGeometryError", "BfoaParams", "DpOptions",
           "Plan", "shortest_route", "constant_rpm_route", "EngineLimits"]
