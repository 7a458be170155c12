"""The one console of the command line: tables at their natural width when output is not a terminal,
`jitroute.*` log lines as progress on stderr, and one-line errors."""

from __future__ import annotations

import logging
import sys
from typing import NoReturn

import typer
from rich.console import Console

# On a terminal rich fits tables to the window; in a pipe or file it would cut them at 80 columns. Text lines are
# never broken (soft_wrap): a path or URL in a message stays whole wherever the output goes.
console = Console(width=None if sys.stdout.isatty() else 4000, soft_wrap=True)
err_console = Console(stderr=True, width=None if sys.stderr.isatty() else 4000, soft_wrap=True)


class _ProgressHandler(logging.Handler):
    def emit(self, record: logging.LogRecord) -> None:
        try:
            msg = record.getMessage()
        except Exception:  # a malformed log call must not stop the command
            msg = str(record.msg)
        style = {logging.WARNING: "yellow", logging.ERROR: "red", logging.CRITICAL: "red"}.get(record.levelno)
        err_console.print(f"[{style}]{msg}[/]" if style else msg, markup=bool(style), highlight=False)


def show_progress(level: int = logging.INFO) -> None:
    """Print the `jitroute.*` log lines (progress, warnings) on stderr, once per process."""
    root = logging.getLogger("jitroute")
    if not any(isinstance(h, _ProgressHandler) for h in root.handlers):
        root.addHandler(_ProgressHandler())
    root.setLevel(level)


def fail(msg: str, code: int = 2) -> NoReturn:
    """One line on stderr, then exit with `code` (2: bad input or a state the user must fix first)."""
    err_console.print(f"[red]error:[/] {msg}", highlight=False)
    raise typer.Exit(code)


def require_data_root(layout) -> None:
    """A check or repair given a data root that is not one (mistyped `--data`) fails with exit 2: a monitoring cron
    must not stay green on a path that holds nothing."""
    if not layout.is_data_root():
        from flows.settings import SettingsError

        raise SettingsError(f"no data root at {layout.root} (no warehouse.duckdb, cubes/ or raw/ there): check --data "
                            "or JITROUTE_DATA")
