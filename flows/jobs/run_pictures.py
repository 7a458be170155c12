"""A fleet run's own pictures, drawn in a dask worker and staged there like the voyages' files: the fleet map (every
voyage's track, coloured by status) and the weather maps of the cycle's first step.

Drawing them (matplotlib, and for the weather a step of the whole grid read from the cube) cost the flow host
seconds a run. The worker reads what a picture shows and a child process draws it (flows/jobs/picture_process.py),
so the worker never loads matplotlib. Each function returns the staged files' manifest entries ({"name", "bytes"})
and one line per picture that could not be made (a picture; the run's data never depends on it).
"""

from __future__ import annotations

import numpy as np

from flows.jobs import picture_process
from flows.jobs.route_worker import exports_root

WEATHER_VARIABLES = ("waves", "wind")
FLEET_MAP = "fleet_map.png"
TRACK_KEYS = ("lat0", "lon0", "lat1", "lon1")


def weather_map_name(var: str, cycle_label: str) -> str:
    return f"weather_{var}_{cycle_label}.png"


def track(legs: list[dict]) -> np.ndarray:
    """What the fleet map draws of a voyage's legs: (lat0, lon0, lat1, lon1) of each, in order, as one (legs, 4)
    array: dask walks every list and tuple of a task's arguments looking for futures, which for 200 voyages' legs
    as tuples cost the run's host about 0.5 s CPU."""
    return np.array([[leg[k] for k in TRACK_KEYS] for leg in legs], dtype=np.float64).reshape(-1, len(TRACK_KEYS))


def stage_fleet_map(exports_to: tuple[str, dict], run_id: str, title: str,
                    voyages: list[tuple[str, str, np.ndarray]]) -> tuple[list[dict], list[str]]:
    """Draw the fleet map of `voyages` = (voyage_id, status, track) and stage it as the run's `fleet_map.png` under
    the exports root `exports_to` = (URL or path, fsspec options). Returns (entries staged, errors)."""
    pairs = [({"voyage_id": vid, "status": status}, [dict(zip(TRACK_KEYS, leg)) for leg in legs.tolist()])
             for vid, status, legs in voyages]
    try:
        png = picture_process.of_this_process()("fleet_map", pairs, title)
        root = exports_root(exports_to)
        return [{"name": root.stage(run_id, FLEET_MAP, png), "bytes": len(png)}], []
    except Exception as exc:  # a picture; the run's data does not depend on it
        return [], [f"fleet: fleet map: {type(exc).__name__}: {exc}"]


def stage_weather_maps(exports_to: tuple[str, dict], run_id: str, cube_url: str, storage_options: dict | None,
                       cycle: str, cycle_label: str) -> tuple[list[dict], list[str]]:
    """Draw the weather of the cycle at its start (its first step read once) and stage one map per variable of
    WEATHER_VARIABLES. Returns (entries staged, errors)."""
    from flows.jobs import weather_maps
    from storage.cube_location import locate

    try:
        pngs = weather_maps.run_maps_png(locate(cube_url, storage_options), cycle, WEATHER_VARIABLES,
                                         draw=picture_process.of_this_process())
        root = exports_root(exports_to)
        return [{"name": root.stage(run_id, weather_map_name(var, cycle_label), png), "bytes": len(png)}
                for var, png in pngs.items()], []
    except Exception as exc:  # a picture; the run's data does not depend on it
        return [], [f"fleet: weather maps: {type(exc).__name__}: {exc}"]
