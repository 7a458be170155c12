"""A fleet run's own pictures, drawn in a dask worker and staged there like the voyages' files: the fleet map (every
voyage's track, coloured by status, and each ship's position at the run's time) and the weather maps of the cycle's
first step over the fleet's extent (FLEET_MARGIN_DEG around every voyage's ports).

Drawing them (matplotlib, and for the weather a step of the whole grid read from the cube) cost the flow host
seconds a run. The worker reads what a picture shows and a child process draws it (flows/jobs/picture_process.py),
so the worker never loads matplotlib. Each function returns the staged files' manifest entries ({"name", "bytes"})
and one line per picture that could not be made (a picture; the run's data never depends on it).
"""

from __future__ import annotations

from datetime import datetime, timedelta

import numpy as np

from flows.jobs import picture_process
from flows.jobs.route_worker import exports_root

WEATHER_VARIABLES = ("waves", "wind")
FLEET_MAP = "fleet_map.png"
TRACK_KEYS = ("lat0", "lon0", "lat1", "lon1")
TIME_KEYS = ("etd_utc", "eta_utc")  # carried as seconds since 1970 UTC (NaN: unknown) in the track's last columns
FLEET_MARGIN_DEG = 5.0
_EPOCH = datetime(1970, 1, 1)


def fleet_box(points) -> tuple[float, float, float, float] | None:
    """(south, north, west, east) in degrees east (east ≥ west; a fleet across 180° gives e.g. (170, 200)) around
    the (lat, lon) `points` with FLEET_MARGIN_DEG; None without points (the maps are then global)."""
    from pipeline.export.voyage import centre_lon_deg, finite_or_none

    pts = [(finite_or_none(a), finite_or_none(b)) for a, b in points]
    pts = np.asarray([p for p in pts if None not in p], dtype=np.float64).reshape(-1, 2)
    if not len(pts):
        return None
    centre = centre_lon_deg(pts[:, 1])
    lon = centre + (pts[:, 1] - centre + 180.0) % 360.0 - 180.0
    west, east = float(lon.min()) - FLEET_MARGIN_DEG, float(lon.max()) + FLEET_MARGIN_DEG
    if east - west >= 360.0:
        west, east = -180.0, 180.0
    west_e = west % 360.0
    south = max(-90.0, float(pts[:, 0].min()) - FLEET_MARGIN_DEG)
    north = min(90.0, float(pts[:, 0].max()) + FLEET_MARGIN_DEG)
    return south, north, west_e, west_e + (east - west)


def weather_map_name(var: str, cycle_label: str) -> str:
    return f"weather_{var}_{cycle_label}.png"


def _seconds(t) -> float:
    from pipeline.export.voyage import utc_datetime

    d = utc_datetime(t)
    return float("nan") if d is None else (d - _EPOCH).total_seconds()


def track(legs: list[dict]) -> np.ndarray:
    """What the fleet map draws of a voyage's legs: (lat0, lon0, lat1, lon1, etd, eta) of each, in order, as one
    (legs, 6) array, times in seconds since 1970 UTC: dask walks every list and tuple of a task's arguments looking
    for futures, which for 200 voyages' legs as tuples cost the run's host about 0.5 s CPU."""
    return np.array([[*(leg[k] for k in TRACK_KEYS), *(_seconds(leg.get(k)) for k in TIME_KEYS)] for leg in legs],
                    dtype=np.float64).reshape(-1, len(TRACK_KEYS) + len(TIME_KEYS))


def track_legs(rows: np.ndarray) -> list[dict]:
    """The legs a `track` array holds, times as naive UTC datetimes (None when unknown)."""
    out = []
    for row in rows.tolist():
        leg = dict(zip(TRACK_KEYS, row))
        for k, s in zip(TIME_KEYS, row[len(TRACK_KEYS):]):
            leg[k] = None if np.isnan(s) else _EPOCH + timedelta(seconds=s)
        out.append(leg)
    return out


def stage_fleet_map(exports_to: tuple[str, dict], run_id: str, title: str,
                    voyages: list[tuple[str, str, np.ndarray, str | None]],
                    now_utc=None) -> tuple[list[dict], list[str]]:
    """Draw the fleet map of `voyages` = (voyage_id, status, track, start_kind) with each ship's position at
    `now_utc` (the run's time) and stage it as the run's `fleet_map.png` under the exports root `exports_to` = (URL or
    path, fsspec options). Returns (entries staged, errors)."""
    pairs = [({"voyage_id": vid, "status": status, "start_kind": start}, track_legs(legs))
             for vid, status, legs, start in voyages]
    try:
        png = picture_process.of_this_process()("fleet_map", pairs, title, now_utc)
        root = exports_root(exports_to)
        return [{"name": root.stage(run_id, FLEET_MAP, png), "bytes": len(png)}], []
    except Exception as exc:  # a picture; the run's data does not depend on it
        return [], [f"fleet: fleet map: {type(exc).__name__}: {exc}"]


def stage_weather_maps(exports_to: tuple[str, dict], run_id: str, cube_url: str, storage_options: dict | None,
                       cycle: str, cycle_label: str, box=None) -> tuple[list[dict], list[str]]:
    """Draw the weather of the cycle at its start (its first step read once) over `box` (fleet_box; None: the
    globe) and stage one map per variable of WEATHER_VARIABLES. Returns (entries staged, errors)."""
    from flows.jobs import weather_maps
    from storage.cube_location import locate

    try:
        pngs = weather_maps.run_maps_png(locate(cube_url, storage_options), cycle, WEATHER_VARIABLES,
                                         draw=picture_process.of_this_process(), box=box)
        root = exports_root(exports_to)
        return [{"name": root.stage(run_id, weather_map_name(var, cycle_label), png), "bytes": len(png)}
                for var, png in pngs.items()], []
    except Exception as exc:  # a picture; the run's data does not depend on it
        return [], [f"fleet: weather maps: {type(exc).__name__}: {exc}"]
