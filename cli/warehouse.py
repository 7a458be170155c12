"""`jitroute warehouse check`: read the whole warehouse, its snapshots and its legs' files, and say what is damaged."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from cli.console import console, require_data_root

DataOpt = typer.Option(None, "--data", help="Data root (default ./data or $JITROUTE_DATA).")


def register(app: typer.Typer) -> None:
    wh_app = typer.Typer(help="The DuckDB warehouse: check it, its snapshots and its legs' files for damage.",
                         no_args_is_help=True)
    app.add_typer(wh_app, name="warehouse")

    @wh_app.command("check")
    def check(data: Optional[Path] = DataOpt):
        """Read every table of the warehouse and of each snapshot (block checksums), and every legs file against
        its SHA-256 (every write checks only the DuckDB file and the legs files' sizes); exit 1 if anything is damaged."""
        from flows.settings import load_settings
        from storage import route_history, warehouse

        layout = load_settings(data_root=data).layout
        require_data_root(layout)
        db = layout.warehouse
        if not db.exists():
            console.print(f"no warehouse at {db}: nothing to check")
            return
        problems = []
        for path in [db, *warehouse.snapshot_generations(db)]:
            if path.exists():
                why = warehouse.check_file(path)
                if why is not None:
                    problems.append(f"{path}: {why}")
        n_files = 0
        if not problems:  # the legs' list is read from an undamaged warehouse
            with warehouse.connect(db, write=False) as con:
                n_files = len(route_history.listed_files(con))
                problems += route_history.check_digests(con)
        for p in problems:
            console.print(f"[red]damaged:[/] {p}", highlight=False)
        if problems:
            raise typer.Exit(1)
        console.print(f"[green]ok:[/] {db}, its snapshots and {n_files} legs files", highlight=False)
