"""Weather maps of a cube cycle: one step of wind, waves or currents as PNG, or every step as a GIF.

A step is read with zarr alone (storage/cube_window.py: the published view, the chunks of that step), once for
every variable drawn from it; a fleet run's summary maps (`run_maps_png`) are drawn every RUN_MAP_STRIDE grid
points, which looks the same at the map's size and leaves the flow host a fraction of the drawing.
"""

from __future__ import annotations

import numpy as np

from pipeline.export import weather_map
from pipeline.export.drawing import Draw, draw_here
from pipeline.sources.cycles import label as cycle_label
from storage import cube_window
from storage.cube_location import locate

STEP_VARIABLES = ("u10", "v10", "swh", "mwd", "uo", "vo")
# every 2nd point of the 0.5° grid: 1° cells, 360 × 160 on the whole globe, about 2 px a cell at the map's size
RUN_MAP_STRIDE = 2


class WeatherMapError(ValueError):
    """A map that cannot be drawn as asked (unknown variable, step or cycle); the message says what exists."""


def _published_cycle(cube_path, cycle, cache_chunks: bool = True) -> tuple[cube_window.Published, np.datetime64]:
    loc = locate(cube_path)
    pub = cube_window.open_published(loc, cache_chunks=cache_chunks)
    c = np.datetime64(cycle, "ns")
    if c not in pub.rows:
        have = ", ".join(cycle_label(x) for x in sorted(pub.rows)[-5:]) or "none"
        raise WeatherMapError(f"cycle {cycle_label(c)} is not in the cube {loc.url} (newest: {have})")
    return pub, c


def steps_h(cube_path, cycle) -> list[int]:
    """The cycle's own leads (not the empty slots past them that the cube keeps for longer cycles)."""
    pub, c = _published_cycle(cube_path, cycle)
    return [int(s) for s in cube_window.cycle_steps_h(pub, c)]


def step_fields(cube_path, cycle, step_h: int, stride: int = 1, cache_chunks: bool = True,
                box: tuple[float, float, float, float] | None = None) -> tuple[np.ndarray, np.ndarray, dict]:
    """(lat, lon, variable → (lat, lon) values) of lead `step_h` of the cycle over the whole grid, or over `box` =
    (south, north, west, east in degrees east, east ≥ west: (170, 200) crosses 180°), every `stride`-th point;
    `cube_path` a path, URL or storage Location (`cache_chunks`: see cube_window.open_published)."""
    pub, c = _published_cycle(cube_path, cycle, cache_chunks)
    have = [int(s) for s in cube_window.cycle_steps_h(pub, c)]
    if int(step_h) not in have:
        raise WeatherMapError(f"cycle {cycle_label(cycle)} has no step {step_h} h; it has {have[0]}..{have[-1]} h "
                              f"every {have[1] - have[0] if len(have) > 1 else 0} h")
    valid = c + np.timedelta64(int(step_h), "h")
    lat_deg, lon_deg = ((-90.0, 90.0), (-180.0, 540.0)) if box is None else ((box[0], box[1]), (box[2], box[3]))
    win = cube_window.read_window(cube_path, c, valid_utc=(valid, valid), lat_deg=lat_deg, lon_deg=lon_deg,
                                  variables=STEP_VARIABLES, margin_cells=0, published=pub)
    k = int(np.flatnonzero(win.step_h == int(step_h))[0])
    s = max(1, int(stride))
    return win.lat[::s], win.lon[::s], {v: a[k, ::s, ::s] for v, a in win.data.items()}


def _title(var: str, cycle, step_h: int) -> str:
    valid = np.datetime64(cycle, "h") + np.timedelta64(int(step_h), "h")
    return f"{var} · cycle {cycle_label(cycle)} + {int(step_h)} h (valid {np.datetime_as_string(valid, unit='h')} UTC)"


def _check_var(var: str) -> None:
    if var not in weather_map.VARIABLES:
        raise WeatherMapError(f"unknown variable {var!r}; use one of {', '.join(weather_map.VARIABLES)}")


def step_png(cube_path, cycle, step_h: int, var: str) -> bytes:
    """The map of `var` (wind | waves | currents) at lead `step_h` of the cycle."""
    _check_var(var)
    lat, lon, fields = step_fields(cube_path, cycle, step_h)
    return weather_map.weather_map_png(lat, lon, fields, var, _title(var, cycle, step_h))


def run_maps_png(cube_path, cycle, variables=("waves", "wind"), step_h: int = 0,
                 stride: int = RUN_MAP_STRIDE, draw: Draw = draw_here,
                 box: tuple[float, float, float, float] | None = None) -> dict[str, bytes]:
    """A run summary's maps: `variables` at lead `step_h` over `box` (the fleet's extent, see step_fields; None: the
    globe), the step read once (past the chunk cache: it is read in a routing worker) and drawn every `stride` points
    by `draw` (pipeline/export/drawing.py); a box is drawn at the grid's own resolution (stride 1)."""
    for var in variables:
        _check_var(var)
    lat, lon, fields = step_fields(cube_path, cycle, step_h, stride if box is None else 1, cache_chunks=False, box=box)
    return {var: draw("weather_map", lat, lon, fields, var, _title(var, cycle, step_h)) for var in variables}


def animation(cube_path, cycle, var: str, progress=None) -> bytes:
    """Every step of the cycle as one looping GIF."""
    steps = steps_h(cube_path, cycle)
    frames = []
    for k, s in enumerate(steps, 1):
        frames.append(step_png(cube_path, cycle, s, var))
        if progress is not None:
            progress(k, len(steps))
    return weather_map.animation_gif(frames)
