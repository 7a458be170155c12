"""`jitroute route`: plan one voyage (ad hoc or from the warehouse) and compare it with the baseline."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer
from rich.table import Table

from cli.console import console, err_console, fail
from pipeline.routing.options import RoutingOptions


def _latlon(text: str, what: str) -> tuple[float, float]:
    try:
        lat, lon = (float(x) for x in text.split(","))
    except ValueError:
        fail(f"{what} must be LAT,LON in degrees (e.g. 35.4,139.7), not {text!r}")
    if not -90.0 <= lat <= 90.0:
        hint = " (did you give LON,LAT? the order is LAT,LON)" if -90.0 <= lon <= 90.0 else ""
        fail(f"{what}: latitude {lat:g} is outside -90..90{hint}")
    if not -180.0 <= lon <= 360.0:
        fail(f"{what}: longitude {lon:g} is outside -180..360")
    return lat, lon


def _utc(text: str, what: str):
    import numpy as np

    try:
        t = np.datetime64(text.strip().removesuffix("Z"), "s")
        if np.isnat(t):
            raise ValueError(text)
    except ValueError:
        fail(f"{what} {text!r} is not a UTC time; use e.g. 2020-12-01T13 or 2020-12-01T13:30")
    return t


def plan_table(plan) -> Table:
    t = Table(title=f"Voyage {plan.voyage_id}: {plan.solver} plan, status {plan.status}")
    waits = plan.wait_h > 0.0  # a plan that heaves to at nodes (the grid DP's): when it waits before each leg
    cols = ("leg", "from", "to", "course°", "NM", "rpm", "STW kn", "SOG kn", "h", "fuel t") + \
        (("wait h", "ETD (UTC)") if waits else ()) + ("ETA (UTC)", "wind kn", "Hs m", "beyond")
    for col in cols:
        t.add_column(col, justify="right", no_wrap=True)
    for g in plan.legs:
        wait = (f"{g['wait_h']:.1f}" if g["wait_h"] > 0 else "", g["etd_utc"].strftime("%m-%d %H:%M")) if waits else ()
        t.add_row(str(g["leg"]), f"{g['lat0']:.2f},{g['lon0']:.2f}", f"{g['lat1']:.2f},{g['lon1']:.2f}", f"{g['course_deg']:.0f}",
                  f"{g['dist_nm']:.1f}", f"{g['rpm']:.1f}", f"{g['stw_kn']:.2f}", f"{g['sog_kn']:.2f}", f"{g['hours']:.2f}",
                  f"{g['fuel_t']:.2f}", *wait, g["eta_utc"].strftime("%m-%d %H:%M"), f"{g['wind_kn']:.0f}",
                  f"{g['hs_m']:.1f}", "yes" if g["beyond_forecast"] else "")
    return t


def comparison_table(plan) -> Table:
    t = Table(title="Plan vs baseline (great circle, constant rpm)")
    for col in ("", "fuel t", "hours", "NM", "ETA (UTC)", "status"):
        t.add_column(col, justify="right")
    for name, p in ((plan.solver, plan), ("baseline", plan.baseline)):
        if p is None:
            continue
        eta = p.eta_utc.strftime("%Y-%m-%d %H:%M") if p.eta_utc is not None else "-"
        t.add_row(name, f"{p.fuel_t:.2f}", f"{p.hours:.1f}", f"{p.distance_nm:.0f}", eta, p.status)
    return t


def register(app: typer.Typer) -> None:
    @app.command("position")
    def position_cmd(voyage: str = typer.Argument(..., help="Voyage ID (at sea)."),
                     at: str = typer.Option(..., "--at", help="Time of the position, UTC, e.g. 2020-12-01T18."),
                     pos: str = typer.Option(..., "--pos", help="LAT,LON of the ship then."),
                     note: Optional[str] = typer.Option(None, help="Who or what gave it."),
                     data: Optional[Path] = typer.Option(None, "--data", help="Data root (default ./data or $JITROUTE_DATA).")):
        """Give the position of a voyage at sea; the next route-fleet or nightly re-plans it from there (if it is
        newer than the vessel's noon reports)."""
        from flows.jobs.fleet import position_refused
        from flows.settings import load_settings
        from pipeline.validate_ids import name_problem
        from storage import fleet_store

        if name_problem(note):  # kept with the position, shown in logs, tables and exports
            fail(f"--note: {name_problem(note)}; give plain text")
        lat, lon = _latlon(pos, "--pos")
        t = _utc(at, "--at")
        lay = load_settings(data_root=data).layout
        if not lay.warehouse.exists() or fleet_store.load_voyages(lay.warehouse, voyage_ids=[voyage]).empty:
            fail(f"voyage {voyage} is not in {lay.warehouse}: import it with `jitroute fleet import`")
        why = position_refused(lay.warehouse, voyage, t, lat, lon)
        if why:
            fail(f"voyage {voyage}: position not stored: {why}")
        fleet_store.add_position(lay.warehouse, voyage, t, lat, lon, note)
        console.print(f"voyage {voyage}: position {lat:.4f},{lon:.4f} at {str(t)[:16]} UTC stored; the next fleet run "
                      "re-plans it from there")

    @app.command()
    def route(
        from_: Optional[str] = typer.Option(None, "--from", help="Departure LAT,LON (at sea)."),
        to: Optional[str] = typer.Option(None, "--to", help="Destination LAT,LON (at sea)."),
        depart: Optional[str] = typer.Option(None, help="Departure time UTC, e.g. 2020-12-01T00."),
        rta: Optional[str] = typer.Option(None, help="Required time of arrival UTC."),
        imo: Optional[int] = typer.Option(None, help="Vessel (its active performance model is used)."),
        voyage: Optional[str] = typer.Option(None, "--voyage", help="Take the voyage from the warehouse instead."),
        solver: str = typer.Option(RoutingOptions.solver, help="bfoa | dp | astar | gc | rhumb (gc/rhumb: the constant-speed voyage "
                                                "along the great circle / rhumb line)."),
        solver_option: Optional[list[str]] = typer.Option(
            None, "--solver-option", help="NAME=VALUE of the solver's own options, repeatable. dp by default: "
                                          "certified within 0.1 % over plans that may heave to at a node while the "
                                          "weather changes (departures on a 1 h grid, RTA / 240 in whole hours "
                                          "on longer voyages, and at the wait-free DP's "
                                          "times, waits up to 6 h more: slot_h=1 max_wait_h=6); gap=0 keeps every "
                                          "label; slot_h=none is the wait-free DP alone (exact in weather that holds "
                                          "still); past max_label_legs=3000000 legs sailed the wait-free DP keeps at "
                                          "most capped_labels=128 labels per node and the plan says so "
                                          "(max_label_legs=none: no limit)."),
        seed: int = typer.Option(RoutingOptions.seed, help="Random seed of the BFOA (same seed, same plan)."),
        objective: str = typer.Option(RoutingOptions.objective, help="jit (least fuel arriving by the RTA) | thesis."),
        cycle: Optional[str] = typer.Option(None, help="Cube cycle to use (default: newest complete)."),
        calm: bool = typer.Option(False, "--calm", help="Ignore the cube: calm water, no current."),
        ensemble: int = typer.Option(4, "--ensemble", help="Sail the plan and its baseline through this many cycles "
                                                           "(the one routed on and the complete ones before it, valid "
                                                           "at the same times): P(on time), fuel and saving P10/P50/P90. "
                                                           "0: none."),
        avoid: Optional[list[str]] = typer.Option(None, "--avoid", help="A passage to keep out of (suez, panama, "
                                                  "kiel, singapore, gibraltar, …: docs/sea-routes.md), repeatable: "
                                                  "--avoid suez rounds the Cape. Adds to the fleet's "
                                                  "JITROUTE_AVOID_PASSAGES."),
        refine_split: Optional[int] = typer.Option(None, "--refine-split", help="After the search, search the route "
                                                   "again on corridors this many times finer across the lines round "
                                                   "it, while that gains (default 3, routing.refine_split; 1: the "
                                                   "graph's plan as found)."),
        rpm: Optional[str] = typer.Option(None, help="Allowed rpm settings, comma separated (default from the vessel); the search uses them, then each run's rpm is refined anywhere between the lowest and the highest (routing.continuous_speed)."),
        png: Optional[Path] = typer.Option(None, help="Write a map of the route, baseline and weather."),
        convergence: Optional[Path] = typer.Option(None, help="Write the BFOA convergence plot."),
        rtz: Optional[Path] = typer.Option(None, help="Write the plan as RTZ 1.1 (validated against the schema)."),
        as_json: bool = typer.Option(False, "--json", help="Print the plan as JSON for scripts."),
        data: Optional[Path] = typer.Option(None, "--data", help="Data root (default ./data or $JITROUTE_DATA)."),
    ):
        """Plan one voyage: waypoints, rpm per leg and ETAs, compared with the great-circle baseline."""
        import numpy as np

        from flows.jobs.route_worker import planned
        from flows.settings import load_settings
        from pipeline.performance.model import model_from_stored, unusable_reason
        from pipeline.routing.job import RouteJob, RoutingOptions
        from pipeline.sources.cycles import parse_cycle
        from storage import cube_window, export_store, fleet_store

        # Bad input is refused before anything is opened.
        from pipeline.routing.options import RoutingOptions as _Options, UnknownSolverError

        try:
            pairs = [_option_pair(x) for x in solver_option or ()]
            chosen = _Options(solver=solver, solver_options=tuple(pairs), avoid_passages=tuple(avoid or ()),
                              refine_split=_Options.refine_split if refine_split is None else refine_split)
            from pipeline.routing.solvers import SOLVERS

            SOLVERS[solver].make_options(chosen.solver_overrides())
            bad_solver = None
        except (UnknownSolverError, ValueError) as exc:  # an unknown solver, solver option or passage
            bad_solver = str(exc)
        if bad_solver:  # outside the except block: the message is said once, not again for the exception behind it
            fail(bad_solver)
        dep = _latlon(from_, "--from") if from_ is not None else None
        arr = _latlon(to, "--to") if to is not None else None
        t_dep = _utc(depart, "--depart") if depart is not None else None
        t_rta = _utc(rta, "--rta") if rta is not None else None
        if cycle is not None:
            parse_cycle(cycle)
        s = load_settings(data_root=data)
        lay = s.layout
        if not lay.warehouse.exists():
            fail(f"no warehouse at {lay.warehouse}: run `jitroute demo`, or `jitroute fleet import` and `jitroute refit` first")
        if voyage:
            rows = fleet_store.load_voyages(lay.warehouse, voyage_ids=[voyage])
            if rows.empty:
                fail(f"voyage {voyage} is not in {lay.warehouse}")
            v = rows.iloc[0].to_dict()
        else:
            missing = [n for n, x in (("--from", from_), ("--to", to), ("--depart", depart), ("--rta", rta), ("--imo", imo)) if x is None]
            if missing:
                fail(f"give {', '.join(missing)} (or --voyage ID)")
            assert dep is not None and arr is not None  # both given: `missing` is empty
            (la0, lo0), (la1, lo1) = dep, arr
            v = {"voyage_id": "adhoc", "imo": imo, "dep_lat": la0, "dep_lon": lo0, "arr_lat": la1, "arr_lon": lo1,
                 "depart_utc": t_dep, "rta_utc": t_rta, "rpm_options": None}
        if rpm:
            try:
                v["rpm_options"] = [float(x) for x in rpm.split(",")]
            except ValueError:
                fail(f"--rpm must be numbers separated by commas (e.g. 60,70,80), not {rpm!r}")
        vessels = fleet_store.load_vessels(lay.warehouse)
        vessel = vessels[vessels.imo == int(v["imo"])]
        if vessel.empty:
            fail(f"vessel {v['imo']} is not in the warehouse: import it with `jitroute fleet import`")
        vessel = vessel.iloc[0].to_dict()
        stored = fleet_store.active_model(lay.warehouse, int(v["imo"]))
        model = model_from_stored(stored, int(v["imo"]))
        if model is None:
            fail(unusable_reason(stored, int(v["imo"]))
                 or f"vessel {v['imo']} has no active performance model: import its noon reports and run `jitroute refit`")
        cube_path, c, version = None, None, None
        if not calm:
            c = parse_cycle(cycle) if cycle else cube_window.newest_complete_cycle(lay.cube_store)
            if c is None:
                fail(f"no complete forecast cycle in {lay.weather_cube_url}: run `jitroute ingest --cycle …` (or use --calm)")
            version = cube_window.cycle_versions(lay.cube_store).get(c)
        if voyage:  # a ship at sea is planned from its latest position, as route-fleet plans it
            from flows.jobs.fleet import FleetRunError, voyage_start

            try:
                v = {**voyage_start(s, lay.warehouse, voyage, None if c is None else np.datetime64(c, "s")),
                     "rpm_options": v["rpm_options"]}  # as --rpm may have set them
            except FleetRunError as exc:
                fail(str(exc))
            if v.get("start_kind") not in (None, "port"):
                _say(as_json, f"voyage {voyage} is at sea: planned from its {v['start_kind']} at "
                              f"{v['dep_lat']:.4f},{v['dep_lon']:.4f}, {str(v['depart_utc'])[:16]} UTC"
                              + (f" ({v['start_note']})" if v.get("start_note") else ""))
        if not calm:
            cube_path, c = lay.weather_cube_url, str(np.datetime_as_string(np.datetime64(c, "s")))
        job = RouteJob(voyage=v, vessel=vessel, model=model.to_json(), run_id="adhoc", cycle=c, exports=False,
                       options=RoutingOptions.from_settings(s.routing, solver=solver, objective=objective, seed=seed,
                                                            solver_options=tuple(pairs) or None,
                                                            refine_split=refine_split,
                                                            avoid_passages=(*s.routing.avoid_passages, *(avoid or ()))
                                                            or None),
                       cycle_version=version, error_model=None if calm else _error_model(lay.warehouse))
        try:
            with console.status(f"routing {v['voyage_id']} with {solver}…", spinner="dots") if not as_json else _null():
                plan, weather = planned(job, cube_path, lay.storage_options, n_members=max(0, ensemble))
        except KeyError as exc:
            fail(str(exc).strip("'\""))
        if as_json:
            print(json.dumps(plan.to_json(), indent=1))
        else:
            console.print(plan_table(plan))
            console.print(comparison_table(plan))
            sp = plan.savings
            sav = ("n/a" if sp is None else f"{sp.total_pct:.1f} % (speed profile {sp.speed_profile_pct:.1f} %, route "
                   f"{sp.route_pct:.1f} %; within the forecast {sp.forecast_pct:.1f} %, past its last step "
                   f"{sp.beyond_forecast_pct:.1f} %) vs constant {sp.baseline_rpm:.1f} rpm arriving at the RTA")
            lim, land_nm = plan.limits_fuel_t, plan.min_land_clearance_nm
            console.print(f"status [bold]{plan.status}[/]{' — ' + plan.reason if plan.reason else ''}; "
                          f"savings {sav}; engine changes {plan.n_engine_changes}"
                          f"{'' if lim != lim else f' (limits cost {lim:.2f} t)'}; runtime {plan.runtime_s:.2f} s; "
                          f"weather {'calm water' if calm else f'cycle {c}'}"
                          f"{'' if land_nm != land_nm else f'; least distance to land {land_nm:.1f} NM (outside the port approaches)'}")
            if cube_path is not None and ensemble > 0:
                from pipeline.routing.ensemble import describe

                console.print(f"uncertainty {describe(plan.spread)}")
        wanted = {"png": png, "convergence": convergence, "rtz": rtz}
        if plan.legs and any(wanted.values()):
            from pipeline.export import bundle  # matplotlib and lxml only when a file is asked for

            made = bundle.export_plan(plan, weather, vessel, v, kinds=[k for k, path in wanted.items() if path])
            for kind, content in made.files.items():
                target = Path(str(wanted[kind]))
                export_store.write_file(target.parent.resolve(), target.name, content)
                _say(as_json, f"{kind}: {target}")
            for kind, err in made.errors.items():
                console.print(f"[red]{kind} export failed:[/] {err}")
            if made.errors:
                raise typer.Exit(1)
        if not plan.legs and any(wanted.values()):
            err_console.print("no plan, so these files were not written: "
                              + ", ".join(f"{path} (--{kind})" for kind, path in wanted.items()
                                          if path), highlight=False)
        if plan.status in ("infeasible", "failed"):
            raise typer.Exit(3)


def _option_pair(text: str) -> tuple[str, str]:
    """NAME=VALUE of --solver-option as a pair; UnknownSolverError when it is not of that shape."""
    from pipeline.routing.options import UnknownSolverError

    name, sep, value = text.partition("=")
    if not sep or not name.strip():
        raise UnknownSolverError(f"--solver-option must be NAME=VALUE (e.g. gap=0), not {text!r}")
    return name.strip(), value.strip()


def _say(quiet: bool, text: str) -> None:
    if not quiet:
        console.print(text)


class _null:
    def __enter__(self):
        return self

    def __exit__(self, *a):
        return False


def _error_model(db):
    """The forecast-error model of the warehouse's verified plans (flows.jobs.fleet.error_model), as route-fleet uses."""
    from flows.jobs.fleet import error_model

    return error_model(db)
