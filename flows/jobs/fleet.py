"""The fleet jobs: `route-fleet` (every upcoming voyage on one cube cycle) and `nightly` (ingest → refit → route).

Voyages go out over dask in batches (flows/jobs/dask_pool.py); workers route with plain functions and
return rows and export bytes, so they write nothing. This process is the one writer: it stages the exports
as results arrive (under the local data root or the object root, storage/export_store.py), puts the run's
rows into DuckDB in one transaction, then publishes the staged exports with their manifest (a run that
fails or is killed publishes nothing). A voyage that fails (bad input, no model, no way through,
even a lost worker) is recorded with status and reason and never fails the others.
"""

from __future__ import annotations

import logging
import math
import uuid
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pandas as pd

from flows.jobs import dask_pool, weather_maps
from flows.jobs.ingest import ingest_cycle
from flows.jobs.refit import refit_job
from flows.jobs.route_worker import failed_result, route_batch
from flows.runner import PLAIN
from flows.settings import Settings, load_settings
from pipeline.export.bundle import SUFFIX
from pipeline.performance.model import model_from_stored
from pipeline.export.paths import ExportPathError, voyage_export_key
from pipeline.validate_ids import markdown_cell, printable
from pipeline.export.voyage import utc_datetime
from pipeline.routing.geodesy import gc_distance_nm
from pipeline.routing.job import RouteJob, RoutingOptions
from pipeline.sources.cycles import label as cycle_label, newest_published_cycles, parse_cycle, parse_day, parse_hours, utcnow_h
from storage import cube, export_store, fleet_store, route_store
from storage.run_lock import job_lock

LOG = logging.getLogger("jitroute.fleet")


class FleetRunError(RuntimeError):
    """A fleet run that cannot start (no cube, unknown cycle); the message says what to do."""


def upcoming(voyages: pd.DataFrame, cycle: np.datetime64, lookahead_h: float) -> pd.DataFrame:
    c = pd.Timestamp(cycle)
    keep = (voyages["depart_utc"] >= c) & (voyages["depart_utc"] < c + pd.Timedelta(hours=lookahead_h))
    return voyages[keep & (voyages["status"].fillna("planned") == "planned")]


def plain(v):
    """A warehouse value as a plain Python value for a worker (numpy scalars and arrays unpacked, NaN and NaT → None,
    times as naive UTC datetimes): jobs then unpickle in a worker without pandas."""
    if isinstance(v, (datetime, np.datetime64)):  # pandas Timestamps and NaT are datetimes
        return utc_datetime(v)
    if isinstance(v, np.generic):
        return plain(v.item())
    if isinstance(v, np.ndarray):
        return [plain(x) for x in v.tolist()]
    if isinstance(v, float) and math.isnan(v):
        return None
    return v


def _length_nm(job: RouteJob) -> float:
    v = job.voyage
    try:
        return gc_distance_nm(float(v["dep_lat"]), float(v["dep_lon"]), float(v["arr_lat"]), float(v["arr_lon"]))
    except (TypeError, ValueError, KeyError):
        return 0.0


def fleet_jobs(s: Settings, db: Path, cycle: np.datetime64, run_id: str, voyage_ids: list[str] | None,
               options: RoutingOptions, exports: bool, cycle_version: int | None = None) -> list[RouteJob]:
    """One RouteJob per voyage to route: the given ones, else those departing within the look-ahead of the cycle;
    each carries the cycle's content version read at the start of the run."""
    table = fleet_store.load_voyages(db, voyage_ids=voyage_ids)
    if voyage_ids:
        unknown = sorted(set(voyage_ids) - set(table["voyage_id"].astype(str)))
        if unknown:
            raise FleetRunError(f"voyage(s) {', '.join(unknown)} not in {db}: import them with `jitroute fleet import`")
    else:
        table = upcoming(table, cycle, s.routing.lookahead_h)
    vessels = {int(v["imo"]): {k: plain(x) for k, x in v.items()} for v in fleet_store.load_vessels(db).to_dict("records")}
    models = {}
    for imo in set(table["imo"].astype(int)):
        m = model_from_stored(fleet_store.active_model(db, imo), imo)
        models[imo] = m.to_json() if m is not None else None
    cyc = str(np.datetime_as_string(cycle, unit="s"))
    jobs = []
    for v in table.to_dict("records"):
        v = {k: plain(x) for k, x in v.items()}
        jobs.append(RouteJob(voyage=v, vessel=vessels.get(int(v["imo"]), {}), model=models.get(int(v["imo"])),
                             run_id=run_id, cycle=cyc, exports=exports, options=options, cycle_version=cycle_version))
    return jobs


def route_voyages(jobs: list[RouteJob], cube_store: cube.Location, run_exports: export_store.RunExports | None,
                  dask_address: str | None, n_workers: int, per_batch: int | None) -> dict:
    """Route every job on dask (workers read the cube at `cube_store`'s path or URL themselves); stage export
    files as results arrive. Returns rows, legs and export errors."""
    rows, legs, export_errors = [], [], []
    done = 0
    level = {"error": logging.ERROR, "warning": logging.WARNING, "info": logging.INFO}

    def on_done(batch, results, error):
        nonlocal done
        if error is not None:
            LOG.error("a batch of %d voyages was lost: %s: %s", len(batch), type(error).__name__, error)
            results = [failed_result(job, f"routing task lost: {type(error).__name__}: {error}") for job in batch]
        for res in results:
            for lvl, msg in res.get("log", []):
                LOG.log(level.get(lvl, logging.INFO), "%s", printable(msg))
            r = res["route"]
            rows.append(r)
            legs.extend(res["legs"])
            for kind, err in res.get("export_errors", {}).items():
                export_errors.append(f"{r['voyage_id']}: {kind}: {err}")
            for kind, data in res.get("exports", {}).items():
                try:  # the voyage ID makes the file name, in the voyage's own folder, or is refused naming the voyage
                    run_exports.stage(r["run_id"], voyage_export_key(r["voyage_id"], SUFFIX[kind]), data)
                except (OSError, ExportPathError) as exc:
                    export_errors.append(f"{r['voyage_id']}: {kind}: {exc}")
                    LOG.error("voyage %s: %s export not written: %s", r["voyage_id"], kind, exc)
            done += 1
            LOG.info("routed %d/%d: %s %s%s", done, len(jobs), printable(r["voyage_id"]), r["status"],
                     f" ({printable(r['reason'])})" if r.get("reason") else "")

    if jobs:
        with dask_pool.dask_client(dask_address, n_workers) as client:
            per = dask_pool.voyages_per_batch(len(jobs), dask_pool.worker_slots(client), per_batch)
            dask_pool.map_batches(client, route_batch, dask_pool.batches(jobs, per, _length_nm), cube_store.url,
                                  cube_store.options, on_done=on_done)
    return {"rows": rows, "legs": legs, "export_errors": export_errors}


def route_fleet_job(cycle: str | None = None, voyages: list[str] | None = None, data_root: str | None = None,
                    solver: str | None = None, seed: int | None = None, trigger: str = "manual", exports: bool = True,
                    batch_size: int | None = None, *, run=PLAIN) -> dict:
    """Route every upcoming voyage (or the given ones) on one cube cycle (default: the newest complete one)."""
    s = load_settings(data_root=Path(data_root) if data_root else None,
                      **{"routing.solver": solver, "routing.seed": seed, "routing.voyages_per_task": batch_size})
    layout = s.layout.ensure()
    c = parse_cycle(cycle) if cycle else cube.latest_complete_cycle(layout.cube_store)
    if c is None:
        raise FleetRunError(f"no complete forecast cycle in {layout.weather_cube_url}: run `jitroute ingest --cycle …` first")
    if c not in cube.cycle_states(layout.cube_store, layout.cube_lock_dir):
        raise FleetRunError(f"cycle {cycle_label(c)} is not in the cube {layout.weather_cube_url}: ingest it first")
    run_id = f"{datetime.now(timezone.utc).strftime('%Y%m%dT%H%M%S')}-{uuid.uuid4().hex[:6]}"
    options = RoutingOptions.from_settings(s.routing)
    jobs = fleet_jobs(s, layout.warehouse, c, run_id, voyages, options, exports,
                      cube.cycle_versions(layout.cube_store).get(c))
    route_store.begin_run(layout.warehouse, run_id, cycle=c, solver=options.solver, trigger=trigger, n_voyages=len(jobs))
    run_exports = export_store.RunExports(layout.run_exports_url, s.storage_options)
    run_exports.discard_stale(route_store.running_run_ids(layout.warehouse))
    LOG.info("run %s: routing %d voyages on cycle %s (%s)", run_id, len(jobs), cycle_label(c),
             f"dask at {s.dask_address}" if s.dask_address else f"local dask cluster, {s.dask_workers} workers")
    try:
        out = run.step(route_voyages, jobs, layout.cube_store, run_exports if exports else None,
                       s.dask_address, s.dask_workers,
                       s.routing.voyages_per_task, name="route-voyages", timeout_s=s.routing.task_timeout_s)
        if exports and out["rows"]:
            from pipeline.export import plots

            by_voyage: dict[str, list] = {}
            for leg in out["legs"]:
                by_voyage.setdefault(leg["voyage_id"], []).append(leg)
            pairs = [(r, by_voyage.get(r["voyage_id"], [])) for r in out["rows"]]
            fig = plots.fleet_map_figure(pairs, title=f"run {run_id} · cycle {cycle_label(c)}")
            run_exports.stage(run_id, "fleet_map.png", plots.png_bytes(fig))
            for var in ("waves", "wind"):  # the weather of the cycle at its start, for people to look at
                try:
                    run_exports.stage(run_id, f"weather_{var}_{cycle_label(c)}.png",
                                      weather_maps.step_png(layout.cube_store, c, 0, var))
                except Exception as exc:  # a picture; the run's data does not depend on it
                    out["export_errors"].append(f"fleet: weather map {var}: {type(exc).__name__}: {exc}")
        route_store.write_run_results(layout.warehouse, layout.exports, run_id, out["rows"], out["legs"],
                                      out["export_errors"])
    except BaseException as exc:
        run_exports.discard(run_id)
        route_store.fail_run(layout.warehouse, run_id, f"{type(exc).__name__}: {exc}")
        raise
    manifest = run_exports.publish(run_id) if exports else None
    files = [f["name"] for f in manifest["files"]] if manifest else []
    out_url = run_exports.run_url(run_id)
    summary = route_store.run_summary(layout.warehouse, run_id)
    summary.update(run_id=run_id, exports_dir=out_url if manifest else None,
                   fleet_map=f"{out_url}/fleet_map.png" if "fleet_map.png" in files else None,
                   weather_maps=[f"{out_url}/{n}" for n in files if n.startswith("weather_") and n.endswith(".png")])
    for line in summary["export_failures"]:
        LOG.warning("export failed: %s", line)
    run.publish(key="route-fleet", markdown=run_markdown(summary), table=summary_table(summary),
                description=f"jitroute route run {run_id}")
    return summary


def nightly_cycles(s: Settings, date: str | None, cycles) -> list[np.datetime64]:
    """The cycles a nightly ingests: the date's (at `cycles` hours) when a date is given, else the newest published."""
    if date:
        day = parse_day(date)
        hours = parse_hours(cycles) if cycles else list(s.sources.cycles_utc)
        return [np.datetime64(day, "ns") + np.timedelta64(h, "h") for h in hours]
    return newest_published_cycles(utcnow_h(), s.sources.cycles_utc, s.sources.publish_delay_h, n=s.sources.nightly_cycles)


def nightly_job(date: str | None = None, data_root: str | None = None, rish_url: str | None = None,
                oscar_url: str | None = None, cycles: str | int | list[int] | None = None, *, run=PLAIN) -> dict:
    """Ingest the cycles (the date's, or the newest published) → refit → route the fleet on the newest complete one."""
    s = load_settings(data_root=Path(data_root) if data_root else None)
    layout = s.layout.ensure()
    targets = nightly_cycles(s, date, cycles)
    labels = [cycle_label(c) for c in targets]
    with job_lock(layout.locks, f"nightly ({', '.join(labels)})", say=LOG.info):
        LOG.info("[nightly 1/3] ingest: %d cycles (%s)", len(labels), ", ".join(labels))
        ingests = []
        for k, lab in enumerate(labels, 1):
            LOG.info("[nightly 1/3] ingest %d/%d: cycle %s", k, len(labels), lab)
            ingests.append(run.subflow("ingest-weather", ingest_cycle, cycle=lab, data_root=data_root, rish_url=rish_url,
                                       oscar_url=oscar_url))
        LOG.info("[nightly 2/3] refit: speed and fuel models from noon reports")
        fits = run.subflow("refit-performance", refit_job, data_root=data_root)
        c = cube.latest_complete_cycle(layout.cube_store, at_or_before=max(targets))
        summary = {"date": date or str(np.datetime64(utcnow_h(), "D")), "cycles_targeted": labels, "ingest": ingests,
                   "models_changed": sum(bool(f.get("changed")) for f in fits), "vessels": len(fits),
                   "cycle_used": cycle_label(c) if c is not None else None}
        if c is None:
            LOG.warning("no complete cycle up to %s: routing skipped", labels[-1])
            summary["routing"] = None
        else:
            LOG.info("[nightly 3/3] route the fleet on cycle %s", cycle_label(c))
            summary["routing"] = run.subflow("route-fleet", route_fleet_job, cycle=cycle_label(c), data_root=data_root,
                                             trigger="nightly")
    run.publish(key="nightly-summary", markdown=nightly_markdown(summary),
                table=summary_table(summary["routing"]) if summary["routing"] else None,
                description=f"jitroute nightly {summary['date']}")
    return summary


def _r(x, nd=1):
    return None if x is None or x != x else round(float(x), nd)


def summary_table(r: dict) -> list[dict]:
    """One row per voyage needing attention plus the run's totals, rounded for people."""
    rows = [{"what": "run", "value": r.get("run_id")}, {"what": "cycle", "value": r.get("cycle")},
            {"what": "voyages", "value": r.get("n")},
            {"what": "… from fleet plans", "value": sum((r.get("from_plans") or {}).values())},
            {"what": "on time", "value": r.get("n_ok")},
            {"what": "late", "value": r.get("n_late")}, {"what": "not routed", "value": r.get("n_failed")},
            {"what": "exports failed", "value": len(r.get("export_failures") or [])},
            {"what": "fuel t", "value": _r(r.get("fuel_t"))},
            {"what": "savings % vs constant speed arriving at the RTA", "value": _r(r.get("savings_total_pct"))},
            {"what": "… of which speed profile %", "value": _r(r.get("savings_speed_profile_pct"))},
            {"what": "… of which route %", "value": _r(r.get("savings_route_pct"))},
            {"what": "constant-speed baseline fuel t", "value": _r(r.get("honest_baseline_fuel_t"))},
            {"what": "engine-change limits cost t", "value": _r(r.get("limits_fuel_t"), 2)},
            {"what": "savings % vs discrete-rpm baseline (arrives early; overstated)",
             "value": _r(r.get("savings_vs_discrete_pct"))}]
    return rows


def _link(where: str) -> str:
    """A local path as a file:// link; URLs (s3://…) as they are."""
    return where if "://" in where else f"file://{where}"


def headline(r: dict) -> str:
    """The run's savings in one sentence: the honest figure, split."""
    total = _r(r.get("savings_total_pct"))
    if total is None:
        return "Savings: no voyage of this run has a constant-speed baseline to compare with."
    return (f"Savings {total} % against sailing the base route at the one constant speed that arrives at the RTA "
            f"({r.get('n_compared')} voyages, fuel-weighted): speed profile {_r(r.get('savings_speed_profile_pct'))} %, "
            f"route {_r(r.get('savings_route_pct'))} %. The engine-change limits cost "
            f"{_r(r.get('limits_fuel_t'), 2)} t.")


def run_markdown(r: dict) -> str:
    lines = [f"# Route run {r.get('run_id')} · cycle {r.get('cycle')}", "", headline(r), "", "| | |", "|---|---|"]
    lines += [f"| {row['what']} | {row['value']} |" for row in summary_table(r)]
    if r.get("exports_dir"):
        lines += ["", f"Exports: `{r['exports_dir']}`"]
    if r.get("fleet_map"):
        lines += [f"Fleet map: [{r['fleet_map']}]({_link(r['fleet_map'])})"]
    lines += [f"Weather: [{p.rsplit('/', 1)[-1]}]({_link(p)})" for p in r.get("weather_maps") or []]
    problems = r.get("problems") or []
    if problems or r.get("export_failures"):
        lines += ["", "## Needing attention", "", "| voyage | status | reason |", "|---|---|---|"]
        lines += [f"| {markdown_cell(p['voyage_id'])} | {markdown_cell(p['status'])} | {markdown_cell(p['reason'] or '')} |"
                  for p in problems]
        lines += [f"| {markdown_cell(e.split(':', 1)[0])} | export failed | {markdown_cell(e.split(':', 1)[1].strip())} |"
                  for e in r["export_failures"]]
    return "\n".join(lines) + "\n"


def nightly_markdown(summary: dict) -> str:
    lines = [f"# jitroute nightly {summary['date']}", "",
             f"Cycles targeted: {', '.join(summary['cycles_targeted'])}; routed on: {summary.get('cycle_used') or 'none'}",
             f"Models changed: {summary['models_changed']} of {summary['vessels']} vessels", ""]
    lines += ["| cycle | complete | files ok | problems |", "|---|---|---|---|"]
    for i in summary["ingest"]:
        lines.append(f"| {i['cycle']} | {'yes' if i['complete'] else 'no'} | {i['n_ok']}/{i['n_expected']} | "
                     f"{'skipped (already complete)' if i.get('skipped') else '; '.join(i.get('missing') or [])[:200]} |")
    if summary.get("routing"):
        lines += ["", run_markdown(summary["routing"])]
    return "\n".join(lines) + "\n"
