"""`jitroute route-fleet`, `jitroute nightly`, `jitroute demo`, `jitroute serve`."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer
from rich.console import Console
from rich.table import Table

console = Console()
DataOpt = typer.Option(None, "--data", help="Data root (default ./data or $JITROUTE_DATA).")


def _f(x, fmt="{:.1f}"):
    return "-" if x is None or x != x else fmt.format(x)


def run_table(summary: dict) -> Table:
    t = Table(title=f"Route run {summary.get('run_id')} · cycle {summary.get('cycle')}")
    t.add_column("")
    t.add_column("", justify="right")
    t.add_row("voyages routed", str(summary.get("n")))
    t.add_row("on time / late / not routed", f"{summary.get('n_ok')} / {summary.get('n_late')} / {summary.get('n_failed')}")
    t.add_row("fuel (t)", _f(summary.get("fuel_t")))
    t.add_row("baseline fuel (t), same voyages", _f(summary.get("baseline_fuel_t")))
    t.add_row("savings vs baseline", _f(summary.get("savings_pct"), "{:.1f} %"))
    return t


def problems_table(summary: dict) -> Table | None:
    rows = summary.get("problems") or []
    if not rows:
        return None
    t = Table(title="Voyages needing attention")
    for col in ("voyage", "IMO", "status", "reason"):
        t.add_column(col)
    for r in rows:
        t.add_row(str(r["voyage_id"]), str(r["imo"]), str(r["status"]), str(r["reason"] or ""))
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


def register(app: typer.Typer) -> None:
    @app.command("route-fleet")
    def route_fleet_cmd(cycle: Optional[str] = typer.Option(None, help="Cube cycle (default: newest complete)."),
                        voyage: Optional[list[str]] = typer.Option(None, "--voyage", help="Only these voyages."),
                        solver: Optional[str] = typer.Option(None, help="bfoa (default) | dp | astar | gc | rhumb."),
                        data: Optional[Path] = DataOpt):
        """Route every upcoming voyage on a local dask cluster (or $JITROUTE_DASK_ADDRESS); write tables and exports."""
        from flows.fleet import route_fleet
        from flows.settings import load_settings

        try:
            summary = route_fleet(cycle=cycle, voyages=voyage or None, data_root=str(data) if data else None, solver=solver)
        except RuntimeError as exc:
            console.print(f"[red]error:[/] {exc}")
            raise typer.Exit(2) from exc
        show_run(summary, load_settings(data_root=data).data_root)

    @app.command()
    def nightly(date: Optional[str] = typer.Option(None, help="Date (UTC, YYYY-MM-DD); default today."),
                cycles: Optional[str] = typer.Option(None, help="Cycle hours, e.g. 00,12 (default from settings)."),
                rish_url: Optional[str] = typer.Option(None, help="RISH base URL (default $JITROUTE_RISH_URL)."),
                oscar_url: Optional[str] = typer.Option(None, help="OSCAR base URL (default $JITROUTE_OSCAR_URL)."),
                data: Optional[Path] = DataOpt):
        """The nightly job: ingest the date's cycles, refit models, route the fleet; prints a summary."""
        from flows.fleet import nightly as nightly_flow
        from flows.settings import load_settings

        s = nightly_flow(date=date, data_root=str(data) if data else None, rish_url=rish_url, oscar_url=oscar_url, cycles=cycles)
        _show_nightly(s, load_settings(data_root=data).data_root)

    @app.command()
    def demo(data: Optional[Path] = DataOpt,
             date: str = typer.Option("2020-12-01", help="Demo day (forecast cycles 00 and 12 UTC are generated)."),
             vessels: int = typer.Option(12, help="Number of demo vessels (≥ 10 routes)."),
             workers: int = typer.Option(2, help="Local dask workers for routing.")):
        """Generate a demo mirror and fleet, then run the nightly job on them end to end."""
        import os

        from flows.fleet import nightly as nightly_flow
        from flows.settings import load_settings
        from pipeline.synthetic.fleet import generate_fleet, write_fleet
        from pipeline.synthetic.mirror import write_mirror

        s = load_settings(data_root=data)
        root = s.layout.ensure().root.resolve()
        os.environ["JITROUTE_DASK_WORKERS"] = str(workers)
        mirror = root / "demo_mirror"
        with console.status("[1/4] writing the demo RISH/OSCAR mirror (GRIB2 + NetCDF)…") as st:
            if not (mirror / ".complete").exists():
                def progress(done, total, name=""):
                    st.update(f"[1/4] writing the demo mirror: {done}/{total} cycles")
                write_mirror(mirror, date, date, cycles=(0, 12), seed=0, progress=progress)
                (mirror / ".complete").write_text("ok\n")
        console.print(f"[green]✓[/] demo mirror: {mirror}")
        with console.status("[2/4] generating the demo fleet and importing it…"):
            fleet_dir = root / "demo_fleet"
            write_fleet(generate_fleet(f"{date}T00", n_vessels=vessels, seed=7), fleet_dir)
            _import_fleet(fleet_dir, root)
        console.print(f"[green]✓[/] fleet: {vessels} vessels, a year of noon reports, {vessels} voyages ({fleet_dir})")
        console.print("[3/4] nightly job: ingest → refit → route (progress below)")
        summary = nightly_flow(date=date, data_root=str(root), rish_url=(mirror / "rish").as_uri() + "/",
                               oscar_url=(mirror / "oscar").as_uri() + "/", cycles="00,12")
        console.print("[4/4] done")
        _show_nightly(summary, root)

    @app.command()
    def serve(timezone: str = typer.Option("UTC", help="Time zone of the nightly cron (e.g. Europe/Oslo)."),
              nightly_cron: str = typer.Option("30 2 * * *", help="Cron of the nightly deployment."),
              data: Optional[Path] = DataOpt):
        """Register the nightly, 6-hourly ingest and backfill deployments and run them (needs a Prefect server)."""
        from deploy.serve import build_deployments, serve_all

        serve_all(build_deployments(timezone=timezone, nightly_cron=nightly_cron, data_root=str(data) if data else None))


def _import_fleet(folder: Path, root: Path) -> None:
    from flows.refit import import_fleet, import_noon_reports

    import_fleet(str(folder), data_root=str(root))  # validated: refused rows are kept with their reason
    c = import_noon_reports(str(folder / "noon_reports.csv"), data_root=str(root))
    console.print(f"  noon reports: {c['rows']} rows → {c['inserted']} imported, {c['already_present']} already present, "
                  f"{c['rejected']} rejected")


def _show_nightly(s: dict, root: Path) -> None:
    t = Table(title=f"Nightly {s['date']}: ingest")
    for col in ("cycle", "complete", "files ok", "problems"):
        t.add_column(col)
    for r in s["ingest"]:
        t.add_row(str(r["cycle"]), "yes" if r["complete"] else "[yellow]no", f"{r['n_ok']}/{r['n_expected']}",
                  "skipped (already complete)" if r.get("skipped") else "; ".join(r.get("missing") or [])[:100])
    console.print(t)
    console.print(f"models: {s['models_changed']} of {s['vessels']} vessels changed")
    if s.get("routing"):
        show_run(s["routing"], Path(root))
    else:
        console.print("[yellow]routing skipped: no complete forecast cycle for the date")
