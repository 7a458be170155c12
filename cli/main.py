"""The `jitroute` command line. Each area registers its commands from its own module."""

from __future__ import annotations

import typer
from typer.core import TyperGroup

from cli import fleet, ingest, performance, routing, weather

# Errors that mean "the input or the data root is not as it must be": one line and exit 2, no traceback.
USER_ERRORS = {"CycleError", "UnknownVesselError", "FleetRunError", "NoonFileError", "FileNotFoundError",
               "WarehouseBusyError", "RoutingInputError", "VoyageGeometryError", "ServeError", "TimeoutError",
               "CubeError", "ExportPathError", "WeatherMapError"}


def is_user_error(exc: BaseException) -> bool:
    return any(cls.__name__ in USER_ERRORS for cls in type(exc).__mro__)


class Commands(TyperGroup):
    """Runs a command; a user error becomes one line on stderr and exit code 2."""

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except Exception as exc:
            if not is_user_error(exc):
                raise
            from cli.console import err_console

            err_console.print(f"[red]error:[/] {str(exc).strip(chr(39) + chr(34))}", highlight=False)
            raise typer.Exit(2) from None


app = typer.Typer(
    name="jitroute",
    cls=Commands,
    help="Fuel-optimal just-in-time voyage planning for a fleet from JMA/OSCAR weather forecasts.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_show_locals=False,
)

for module in (ingest, performance, routing, fleet, weather):
    module.register(app)


def main() -> None:
    from cli.console import show_progress

    show_progress()
    app()


if __name__ == "__main__":
    main()
