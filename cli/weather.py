"""`jitroute weather map`: a forecast step of wind, waves or currents on a map, or all steps animated."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Optional

import typer

from cli.console import console

DataOpt = typer.Option(None, "--data", help="Data root (default ./data or $JITROUTE_DATA).")


def register(app: typer.Typer) -> None:
    weather = typer.Typer(help="Weather in the cube: maps of wind, waves and currents.", no_args_is_help=True)
    app.add_typer(weather, name="weather")

    @weather.command("map")
    def weather_map(cycle: Optional[str] = typer.Option(None, help="Cube cycle (default: newest complete)."),
                    step: int = typer.Option(0, help="Lead time in hours from the cycle."),
                    var: str = typer.Option("waves", "--var", help="wind | waves | currents."),
                    animate: bool = typer.Option(False, "--animate", help="Every step of the cycle as one GIF."),
                    out: Optional[Path] = typer.Option(None, "--out", help="File to write (default under "
                                                       "<data root>/exports/weather/)."),
                    data: Optional[Path] = DataOpt):
        """Draw wind, waves or currents of one forecast step (or all steps, --animate) with coastlines and units."""
        from flows.jobs import weather_maps
        from flows.settings import load_settings
        from pipeline.export.weather_map import VARIABLES
        from pipeline.sources.cycles import label, parse_cycle
        from storage import cube, export_store

        if var not in VARIABLES:
            raise weather_maps.WeatherMapError(f"--var {var!r} is not one of {', '.join(VARIABLES)}")
        suffix = ".gif" if animate else ".png"
        if out is not None and Path(out).suffix.lower() != suffix:  # a GIF under .png opens as a broken picture
            raise weather_maps.WeatherMapError(f"--out {out}: {'an animation' if animate else 'a map'} is written as "
                                               f"{suffix[1:].upper()}; give a file name ending in {suffix}")
        c = parse_cycle(cycle) if cycle else None
        lay = load_settings(data_root=data).layout
        if c is None:
            c = cube.latest_complete_cycle(lay.cube_store)
            if c is None:
                raise FileNotFoundError(f"no complete forecast cycle in {lay.weather_cube_url}: run `jitroute ingest` first")
        name = f"{var}_{label(c)}.gif" if animate else f"{var}_{label(c)}_{step:03d}h.png"
        target = Path(out) if out else lay.exports / "weather" / name
        if animate:
            log = logging.getLogger("jitroute.weather")
            data_bytes = weather_maps.animation(lay.cube_store, c, var,
                                                progress=lambda k, n: log.info("frame %d/%d", k, n))
        else:
            data_bytes = weather_maps.step_png(lay.cube_store, c, step, var)
        path = export_store.write_file(target.parent.resolve(), target.name, data_bytes)
        console.print(f"{'animation' if animate else 'map'}: {path}")
