"""Weather at a glance: one forecast step of wind, waves or currents on a map, and the steps as an animation.

A map shows the variable's magnitude in colour (knots for wind and currents, metres for Hs) with
thinned arrows pointing where the air, the waves or the water *go* (wind and waves are stored as
coming-from directions, so their arrows are turned by 180°), over the land mask's coastlines; its title says so
(ARROWS), under the caller's title, which names the valid time. The grid may be the globe or a box (a fleet's extent,
also across the antimeridian: drawn in one longitude frame centred on it).
Input is a plain dict of 2-D arrays on a (lat, lon) grid, as read from one cube step. matplotlib is imported only
when a map is drawn, so the variables' names and magnitudes cost a process nothing.
"""

from __future__ import annotations

import io
from typing import TYPE_CHECKING

import numpy as np

from pipeline.routing.sphere import KN_PER_MS

if TYPE_CHECKING:
    from matplotlib.figure import Figure

VARIABLES = ("wind", "waves", "currents")
ARROWS = {"wind": "arrows point where the wind blows TO (its coming-from direction + 180°)",
          "waves": "arrows point where the waves run TO (their mean coming-from direction + 180°)",
          "currents": "arrows point where the current sets TO"}
ARROWS_X, ARROWS_Y = 36, 18  # arrows across and down the map at most


def magnitude_and_flow(step: dict, var: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, str, str]:
    """(magnitude, u, v of the flow direction, colour-bar label, colour map) of one step's variable.

    `step` has u10, v10 (m/s), swh (m), mwd (deg, coming from), uo, vo (m/s, going to) on (lat, lon).
    """
    if var == "wind":
        u, v = np.asarray(step["u10"], float), np.asarray(step["v10"], float)
        return np.hypot(u, v) * KN_PER_MS, u, v, "10 m wind speed [kn]", "viridis"
    if var == "waves":
        hs = np.asarray(step["swh"], float)
        going = np.radians(np.asarray(step["mwd"], float) + 180.0)  # coming-from → going-to
        return hs, np.sin(going), np.cos(going), "significant wave height Hs [m]", "YlGnBu"
    if var == "currents":
        u, v = np.asarray(step["uo"], float), np.asarray(step["vo"], float)
        return np.hypot(u, v) * KN_PER_MS, u, v, "surface current [kn]", "PuBu"
    raise ValueError(f"unknown weather variable {var!r}; use one of {', '.join(VARIABLES)}")


def weather_map_figure(lat, lon, step: dict, var: str, title: str) -> Figure:
    """The variable of one step over its whole grid: the globe drawn −180..180, a box in a frame centred on it."""
    from matplotlib.ticker import MaxNLocator

    from pipeline.export.plots import _centre_deg, _draw_land, _in_frame, _map_axes
    from pipeline.routing.land_mask import is_sea

    lat = np.asarray(lat, dtype=np.float64)
    lon = np.asarray(lon, dtype=np.float64) % 360.0
    # the globe is drawn −180..180; a box in one frame centred on it, so one across 180° stays in one piece
    ring = np.sort(lon)
    gaps = np.diff(np.concatenate([ring, ring[:1] + 360.0])) if ring.size > 1 else np.array([0.0])
    global_grid = ring.size < 2 or gaps.max() <= 2.0 * np.median(gaps)  # no wide gap: the grid goes round
    lon = _in_frame(lon, 0.0 if global_grid else _centre_deg(lon))
    bad = {k: np.shape(a) for k, a in step.items() if np.shape(a) != (lat.size, lon.size)}
    if bad:
        raise ValueError(f"weather step arrays must be (lat, lon) = ({lat.size}, {lon.size}); got {bad}")
    order = np.argsort(lon, kind="stable")
    lon = lon[order]
    lat_order = np.argsort(lat)
    lat = lat[lat_order]
    mag, u, v, label, cmap = (a[lat_order][:, order] if isinstance(a, np.ndarray) else a
                              for a in magnitude_and_flow(step, var))
    extent = (float(lon.min()), float(lon.max()), float(max(lat.min(), -85.0)), float(min(lat.max(), 85.0)))
    fig, ax, cax = _map_axes([title, ARROWS[var]], extent, colorbar=True)
    finite = np.isfinite(mag)
    if finite.any():
        top = float(np.nanpercentile(mag[finite], 99.5)) or float(np.nanmax(mag)) or 1.0
        levels = MaxNLocator(14).tick_values(0.0, top)
        cf = ax.contourf(lon, lat, np.clip(mag, 0.0, levels[-1]), levels=levels, cmap=cmap, zorder=0)
        fig.colorbar(cf, cax=cax, label=label)
    else:
        cax.remove()
    _draw_land(ax, extent)
    sy, sx = max(1, lat.size // ARROWS_Y), max(1, lon.size // ARROWS_X)
    uu, vv = u[::sy, ::sx], v[::sy, ::sx]
    sea = is_sea(lat[::sy, None], lon[None, ::sx])  # no arrow on land: the field there is not the sea's
    uu, vv = np.where(sea, uu, np.nan), np.where(sea, vv, np.nan)
    norm = np.hypot(uu, vv)
    with np.errstate(invalid="ignore", divide="ignore"):
        uu, vv = np.where(norm > 0, uu / norm, np.nan), np.where(norm > 0, vv / norm, np.nan)
    ax.quiver(lon[::sx], lat[::sy], uu, vv, color="0.2", scale=60, width=0.0015, zorder=2)
    if not finite.any():
        ax.text(0.5, 0.5, f"no {var} values in this step", transform=ax.transAxes, ha="center", va="center")
    return fig


def weather_map_png(lat, lon, step: dict, var: str, title: str) -> bytes:
    from pipeline.export.plots import png_bytes

    return png_bytes(weather_map_figure(lat, lon, step, var, title))


def animation_gif(frames_png: list[bytes], frame_ms: int = 700) -> bytes:
    """The PNG frames as one looping GIF."""
    from PIL import Image

    if not frames_png:
        raise ValueError("no frames to animate")
    images = [Image.open(io.BytesIO(b)).convert("RGB").quantize(colors=255) for b in frames_png]
    out = io.BytesIO()
    images[0].save(out, format="GIF", save_all=True, append_images=images[1:], duration=frame_ms, loop=0)
    return out.getvalue()
