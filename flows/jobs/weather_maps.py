"""Weather maps of a cube cycle: one step of wind, waves or currents as PNG, or every step as a GIF."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.export import weather_map
from pipeline.sources.cycles import label as cycle_label
from schemas.cube_variables import step_hours
from storage import cube

STEP_VARIABLES = ("u10", "v10", "swh", "mwd", "uo", "vo")


class WeatherMapError(ValueError):
    """A map that cannot be drawn as asked (unknown variable, step or cycle); the message says what exists."""


def _cycle(cube_path: Path, cycle) -> "object":
    ds = cube.open_cube(cube_path)
    c = np.datetime64(cycle, "ns")
    if c not in ds["cycle"].values:
        have = ", ".join(cycle_label(x) for x in ds["cycle"].values[-5:]) or "none"
        raise WeatherMapError(f"cycle {cycle_label(c)} is not in the cube {cube.locate(cube_path).url} (newest: {have})")
    return ds.sel(cycle=c)


def steps_h(cube_path: Path, cycle) -> list[int]:
    return [int(s) for s in step_hours(_cycle(cube_path, cycle)["step"].values)]


def step_png(cube_path: Path, cycle, step_h: int, var: str) -> bytes:
    """The map of `var` (wind | waves | currents) at lead `step_h` of the cycle."""
    if var not in weather_map.VARIABLES:
        raise WeatherMapError(f"unknown variable {var!r}; use one of {', '.join(weather_map.VARIABLES)}")
    one = _cycle(cube_path, cycle)
    have = [int(s) for s in step_hours(one["step"].values)]
    if int(step_h) not in have:
        raise WeatherMapError(f"cycle {cycle_label(cycle)} has no step {step_h} h; it has {have[0]}..{have[-1]} h "
                              f"every {have[1] - have[0] if len(have) > 1 else 0} h")
    at = one.isel(step=have.index(int(step_h)))[list(STEP_VARIABLES)].load()
    valid = np.datetime64(cycle, "h") + np.timedelta64(int(step_h), "h")
    title = (f"{var} · cycle {cycle_label(cycle)} + {int(step_h)} h (valid {np.datetime_as_string(valid, unit='h')} UTC)")
    return weather_map.weather_map_png(at["lat"].values, at["lon"].values, {k: at[k].values for k in STEP_VARIABLES},
                                       var, title)


def animation(cube_path: Path, cycle, var: str, progress=None) -> bytes:
    """Every step of the cycle as one looping GIF."""
    steps = steps_h(cube_path, cycle)
    frames = []
    for k, s in enumerate(steps, 1):
        frames.append(step_png(cube_path, cycle, s, var))
        if progress is not None:
            progress(k, len(steps))
    return weather_map.animation_gif(frames)
