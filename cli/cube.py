"""`jitroute cube check`, `jitroute cube repair`: find and fix a weather cube damaged on disk; `jitroute cube retire`:
drop old cycles (retention)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from cli.console import console, require_data_root

DataOpt = typer.Option(None, "--data", help="Data root (default ./data or $JITROUTE_DATA).")


def _cycle_label(c) -> str:
    import numpy as np

    return str(np.datetime_as_string(np.datetime64(c, "h"), unit="h"))


def _recorded_cycles(warehouse: Path) -> list[str]:
    """Cycles the warehouse knows were ingested (to rebuild a store that had to be moved aside)."""
    from storage import ingest_log

    if not warehouse.exists():
        return []
    return [_cycle_label(c) for c in ingest_log.cycle_status(warehouse)["cycle"].values]


def register(app: typer.Typer) -> None:
    cube_app = typer.Typer(help="The weather cube: check it for damage, repair it, retire old cycles.",
                           no_args_is_help=True)
    app.add_typer(cube_app, name="cube")

    @cube_app.command("check")
    def check(data: Optional[Path] = DataOpt):
        """Read every metadata file and every chunk of the cube; list what is missing or corrupt (exit 1 if any)."""
        from flows.settings import load_settings
        from storage import cube, cube_damage

        layout = load_settings(data_root=data).layout
        require_data_root(layout)
        store = layout.weather_cube
        if not store.exists():
            console.print(f"no weather cube at {store}: nothing to check")
            return
        meta, chunks = cube_damage.check_store(store)
        leftover = store.with_name(store.name + ".creating")
        for m in meta:
            console.print(f"[red]damaged:[/] {m}")
        for b in chunks:
            console.print(f"[red]corrupt chunk:[/] {b.chunk} ({b.variable}, cycle {_cycle_label(b.cycle)}): {b.error}")
        if leftover.exists():
            console.print(f"[yellow]leftover:[/] {leftover} (a failed store creation; `jitroute cube repair` removes it)")
        if meta or chunks:
            console.print("run `jitroute cube repair`" + (" (the store is moved aside and rebuilt from the raw files)" if meta
                                                         else " (hides the damaged cycles), then re-ingest them"))
            raise typer.Exit(1)
        console.print(f"[green]ok:[/] {store} ({len(cube.cycle_states(store))} cycles, every chunk decodes)")

    @cube_app.command("repair")
    def repair(data: Optional[Path] = DataOpt,
               rebuild: bool = typer.Option(True, help="Re-ingest the affected cycles now (from the raw files already "
                                                       "downloaded; only what is missing is fetched)."),
               rish_url: Optional[str] = typer.Option(None, "--rish-url", help="RISH base URL for the re-ingest."),
               oscar_url: Optional[str] = typer.Option(None, "--oscar-url", help="OSCAR base URL for the re-ingest.")):
        """Damaged metadata: move the store aside (kept) and rebuild it; corrupt chunks: hide those cycles and re-ingest them."""
        from flows.settings import load_settings
        from storage import cube, cube_damage

        s = load_settings(data_root=data)
        require_data_root(s.layout)
        store = s.layout.weather_cube
        if not store.exists():
            console.print(f"no weather cube at {store}: nothing to repair")
            return
        meta, chunks = cube_damage.check_store(store)
        if meta:
            aside = cube.move_aside(store)
            cycles = _recorded_cycles(s.layout.warehouse)
            console.print(f"moved the damaged store aside: {aside} ({'; '.join(meta)})")
        elif chunks:
            cycles = sorted({_cycle_label(b.cycle) for b in chunks})
            cube.hide_cycles(store, [b.cycle for b in chunks])
            console.print(f"hid {len(cycles)} cycle(s) with corrupt chunks: {', '.join(cycles)}")
        else:
            console.print(f"[green]ok:[/] {store}: nothing to repair")
            return
        if not cycles:
            return
        if not rebuild:
            for c in cycles:
                console.print(f"  jitroute ingest --cycle {c} --force")
            return
        from flows.ingest import ingest_weather

        for c in cycles:
            r = ingest_weather(c, data_root=str(s.data_root), rish_url=rish_url, oscar_url=oscar_url, force=True)
            console.print(f"re-ingested {c}: {'complete' if r['complete'] else 'incomplete: ' + '; '.join(r['missing'])[:200]}")

    @cube_app.command("retire")
    def retire(data: Optional[Path] = DataOpt,
               keep_days: Optional[float] = typer.Option(
                   None, "--keep-days", min=0.0,
                   help="Keep the cycles initialised at most this many days before the newest one "
                        "(default: the setting JITROUTE_CUBE_RETENTION_DAYS).")):
        """Retire old cycles: hide them and delete their chunks (routing no longer sees them; re-ingest brings one back)."""
        from flows.settings import load_settings
        from storage import cube

        s = load_settings(data_root=data)
        days = keep_days if keep_days is not None else s.cube_retention_days
        if days is None:
            console.print("no retention given: pass --keep-days N or set JITROUTE_CUBE_RETENTION_DAYS")
            raise typer.Exit(2)
        layout = s.layout
        require_data_root(layout)
        retired = cube.retire_cycles(layout.cube_store, days, lock_dir=layout.cube_lock_dir)
        console.print(f"retired {len(retired)} cycle(s) older than {days:g} days before the newest"
                      + (f": {', '.join(_cycle_label(c) for c in retired)}" if retired else ""))
