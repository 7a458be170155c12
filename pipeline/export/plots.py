"""PNG pictures of plans: a route over the weather, solver convergence, all voyages of a run.

Drawn for an operator: every map says the valid time (UTC) of the weather it shows and the unit of every colour and
symbol; tracks carry time marks (day/hhmmZ, UTC); a late plan's map says by how many hours; the fleet map shows where
each ship is at the run's time along its plan, with labels placed clear of each other. The convergence plot is a
developer's diagnostic (pipeline/export/bundle.py makes it only when asked).

Maps use plain lon/lat axes with a 1/cos(latitude) aspect (locally true shape) and coastlines
contoured from the `global-land-mask` grid sampled over the map extent. Everything is drawn in
one longitude frame centred on the voyages (tick labels in °E/°W), so a route across the
dateline is drawn as one piece. Legs are drawn as great circles (8 points per leg). The land and the great circles
are numpy's (pipeline/routing/land_mask.py, sphere.py): drawing never loads numba.

Figures come from matplotlib's object API, not pyplot: rendering is Agg, headless and safe in
worker threads. The `*_figure` functions return the Figure (for notebooks and tests), the
`*_png` functions write it and return the Path, the `*_image` functions return its PNG bytes (`png_bytes`).
"""

from __future__ import annotations

import re
from datetime import datetime, timedelta
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.ticker import FuncFormatter, MaxNLocator
from matplotlib.transforms import ScaledTranslation

from pipeline.export.voyage import (centre_lon_deg, finite_or_none, iso_utc, spread_text, unwrap_lon_deg, utc_datetime,
                                    vessel_label, voyage_id, waypoint_names, waypoints_deg)
from pipeline.routing.land_mask import MASK_RES_DEG, is_sea
from pipeline.routing.sphere import KN_PER_MS, gc_points

STATUS_COLOURS = {"ok": "#2ca02c", "late": "#ff7f0e"}
FAILED_COLOUR = "#d62728"  # infeasible, failed, error and anything unknown
POINTS_PER_LEG = 8
MAX_LAND_SAMPLES = 450  # per axis (700 drew the same coastlines at this size for 18 MB more peak memory and +25 % CPU)
DPI = 110
MAX_MAP_SHAPE = 0.85  # map height / width at most (the figure is 11 in wide, at most 9 in high)


def status_colour(status) -> str:
    return STATUS_COLOURS.get(str(status), FAILED_COLOUR)


def _in_frame(lon_deg, centre_deg: float) -> np.ndarray:
    """Each longitude moved by a multiple of 360° to within 180° of the centre."""
    return centre_deg + (np.asarray(lon_deg, dtype=np.float64) - centre_deg + 180.0) % 360.0 - 180.0


_centre_deg = centre_lon_deg


def _track(legs: list[dict], centre_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """Great-circle polyline through the legs, longitudes continuous and near the centre."""
    if not legs:
        return np.empty(0), np.empty(0)
    fracs = np.linspace(0.0, 1.0, POINTS_PER_LEG + 1)[1:]
    ends = np.array([[leg["lat0"], leg["lon0"], leg["lat1"], leg["lon1"]] for leg in legs], dtype=np.float64)
    lat, lon = gc_points(*(ends[:, k, None] for k in range(4)), fracs[None, :])  # (legs, points of a leg)
    lat = np.concatenate([ends[:1, 0], lat.ravel()])
    lon = np.concatenate([ends[:1, 1], lon.ravel()])
    return lat, unwrap_lon_deg(lon, centre_deg)


def _waypoints(legs: list[dict], centre_deg: float) -> tuple[np.ndarray, np.ndarray]:
    lat, lon = waypoints_deg(legs)
    return lat, unwrap_lon_deg(lon, centre_deg)


def _extent(lat, lon) -> tuple[float, float, float, float]:
    """(lon0, lon1, lat0, lat1) around the points with a margin; the world when there are none."""
    lat, lon = np.asarray(lat, dtype=np.float64), np.asarray(lon, dtype=np.float64)
    ok = np.isfinite(lat) & np.isfinite(lon)
    if not ok.any():
        return -180.0, 180.0, -80.0, 80.0
    lat, lon = lat[ok], lon[ok]
    mx = max(2.0, 0.08 * np.ptp(lon))
    my = max(2.0, 0.08 * np.ptp(lat))
    x0, x1 = lon.min() - mx, lon.max() + mx
    y0, y1 = max(-85.0, lat.min() - my), min(85.0, lat.max() + my)
    # a north-south voyage would be a thin strip in a wide frame: show more ocean either side instead
    min_width = (y1 - y0) * _lon_stretch(y0, y1) / MAX_MAP_SHAPE
    if x1 - x0 < min_width:
        x0, x1 = 0.5 * (x0 + x1) - 0.5 * min_width, 0.5 * (x0 + x1) + 0.5 * min_width
    if x1 - x0 > 360.0:  # never show a longitude twice
        x0, x1 = 0.5 * (x0 + x1) - 180.0, 0.5 * (x0 + x1) + 180.0
    return float(x0), float(x1), float(y0), float(y1)



def _lon_stretch(y0: float, y1: float) -> float:
    """Plot units of latitude per degree of longitude that keep the map conformal at mid-latitude."""
    return 1.0 / max(0.1, np.cos(np.radians(0.5 * (y0 + y1))))


def _lon_label(x, _pos=None) -> str:
    w = (x + 180.0) % 360.0 - 180.0
    if abs(w) < 1e-9 or abs(abs(w) - 180.0) < 1e-9:
        return f"{abs(w):.0f}°"
    return f"{abs(w):g}°{'E' if w > 0 else 'W'}"


FIG_WIDTH_IN = 11.0
MARGIN_LEFT_IN, MARGIN_BOTTOM_IN, TITLE_LINE_IN = 0.75, 0.85, 0.2  # latitude labels; longitude labels and legend
COLORBAR_BAND_IN = 1.35  # right of the map: the colourbar (0.18 in), its ticks and its label


def _map_axes(title_lines: list[str], extent, colorbar: bool = False):
    """(figure, map axes, colourbar axes or None) with the map's shape kept (1/cos(latitude) aspect).

    The layout is computed here, not by a layout engine: the margins are fixed in inches and the map's box is
    the largest of its shape that fits between them. matplotlib's constrained layout measured every tick label
    in an extra drawing pass, a third of the time a worker spent on each route map."""
    x0, x1, y0, y1 = extent
    aspect = _lon_stretch(y0, y1)
    shape = (y1 - y0) * aspect / (x1 - x0)  # the map's height / width
    right_in = COLORBAR_BAND_IN if colorbar else 0.35
    top_in = 0.25 + TITLE_LINE_IN * len(title_lines)
    avail_w = FIG_WIDTH_IN - MARGIN_LEFT_IN - right_in
    # height follows the map's shape (about 9 in of map width), so wide maps get no empty bands
    height_in = float(np.clip(avail_w * shape + MARGIN_BOTTOM_IN + top_in, 3.5, 9.0))
    avail_h = height_in - MARGIN_BOTTOM_IN - top_in
    w_in, h_in = (avail_w, avail_w * shape) if avail_w * shape <= avail_h else (avail_h / shape, avail_h)
    left_in = MARGIN_LEFT_IN + 0.5 * (avail_w - w_in)
    bottom_in = MARGIN_BOTTOM_IN + 0.5 * (avail_h - h_in)
    fig = Figure(figsize=(FIG_WIDTH_IN, height_in))
    W, H = FIG_WIDTH_IN, height_in
    ax = fig.add_axes((left_in / W, bottom_in / H, w_in / W, h_in / H))
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect(aspect)
    ax.xaxis.set_major_formatter(FuncFormatter(_lon_label))
    ax.yaxis.set_major_formatter(FuncFormatter(lambda y, _p: f"{abs(y):g}°{'N' if y > 0 else 'S' if y < 0 else ''}"))
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.set_title("\n".join(title_lines), fontsize=10)
    cax = None
    if colorbar:
        cax = fig.add_axes(((left_in + w_in + 0.3) / W, (bottom_in + 0.1 * h_in) / H, 0.18 / W, 0.8 * h_in / H))
    return fig, ax, cax


def _draw_land(ax, extent) -> None:
    """Land filled and outlined, from the land mask sampled over the extent (≤ MAX_LAND_SAMPLES points a side)."""
    x0, x1, y0, y1 = extent
    nx = int(min(MAX_LAND_SAMPLES, max(2, (x1 - x0) / MASK_RES_DEG)))
    ny = int(min(MAX_LAND_SAMPLES, max(2, (y1 - y0) / MASK_RES_DEG)))
    lon, lat = np.linspace(x0, x1, nx), np.linspace(y0, y1, ny)
    land = (~is_sea(lat[:, None], lon[None, :])).astype(np.float64)  # the contour generator works in float64: no copy
    if land.any():
        filled = ax.contourf(lon, lat, land, levels=[0.5, 1.5], colors=["#ddd5c4"], zorder=1)
        # the coastline from the fill's contour generator: one copy of the sampled grid held with the figure, not two
        ax.contour(filled, levels=[0.5], colors="0.3", linewidths=0.5, zorder=1)


def _draw_field(fig, ax, cax, field: dict, centre_deg: float, extent) -> None:
    """Filled Hs contours with a colourbar (in `cax`, removed when there is nothing to show) and thinned wind barbs
    (knots), clipped to the extent."""
    lat = np.asarray(field["lat"], dtype=np.float64)
    lon = _in_frame(field["lon"], centre_deg)
    lon, cols = np.unique(lon, return_index=True)  # sorted, and 0/360 duplicates dropped
    x0, x1, y0, y1 = extent
    pad = 2.0 * max(np.diff(lon).max(initial=0.0), np.abs(np.diff(lat)).max(initial=0.0))
    keep_x = (lon >= x0 - pad) & (lon <= x1 + pad)
    keep_y = (lat >= y0 - pad) & (lat <= y1 + pad)
    if keep_x.sum() < 2 or keep_y.sum() < 2:
        cax.remove()
        return
    x, y = lon[keep_x], lat[keep_y]

    def cut(name):
        a = field.get(name)
        if a is None:
            return None
        a = np.asarray(a, dtype=np.float64)
        if a.shape != (lat.size, np.asarray(field["lon"]).size):
            raise ValueError(f"weather field {name!r} has shape {a.shape}, expected (lat, lon) = "
                             f"({lat.size}, {np.asarray(field['lon']).size})")
        return a[:, cols][np.ix_(keep_y, keep_x)]

    hs = cut("hs_m")
    if hs is not None and np.isfinite(hs).any() and np.nanmax(hs) > 0:
        levels = MaxNLocator(12).tick_values(0.0, float(np.nanmax(hs)))
        cf = ax.contourf(x, y, hs, levels=levels, cmap="YlGnBu", zorder=0)
        fig.colorbar(cf, cax=cax, label="significant wave height Hs [m]")
    else:
        cax.remove()
    u, v = cut("u_ms"), cut("v_ms")
    if u is not None and v is not None:
        sy, sx = max(1, y.size // 16), max(1, x.size // 22)
        bx, by = np.meshgrid(x[::sx], y[::sy])
        bu, bv = u[::sy, ::sx] * KN_PER_MS, v[::sy, ::sx] * KN_PER_MS
        keep = is_sea(by, bx) & np.isfinite(bu) & np.isfinite(bv)  # no barb on land: the wind there is not the sea's
        ax.barbs(bx[keep], by[keep], bu[keep], bv[keep], length=5, linewidth=0.5, color="0.25", zorder=2)


def _hours_between(a, b) -> float | None:
    """Hours from time a to time b (None when either is missing)."""
    da, db = utc_datetime(a), utc_datetime(b)
    return None if da is None or db is None else (db - da).total_seconds() / 3600.0


def late_hours(route: dict) -> float | None:
    """How many hours after its RTA the plan arrives (None when it is not late or the times are missing)."""
    h = _hours_between(route.get("rta_utc"), route.get("eta_utc"))
    return h if h is not None and h > 1e-6 else None


def position_at(legs: list[dict], when, starts_at_sea: bool = False) -> tuple[float, float, str] | None:
    """(lat, lon, where) of the ship at time `when` along its plan: at the departure before it sails ("in port", or
    "at sea" for a plan re-made at sea: `starts_at_sea`), on the leg's great circle in proportion to the leg's time
    ("at sea"; at a waypoint while it waits there), at the arrival after the ETA ("arrived"). None without legs or
    times."""
    t = utc_datetime(when)
    if t is None or not legs:
        return None
    etd0, eta_n = utc_datetime(legs[0].get("etd_utc")), utc_datetime(legs[-1].get("eta_utc"))
    if etd0 is None or eta_n is None:
        return None
    if t <= etd0:
        return float(legs[0]["lat0"]), float(legs[0]["lon0"]), "at sea" if starts_at_sea else "in port"
    if t >= eta_n:
        return float(legs[-1]["lat1"]), float(legs[-1]["lon1"]), "arrived"
    for leg in legs:
        etd, eta = utc_datetime(leg.get("etd_utc")), utc_datetime(leg.get("eta_utc"))
        if etd is None or eta is None or t > eta:
            continue
        if t <= etd:  # waiting at the leg's start
            return float(leg["lat0"]), float(leg["lon0"]), "at sea"
        frac = (t - etd).total_seconds() / max(1e-9, (eta - etd).total_seconds())
        lat, lon = gc_points(leg["lat0"], leg["lon0"], leg["lat1"], leg["lon1"], frac)
        return float(lat), float(lon), "at sea"
    return float(legs[-1]["lat1"]), float(legs[-1]["lon1"]), "arrived"


def time_mark_step_h(hours: float) -> int:
    """Hours between time marks: about 4 to 10 marks along a voyage of `hours`."""
    for step in (3, 6, 12, 24, 48, 96):
        if hours / step <= 10:
            return step
    return 168


def time_marks(legs: list[dict]) -> list[tuple[datetime, float, float]]:
    """(time, lat, lon) of the ship along its plan at every whole multiple of time_mark_step_h UTC hours after its
    departure and before its arrival."""
    if not legs:
        return []
    t0, t1 = utc_datetime(legs[0].get("etd_utc")), utc_datetime(legs[-1].get("eta_utc"))
    if t0 is None or t1 is None or t1 <= t0:
        return []
    step = time_mark_step_h((t1 - t0).total_seconds() / 3600.0)
    t = t0.replace(minute=0, second=0, microsecond=0)
    t += timedelta(hours=step - t.hour % step if t.hour % step or t <= t0 else 0)
    marks = []
    while t < t1:
        if t > t0:
            lat, lon, _where = position_at(legs, t)
            marks.append((t, lat, lon))
        t += timedelta(hours=step)
    return marks


def dtg(t: datetime) -> str:
    """day/hhmmZ, the mariner's date-time group in UTC (e.g. 02/0600Z)."""
    return f"{t:%d/%H%M}Z"


MAX_FLEET_LABELS = 60  # beyond this many voyages a fleet map labels only those not ok (placing a label costs a drawing)
PLAN_VOYAGE_ID = re.compile(r"^plan-\d{8}T\d{4}-[0-9a-f]+-(\d+)-(\d+)$")  # pipeline/planning/voyages.py
MAX_LABEL_CHARS = 14


def short_voyage_label(vid: str) -> str:
    """A label that fits on a map: a fleet plan's voyage `plan-<time>-<hex>-<imo>-<leg>` becomes `<imo>/<leg>`;
    other IDs longer than MAX_LABEL_CHARS keep their start and end."""
    m = PLAN_VOYAGE_ID.match(vid)
    if m:
        return f"{m.group(1)}/{m.group(2)}"
    if len(vid) > MAX_LABEL_CHARS:
        return vid[:6] + "…" + vid[-(MAX_LABEL_CHARS - 7):]
    return vid


def _place_labels(fig, ax, labels: list[tuple[str, list[tuple[float, float]], str]], avoid=()) -> list:
    """Annotate each (text, candidate points, colour) at the first candidate (and offset) where its box overlaps no
    label placed before and none of the `avoid` display boxes; the first candidate when none is free."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    renderer = (fig.canvas if isinstance(fig.canvas, FigureCanvasAgg) else FigureCanvasAgg(fig)).get_renderer()
    placed, out = list(avoid), []
    offsets = ((4, 4, "left", "bottom"), (4, -4, "left", "top"), (-4, 4, "right", "bottom"), (-4, -4, "right", "top"))
    for text, points, colour in labels:
        chosen = None
        for point in points:
            for dx, dy, ha, va in offsets:
                a = ax.annotate(text, point, xytext=(dx, dy), textcoords="offset points", fontsize=7, color=colour,
                                ha=ha, va=va, zorder=6,
                                bbox=dict(boxstyle="square,pad=0.1", fc="white", ec="none", alpha=0.7))
                box = a.get_window_extent(renderer)
                if not any(box.overlaps(b) for b in placed):
                    chosen = (a, box)
                    break
                a.remove()
            if chosen:
                break
        if chosen is None:
            a = ax.annotate(text, points[0], xytext=(4, 4), textcoords="offset points", fontsize=7, color=colour,
                            zorder=6)
            chosen = (a, a.get_window_extent(renderer))
        placed.append(chosen[1])
        out.append(chosen[0])
    return out


def _fmt(x, unit: str, decimals: int = 1) -> str:
    v = finite_or_none(x)
    return "n/a" if v is None else f"{v:.{decimals}f}{unit}"


def route_map_figure(route: dict, legs: list[dict], baseline_legs: list[dict] | None = None,
                     field: dict | None = None, title: str | None = None) -> Figure:
    """The plan (solid, with time marks) and the baseline (dashed) over Hs and wind; waypoints marked. The title names
    the weather's valid time (`field["valid_utc"]`, and `field["valid_note"]` saying which time that is) and, for a
    late plan, by how many hours it misses the RTA."""
    baseline_legs = baseline_legs or []
    all_lon = np.concatenate([waypoints_deg(legs)[1], waypoints_deg(baseline_legs)[1]])
    if all_lon.size:
        centre = _centre_deg(all_lon)
    elif field is not None:
        centre = _centre_deg(field["lon"])
    else:
        centre = 0.0
    lat, lon = _track(legs, centre)
    blat, blon = _track(baseline_legs, centre)
    if lat.size or blat.size:
        extent = _extent(np.concatenate([lat, blat]), np.concatenate([lon, blon]))
    elif field is not None:
        extent = _extent(*np.meshgrid(np.asarray(field["lat"]), _in_frame(field["lon"], centre), indexing="ij"))
    else:
        extent = _extent([], [])
    head = title or f"{voyage_id(route)} · {vessel_label(route)} · {route.get('solver') or '?'} · " \
                    f"{route.get('status') or '?'}"
    if finite_or_none(route.get("honest_baseline_fuel_t")) is not None:  # the honest figure (savings.py)
        fuel = (f"fuel {_fmt(route.get('fuel_t'), ' t')} vs {_fmt(route.get('honest_baseline_fuel_t'), ' t')} at the "
                f"constant speed arriving at the RTA (saving {_fmt(route.get('savings_total_pct'), ' %')}: speed "
                f"profile {_fmt(route.get('savings_speed_profile_pct'), ' %')}, route {_fmt(route.get('savings_route_pct'), ' %')})")
    else:
        fuel = (f"fuel {_fmt(route.get('fuel_t'), ' t')} vs baseline {_fmt(route.get('baseline_fuel_t'), ' t')} "
                f"(saving {_fmt(route.get('savings_pct'), ' %')})")
    late = late_hours(route)
    times = (f"ETD {iso_utc(route.get('depart_utc')) or 'n/a'} · ETA {iso_utc(route.get('eta_utc')) or 'n/a'} · "
             f"RTA {iso_utc(route.get('rta_utc')) or 'n/a'}" + (f" · LATE by {late:.1f} h" if late is not None else ""))
    lines = [head, fuel, times]
    spread = spread_text(route)
    if spread is not None and legs:
        lines.append(f"uncertainty {spread} (the plan and its baseline sailed through each)")
    if field is not None:
        valid = field.get("valid_utc")
        note = f" ({field['valid_note']})" if field.get("valid_note") else ""
        lines.append(f"weather valid {iso_utc(valid) if valid is not None else 'n/a (time not given)'}{note}")
        lines.append("Hs [m] in colour · wind barbs [kn] point where the wind comes FROM: half barb 5, barb 10, "
                     "pennant 50")
    lines += [f"no route: {route.get('reason') or route.get('status')}"] if not legs else []
    fig, ax, cax = _map_axes(lines, extent, colorbar=field is not None)
    if field is not None:
        _draw_field(fig, ax, cax, field, centre, extent)
    _draw_land(ax, extent)
    if blat.size:
        ax.plot(blon, blat, "--", color="0.15", lw=1.3, zorder=3, label="baseline")
    if lat.size:
        ax.plot(lon, lat, "-", color="#c2185b", lw=2.0, zorder=4, label="plan")
        wlat, wlon = _waypoints(legs, centre)
        ax.plot(wlon, wlat, "o", ms=3.5, mfc="white", mec="#c2185b", zorder=5, label="waypoints")
        names = waypoint_names(route, wlat.size)  # a plan re-made at sea starts at its report (pipeline/enroute.py)
        for k in (0, wlat.size - 1):
            ax.annotate(names[k], (wlon[k], wlat[k]), xytext=(4, 4), textcoords="offset points", fontsize=8,
                        zorder=6)
        marks = time_marks(legs)
        if marks:
            step = time_mark_step_h(_hours_between(legs[0].get("etd_utc"), legs[-1].get("eta_utc")) or 0.0)
            mlat = np.array([m[1] for m in marks])
            mlon = unwrap_lon_deg([m[2] for m in marks], centre)
            ax.plot(mlon, mlat, "|", ms=7, mew=1.4, color="black", zorder=5,
                    label=f"ship's position every {step} h (day/hhmmZ, UTC)")
            for (t, _la, _lo), x, y in zip(marks, mlon, mlat):
                ax.annotate(dtg(t), (x, y), xytext=(0, -9), textcoords="offset points", fontsize=6.5, ha="center",
                            va="top", zorder=6, bbox=dict(boxstyle="square,pad=0.05", fc="white", ec="none", alpha=0.6),
                            clip_on=True, in_layout=False)  # a mark by the map's edge is cut there, never spills
        if late is not None:
            ax.annotate(f"ETA {dtg(utc_datetime(route.get('eta_utc')))}: {late:.1f} h after the RTA",
                        (wlon[-1], wlat[-1]), xytext=(4, -10), textcoords="offset points", fontsize=8,
                        color="#b34700", fontweight="bold", zorder=6, clip_on=True, in_layout=False,
                        bbox=dict(boxstyle="round,pad=0.2", fc="white", ec="#b34700", alpha=0.9))
    if lat.size or blat.size:  # below the map: never over the route, and no search for a free corner
        below = ax.transAxes + ScaledTranslation(0.0, -0.3, fig.dpi_scale_trans)  # under the longitude labels
        fig.legend(loc="upper center", bbox_to_anchor=(0.5, 0.0), bbox_transform=below, ncols=4, fontsize=8,
                   frameon=False)
    return fig


def route_map_png(path, route: dict, legs: list[dict], baseline_legs: list[dict] | None = None,
                  field: dict | None = None, title: str | None = None) -> Path:
    """Write `route_map_figure(...)` as a PNG. `field`: dict(lat=1-D, lon=1-D, hs_m=2-D or None,
    u_ms=2-D, v_ms=2-D or None), arrays indexed (lat, lon); lon may be −180..180 or 0..360."""
    return _save(route_map_figure(route, legs, baseline_legs, field, title), path)


def route_map_image(route: dict, legs: list[dict], baseline_legs: list[dict] | None = None,
                    field: dict | None = None, title: str | None = None) -> bytes:
    """`route_map_figure(...)` as PNG bytes."""
    return png_bytes(route_map_figure(route, legs, baseline_legs, field, title))


def convergence_figure(history, title: str | None = None) -> Figure:
    """Best cost per BFOA cycle (and the running best when it differs), with the DP optimum if given.

    `history`: 1-D costs, or {"bfoa": costs, "dp_cost": float | None}.
    """
    dp = None
    if isinstance(history, dict):
        dp = finite_or_none(history.get("dp_cost"))
        history = history.get("bfoa", [])
    cost = np.asarray(history if history is not None else [], dtype=np.float64).ravel()
    fig = Figure(figsize=(8, 5))
    fig.subplots_adjust(left=0.12, right=0.97, bottom=0.11, top=0.87)  # fixed: no layout engine's extra pass
    ax = fig.add_subplot()
    cycle = np.arange(1, cost.size + 1)
    sub = "no BFOA history"
    if cost.size:
        ax.plot(cycle, cost, "o-", ms=3, lw=1.2, label="best in cycle")
        best = np.fmin.accumulate(cost)
        if not np.allclose(best, cost, equal_nan=True):
            ax.step(cycle, best, where="post", lw=1.5, label="best so far")
        final = np.nanmin(cost) if np.isfinite(cost).any() else np.nan
        sub = f"{cost.size} cycles, best {_fmt(final, '', 4)}"
        if dp is not None and np.isfinite(final) and dp != 0:
            sub += f" ({100.0 * (final - dp) / abs(dp):+.2f} % vs DP)"
    if dp is not None:
        ax.axhline(dp, ls="--", color="k", lw=1.0, label=f"DP optimum {dp:.4g}")
    ax.set_xlabel("BFOA cycle")
    ax.set_ylabel("objective cost")
    ax.grid(True, lw=0.3, alpha=0.5)
    if cost.size or dp is not None:
        ax.legend(fontsize=8)
    ax.set_title(f"{title or 'BFOA convergence'}\n{sub}", fontsize=10)
    return fig


def convergence_png(path, history, title: str | None = None) -> Path:
    return _save(convergence_figure(history, title), path)


def convergence_image(history, title: str | None = None) -> bytes:
    return png_bytes(convergence_figure(history, title))


def fleet_map_figure(routes_with_legs: list[tuple[dict, list[dict]]], title: str | None = None,
                     now_utc=None) -> Figure:
    """Every voyage of a run on one map, coloured by status, labelled with a short voyage id and its ETA (day/hhmmZ;
    labels kept clear of each other), each ship's position at `now_utc` (the run's time) along its plan marked; voyages without legs are
    listed in a box. A route dict needs voyage_id and status (and start_kind: a plan re-made at sea starts at sea);
    legs need lat0/lon0/lat1/lon1 and, for the positions, etd_utc/eta_utc."""
    all_lon = np.concatenate([waypoints_deg(legs)[1] for _r, legs in routes_with_legs] or [np.empty(0)])
    centre = _centre_deg(all_lon)
    tracks = [(route, legs, *_track(legs, centre)) for route, legs in routes_with_legs]
    lat_all = np.concatenate([t[2] for t in tracks] or [np.empty(0)])
    lon_all = np.concatenate([t[3] for t in tracks] or [np.empty(0)])
    statuses = [str(r.get("status")) for r, _legs in routes_with_legs]
    counts = {s: statuses.count(s) for s in dict.fromkeys(statuses)}
    head = title or f"{len(routes_with_legs)} voyages"
    now = utc_datetime(now_utc)
    sub = ", ".join(f"{n} {s}" for s, n in counts.items()) or "no voyages"
    if now is not None:
        sub += f" · ships' positions at {iso_utc(now)} along their plans"
    plans = sorted({m.group(0).rsplit("-", 2)[0] for r, _l in routes_with_legs
                    if (m := PLAN_VOYAGE_ID.match(voyage_id(r)))})
    lines = [head, sub] + ([f"labels IMO/leg: voyages of fleet plan {', '.join(plans)}"] if plans else [])
    routed = [r for r, lg in routes_with_legs if lg]
    to_label = routed
    if len(routed) > MAX_FLEET_LABELS:
        to_label = [r for r in routed if str(r.get("status")) != "ok"][:MAX_FLEET_LABELS]
        lines.append(f"labels on {len(to_label)} voyages not ok only, of {len(routed)}")
    labelled = {id(r) for r in to_label}
    extent = _extent(lat_all, lon_all)
    fig, ax, _ = _map_axes(lines, extent)
    _draw_land(ax, extent)
    missing, labels, ships = [], [], {"at sea": [], "in port": [], "arrived": []}
    for route, legs, lat, lon in tracks:
        colour = status_colour(route.get("status"))
        if not lat.size:
            missing.append(f"{short_voyage_label(voyage_id(route))} ({route.get('status')})")
            continue
        ax.plot(lon, lat, "-", color=colour, lw=1.6, zorder=3)
        ax.plot(lon[[0, -1]], lat[[0, -1]], "o", ms=3, color=colour, zorder=4)
        n = lat.size
        spots = [(lon[k], lat[k]) for k in (n // 2, n // 3, 2 * n // 3, n // 5, 4 * n // 5, 0, n - 1)]
        eta = utc_datetime(legs[-1].get("eta_utc")) if legs else None
        if id(route) in labelled:
            labels.append((short_voyage_label(voyage_id(route)) + (f" ETA {dtg(eta)}" if eta is not None else ""),
                           spots, colour))
        at_sea = route.get("start_kind") not in (None, "port")  # re-planned at sea (pipeline/enroute.py)
        pos = position_at(legs, now, at_sea) if now is not None else None
        if pos is not None:
            ships[pos[2]].append((float(unwrap_lon_deg([pos[1]], centre)[0]), pos[0]))
    marker = {"at sea": dict(marker="^", ms=8, mfc="black", mec="white"),
              "in port": dict(marker="s", ms=6, mfc="white", mec="black"),
              "arrived": dict(marker="s", ms=6, mfc="0.6", mec="black")}
    handles = [Line2D([], [], color=status_colour(s), lw=2, label=s) for s in counts]
    for where, pts in ships.items():
        if pts:
            xs, ys = zip(*pts)
            ax.plot(xs, ys, ls="none", zorder=7, **marker[where])
            handles.append(Line2D([], [], ls="none", label=f"ship {where} now", **marker[where]))
    from matplotlib.transforms import Bbox

    pad_px = 5.0 * fig.dpi / 72.0  # half a marker: labels keep off the ships too
    avoid = [Bbox.from_extents(px - pad_px, py - pad_px, px + pad_px, py + pad_px)
             for pts in ships.values() for px, py in ax.transData.transform(np.asarray(pts).reshape(-1, 2))]
    _place_labels(fig, ax, labels, avoid)
    if handles:
        ax.legend(handles=handles, loc="best", fontsize=8, title="status / ship now", title_fontsize=8)
    if missing:
        ax.text(0.01, 0.01, "no route: " + ", ".join(missing), transform=ax.transAxes, fontsize=7,
                va="bottom", ha="left", color=FAILED_COLOUR, zorder=6,
                bbox=dict(boxstyle="round", fc="white", ec=FAILED_COLOUR, alpha=0.85))
    return fig


def fleet_map_png(path, routes_with_legs: list[tuple[dict, list[dict]]], title: str | None = None,
                  now_utc=None) -> Path:
    return _save(fleet_map_figure(routes_with_legs, title, now_utc), path)


def fleet_map_image(routes_with_legs: list[tuple[dict, list[dict]]], title: str | None = None,
                    now_utc=None) -> bytes:
    return png_bytes(fleet_map_figure(routes_with_legs, title, now_utc))


def png_bytes(fig: Figure) -> bytes:
    """The figure as PNG bytes (for exports returned by workers rather than written where they run)."""
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI)
    _release(fig)
    return buf.getvalue()


def _release(fig: Figure) -> None:
    """Free a rendered figure now: a Figure and its artists reference each other, so without this their tens of
    MB wait for the cyclic garbage collector, and a worker rendering one map per voyage grows by ~35 MB a voyage."""
    fig.clear()
    fig.canvas = None


def _save(fig: Figure, path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, format="png", dpi=DPI)
    _release(fig)
    return path
