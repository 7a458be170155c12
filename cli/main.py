"""The `jitroute` command line. Each area registers its commands from its own module."""

from __future__ import annotations

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


def main() -> None:
    app()


if __name__ == "__main__":
    main()
