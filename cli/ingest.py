"""`jitroute ingest`, `jitroute backfill`, `jitroute mirror`."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import numpy as np
import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

console = Console()

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
        cycle: str = typer.Option(..., "--cycle", help="Forecast cycle (model init, UTC), e.g. 2020-12-01T00."),
        data: Optional[Path] = DataOpt,
        rish_url: Optional[str] = RishOpt,
        oscar_url: Optional[str] = OscarOpt,
        force: bool = typer.Option(False, help="Re-ingest even if the cycle is already complete."),
    ):
        """Fetch, decode and write one forecast cycle (GSM wind, GWM waves, OSCAR currents) into the cube."""
        from flows.ingest import ingest_weather, parse_cycle

        try:
            parse_cycle(cycle)
        except ValueError as exc:
            raise typer.BadParameter(str(exc)) from exc
        with console.status(f"Ingesting cycle {cycle} …"):
            report = ingest_weather(cycle, data_root=str(data) if data else None, rish_url=rish_url, oscar_url=oscar_url, force=force)
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
        from flows.ingest import cycles_between, ingest_weather

        hours = [int(h) for h in cycles.split(",") if h.strip()]
        todo = cycles_between(start, end, hours)
        reports = []
        with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(), console=console) as bar:
            job = bar.add_task("backfill", total=len(todo))
            for c in todo:
                label = str(np.datetime_as_string(c, unit="h"))
                bar.update(job, description=f"cycle {label}")
                reports.append(ingest_weather(label, data_root=str(data) if data else None, rish_url=rish_url, oscar_url=oscar_url))
                bar.advance(job)
        console.print(_report_table(reports))
        if route:
            from flows.fleet import route_fleet

            for r in reports:
                if r["complete"]:
                    summary = route_fleet(cycle=r["cycle"], data_root=str(data) if data else None, trigger="backfill")
                    console.print(f"routed cycle {r['cycle']}: run {summary['run_id']} ({summary['status']})")

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
