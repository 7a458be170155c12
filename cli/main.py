"""The `jitroute` command line. Each area registers its commands from its own module."""

from __future__ import annotations

import sys

import typer

from cli import fleet, ingest, performance, routing

app = typer.Typer(
    name="jitroute",
    help="Fuel-optimal just-in-time voyage planning for a fleet from JMA/OSCAR weather forecasts.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_show_locals=False,
)

for module in (ingest, performance, routing, fleet):
    module.register(app)

# Errors that mean "the input or the data root is not as it must be": one line and exit 2, no traceback.
USER_ERRORS = {"CycleError", "UnknownVesselError", "FleetRunError", "NoonFileError", "FileNotFoundError",
               "WarehouseBusyError", "RoutingInputError", "VoyageGeometryError", "ServeError", "TimeoutError",
               "CubeError", "ExportPathError"}


def main() -> None:
    from cli.console import err_console, show_progress

    show_progress()
    try:
        app()
    except Exception as exc:
        if any(cls.__name__ in USER_ERRORS for cls in type(exc).__mro__):
            err_console.print(f"[red]error:[/] {str(exc).strip(chr(39) + chr(34))}", highlight=False)
            sys.exit(2)
        raise


if __name__ == "__main__":
    main()
