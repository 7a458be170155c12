"""What a dask worker runs for a fleet: route a batch of voyages, each on its own, and return plain results.

No Prefect here (workers never start or call a Prefect API) and nothing written where the worker
runs: each result carries the route row, leg rows, export files as bytes and the log lines the
parent re-emits (so errors from workers reach the run's logs).
"""

from __future__ import annotations

import functools
import logging
import math
import traceback
from pathlib import Path

import numpy as np
import pandas as pd

from pipeline.routing.job import RouteJob, plan_voyage
from storage import cube
from storage.route_store import ROUTE_COLUMNS

LOG = logging.getLogger("jitroute.fleet")


def failed_row(run_id: str, voyage: dict, cycle, reason: str, status: str = "failed") -> dict:
    """The route row of a voyage that was not routed, with the reason."""
    row = {k: None for k in ROUTE_COLUMNS}
    row.update(run_id=run_id, voyage_id=str(voyage.get("voyage_id")), imo=voyage.get("imo"), status=status, reason=reason,
               depart_utc=voyage.get("depart_utc"), rta_utc=voyage.get("rta_utc"),
               cycle=pd.Timestamp(cycle) if cycle is not None else None, n_legs=0, n_legs_beyond_forecast=0)
    return row


def failed_result(job: RouteJob, reason: str, log: list | None = None) -> dict:
    return {"route": failed_row(job.run_id, job.voyage, job.cycle, reason), "legs": [], "exports": {},
            "export_errors": {}, "log": log or []}


@functools.lru_cache(maxsize=2)
def cycle_field(cube_path: str, cycle: str):
    """One cube cycle as a WeatherField, read once per worker process and reused for its voyages."""
    from pipeline.routing import weather_field as wf

    return wf.from_cycle(cube.load_cycle(Path(cube_path), cycle), cycle)


def route_one(job: RouteJob, cube_path: str | None) -> dict:
    """Route one voyage end to end; a voyage that cannot be routed becomes a `failed` row with the reason."""
    from pipeline.export.bundle import export_plan
    from pipeline.routing.problem import RoutingInputError
    from pipeline.routing.search_space import VoyageGeometryError

    try:
        weather = cycle_field(cube_path, job.cycle) if cube_path is not None else None
        plan, weather = plan_voyage(job, weather)
    except (RoutingInputError, VoyageGeometryError, KeyError, cube.CubeError) as exc:  # the message says what to do
        return failed_result(job, str(exc).strip("'\""))
    except Exception as exc:  # a bug or bad data: record it, keep the rest of the fleet going
        return failed_result(job, f"unexpected error: {type(exc).__name__}: {exc}",
                             log=[("error", f"voyage {job.voyage_id} failed:\n{traceback.format_exc()}")])
    out = {"route": plan.route_row(job.run_id), "legs": plan.leg_rows(job.run_id), "exports": {}, "export_errors": {},
           "log": []}
    if job.exports and plan.legs:
        bundle = export_plan(plan, weather, job.vessel, job.voyage)
        out["exports"] = dict(bundle.files)  # kind → bytes; the run's process names and writes them
        out["export_errors"] = bundle.errors
        out["log"] += [("error", f"voyage {job.voyage_id}: {kind} export failed: {err}")
                       for kind, err in bundle.errors.items()]
    return out


def route_batch(jobs: list[RouteJob], cube_path: str | None) -> list[dict]:
    """Route a few voyages one after the other; each is isolated (its own try/except and row)."""
    return [route_one(job, cube_path) for job in jobs]


def plain(v):
    """A warehouse value as a plain Python value (numpy scalars and arrays unpacked, NaN → None)."""
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, np.ndarray):
        return [plain(x) for x in v.tolist()]
    if isinstance(v, float) and math.isnan(v):
        return None
    return v
