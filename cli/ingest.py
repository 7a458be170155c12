"""`jitroute ingest`, `jitroute backfill`, `jitroute mirror`."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from cli.console import console
from cli.launch import run_job

DataOpt = typer.Option(None, "--data", help="Data root (default ./data or $JITROUTE_DATA).")
RishOpt = typer.Option(None, "--rish-url", help="RISH base URL (https://, http:// or file://); default $JITROUTE_RISH_URL or the RISH archive.")
OscarOpt = typer.Option(None, "--oscar-url", help="OSCAR base URL; default $JITROUTE_OSCAR_URL.")


def _report_table(reports: list[dict]) -> Table:
    t = Table(title="Ingest summary")
    for col in ("cycle", "status", "files ok", "problems"):
        t.add_column(col)
    for r in reports:
        status = "skipped (complete)" if r.get("skipped") else ("[green]complete" if r["complete"] else "[yellow]incomplete")
        t.add_row(r["cycle"], status, f"{r['n_ok']}/{r['n_expected']}" if not r.get("skipped") else "-",
                  "; ".join(r.get("missing", []))[:120])
    return t


def register(app: typer.Typer) -> None:
    @app.command()
    def ingest(
        cycle: str = typer.Option(..., "--cycle", help="Forecast cycle (model init, UTC), e.g. 2020-12-01T00, or 'latest' (the newest published)."),
        data: Optional[Path] = DataOpt,
        rish_url: Optional[str] = RishOpt,
        oscar_url: Optional[str] = OscarOpt,
        force: bool = typer.Option(False, help="Re-ingest even if the cycle is already complete."),
    ):
        """Fetch, decode and write one forecast cycle (GSM wind, GWM waves, OSCAR currents) into the cube."""
        from flows.jobs.ingest import ingest_cycle
        from pipeline.sources.cycles import check_cycle_hour, parse_cycle

        if cycle.strip().lower() != "latest":
            check_cycle_hour(parse_cycle(cycle), cycle)  # a bad cycle is refused before anything starts
        report = run_job("flows.ingest", "ingest_weather", ingest_cycle, cycle=cycle, data_root=str(data) if data else None,
                         rish_url=rish_url, oscar_url=oscar_url, force=force)
        console.print(_report_table([report]))
        if not report["complete"] and not report.get("skipped"):
            raise typer.Exit(1)

    @app.command()
    def backfill(
        start: str = typer.Option(..., help="First day, e.g. 2020-12-01."),
        end: str = typer.Option(..., help="Last day (inclusive)."),
        cycles: str = typer.Option("00,12", help="Cycle hours to ingest, comma separated."),
        data: Optional[Path] = DataOpt,
        rish_url: Optional[str] = RishOpt,
        oscar_url: Optional[str] = OscarOpt,
        route: bool = typer.Option(False, "--route", help="Also re-route the fleet for every complete cycle."),
    ):
        """Ingest a range of past cycles, skipping those already complete; optionally re-route."""
        from flows.jobs.backfill import backfill_range
        from pipeline.sources.cycles import cycles_between, parse_hours

        todo = cycles_between(start, end, parse_hours(cycles))  # bad dates are refused before anything starts
        args = dict(start=start, end=end, cycles=cycles, data_root=str(data) if data else None, rish_url=rish_url,
                    oscar_url=oscar_url, route=route)
        with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                      console=console, transient=True) as bar:
            job = bar.add_task("backfill", total=len(todo))

            def progress(done, total, label):
                bar.update(job, completed=done, description=f"cycle {label}")

            reports = run_job("flows.ingest", "backfill", lambda **kw: backfill_range(**kw, progress=progress), **args)
        console.print(_report_table(reports))
        for r in reports:
            if r.get("route_run"):
                console.print(f"routed cycle {r['cycle']}: run {r['route_run']}")

    @app.command()
    def mirror(
        out: Path = typer.Option(..., "--out", help="Folder to write the mirror into."),
        start: str = typer.Option(..., help="First day, e.g. 2020-12-01."),
        end: str = typer.Option(..., help="Last day (inclusive)."),
        seed: int = typer.Option(0, help="Seed of the synthetic weather."),
        cycles: str = typer.Option("00,12", help="Cycle hours, comma separated."),
    ):
        """Write a RISH-style mirror (real GRIB2 + OSCAR NetCDF) of synthetic weather for demos and tests."""
        from pipeline.synthetic.mirror import write_mirror

        hours = tuple(int(h) for h in cycles.split(","))
        with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), console=console) as bar:
            job = bar.add_task("writing cycles", total=None)

            def progress(done, total, label):
                bar.update(job, total=total, completed=done, description=f"cycle {label}")

            write_mirror(out, start, end, seed=seed, cycles=hours, progress=progress)
        console.print(f"mirror written: RISH base [bold]file://{(out / 'rish').resolve()}/[/], OSCAR base [bold]file://{(out / 'oscar').resolve()}/[/]")
