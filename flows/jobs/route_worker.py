"""What a dask worker runs for a fleet: route a batch of voyages, each on its own, and return plain results.

No Prefect here (workers never start or call a Prefect API). A worker given the run's exports root writes its
voyages' export files to the run's staging area there itself (storage/export_store.py: a shared folder or an
object store) and returns only the route row, leg rows, the staged files' manifest entries and the log lines the
parent re-emits (so errors from workers reach the run's logs); without one, the export files come back as bytes.

Each voyage reads only its window of the cube cycle (the steps and the lat/lon box it can meet), without dask;
windows are cached per (store, cycle, content version, window), so a re-ingested cycle is read afresh.
"""

from __future__ import annotations

import functools
import itertools
import json
import logging
import traceback

import numpy as np

from flows.jobs import picture_process
from flows.jobs.worker_memory import drop_code_pages_after_kernel_loads, release_free_memory
from pipeline.routing import weather_field as wf
from pipeline.routing.job import RouteJob, WeatherFor, plan_voyage
from pipeline.routing.plan import Plan
from pipeline.routing.problem import WeatherWindow
from storage import cube_window
from storage.cube_location import CubeError

LOG = logging.getLogger("jitroute.fleet")


def failed_row(run_id: str, voyage: dict, cycle, reason: str, status: str = "failed") -> dict:
    """The route row of a voyage that was not routed, with the reason (every column of a plan's row, empty)."""
    row = dict.fromkeys(Plan(voyage_id="", imo=None, solver="", objective="", status=status, reason=reason,
                             depart_utc=None, rta_utc=None).route_row())
    row.update(run_id=run_id, voyage_id=str(voyage.get("voyage_id")), imo=voyage.get("imo"), status=status, reason=reason,
               depart_utc=voyage.get("depart_utc"), rta_utc=voyage.get("rta_utc"),
               cycle=np.datetime64(cycle, "s").item() if cycle is not None else None, n_legs=0, n_legs_beyond_forecast=0)
    return row


# what a fleet run adds to a voyage's job (pipeline/enroute.py, storage.fleet_store.voyage_fingerprints) and keeps
# in its route row: where the plan starts and the voyage it was made for
START_COLUMNS = ("start_kind", "start_lat", "start_lon", "start_utc", "start_position_utc", "start_advanced_h",
                 "start_note", "voyage_fingerprint")


def start_columns(job: RouteJob) -> dict:
    return {k: job.voyage.get(k) for k in START_COLUMNS}  # every column of the row: None where the job has none


def failed_result(job: RouteJob, reason: str, log: list | None = None) -> dict:
    row = failed_row(job.run_id, job.voyage, job.cycle, reason)
    row.update(start_columns(job))
    return {"route": row, "legs": [], "exports": {}, "export_errors": {}, "log": log or []}


WINDOWS_CACHED = 4  # a few MB each for an ocean crossing; voyages on one route and departure share theirs


@functools.lru_cache(maxsize=2)
def published_view(store: str, options_json: str, cycle: str, version: int | None):
    """The store's published view (metadata and coordinates only), opened once per cycle content version."""
    return cube_window.open_published(store, json.loads(options_json))


@functools.lru_cache(maxsize=WINDOWS_CACHED)
def window_field(store: str, options_json: str, cycle: str, version: int | None, window: WeatherWindow) -> wf.WeatherField:
    """A voyage's window of a cube cycle as a WeatherField, read once per (store, cycle, content version, window)
    in this process; `options_json` is the store's fsspec options as JSON (hashable)."""
    win = cube_window.read_window(store, cycle, valid_utc=(window.from_utc, window.to_utc), lat_deg=window.lat_deg,
                                  lon_deg=window.lon_deg, variables=wf.CUBE_VARIABLES,
                                  storage_options=json.loads(options_json),
                                  published=published_view(store, options_json, cycle, version))
    return wf.from_window(win)


def lagged_members(cube_path: str, storage_options: dict | None, cycle: str, window: WeatherWindow,
                   n_members: int) -> list[wf.WeatherField]:
    """A lagged ensemble for a voyage: its window of `cycle` and of the complete cycles before it (newest first, up to
    `n_members` in all), valid at the same times; a cycle whose leads end before the window starts is left out."""
    options_json = json.dumps(storage_options or {}, sort_keys=True)
    c = np.datetime64(cycle, "ns")
    older = (x for x in cube_window.complete_cycles_newest_first(cube_path, storage_options) if x < c)
    members = []
    for x in itertools.chain([c], older):
        if len(members) >= n_members:
            break
        try:
            field = window_field(str(cube_path), options_json, str(np.datetime_as_string(np.datetime64(x, "s"))), None,
                                 window)
        except (KeyError, CubeError):  # retired, being re-written or damaged meanwhile: one member less
            continue
        if field.horizon_utc > np.datetime64(window.from_utc, "s"):
            members.append(field)
    return members


def planned(job: RouteJob, cube_path: str | None, storage_options: dict | None = None,
            n_members: int | None = None) -> tuple[Plan, wf.WeatherField]:
    """`plan_voyage` in the job's cube weather; with a cube, the robust decisions its options ask for
    (job.robust_plan) and the plan's spread across a lagged ensemble of `n_members` cycles (default the job's
    `ensemble_members`; 0: none), or from the job's calibrated error model (job.plan_spread), in `Plan.spread`."""
    from pipeline.routing.job import kept_or_replanned, plan_spread, robust_plan

    windows = []
    from_cube = cube_weather(cube_path, job, storage_options)
    weather_for = None
    if from_cube is not None:
        def weather_for(problem, space):
            windows.append(problem.weather_window(space))  # the voyage's window: the members' too
            return from_cube(problem, space)
    plan, weather = plan_voyage(job, weather_for)
    n = job.options.ensemble_members if n_members is None else n_members
    if windows and n > 0 and plan.legs:
        members = lagged_members(cube_path, storage_options, job.cycle, windows[-1], n)
        plan, weather = robust_plan(job, plan, weather, weather_for, members)
        plan = kept_or_replanned(job, plan, weather, members)
        plan.spread = plan_spread(job, plan, members)  # from the job's error model where it applies
    return plan, weather


def cube_weather(cube_path: str | None, job: RouteJob, storage_options: dict | None = None) -> WeatherFor | None:
    """Where a job's weather comes from: its voyage's window of the job's cube cycle (None: calm water)."""
    if cube_path is None:
        return None
    options_json = json.dumps(storage_options or {}, sort_keys=True)
    return lambda problem, space: window_field(str(cube_path), options_json, job.cycle, job.cycle_version,
                                               problem.weather_window(space))


@functools.lru_cache(maxsize=2)
def run_exports(url: str, options_json: str):
    """The exports root a worker stages into, opened once per process."""
    from storage.export_store import RunExports

    return RunExports(url, json.loads(options_json))


def exports_root(exports_to: tuple[str, dict]):
    """The exports root `exports_to` = (URL or path, fsspec options) as a RunExports, opened once per process."""
    return run_exports(exports_to[0], json.dumps(exports_to[1] or {}, sort_keys=True))


def stage_exports(exports_to: tuple[str, dict], run_id: str, voyage_id: str, files: dict) -> tuple[list[dict], dict]:
    """Write a voyage's export files (kind → bytes) to the run's staging area under the exports root
    `exports_to` = (URL or path, fsspec options). Returns (manifest entries {"name", "bytes"}, kind → error)."""
    from pipeline.export.bundle import SUFFIX
    from pipeline.export.paths import ExportPathError, voyage_export_key
    from storage.export_store import ExportPathError as StoreNameError

    root = exports_root(exports_to)
    staged, errors = [], {}
    for kind, data in files.items():
        try:  # the voyage ID makes the file name, in the voyage's own folder, or is refused naming the voyage
            name = voyage_export_key(voyage_id, SUFFIX[kind])
            root.stage(run_id, name, data)
            staged.append({"name": name, "bytes": len(data)})
        except (OSError, ExportPathError, StoreNameError) as exc:
            errors[kind] = f"not written: {exc}"
    return staged, errors


def copy_staged(exports_to: tuple[str, dict], run_id: str, names: list[str]) -> bool:
    """Copy a share of the run's staged files to its run folder (storage/export_store.RunExports.copy_staged): the
    publish's copies, done by the workers rather than the flow host. True when done."""
    exports_root(exports_to).copy_staged(run_id, names)
    return True


def route_one(job: RouteJob, cube_path: str | None, storage_options: dict | None = None,
              exports_to: tuple[str, dict] | None = None, draw=None) -> dict:
    """Route one voyage end to end; a voyage that cannot be routed becomes a `failed` row with the reason. With
    `exports_to` (the run's exports root and its fsspec options) the export files are staged there, else returned.
    `draw` draws the PNGs (pipeline/export/drawing.py; default: in this process)."""
    from pipeline.routing.problem import RoutingInputError
    from pipeline.routing.search_space import VoyageGeometryError

    try:
        plan, weather = planned(job, cube_path, storage_options)
    except (RoutingInputError, VoyageGeometryError, KeyError, CubeError) as exc:  # the message says what to do
        return failed_result(job, str(exc).strip("'\""))
    except Exception as exc:  # a bug or bad data: record it, keep the rest of the fleet going
        return failed_result(job, f"unexpected error: {type(exc).__name__}: {exc}",
                             log=[("error", f"voyage {job.voyage_id} failed:\n{traceback.format_exc()}")])
    out = {"route": {**plan.route_row(job.run_id), **start_columns(job)}, "legs": plan.leg_rows(job.run_id),
           "exports": {}, "export_errors": {}, "staged": [], "log": []}
    if job.exports and plan.legs:
        from pipeline.export.bundle import export_plan, kinds_of_run  # lxml: only workers that export load it
        from pipeline.export.drawing import draw_here

        bundle = export_plan(plan, weather, job.vessel, job.voyage, kinds=kinds_of_run(job.debug_plots),
                             draw=draw or draw_here, run_id=job.run_id)
        out["export_errors"] = dict(bundle.errors)
        if exports_to is None:
            out["exports"] = dict(bundle.files)  # kind → bytes; the caller names and writes them
        else:
            out["staged"], unwritten = stage_exports(exports_to, job.run_id, job.voyage_id, bundle.files)
            out["export_errors"].update(unwritten)
        out["log"] += [("error", f"voyage {job.voyage_id}: {kind} export failed: {err}")
                       for kind, err in out["export_errors"].items()]
    return out


def route_batch(jobs: list[RouteJob], cube_path: str | None, storage_options: dict | None = None,
                exports_to: tuple[str, dict] | None = None) -> list[dict]:
    """Route a few voyages one after the other; each is isolated (its own try/except and row). `cube_path` is a
    local path or a URL (`s3://…`, with fsspec `storage_options`); `exports_to` as for route_one. The voyages' PNGs
    are drawn in this process's child (flows/jobs/picture_process.py, started at the first picture), so this
    process never loads matplotlib."""
    stop_task_profiler()
    drop_code_pages_after_kernel_loads()
    release_free_memory()  # before the first voyage too: what the imports left resident
    out = []
    for job in jobs:
        out.append(route_one(job, cube_path, storage_options, exports_to, picture_process.of_this_process()))
        release_free_memory()
    return out


def stop_task_profiler() -> bool:
    """Stop the dask worker's statistical profiler, when this runs in a dask worker that has it on (the default of
    `dask worker`). It samples the task thread's stack every 10 ms and keeps one profile per second of work for the
    last 1,000 s: with routing's and plotting's deep stacks that grew a worker by about 1 MB a second, 250 MB
    over a 200-voyage run. Returns True when it was running here and is now stopped (False outside dask, or off).
    Workers can also start with it off: `DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED=False`."""
    try:
        from distributed import get_worker

        worker = get_worker()
    except (ImportError, ValueError):  # not in a dask worker
        return False
    callbacks = getattr(worker, "periodic_callbacks", {})
    if "profile" not in callbacks and "profile-cycle" not in callbacks:
        return False

    def stop() -> None:  # on the worker's event loop, which owns the callbacks and the profiles
        for name in ("profile", "profile-cycle"):
            pc = callbacks.pop(name, None)
            if pc is not None:
                pc.stop()
        worker.profile_history.clear()
        worker.profile_keys_history.clear()

    worker.loop.add_callback(stop)
    LOG.info("dask worker %s: its task profiler stopped (it held a profile per second of routing)", worker.address)
    return True
