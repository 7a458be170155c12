"""The `jitroute` command line. Each area registers its commands from its own module."""

from __future__ import annotations

import typer
from typer.core import TyperGroup

from cli import (cube, errors, fleet, ingest, performance, planning, routing, sea_routes, signals, warehouse, weather,
                 web_console)


class Commands(TyperGroup):
    """Runs a command; a user error (cli/errors.py) becomes one line on stderr and exit code 2."""

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except Exception as exc:
            code = errors.exit_code_of(exc)
            if code is None and not errors.is_user_error(exc):
                raise
            from cli.console import err_console

            msg = str(errors.user_error_of(exc)).strip(chr(39) + chr(34))
            err_console.print(f"[red]error:[/] {msg}", highlight=False)
            raise typer.Exit(code or 2) from None


app = typer.Typer(
    name="jitroute",
    cls=Commands,
    help="Fuel-optimal just-in-time voyage planning for a fleet from JMA/OSCAR weather forecasts.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_show_locals=False,
)

for module in (ingest, performance, routing, fleet, weather, cube, warehouse, planning, sea_routes, web_console):
    module.register(app)


def main() -> None:
    from cli.console import show_progress

    signals.install()
    errors.quiet_user_error_tracebacks()
    show_progress()
    app()


if __name__ == "__main__":
    main()
