"""The fleet jobs: `route-fleet` (every upcoming voyage on one cube cycle) and `nightly` (ingest → refit → route).

Voyages go out over dask in batches (flows/jobs/dask_pool.py); workers route with plain functions, stage
their voyages' export files in the run's staging area themselves (under the local data root or the object root,
storage/export_store.py) and return rows and manifest entries. This process stores the rows of each batch as it
finishes (DuckDB and Parquet, route_store.write_batch: a killed run keeps the batches it stored), then publishes
the staged exports with their manifest (a run that fails or is killed publishes nothing). The run's own pictures
and, on an object store, the publish's copies are done by the workers too, so this process spends little per
voyage. A voyage that fails (bad input, no model, no way through, even a lost worker) is recorded with status and
reason and never fails the others.
"""

from __future__ import annotations

import logging
import math
import time
import uuid
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from flows.jobs import dask_pool, run_pictures
from flows.jobs.ingest import ingest_cycle
from flows.jobs.refit import refit_job
from flows.jobs.route_worker import START_COLUMNS, copy_staged, failed_result, failed_row, route_batch
from flows.runner import PLAIN
from flows.settings import Settings, load_settings
from pipeline import enroute
from pipeline.export.bundle import SUFFIX
from pipeline.performance.model import model_from_stored, unusable_reason
from pipeline.export.paths import ExportPathError, voyage_export_key
from pipeline.validate_ids import markdown_cell, printable
from pipeline.export.voyage import utc_datetime
from pipeline.routing.geodesy import gc_distance_nm
from pipeline.routing.job import RouteJob, RoutingOptions
from pipeline.routing.problem import MAX_VOYAGE_H
from pipeline.sources.cycles import label as cycle_label, newest_published_cycles, parse_cycle, parse_day, parse_hours, utcnow_h
from storage import cube, export_store, fleet_store, route_store, verification_store, warehouse
from storage.run_lock import job_lock

LOG = logging.getLogger("jitroute.fleet")


class FleetRunError(RuntimeError):
    """A fleet run that cannot start (no cube, unknown cycle); the message says what to do."""


class StaleWeatherError(RuntimeError):
    """The newest cycle is older than `routing.max_cycle_age_h` at the run's nominal time: routing on it is refused
    (the message names the cycle and its age)."""


def cycle_age_h(cycle: np.datetime64, nominal_utc: np.datetime64) -> float:
    """Hours from the cycle's init time to the run's nominal time."""
    return float((np.datetime64(nominal_utc, "s") - np.datetime64(cycle, "s")) / np.timedelta64(1, "s")) / 3600.0


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


def _noon_positions(db: Path, imos: list[int], since) -> dict[int, list[enroute.Position]]:
    """The vessels' noon-report positions after `since`, by IMO."""
    positions: dict[int, list[enroute.Position]] = {}
    for p in fleet_store.positions_after(db, imos, since).to_dict("records"):
        positions.setdefault(int(p["imo"]), []).append(
            enroute.Position(np.datetime64(plain(p["ts_utc"]), "s"), float(p["lat"]), float(p["lon"])))
    return positions


def plan_starts(s: Settings, db: Path, rows: list[dict], cycle: np.datetime64, ref: np.datetime64,
                explicit: bool) -> list[enroute.Selection]:
    """Where each voyage's next plan starts (enroute.select_starts) on `cycle` at `ref`, from its vessel's noon
    reports, the operators' positions and its current plan; `rows`: voyages as plain values."""
    # reports of the last MAX_VOYAGE_H only (a voyage is never at sea longer): not every report ever made
    since = max(min((np.datetime64(r["depart_utc"], "s") for r in rows), default=ref),
                ref - np.timedelta64(int(MAX_VOYAGE_H * 3600), "s")) if rows else None
    positions = _noon_positions(db, sorted({int(r["imo"]) for r in rows}), since) if rows else {}
    given: dict[str, list[enroute.Position]] = {}
    for p in fleet_store.voyage_positions(db, [x["voyage_id"] for x in rows]).to_dict("records"):
        given.setdefault(str(p["voyage_id"]), []).append(enroute.Position(
            np.datetime64(plain(p["ts_utc"]), "s"), float(p["lat"]), float(p["lon"]), enroute.START_OPERATOR))
    r = s.routing
    return enroute.select_starts(rows, positions, route_store.current_plan_legs(db, [x["voyage_id"] for x in rows]),
                                 given=given, cycle_utc=cycle, ref_utc=ref, lookahead_h=r.lookahead_h,
                                 max_report_age_h=r.max_report_age_h, arrived_within_nm=r.arrived_within_nm,
                                 max_voyage_h=MAX_VOYAGE_H, explicit=explicit)


def voyage_start(s: Settings, db: Path, voyage_id: str, cycle: np.datetime64 | None) -> dict:
    """The stored voyage as one plan of it starts (plain values, enroute.voyage_from): at sea, from its latest
    position, as an operator's route-fleet run of it on `cycle` would start it (at the cycle's time when the cycle
    is older than routing.max_cycle_age_h, else now; now without a cycle); else from its port."""
    rows = [{k: plain(x) for k, x in v.items()} for v in fleet_store.load_voyages(db, voyage_ids=[voyage_id]).to_dict("records")]
    if not rows:
        raise FleetRunError(f"voyage {voyage_id} not in {db}: import it with `jitroute fleet import`")
    now = utcnow_h()
    if cycle is None:
        ref = now
    else:
        ref = np.datetime64(cycle, "s") if cycle_age_h(cycle, now) > s.routing.max_cycle_age_h else max(now, np.datetime64(cycle, "s"))
    (sel,) = plan_starts(s, db, rows, cycle if cycle is not None else ref, ref, explicit=True)
    if sel.start is None:
        raise FleetRunError(sel.why)
    return enroute.voyage_from(sel.voyage, sel.start)


def _plan_leg(rec: dict) -> dict:
    """A stored leg of a current plan as plain values (times numpy UTC, a missing wait 0)."""
    out = {k: plain(x) for k, x in rec.items()}
    for k in ("etd_utc", "eta_utc"):
        out[k] = np.datetime64(out[k], "s")
    for k in ("wait_h", "wait_fuel_t"):
        x = out.get(k)
        out[k] = float(x) if x is not None and np.isfinite(float(x)) else 0.0
    return out


DEFAULT_TOP_SPEED_KN = 15.0  # a vessel without a design speed: a merchant ship's usual top speed


def position_refused(db: Path, voyage_id: str, at_utc, lat: float, lon: float) -> str | None:
    """Why an operator's position of a stored voyage cannot be right (enroute.position_problem), or None: checked
    against the land mask, the voyage's departure and RTA, and its vessel's noon reports within a day of it."""
    from pipeline.routing.land import is_sea

    v = {k: plain(x) for k, x in fleet_store.load_voyages(db, voyage_ids=[voyage_id]).iloc[0].to_dict().items()}
    at = np.datetime64(at_utc, "s")
    near = [p for p in _noon_positions(db, [int(v["imo"])], at - np.timedelta64(1, "D")).get(int(v["imo"]), [])
            if p.utc <= at + np.timedelta64(1, "D")]
    vessels = fleet_store.load_vessels(db)
    design = vessels.loc[vessels["imo"] == int(v["imo"]), "design_speed_kn"].dropna()
    top_kn = float(design.iloc[0]) if len(design) and float(design.iloc[0]) > 0 else DEFAULT_TOP_SPEED_KN
    return enroute.position_problem(v, at, lat, lon, at_sea=bool(is_sea(lat, lon)), reports=near, top_speed_kn=top_kn)


def error_model(db: Path):
    """The forecast-error model fitted on the warehouse's verified plans (pipeline/routing/calibration.py; the stated
    default, saying so, with too few of them)."""
    from pipeline.routing import calibration

    rows = verification_store.verifications(db).to_dict("records")
    return calibration.fit_error_model(calibration.verification_errors(rows))


def fleet_jobs(s: Settings, db: Path, cycle: np.datetime64, run_id: str, voyage_ids: list[str] | None,
               options: RoutingOptions, exports: bool, cycle_version: int | None = None,
               ref_utc: np.datetime64 | None = None, unrouted: list[dict] | None = None) -> list[RouteJob]:
    """One RouteJob per voyage to route: the given ones, else those departing within the look-ahead of the cycle
    and those at sea (pipeline/enroute.py), each from where its plan starts (its port, or its latest position at
    `ref_utc`, default the cycle's time); each carries the cycle's content version read at the start of the run.
    A voyage that should be routed but has no start (it departed before the cycle with neither a position since
    nor a current plan, e.g. a plan voyage departing before the next routable cycle) gets no job: its route row,
    status failed with the reason, is added to `unrouted` (when given), so the run lists it as needing attention."""
    table = fleet_store.load_voyages(db, voyage_ids=voyage_ids)
    if voyage_ids:
        unknown = sorted(set(voyage_ids) - set(table["voyage_id"].astype(str)))
        if unknown:
            raise FleetRunError(f"voyage(s) {', '.join(unknown)} not in {db}: import them with `jitroute fleet import`")
    ref = np.datetime64(ref_utc if ref_utc is not None else cycle, "s")
    rows = [{k: plain(x) for k, x in v.items()} for v in table.to_dict("records")]
    chosen = plan_starts(s, db, rows, cycle, ref, explicit=bool(voyage_ids))
    for sel in chosen:
        if sel.start is None:
            LOG.warning("%s", sel.why)
            if unrouted is not None:
                row = failed_row(run_id, sel.voyage, cycle, f"not routed: {sel.why}")
                unrouted.append({**row, **dict.fromkeys(START_COLUMNS)})
    chosen = [sel for sel in chosen if sel.start is not None]
    fingerprints = fleet_store.voyage_fingerprints(db, [sel.voyage["voyage_id"] for sel in chosen])
    vessels = {int(v["imo"]): {k: plain(x) for k, x in v.items()} for v in fleet_store.load_vessels(db).to_dict("records")}
    models, notes, stored = {}, {}, fleet_store.active_models(db) if chosen else {}  # one read for every vessel
    for imo in {int(sel.voyage["imo"]) for sel in chosen}:
        m = model_from_stored(stored.get(imo), imo)
        models[imo] = m.to_json() if m is not None else None
        notes[imo] = unusable_reason(stored.get(imo), imo)
    cyc = str(np.datetime_as_string(cycle, unit="s"))
    at_sea = [str(sel.voyage["voyage_id"]) for sel in chosen if sel.start.kind != enroute.START_PORT]
    # the current plans a re-plan at sea is weighed against (robust decisions: routing.replan_gain_sigmas)
    current = route_store.current_plan_legs(db, at_sea) if at_sea and options.replan_gain_sigmas > 0 else {}
    errors = error_model(db) if chosen else None  # how far verified plans realised from their claims
    jobs = []
    for sel in chosen:
        v = enroute.voyage_from(sel.voyage, sel.start)
        v["voyage_fingerprint"] = fingerprints.get(str(v["voyage_id"]))
        jobs.append(RouteJob(voyage=v, vessel=vessels.get(int(v["imo"]), {}), model=models.get(int(v["imo"])),
                             model_note=notes.get(int(v["imo"])),
                             run_id=run_id, cycle=cyc, exports=exports, options=options, cycle_version=cycle_version,
                             debug_plots=s.debug_plots, error_model=errors,
                             current_legs=tuple(_plan_leg(g) for g in current.get(str(v["voyage_id"]), []))))
    return jobs


def abandon_run(warehouse_path: Path, run_exports: export_store.RunExports | None, run_id: str,
                exc: BaseException) -> None:
    """Record the run failed with the error, then remove its staged exports: nothing of it is published. Safe to
    repeat (route_voyages does it before its cluster's teardown, route_fleet_job again for what failed outside)."""
    route_store.fail_run(warehouse_path, run_id, f"{type(exc).__name__}: {exc}")
    if run_exports is not None:
        run_exports.discard(run_id)


def route_voyages(jobs: list[RouteJob], cube_store: cube.Location, run_exports: export_store.RunExports | None,
                  dask_address: str | None, n_workers: int, per_batch: int | None, store_to: tuple[Path, Path],
                  pictures_of: tuple[np.datetime64, np.datetime64] | None = None,
                  store_every_s: float = 0.0) -> dict:
    """Route every job on dask (workers read the cube at `cube_store`'s path or URL themselves and stage their
    export files under `run_exports`), storing the rows of the batches as they finish in the warehouse and the Parquet
    exports `store_to` = (warehouse, exports folder) of the jobs' run (route_store.write_batch): those finished since
    the last store, at most every `store_every_s` seconds, and the rest at the end. With `pictures_of`
    = (cycle, the run's nominal time) and exports, workers also draw the run's weather maps over the fleet's
    extent (while the voyages route) and its fleet map with the ships' positions at the nominal time (after them)
    and stage them (flows/jobs/run_pictures.py); on an object store they then copy the staged files to the run's
    folder (`copied`: all copies done). Returns the export errors, the staged files (name → bytes), the
    number of voyages stored and `copied`."""
    export_errors, staged, tracks, pending = [], {}, [], {"rows": [], "legs": []}  # staged: name → bytes
    run_id = jobs[0].run_id if jobs else ""  # every job is of the one run
    done, stored, copied = 0, 0, False
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
            pending["rows"].append(r)
            pending["legs"].extend(res["legs"])
            staged.update((f["name"], f["bytes"]) for f in res.get("staged", []))
            if run_exports is not None and pictures_of is not None:
                tracks.append((r["voyage_id"], r["status"], run_pictures.track(res["legs"]), r.get("start_kind")))
            for kind, err in res.get("export_errors", {}).items():
                export_errors.append(f"{r['voyage_id']}: {kind}: {err}")
            for kind, data in res.get("exports", {}).items():  # only from a worker given no exports root
                try:  # the voyage ID makes the file name, in the voyage's own folder, or is refused naming the voyage
                    staged[run_exports.stage(r["run_id"], voyage_export_key(r["voyage_id"], SUFFIX[kind]), data)] = len(data)
                except (OSError, ExportPathError) as exc:
                    export_errors.append(f"{r['voyage_id']}: {kind}: {exc}")
                    LOG.error("voyage %s: %s export not written: %s", r["voyage_id"], kind, exc)
            done += 1
            LOG.info("routed %d/%d: %s %s%s", done, len(jobs), printable(r["voyage_id"]), r["status"],
                     f" ({printable(r['reason'])})" if r.get("reason") else "")

    last_store = time.monotonic()

    def store(final: bool = False) -> None:  # the batches finished since the last store, in one transaction
        nonlocal stored, last_store
        if pending["rows"] and (final or time.monotonic() - last_store >= store_every_s):
            stored += len(route_store.write_batch(*store_to, run_id, pending["rows"], pending["legs"]))
            pending["rows"], pending["legs"] = [], []
            last_store = time.monotonic()

    if jobs:
        with dask_pool.dask_client(dask_address, n_workers,
                                   on_error=lambda exc: abandon_run(store_to[0], run_exports, run_id, exc)) as client:
            per = dask_pool.voyages_per_batch(len(jobs), dask_pool.worker_slots(client), per_batch)
            exports_to = (run_exports.url, run_exports.storage_options) if run_exports is not None else None
            pictures = []
            if exports_to is not None and pictures_of is not None:
                cycle, nominal = pictures_of
                box = run_pictures.fleet_box([(j.voyage[f"{end}_lat"], j.voyage[f"{end}_lon"]) for j in jobs
                                              for end in ("dep", "arr")])
                pictures.append(client.submit(run_pictures.stage_weather_maps, exports_to, run_id, cube_store.url,
                                              cube_store.options, str(np.datetime64(cycle, "s")), cycle_label(cycle),
                                              box, pure=False))
            dask_pool.map_batches(client, route_batch, dask_pool.batches(jobs, per, _length_nm), cube_store.url,
                                  cube_store.options, exports_to, on_done=on_done, on_group_done=store)
            store(final=True)
            if pictures:
                pictures.append(client.submit(run_pictures.stage_fleet_map, exports_to, run_id,
                                              f"run {run_id} · cycle {cycle_label(cycle)}", tracks,
                                              str(np.datetime64(nominal, "s")), pure=False))
            for future in pictures:
                entries, errors = dask_pool.result_or(
                    future, lambda exc: ([], [f"fleet: pictures: {type(exc).__name__}: {exc}"]))
                staged.update((f["name"], f["bytes"]) for f in entries)
                export_errors.extend(errors)
            if exports_to is not None and staged and not run_exports.local:  # the copies of the publish, shared out
                names, n = sorted(staged), dask_pool.worker_slots(client)
                copies = [client.submit(copy_staged, exports_to, run_id, names[k::n], pure=False)
                          for k in range(min(n, len(names)))]
                copied = all([dask_pool.result_or(f, lambda exc: LOG.warning(
                    "exports: a worker's share of the copies failed (%s: %s); this process copies them",
                    type(exc).__name__, exc)) for f in copies])
    return {"export_errors": export_errors, "staged": staged, "n_stored": stored, "copied": copied}


def route_fleet_job(cycle: str | None = None, voyages: list[str] | None = None, data_root: str | None = None,
                    solver: str | None = None, seed: int | None = None, trigger: str = "manual", exports: bool = True,
                    batch_size: int | None = None, nominal_utc: str | None = None, *, run=PLAIN) -> dict:
    """Route every upcoming voyage and every voyage at sea (or the given ones) on one cube cycle (default: the
    newest complete one).

    The run records the cycle's age at its nominal time (`nominal_utc`, default now). With a nominal time given
    (the nightly's) routing on a cycle older than `routing.max_cycle_age_h` is refused (StaleWeatherError, the run
    recorded failed with the reason); without one (an operator's run) it goes on with a warning. Voyages at sea start
    from their latest position at the nominal time (at the cycle's time when the cycle is that old).
    """
    s = load_settings(data_root=Path(data_root) if data_root else None,
                      **{"routing.solver": solver, "routing.seed": seed, "routing.voyages_per_task": batch_size})
    layout = s.layout.ensure()
    c = parse_cycle(cycle) if cycle else cube.latest_complete_cycle(layout.cube_store)
    if c is None:
        raise FleetRunError(f"no complete forecast cycle in {layout.weather_cube_url}: run `jitroute ingest --cycle …` first")
    if c not in cube.cycle_states(layout.cube_store, layout.cube_lock_dir):
        raise FleetRunError(f"cycle {cycle_label(c)} is not in the cube {layout.weather_cube_url}: ingest it first")
    run_id = f"{datetime.now(timezone.utc).strftime('%Y%m%dT%H%M%S')}-{uuid.uuid4().hex[:6]}"
    nominal = np.datetime64(str(nominal_utc).rstrip("Z"), "s") if nominal_utc else utcnow_h()
    age_h = cycle_age_h(c, nominal)
    stale = age_h > s.routing.max_cycle_age_h
    if stale and nominal_utc:
        newest = cube.latest_complete_cycle(layout.cube_store)
        why = (f"weather too old: the newest complete cycle {cycle_label(newest)} is {cycle_age_h(newest, nominal):.0f} h "
               f"old at {str(nominal)[:16]}Z" if newest is not None and newest != c else
               f"weather too old: cycle {cycle_label(c)} is {age_h:.0f} h old at {str(nominal)[:16]}Z")
        why += (f" (more than routing.max_cycle_age_h = {s.routing.max_cycle_age_h:g} h); routing refused: ingest a newer "
                "cycle (`jitroute ingest --cycle latest`), or route on this one by hand (`jitroute route-fleet`)")
        route_store.begin_run(layout.warehouse, run_id, cycle=c, solver=s.routing.solver, trigger=trigger, n_voyages=0,
                              nominal_utc=nominal, cycle_age_h=age_h)
        route_store.fail_run(layout.warehouse, run_id, why)
        raise StaleWeatherError(why)
    if stale:
        LOG.warning("cycle %s is %.0f h old at %sZ (more than routing.max_cycle_age_h = %g h): routing on it as asked; "
                    "voyages at sea start from their position at the cycle's time", cycle_label(c), age_h,
                    str(nominal)[:16], s.routing.max_cycle_age_h)
    options = RoutingOptions.from_settings(s.routing)
    version = cube.cycle_versions(layout.cube_store).get(c)
    unrouted: list[dict] = []  # voyages due that cannot be routed: stored as failed, with why
    with warehouse.one_reader(layout.warehouse):  # every read of the jobs on one connection
        jobs = fleet_jobs(s, layout.warehouse, c, run_id, voyages, options, exports, version,
                          ref_utc=c if stale else max(nominal, np.datetime64(c, "s")), unrouted=unrouted)
    running = route_store.begin_run(layout.warehouse, run_id, cycle=c, solver=options.solver, trigger=trigger,
                                    n_voyages=len(jobs) + len(unrouted), nominal_utc=nominal, cycle_age_h=age_h)
    run_exports = export_store.RunExports(layout.run_exports_url, s.storage_options)
    run_exports.discard_stale(running)
    from flows.jobs.warm import cold_cache_warning

    cold = cold_cache_warning(options.solver) if jobs and not s.dask_address else None
    if cold:
        LOG.warning("%s", cold)
    n_at_sea = sum(j.voyage.get("start_kind") not in (None, enroute.START_PORT) for j in jobs)
    LOG.info("run %s: routing %d voyages (%d from port, %d at sea re-planned) on cycle %s, %.0f h old (%s)", run_id,
             len(jobs), len(jobs) - n_at_sea, n_at_sea, cycle_label(c), age_h,
             f"dask at {s.dask_address}" if s.dask_address else f"local dask cluster, {s.dask_workers} workers")
    try:
        if unrouted:
            route_store.write_batch(layout.warehouse, layout.exports, run_id, unrouted, [])
        out = run.step(route_voyages, jobs, layout.cube_store, run_exports if exports else None,
                       s.dask_address, s.dask_workers, s.routing.voyages_per_task, (layout.warehouse, layout.exports),
                       (c, nominal), s.routing.store_every_s, name="route-voyages",
                       timeout_s=s.routing.task_timeout_s)
        summary = route_store.finish_run(layout.warehouse, layout.exports, run_id, out["export_errors"])
    except BaseException as exc:
        abandon_run(layout.warehouse, run_exports, run_id, exc)
        raise
    manifest = (run_exports.publish(run_id, only=set(out["staged"]), copied=out["copied"], sizes=out["staged"])
                if exports else None)
    files = [f["name"] for f in manifest["files"]] if manifest else []
    out_url = run_exports.run_url(run_id)
    summary.update(run_id=run_id, exports_dir=out_url if manifest else None,
                   fleet_map=f"{out_url}/fleet_map.png" if "fleet_map.png" in files else None,
                   weather_maps=[f"{out_url}/{n}" for n in files if n.startswith("weather_") and n.endswith(".png")])
    for line in summary["export_failures"]:
        LOG.warning("export failed: %s", line)
    if manifest and s.export_retention_days is not None:
        retired = run_exports.retire_runs(s.export_retention_days)
        if retired:
            LOG.info("retired the exports of %d run(s) older than %g days: %s", len(retired), s.export_retention_days,
                     ", ".join(retired))
    run.publish(key="route-fleet", markdown=run_markdown(summary), table=summary_table(summary),
                description=f"jitroute route run {run_id}")
    return summary


def nightly_cycles(s: Settings, date: str | None, cycles) -> list[np.datetime64]:
    """The cycles a nightly ingests: the date's (at `cycles` hours) when a date is given, else the newest published."""
    if date:
        day = parse_day(date)
        hours = parse_hours(cycles) if cycles not in (None, "", []) else list(s.sources.cycles_utc)  # 0 is hour 00
        return [np.datetime64(day, "ns") + np.timedelta64(h, "h") for h in hours]
    return newest_published_cycles(utcnow_h(), s.sources.cycles_utc, s.sources.publish_delay_h, n=s.sources.nightly_cycles)


def nightly_job(date: str | None = None, data_root: str | None = None, rish_url: str | None = None,
                oscar_url: str | None = None, cycles: str | int | list[int] | None = None, *, run=PLAIN) -> dict:
    """Ingest the cycles (the date's, or the newest published) → refit → route the fleet on the newest complete one.

    An ingest that fails is recorded as its cycle incomplete and the nightly goes on. The summary's `state` is
    "Completed", or "Incomplete" when a targeted cycle is not complete (`cycles_missing` lists them). Routing on a
    cycle older than `routing.max_cycle_age_h` at the nightly's nominal time (now, or the newest targeted cycle of
    a `date`), or on none, raises StaleWeatherError after the summary is published."""
    s = load_settings(data_root=Path(data_root) if data_root else None)
    layout = s.layout.ensure()
    targets = nightly_cycles(s, date, cycles)
    labels = [cycle_label(c) for c in targets]
    nominal = max(targets) if date else utcnow_h()
    refused = None
    with job_lock(layout.locks, f"nightly ({', '.join(labels)})", say=LOG.info):
        LOG.info("[nightly 1/3] ingest: %d cycles (%s)", len(labels), ", ".join(labels))
        ingests = []
        for k, lab in enumerate(labels, 1):
            LOG.info("[nightly 1/3] ingest %d/%d: cycle %s", k, len(labels), lab)
            try:
                ingests.append(run.subflow("ingest-weather", ingest_cycle, cycle=lab, data_root=data_root,
                                           rish_url=rish_url, oscar_url=oscar_url))
            except Exception as exc:  # one cycle's ingest failing leaves it incomplete; the nightly goes on
                LOG.error("ingest of cycle %s failed: %s: %s; going on with the cycles the cube has", lab,
                          type(exc).__name__, exc)
                ingests.append({"cycle": lab, "complete": False, "n_ok": 0, "n_expected": 0,
                                "missing": [f"ingest failed: {type(exc).__name__}: {exc}"]})
        LOG.info("[nightly 2/3] refit: speed and fuel models from noon reports")
        fits = run.subflow("refit-performance", refit_job, data_root=data_root)
        c = cube.latest_complete_cycle(layout.cube_store, at_or_before=max(targets))
        missing = [i["cycle"] for i in ingests if not i.get("complete")]
        summary = {"date": date or str(np.datetime64(utcnow_h(), "D")), "cycles_targeted": labels, "ingest": ingests,
                   "models_changed": sum(bool(f.get("changed")) for f in fits), "vessels": len(fits),
                   "cycle_used": cycle_label(c) if c is not None else None, "nominal_utc": str(nominal)[:16] + "Z",
                   "cycle_age_h": round(cycle_age_h(c, nominal), 1) if c is not None else None,
                   "cycles_missing": missing, "state": "Incomplete" if missing else "Completed", "routing": None}
        if c is None:
            refused = (f"no complete forecast cycle up to {labels[-1]} in {layout.weather_cube_url}: routing refused; "
                       "ingest a cycle (`jitroute ingest --cycle latest`)")
        else:
            LOG.info("[nightly 3/3] route the fleet on cycle %s (%.0f h old)", cycle_label(c), cycle_age_h(c, nominal))
            try:
                summary["routing"] = run.subflow("route-fleet", route_fleet_job, cycle=cycle_label(c),
                                                 data_root=data_root, trigger="nightly",
                                                 nominal_utc=str(np.datetime64(nominal, "m")))
            except StaleWeatherError as exc:
                refused = str(exc)
        summary["verification"] = verify_after_routing(run, data_root)
        if refused:
            summary.update(state="Failed", refused=refused)
    run.publish(key="nightly-summary", markdown=nightly_markdown(summary),
                table=summary_table(summary["routing"]) if summary["routing"] else None,
                description=f"jitroute nightly {summary['date']}")
    if refused:
        raise StaleWeatherError(refused)
    return summary


def verify_after_routing(run, data_root: str | None) -> dict | None:
    """The nightly's last step: the stored plans re-sailed in the analysed weather of the cycles now in the cube
    (flows/jobs/verify.py). A failure is logged and said in the summary; it never fails the nightly's routing."""
    from flows.jobs.verify import verify_plans_job

    LOG.info("[nightly] verify: stored plans re-sailed in the analysed weather of the newest cycles")
    try:
        return run.subflow("verify-plans", verify_plans_job, data_root=data_root)
    except Exception as exc:  # the plans are stored; verification can run again (`jitroute verify`)
        LOG.error("verification failed: %s: %s; run `jitroute verify` once fixed", type(exc).__name__, exc)
        return {"error": f"{type(exc).__name__}: {exc}"}


def _r(x, nd=1):
    return None if x is None or x != x else round(float(x), nd)


def summary_table(r: dict) -> list[dict]:
    """One row per voyage needing attention plus the run's totals, rounded for people."""
    rows = [{"what": "run", "value": r.get("run_id")}, {"what": "cycle", "value": r.get("cycle")},
            {"what": "cycle age h", "value": _r(r.get("cycle_age_h"))},
            {"what": "voyages", "value": r.get("n")}, {"what": "planned from port", "value": r.get("n_from_port")},
            {"what": "re-planned at sea", "value": r.get("n_replanned")},
            {"what": "… from fleet plans", "value": sum((r.get("from_plans") or {}).values())},
            {"what": "on time", "value": r.get("n_ok")},
            {"what": "late", "value": r.get("n_late")}, {"what": "not routed", "value": r.get("n_failed")},
            {"what": "exports failed", "value": len(r.get("export_failures") or [])},
            {"what": "fuel t", "value": _r(r.get("fuel_t"))},
            {"what": "savings % vs constant speed arriving at the RTA", "value": _r(r.get("savings_total_pct"))},
            {"what": "… of which speed profile %", "value": _r(r.get("savings_speed_profile_pct"))},
            {"what": "… of which route %", "value": _r(r.get("savings_route_pct"))},
            {"what": "savings % within the forecast's valid times", "value": _r(r.get("savings_forecast_pct"))},
            {"what": "savings % past the forecast (neutral weather, not forecast)",
             "value": _r(r.get("savings_beyond_forecast_pct"))},
            {"what": "voyages past the forecast's last step", "value": r.get("n_beyond_horizon")},
            {"what": "P(on time) across the lagged ensemble, mean of the voyages", "value": _r(r.get("p_on_time"), 2)},
            {"what": "saving P10 % across the ensemble (fuel-weighted)", "value": _r(r.get("savings_p10_pct"))},
            {"what": "saving P90 % across the ensemble (fuel-weighted)", "value": _r(r.get("savings_p90_pct"))},
            {"what": "plans verified in analysed weather (wholly)",
             "value": f"{r.get('n_verified') or 0} ({r.get('n_verified_whole') or 0})"},
            {"what": "… their saving % claimed / realised",
             "value": f"{_r(r.get('verified_claimed_savings_pct'))} / {_r(r.get('realised_savings_pct'))}"
                      if _r(r.get("realised_savings_pct")) is not None else "not known yet"},
            {"what": "constant-speed baseline fuel t", "value": _r(r.get("honest_baseline_fuel_t"))},
            {"what": "engine-change limits cost t", "value": _r(r.get("limits_fuel_t"), 2)}]
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
            f"{_r(r.get('limits_fuel_t'), 2)} t.{_forecast_split(r)}{_spread(r)}")


def _spread(r: dict) -> str:
    """The run's spread across the lagged ensemble (ensemble.py), when its plans have it."""
    p = _r(r.get("p_on_time"), 2)
    if p is None:
        return ""
    n = r.get("n_ensemble") or 0
    return (f" Across the lagged ensemble ({n} voyage{'s' if n != 1 else ''}): on time {100 * p:.0f} % of the time on "
            f"average, saving P10–P90 {_r(r.get('savings_p10_pct'))} to {_r(r.get('savings_p90_pct'))} % (fuel-weighted).")


def _forecast_split(r: dict) -> str:
    """What of the saving the forecast backs, when the run's plans have the split (savings.py)."""
    inside = _r(r.get("savings_forecast_pct"))
    if inside is None:
        return ""
    n = r.get("n_beyond_horizon") or 0
    return (f" Of it, {inside} % is saved within the forecast's valid times and "
            f"{_r(r.get('savings_beyond_forecast_pct'))} % past them ({n} voyage{'s sail' if n != 1 else ' sails'} past "
            "the forecast's last step, where every route meets the same neutral weather: not a forecast).")


def run_markdown(r: dict) -> str:
    lines = [f"# Route run {r.get('run_id')} · cycle {r.get('cycle')}", "", headline(r), "", "| | |", "|---|---|"]
    lines += [f"| {row['what']} | {row['value']} |" for row in summary_table(r)]
    if r.get("exports_dir"):
        lines += ["", f"Exports: `{r['exports_dir']}`"]
    if r.get("fleet_map"):
        lines += [f"Fleet map: [{r['fleet_map']}]({_link(r['fleet_map'])})"]
    lines += [f"Weather: [{p.rsplit('/', 1)[-1]}]({_link(p)})" for p in r.get("weather_maps") or []]
    problems = (r.get("problems") or []) + (r.get("stale") or [])
    if problems or r.get("export_failures"):
        lines += ["", "## Needing attention", "", "| voyage | status | reason |", "|---|---|---|"]
        lines += [f"| {markdown_cell(p['voyage_id'])} | {markdown_cell(p['status'])} | {markdown_cell(p['reason'] or '')} |"
                  for p in problems]
        lines += [f"| {markdown_cell(e.split(':', 1)[0])} | export failed | {markdown_cell(e.split(':', 1)[1].strip())} |"
                  for e in r["export_failures"]]
    return "\n".join(lines) + "\n"


def nightly_markdown(summary: dict) -> str:
    age = summary.get("cycle_age_h")
    lines = [f"# jitroute nightly {summary['date']}: {summary.get('state', 'Completed')}", "",
             f"Cycles targeted: {', '.join(summary['cycles_targeted'])}; routed on: {summary.get('cycle_used') or 'none'}"
             + (f" ({age:g} h old at {summary.get('nominal_utc')})" if age is not None else ""),
             f"Models changed: {summary['models_changed']} of {summary['vessels']} vessels", ""]
    if summary.get("refused"):
        lines += [f"**Routing refused:** {summary['refused']}", ""]
    if summary.get("cycles_missing"):
        lines += [f"**Targeted cycles not complete:** {', '.join(summary['cycles_missing'])}", ""]
    lines += ["| cycle | complete | files ok | problems |", "|---|---|---|---|"]
    for i in summary["ingest"]:
        lines.append(f"| {i['cycle']} | {'yes' if i['complete'] else 'no'} | {i['n_ok']}/{i['n_expected']} | "
                     f"{'skipped (already complete)' if i.get('skipped') else '; '.join(i.get('missing') or [])[:200]} |")
    if summary.get("routing"):
        lines += ["", run_markdown(summary["routing"])]
    lines += ["", verification_markdown(summary.get("verification"))] if summary.get("verification") else []
    return "\n".join(lines) + "\n"


def verification_markdown(v: dict) -> str:
    """What the plans realised in the analysed weather: claimed beside realised, with the coverage."""
    from flows.jobs.verify import verification_sentence

    if v.get("error"):
        return f"## Verification\n\nVerification failed: {markdown_cell(v['error'])} (run `jitroute verify` once fixed)\n"
    said = verification_sentence(v) or (f"No plan to verify yet with the analysed weather up to cycle {v.get('newest_cycle')}."
                                        if v.get("newest_cycle") else "No cycle to verify with.")
    lines = ["## Verification", "", said]
    if v.get("skipped"):
        lines += ["", f"Not verified: {markdown_cell('; '.join(v['skipped'])[:500])}"]
    return "\n".join(lines) + "\n"
