"""`jitroute route-fleet`, `jitroute nightly`, `jitroute demo`, `jitroute serve`."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer
from rich.table import Table

from cli.console import console
from cli.launch import run_job
DEMO_AT_SEA = (0, 4)  # demo voyages that sailed the day before: re-planned at sea from their noon positions
DataOpt = typer.Option(None, "--data", help="Data root (default ./data or $JITROUTE_DATA).")


def _f(x, fmt="{:.1f}"):
    return "-" if x is None or x != x else fmt.format(x)


def run_table(summary: dict) -> Table:
    t = Table(title=f"Route run {summary.get('run_id')} · cycle {summary.get('cycle')}")
    t.add_column("")
    t.add_column("", justify="right")
    t.add_row("cycle age at the run's time", _f(summary.get("cycle_age_h"), "{:.0f} h"))
    t.add_row("voyages routed", str(summary.get("n")))
    t.add_row("  planned from port / re-planned at sea", f"{summary.get('n_from_port')} / {summary.get('n_replanned')}")
    if summary.get("from_plans"):
        t.add_row("  of which from fleet plans", ", ".join(f"{n} ({p})" for p, n in summary["from_plans"].items()))
    t.add_row("on time / late / not routed", f"{summary.get('n_ok')} / {summary.get('n_late')} / {summary.get('n_failed')}")
    t.add_row("exports failed", str(len(summary.get("export_failures") or [])))
    t.add_row("fuel (t)", _f(summary.get("fuel_t")))
    t.add_row("savings vs constant speed arriving at the RTA", _f(summary.get("savings_total_pct"), "{:.1f} %"))
    t.add_row("  of which speed profile / route", f"{_f(summary.get('savings_speed_profile_pct'), '{:.1f} %')} / "
              f"{_f(summary.get('savings_route_pct'), '{:.1f} %')}")
    t.add_row("  within the forecast / past its last step", f"{_f(summary.get('savings_forecast_pct'), '{:.1f} %')} / "
              f"{_f(summary.get('savings_beyond_forecast_pct'), '{:.1f} %')} "
              f"({summary.get('n_beyond_horizon')} voyages past it)")
    p = summary.get("p_on_time")
    t.add_row("on time across the lagged ensemble (mean of the voyages)", _f(None if p is None else 100 * p, "{:.0f} %"))
    t.add_row("  saving P10 – P90 (fuel-weighted)", f"{_f(summary.get('savings_p10_pct'), '{:.1f} %')} – "
              f"{_f(summary.get('savings_p90_pct'), '{:.1f} %')}")
    if summary.get("n_verified"):
        t.add_row("verified in analysed weather: plans (wholly)",
                  f"{summary.get('n_verified')} ({summary.get('n_verified_whole')})")
        t.add_row("  saving claimed / realised, same plans", f"{_f(summary.get('verified_claimed_savings_pct'), '{:.1f} %')} / "
                  f"{_f(summary.get('realised_savings_pct'), '{:.1f} %')}")
    t.add_row("constant-speed baseline fuel (t), same voyages", _f(summary.get("honest_baseline_fuel_t")))
    t.add_row("engine-change limits cost (t)", _f(summary.get("limits_fuel_t"), "{:.2f}"))
    return t


def problems_table(summary: dict) -> Table | None:
    rows = (summary.get("problems") or []) + (summary.get("stale") or [])
    exports = summary.get("export_failures") or []
    if not rows and not exports:
        return None
    t = Table(title="Voyages needing attention")
    for col in ("voyage", "IMO", "status", "reason"):
        t.add_column(col)
    from rich.text import Text

    from pipeline.validate_ids import printable

    def cell(x) -> Text:  # plain text: no rich markup, control characters shown as escapes
        return Text(printable(x))

    for r in rows:
        t.add_row(cell(r["voyage_id"]), cell(r["imo"]), cell(r["status"]), cell(r["reason"] or ""))
    for line in exports:
        vid, _, err = line.partition(": ")
        t.add_row(cell(vid), "", "export failed", cell(err))
    return t


def show_run(summary: dict, data_root: Path) -> None:
    console.print(run_table(summary))
    p = problems_table(summary)
    if p is not None:
        console.print(p)
    console.print(f"warehouse: {data_root / 'warehouse.duckdb'} (read-only copy for analysts: "
                  f"{data_root / 'warehouse.snapshot.duckdb'})")
    if summary.get("fleet_map"):
        console.print(f"fleet map: {summary['fleet_map']}")
    console.print(f"exports: {summary.get('exports_dir')}")


def show_verification(out: dict, db: Path, run_id: str | None = None) -> None:
    """The verification's outcome: one sentence, and the rows of the plans verified now."""
    from flows.jobs.verify import verification_sentence
    from storage.verification_store import verifications

    if out.get("newest_cycle"):
        console.print(verification_sentence(out) or f"no plan to verify with the analysed weather up to cycle "
                                                    f"{out['newest_cycle']}")
    for why in out.get("skipped") or []:
        console.print(f"[yellow]not verified:[/] {why}", highlight=False)
    if not out.get("n_verified"):
        return
    rows = verifications(db, run_id).head(out["n_verified"])
    t = Table(title="Plans re-sailed in the analysed weather (plan_verification)")
    for col in ("voyage", "run", "coverage", "analysed h", "fuel t claimed / realised", "late h", "saving % claimed / realised"):
        t.add_column(col)
    for r in rows.to_dict("records"):
        t.add_row(str(r["voyage_id"]), str(r["run_id"]), str(r["coverage"]),
                  f"{_f(r['hours_analysed'], '{:.0f}')} of {_f(r['hours_total'], '{:.0f}')}",
                  f"{_f(r['claimed_fuel_t'])} / {_f(r['realised_fuel_t'])}", _f(r["realised_late_h"]),
                  f"{_f(r['claimed_savings_pct'])} / {_f(r['realised_savings_pct'])}")
    console.print(t)


def register(app: typer.Typer) -> None:
    @app.command("route-fleet")
    def route_fleet_cmd(cycle: Optional[str] = typer.Option(None, help="Cube cycle (default: newest complete)."),
                        voyage: Optional[list[str]] = typer.Option(None, "--voyage", help="Only these voyages."),
                        solver: Optional[str] = typer.Option(None, help="bfoa (default) | dp | astar | gc | rhumb."),
                        batch_size: Optional[int] = typer.Option(None, "--batch-size", min=1,
                                                                 help="Voyages per dask task (default: about three "
                                                                      "tasks per worker thread of the live cluster, "
                                                                      "at most 16 voyages each)."),
                        data: Optional[Path] = DataOpt):
        """Route every upcoming voyage, and re-plan every ship at sea from its latest position, on a local dask cluster
        (or $JITROUTE_DASK_ADDRESS); write tables and exports."""
        from flows.jobs.fleet import route_fleet_job
        from flows.settings import load_settings
        from pipeline.sources.cycles import parse_cycle

        if cycle:
            parse_cycle(cycle)
        summary = run_job("flows.fleet", "route_fleet", route_fleet_job, cycle=cycle, voyages=voyage or None,
                          data_root=str(data) if data else None, solver=solver, batch_size=batch_size)
        show_run(summary, load_settings(data_root=data).data_root)

    @app.command()
    def verify(run: Optional[str] = typer.Option(None, "--run", help="Only this routing run's plans (default: every "
                                                                     "stored plan the analysed weather covers)."),
               data: Optional[Path] = DataOpt):
        """Re-sail stored plans and their constant-speed baselines in the analysed weather of the cube's newest cycles
        (each cycle's leads to 6 h): realised fuel and arrival against the claim, in the table plan_verification."""
        from flows.jobs.verify import verify_plans_job
        from flows.settings import load_settings

        out = run_job("flows.fleet", "verify_plans", verify_plans_job, data_root=str(data) if data else None, run_id=run)
        show_verification(out, load_settings(data_root=data).data_root / "warehouse.duckdb", run)

    @app.command()
    def nightly(date: Optional[str] = typer.Option(None, help="Date (UTC, YYYY-MM-DD) whose cycles to ingest; "
                                                              "default the newest published cycles."),
                cycles: Optional[str] = typer.Option(None, help="Cycle hours of --date, e.g. 00,12 (default from settings)."),
                rish_url: Optional[str] = typer.Option(None, help="RISH base URL (default $JITROUTE_RISH_URL)."),
                oscar_url: Optional[str] = typer.Option(None, help="OSCAR base URL (default $JITROUTE_OSCAR_URL)."),
                data: Optional[Path] = DataOpt):
        """The nightly job: ingest the newest published cycles (or a date's), refit models, route the fleet (ships at sea
        from their latest positions). Exit 4 when the newest cycle is older than routing.max_cycle_age_h (36 h)."""
        from flows.jobs.fleet import nightly_job
        from flows.settings import load_settings
        from pipeline.sources.cycles import parse_day, parse_hours

        if date:
            parse_day(date)
        if cycles:
            parse_hours(cycles)
        s = run_job("flows.fleet", "nightly", nightly_job, date=date, data_root=str(data) if data else None,
                    rish_url=rish_url, oscar_url=oscar_url, cycles=cycles)
        _show_nightly(s, load_settings(data_root=data).data_root)

    @app.command()
    def demo(data: Optional[Path] = DataOpt,
             date: str = typer.Option("2020-12-01", help="Demo day (forecast cycles 00 and 12 UTC are generated)."),
             vessels: int = typer.Option(12, help="Number of demo vessels (≥ 10 routes)."),
             workers: int = typer.Option(2, help="Local dask workers for routing."),
             contracts: bool = typer.Option(True, "--contracts/--no-contracts",
                                            help="Also plan demo cargo contracts (`plan fleet`); their legs are routed too.")):
        """Generate a demo mirror and fleet, then run the nightly job on them end to end."""
        import logging
        import os
        import time

        from flows.jobs.fleet import nightly_job
        from flows.settings import load_settings
        from pipeline.sources.cycles import parse_day
        from pipeline.synthetic.fleet import generate_fleet, write_fleet
        from pipeline.synthetic.mirror import write_mirror

        parse_day(date)
        log = logging.getLogger("jitroute.demo")
        t0 = time.monotonic()
        s = load_settings(data_root=data)
        root = s.layout.ensure().root.resolve()
        os.environ["JITROUTE_DASK_WORKERS"] = str(workers)
        mirror = root / "demo_mirror"
        log.info("[demo 1/3] writing the demo RISH/OSCAR mirror (real GRIB2 + NetCDF) in %s", mirror)
        if not (mirror / ".complete").exists():
            def progress(done, total, name=""):
                log.info("[demo 1/3] demo mirror: %d/%d cycles written", done, total)
            write_mirror(mirror, date, date, cycles=(0, 12), seed=0, progress=progress)
            (mirror / ".complete").write_text("ok\n")
        log.info("[demo 2/3] generating the demo fleet (%d vessels, a year of noon reports) and importing it", vessels)
        fleet_dir = root / "demo_fleet"
        fleet = generate_fleet(f"{date}T00", n_vessels=vessels, seed=7, at_sea=DEMO_AT_SEA)
        write_fleet(fleet, fleet_dir)
        _import_fleet(fleet_dir, root)
        if contracts:
            _plan_demo_contracts(fleet, date, fleet_dir / "planning", root)
        log.info("[demo 3/3] the nightly job on %s: ingest → refit → route", date)
        summary = run_job("flows.fleet", "nightly", nightly_job, date=date, data_root=str(root),
                          rish_url=(mirror / "rish").as_uri() + "/", oscar_url=(mirror / "oscar").as_uri() + "/",
                          cycles="00,12")
        _show_nightly(summary, root)
        console.print(f"demo finished in {time.monotonic() - t0:.0f} s")

    @app.command()
    def warm(solver: Optional[list[str]] = typer.Option(None, "--solver",
                                                       help="Solvers to compile (default bfoa, the fleet's; repeat "
                                                            "for more: dp, astar, gc, rhumb).")):
        """Compile the refit, fleet-planning and routing kernels into numba's cache (one folder per digest of the
        pipeline's sources, see docs/development.md) before the first fleet run; `make install` runs it. Quick when
        the cache is already warm."""
        from flows.jobs.warm import warm_job
        from pipeline.routing.solvers import SOLVERS

        unknown = sorted(set(solver or []) - set(SOLVERS))
        if unknown:
            from cli.console import fail

            fail(f"unknown solver(s) {', '.join(unknown)}; use {', '.join(SOLVERS)}")
        out = warm_job(solver or None)
        console.print("kernels ready: " + ", ".join(f"{k} {v:.0f} s" for k, v in out["seconds"].items())
                      + (" (compiled)" if out["compiled"] else " (from the cache)"))

    @app.command()
    def serve(timezone: str = typer.Option("UTC", help="Time zone of the nightly cron (e.g. Europe/Oslo)."),
              nightly_cron: str = typer.Option("30 2 * * *", help="Cron of the nightly deployment (in --timezone)."),
              ingest_cron: Optional[str] = typer.Option(None, help="Cron (UTC) of the ingest deployment; default: when "
                                                                  "each cycle is published (cycle hours + publish delay)."),
              rish_url: Optional[str] = typer.Option(None, help="RISH base URL the deployments fetch from "
                                                               "(default $JITROUTE_RISH_URL or the RISH archive)."),
              oscar_url: Optional[str] = typer.Option(None, help="OSCAR base URL (default $JITROUTE_OSCAR_URL)."),
              drain_s: float = typer.Option(1800.0, "--drain-s", min=0.0, max=86400.0,
                                            help="On SIGTERM, how long in-flight flow runs may finish before they are "
                                                 "cancelled (a second SIGTERM stops at once)."),
              data: Optional[Path] = DataOpt):
        """Register the nightly, ingest and backfill deployments and run their flow runs (needs a Prefect server)."""
        from deploy.serve import check_api, serve_deployments

        check_api()
        serve_deployments(timezone=timezone, nightly_cron=nightly_cron, ingest_cron=ingest_cron,
                          data_root=str(Path(data).resolve()) if data else None, rish_url=rish_url, oscar_url=oscar_url,
                          drain_s=drain_s)


def _import_fleet(folder: Path, root: Path) -> None:
    import logging

    from flows.jobs.refit import import_fleet_folder, import_noon_file

    # validated: refused rows are kept with their reason
    run_job("flows.refit", "import_fleet", import_fleet_folder, folder=str(folder), data_root=str(root))
    c = run_job("flows.refit", "import_noon_reports", import_noon_file, path=str(folder / "noon_reports.csv"),
                data_root=str(root))
    logging.getLogger("jitroute.demo").info(
        "  noon reports: %d rows → %d imported, %d already present, %d rejected", c["rows"], c["inserted"],
        c["already_present"], c["rejected"])


def _plan_demo_contracts(fleet, date: str, folder: Path, root: Path) -> None:
    """Demo cargo contracts planned on the demo fleet as of the demo day; the plan's legs become voyages."""
    import logging

    from cli.planning import show_plan
    from flows.jobs.planning import plan_fleet_job
    from pipeline.synthetic.contracts import write_demo_planning

    files = write_demo_planning(fleet.vessels, f"{date}T00", folder)
    logging.getLogger("jitroute.demo").info("[demo 2/3] planning the demo cargo contracts (%s)", files["contracts"])
    s = run_job("flows.planning", "plan_fleet", plan_fleet_job, contracts=files["contracts"],
                availability=files["availability"], ports=files["ports"], as_of=f"{date}T00:00Z", data_root=str(root))
    show_plan(s)


def _show_nightly(s: dict, root: Path) -> None:
    t = Table(title=f"Nightly {s['date']}: ingest (routed on cycle {s.get('cycle_used') or 'none'})")
    for col in ("cycle", "complete", "files ok", "problems"):
        t.add_column(col)
    for r in s["ingest"]:
        t.add_row(str(r["cycle"]), "yes" if r["complete"] else "[yellow]no", f"{r['n_ok']}/{r['n_expected']}",
                  "skipped (already complete)" if r.get("skipped") else "; ".join(r.get("missing") or [])[:100])
    console.print(t)
    console.print(f"models: {s['models_changed']} of {s['vessels']} vessels changed")
    if s.get("routing"):
        show_run(s["routing"], Path(root))
    if s.get("verification"):
        from flows.jobs.verify import verification_sentence

        v = s["verification"]
        console.print(f"[yellow]verification failed:[/] {v['error']}" if v.get("error") else
                      verification_sentence(v) or "verification: no plan to verify yet with the analysed weather")
    if s.get("cycles_missing"):
        console.print(f"[yellow]nightly {s.get('state', 'Incomplete')}: targeted cycles not complete: "
                      f"{', '.join(s['cycles_missing'])}")
