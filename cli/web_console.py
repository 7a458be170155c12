"""`jitroute console`: the operator's web console over a data root (cli/console_app), served on this machine."""

from __future__ import annotations

import ipaddress
from pathlib import Path
from typing import Optional

import typer

from cli.console import console, fail

DEFAULT_PORT = 8043


def is_loopback(host: str) -> bool:
    """True for localhost and loopback addresses (127.0.0.0/8, ::1): a console only this machine can reach."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def register(app: typer.Typer) -> None:
    @app.command("console")
    def console_command(data: Optional[Path] = typer.Option(None, "--data", help="Data root (default ./data or $JITROUTE_DATA)."),
                        host: str = typer.Option("127.0.0.1", help="Interface to bind; anything but loopback needs --token."),
                        port: int = typer.Option(DEFAULT_PORT, help="TCP port."),
                        token: Optional[str] = typer.Option(None, envvar="JITROUTE_CONSOLE_TOKEN",
                                                            help="Secret every request must carry (Bearer header, or "
                                                                 "?token= once); required off loopback "
                                                                 "(or $JITROUTE_CONSOLE_TOKEN).")):
        """Serve the operator's console (fleet map with weather, voyages, fleet plan, runs), read-only, fully offline."""
        import uvicorn

        from cli.console_app.app import create_app
        from flows.settings import load_settings

        if not is_loopback(host) and not token:
            fail(f"binding {host} makes the console reachable from other machines: give --token (a long random "
                 "secret, e.g. `--token $(openssl rand -hex 16)`) or bind 127.0.0.1")
        if token is not None and len(token) < 12:
            fail("--token is too short: use at least 12 characters (e.g. `openssl rand -hex 16`)")
        layout = load_settings(data_root=data).layout
        if not layout.root.exists():
            fail(f"data root {layout.root} does not exist: run `jitroute demo` or the nightly job first, or pass --data")
        url = f"http://{'[' + host + ']' if ':' in host else host}:{port}/fleet"
        console.print(f"jitroute console on {layout.root}: {url}" + ("?token=<token>" if token else ""), highlight=False)
        uvicorn.run(create_app(layout, token=token), host=host, port=port, log_level="warning")
