"""Fleet flows: `route-fleet` (every upcoming voyage, one dask task each) and `nightly`.

Workers read the Zarr cube themselves (one cycle, once per worker process, then reused); the
scheduler ships small job dicts out and plain result rows back. Voyages go out in small batches
(about three Prefect tasks per worker, `routing.voyages_per_task` to override): a Prefect task
costs about a second of orchestration, several times the routing of a coastal voyage. One writer (this flow) puts a
run's rows into DuckDB in one transaction and into Parquet partitions. A voyage that fails —
bad input, no model, no way through, even a lost worker — is recorded with status and reason
and never fails the others.
"""

from __future__ import annotations

import functools
import logging
import math
import traceback
import uuid
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pandas as pd
from prefect import flow, get_run_logger, task
from prefect.cache_policies import NO_CACHE
from prefect.futures import as_completed

from flows.ingest import ingest_weather, parse_cycle
from flows.refit import refit_performance
from flows.settings import Settings, load_settings
from pipeline.performance.model import model_from_stored
from storage import cube, fleet_store, route_store, warehouse
from storage.route_store import ROUTE_COLUMNS

LOG = logging.getLogger("jitroute.fleet")


def _plain(v):
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, np.ndarray):
        return [_plain(x) for x in v.tolist()]
    if isinstance(v, float) and math.isnan(v):
        return None
    return v


def failed_row(run_id: str, voyage: dict, cycle, reason: str, status: str = "failed") -> dict:
    row = {k: None for k in ROUTE_COLUMNS}
    row.update(run_id=run_id, voyage_id=str(voyage.get("voyage_id")), imo=voyage.get("imo"), status=status, reason=reason,
               depart_utc=voyage.get("depart_utc"), rta_utc=voyage.get("rta_utc"), cycle=pd.Timestamp(cycle), n_legs=0,
               beyond_forecast=0)
    return row


def plan_voyage(voyage: dict, vessel: dict, model_json: dict | None, cube_path: str | None, cycle: str | None,
                routing: dict):
    """Build the problem, read the voyage's band of the cube cycle (or calm water when cube_path is None), solve.

    Returns (plan, weather). Raises RoutingInputError / VoyageGeometryError / KeyError for voyages that
    cannot be routed as given (the message names the voyage and what to do).
    """
    from pipeline.performance.model import PerformanceModel
    from pipeline.routing import weather_field as wf
    from pipeline.routing.problem import RoutingInputError
    from pipeline.routing.solve import solve
    from pipeline.routing.voyage import problem_from_voyage

    vid = str(voyage["voyage_id"])
    if model_json is None:
        raise RoutingInputError(f"voyage {vid}: vessel {voyage.get('imo')} has no active performance model; "
                                "import its noon reports and run `jitroute refit` first")
    model = PerformanceModel.from_json(model_json)
    problem = problem_from_voyage(voyage, model, rpm_max=vessel.get("rpm_max"), objective=routing["objective"],
                                  window_h=routing["arrival_window_h"], n_lines=routing["n_lines"],
                                  n_points=routing["n_points"], d_point_nm=routing["d_point_nm"])
    space = problem.search_space()
    if cube_path is None:
        weather = wf.uniform(problem.depart_utc - np.timedelta64(1, "h"), 2.0 * problem.t_req_h + 240.0)
    else:
        weather = cycle_field(cube_path, cycle)
    plan = solve(problem, weather, solver=routing["solver"], seed=routing["seed"], space=space)
    return plan, weather


@functools.lru_cache(maxsize=2)
def cycle_field(cube_path: str, cycle: str):
    """One cube cycle as a WeatherField, read once per worker process and reused for its voyages."""
    from pipeline.routing import weather_field as wf

    return wf.from_cycle(cube.load_cycle(Path(cube_path), cycle), cycle)


def route_one(job: dict) -> dict:
    """Route one voyage end to end (runs on a dask worker). Returns {"route": row, "legs": rows, "files": [...]}."""
    from pipeline.routing.problem import RoutingInputError
    from pipeline.routing.search_space import VoyageGeometryError

    voyage, vessel, run_id, cycle = job["voyage"], job["vessel"], job["run_id"], job["cycle"]
    vid = str(voyage["voyage_id"])
    try:
        plan, weather = plan_voyage(voyage, vessel, job["model"], job["cube"], cycle, job["routing"])
    except (RoutingInputError, VoyageGeometryError, KeyError) as exc:
        return {"route": failed_row(run_id, voyage, cycle, str(exc).strip("'\"")), "legs": [], "files": []}
    except Exception as exc:  # a bug or bad data: record it, keep the rest of the fleet going
        LOG.error("voyage %s failed:\n%s", vid, traceback.format_exc())
        return {"route": failed_row(run_id, voyage, cycle, f"unexpected error: {type(exc).__name__}: {exc}"), "legs": [],
                "files": []}
    row = plan.route_row(run_id)
    legs = plan.leg_rows(run_id)
    files = write_exports(Path(job["exports_dir"]), plan, weather, vessel, voyage) if job.get("exports_dir") and plan.legs else []
    if files and isinstance(files[-1], Exception):
        row["reason"] = (row["reason"] + "; " if row["reason"] else "") + f"export failed: {files.pop()}"
    return {"route": row, "legs": legs, "files": files}


def write_exports(out: Path, plan, weather, vessel: dict, voyage: dict) -> list:
    """RTZ (schema-validated), GeoJSON, route map and convergence PNGs of a plan; an export error is appended, not raised."""
    from pipeline.export import geojson, plots, rtz
    from pipeline.routing import weather_field as wf

    vid = plan.voyage_id
    out.mkdir(parents=True, exist_ok=True)
    named = dict(plan.route_row(), vessel_name=vessel.get("name"), dep_name=voyage.get("dep_name"),
                 arr_name=voyage.get("arr_name"))
    files: list = []
    try:
        doc = rtz.route_to_rtz(named, plan.legs)
        rtz.validate_rtz(doc)
        files.append(_write_bytes(out / f"{vid}.rtz", doc))
        files.append(_write_bytes(out / f"{vid}.geojson", _json_bytes(geojson.route_to_geojson(named, plan.legs))))
        lats = [p[0] for p in plan.waypoints]
        lons = [p[1] for p in plan.waypoints]
        mid = plan.legs[len(plan.legs) // 2]["etd_utc"]
        field = wf.snapshot(weather, mid, (min(lats), max(lats)), (min(lons), max(lons)))
        base_legs = plan.baseline.legs if plan.baseline is not None else None
        files.append(str(plots.route_map_png(out / f"{vid}.png", named, plan.legs, base_legs,
                                             field if field["hs_m"] is not None else None)))
        if plan.history is not None:
            files.append(str(plots.convergence_png(out / f"{vid}.convergence.png", plan.history,
                                                   title=f"{vid}: BFOA best cost per cycle")))
    except Exception as exc:  # exports are secondary: keep the route, say what went wrong
        LOG.error("voyage %s: export failed: %s", vid, exc)
        files.append(exc)
    return files


def _json_bytes(obj) -> bytes:
    import json

    return json.dumps(obj, indent=1).encode()


def _write_bytes(path: Path, data: bytes) -> str:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_bytes(data)
    tmp.replace(path)
    return str(path)


@task(name="route-voyages-batch", retries=1, retry_delay_seconds=0, cache_policy=NO_CACHE)
def route_batch(jobs: list[dict]) -> list[dict]:
    """Route a few voyages one after the other; each is isolated (its own try/except and row)."""
    return [route_one(job) for job in jobs]


def batches(jobs: list[dict], per_task: int) -> list[list[dict]]:
    """Deal the voyages, longest first, round-robin into batches of about `per_task` so batches take similar time."""
    from pipeline.routing.geodesy import gc_distance_nm

    def length_nm(job):
        v = job["voyage"]
        try:
            return -gc_distance_nm(float(v["dep_lat"]), float(v["dep_lon"]), float(v["arr_lat"]), float(v["arr_lon"]))
        except (TypeError, ValueError, KeyError):
            return 0.0

    ordered = sorted(jobs, key=length_nm)
    n = max(1, math.ceil(len(jobs) / per_task))
    return [ordered[k::n] for k in range(n) if ordered[k::n]]


def voyages_per_task(n_jobs: int, n_workers: int, setting: int | None) -> int:
    """Explicit setting, else about three tasks per worker (a Prefect task costs ~1 s of orchestration)."""
    if setting:
        return max(1, int(setting))
    return max(1, math.ceil(n_jobs / (3 * max(1, n_workers))))


@flow(name="route-voyages")
def route_voyages(jobs: list[dict], per_task: int = 1) -> list[dict]:
    """Fan the jobs out over the flow's task runner; a lost task becomes failed rows, never lost voyages."""
    logger = get_run_logger()
    futures = {route_batch.submit(chunk): chunk for chunk in batches(jobs, per_task)}
    results = []
    for fut in as_completed(list(futures)):
        chunk = futures[fut]
        try:
            done = fut.result()
        except Exception as exc:
            done = [{"route": failed_row(job["run_id"], job["voyage"], job["cycle"],
                                         f"routing task lost: {type(exc).__name__}: {exc}"), "legs": [], "files": []}
                    for job in chunk]
        results.extend(done)
        for res in done:
            r = res["route"]
            logger.info("routed %d/%d: %s %s%s", len(results), len(jobs), r["voyage_id"], r["status"],
                        f" ({r['reason']})" if r.get("reason") else "")
    return results


def task_runner(s: Settings):
    from prefect_dask import DaskTaskRunner

    logging.getLogger("distributed").setLevel(logging.WARNING)  # progress is reported per voyage instead

    if s.dask_address:
        return DaskTaskRunner(address=s.dask_address)
    return DaskTaskRunner(cluster_kwargs={"n_workers": s.dask_workers, "threads_per_worker": 1, "processes": True,
                                          "dashboard_address": None, "silence_logs": logging.WARNING})


def upcoming(voyages: pd.DataFrame, cycle: np.datetime64, lookahead_h: float) -> pd.DataFrame:
    c = pd.Timestamp(cycle)
    keep = (voyages["depart_utc"] >= c) & (voyages["depart_utc"] < c + pd.Timedelta(hours=lookahead_h))
    return voyages[keep & (voyages["status"].fillna("planned") == "planned")]


@flow(name="route-fleet")
def route_fleet(cycle: str | None = None, voyages: list[str] | None = None, data_root: str | None = None,
                solver: str | None = None, seed: int | None = None, trigger: str = "manual", exports: bool = True) -> dict:
    """Route every upcoming voyage (or the given ones) on one cube cycle (default: the newest complete one)."""
    s = load_settings(data_root=Path(data_root) if data_root else None,
                      **{"routing.solver": solver, "routing.seed": seed})
    layout = s.layout.ensure()
    logger = get_run_logger()
    c = parse_cycle(cycle) if cycle else cube.latest_complete_cycle(layout.weather_cube)
    if c is None:
        raise RuntimeError(f"no complete forecast cycle in {layout.weather_cube}: run `jitroute ingest --cycle …` first")
    states = cube.cycle_states(layout.weather_cube)
    if c not in states:
        raise RuntimeError(f"cycle {np.datetime_as_string(c, unit='h')} is not in the cube {layout.weather_cube}: ingest it first")
    table = fleet_store.load_voyages(layout.warehouse, voyage_ids=voyages)
    if not voyages:
        table = upcoming(table, c, s.routing.lookahead_h)
    vessels = {int(v["imo"]): {k: _plain(x) for k, x in v.items()} for v in fleet_store.load_vessels(layout.warehouse).to_dict("records")}
    models = {}
    for imo in set(table["imo"].astype(int)):
        m = model_from_stored(fleet_store.active_model(layout.warehouse, imo), imo)
        models[imo] = m.to_json() if m is not None else None
    stamp = datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%S")
    run_id = f"{stamp}-{uuid.uuid4().hex[:6]}"
    route_store.begin_run(layout.warehouse, run_id, cycle=c, solver=s.routing.solver, trigger=trigger, n_voyages=len(table))
    run_dir = layout.exports / "runs" / run_id
    routing = {k: getattr(s.routing, k) for k in ("solver", "objective", "arrival_window_h", "seed", "n_lines", "n_points", "d_point_nm")}
    jobs = []
    for v in table.to_dict("records"):
        v = {k: _plain(x) for k, x in v.items()}
        jobs.append({"voyage": v, "vessel": vessels.get(int(v["imo"]), {}), "model": models.get(int(v["imo"])),
                     "run_id": run_id, "cycle": str(np.datetime_as_string(c, unit="s")), "cube": str(layout.weather_cube),
                     "routing": routing, "exports_dir": str(run_dir) if exports else None})
    logger.info("run %s: routing %d voyages on cycle %s (%s)", run_id, len(jobs), np.datetime_as_string(c, unit="h"),
                f"dask at {s.dask_address}" if s.dask_address else f"local dask cluster, {s.dask_workers} workers")
    try:
        per_task = voyages_per_task(len(jobs), s.dask_workers, s.routing.voyages_per_task)
        results = route_voyages.with_options(task_runner=task_runner(s))(jobs, per_task) if jobs else []
        rows = [r["route"] for r in results]
        legs = [leg for r in results for leg in r["legs"]]
        route_store.write_run_results(layout.warehouse, layout.exports, run_id, rows, legs)
    except BaseException as exc:
        route_store.fail_run(layout.warehouse, run_id, f"{type(exc).__name__}: {exc}")
        raise
    if exports and results:
        from pipeline.export import plots

        pairs = [(r["route"], r["legs"]) for r in results]
        plots.fleet_map_png(run_dir / "fleet_map.png", pairs, title=f"run {run_id} · cycle {np.datetime_as_string(c, unit='h')}")
    warehouse.publish_snapshot(layout.warehouse)
    summary = route_store.run_summary(layout.warehouse, run_id)
    summary.update(run_id=run_id, exports_dir=str(run_dir), fleet_map=str(run_dir / "fleet_map.png") if exports and results else None)
    return summary


@flow(name="nightly")
def nightly(date: str | None = None, data_root: str | None = None, rish_url: str | None = None,
            oscar_url: str | None = None, cycles: str | None = None) -> dict:
    """Ingest the date's cycles → refit → route the fleet on the newest complete cycle; a one-screen summary."""
    s = load_settings(data_root=Path(data_root) if data_root else None)
    logger = get_run_logger()
    day = np.datetime64(date[:10] if date else datetime.now(timezone.utc).strftime("%Y-%m-%d"), "D")
    hours = [int(h) for h in cycles.split(",")] if cycles else list(s.sources.cycles_utc)
    ingests = []
    for h in hours:
        label = f"{np.datetime_as_string(day)}T{h:02d}"
        ingests.append(ingest_weather(label, data_root=data_root, rish_url=rish_url, oscar_url=oscar_url))
    fits = refit_performance(data_root=data_root)
    end_of_day = np.datetime64(day + 1, "ns") - np.timedelta64(1, "ns")
    c = cube.latest_complete_cycle(s.layout.weather_cube, at_or_before=end_of_day)
    summary = {"date": str(day), "ingest": ingests, "models_changed": sum(bool(f.get("changed")) for f in fits),
               "vessels": len(fits)}
    if c is None:
        logger.warning("no complete cycle up to %s: routing skipped", day)
        summary["routing"] = None
        return summary
    summary["routing"] = route_fleet(cycle=str(np.datetime_as_string(c, unit="h")), data_root=data_root, trigger="nightly")
    _artifact(summary)
    return summary


def _artifact(summary: dict) -> None:
    try:
        from prefect.artifacts import create_markdown_artifact

        r = summary["routing"]
        md = (f"# jitroute nightly {summary['date']}\n\n| | |\n|---|---|\n| cycle | {r.get('cycle')} |\n"
              f"| voyages | {r.get('n')} |\n| ok / late / not routed | {r.get('n_ok')} / {r.get('n_late')} / "
              f"{r.get('n_failed')} |\n"
              f"| fuel t | {r.get('fuel_t')} |\n| savings % | {r.get('savings_pct')} |\n")
        create_markdown_artifact(md, key="nightly-summary", description="jitroute nightly summary")
    except Exception as exc:  # the artifact is a convenience; the run's data is already stored
        get_run_logger().warning("could not create the summary artifact: %s", exc)
