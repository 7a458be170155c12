"""The `jitroute` command line. Each area registers its commands from its own module."""

from __future__ import annotations

import sys

import typer

from cli import cube, errors, fleet, ingest, performance, routing, signals

app = typer.Typer(
    name="jitroute",
    help="Fuel-optimal just-in-time voyage planning for a fleet from JMA/OSCAR weather forecasts.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_show_locals=False,
)

for module in (ingest, performance, routing, fleet, cube):
    module.register(app)


def main() -> None:
    signals.install()
    errors.quiet_store_tracebacks()
    try:
        app()
    except Exception as exc:
        if not errors.is_store_error(exc):
            raise
        print(f"error: {exc}", file=sys.stderr)  # one line naming the file and the recovery
        sys.exit(2)


if __name__ == "__main__":
    main()
