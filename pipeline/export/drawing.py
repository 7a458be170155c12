"""The pictures by name, and drawing one here: what a process that never imports matplotlib asks another to draw.

`draw(name, *args)` returns the PNG bytes of the picture `name` (a key of PICTURES) made from plain arguments
(dicts, lists, numpy arrays). `draw_here` draws in this process; flows/jobs/picture_process.py draws in a child
process, so a routing worker keeps matplotlib (about 80 MB) out of its memory. This module imports nothing heavy.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable

# name → "module:function" returning PNG bytes
PICTURES = {
    "route_map": "pipeline.export.plots:route_map_image",
    "convergence": "pipeline.export.plots:convergence_image",
    "fleet_map": "pipeline.export.plots:fleet_map_image",
    "weather_map": "pipeline.export.weather_map:weather_map_png",
}

Draw = Callable[..., bytes]  # draw(name, *args) → PNG bytes


class UnknownPictureError(ValueError):
    """A picture name that is not in PICTURES."""


def drawing_function(name: str) -> Callable[..., bytes]:
    """The function that draws the picture `name` (its module is imported here)."""
    try:
        module, function = PICTURES[name].split(":")
    except KeyError:
        raise UnknownPictureError(f"no picture named {name!r}; known: {', '.join(PICTURES)}") from None
    return getattr(importlib.import_module(module), function)


def draw_here(name: str, *args) -> bytes:
    """Draw the picture `name` from `args` in this process."""
    return drawing_function(name)(*args)
