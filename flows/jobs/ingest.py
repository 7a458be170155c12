"""The ingest job: one cycle (the backfill job over a range of cycles is flows/jobs/backfill.py).

Four steps: list → download → decode → write. Downloads run a few at a time and GRIB2 files are
decoded in two threads; the write step writes the cube, then the file log, then the cycle status. A file that
is missing or corrupt is logged and the cycle is written incomplete (never silently complete);
a later run that finds the file completes it. A cycle is skipped only when both the cube and the
warehouse's cycle status (written last) say it is complete. Steps do not hash their inputs for
Prefect's cache (they pass whole decoded cycles): re-runs are made idempotent by the cube and the log.
Only one job runs on a data root at a time (storage/run_lock.py).
"""

from __future__ import annotations

import logging
import uuid
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass, field, replace
from pathlib import Path
from urllib.parse import unquote, urlparse

import numpy as np
import xarray as xr

from flows.runner import PLAIN
from flows.settings import Settings, load_settings
from pipeline.decode.errors import DecodeError
from pipeline.sources import rish
from pipeline.sources.cycles import (check_cycle_hour, label as cycle_label, newest_published_cycles,
                                     parse_cycle, utcnow_h)
from pipeline.sources.fetch import FetchOptions, FetchResult, fetch, read_text, token_may_go_to
from pipeline.sources.registry import BY_NAME, SOURCES
from pipeline.sources.source import ROLES
from pipeline.weather.assemble import assemble_cycle
from pipeline.weather.grid import routing_grid
from pipeline.weather.regrid import regrid
from storage import cube, cube_damage, ingest_log, raw_store
from storage.run_lock import job_lock

LOG = logging.getLogger("jitroute.ingest")


@dataclass
class Download:
    source: str
    name: str
    url: str
    result: FetchResult | None = None
    status: str = "missing"
    error: str | None = None
    started_at: object = None


@dataclass
class CycleReport:
    cycle: str
    complete: bool
    n_expected: int
    n_ok: int
    missing: list[str] = field(default_factory=list)
    corrupt: list[str] = field(default_factory=list)
    skipped: bool = False


def _opts(s: Settings, source: str, token: str | None = None) -> FetchOptions:
    """Fetch options for one source; only a source that needs it (OSCAR) sends the Earthdata token (`token`, else the
    settings'), and only when its configured URL is https (or on this machine): never in clear text."""
    src = s.sources
    if not token_may_go_to(getattr(src, BY_NAME[source].url_setting)):
        token = None
        src = replace(src, earthdata_token=None)
    return FetchOptions(timeout_s=src.http_timeout_s, retries=src.http_retries, backoff_s=src.http_backoff_s,
                        allowed_redirect_hosts=src.allowed_redirect_hosts, deadline_s=src.http_deadline_s,
                        min_rate_bps=src.http_min_rate_bps, rate_window_s=src.http_rate_window_s,
                        max_bytes=getattr(src, f"{source.lower()}_max_bytes"), max_index_bytes=src.index_max_bytes,
                        token=(token or src.earthdata_token) if BY_NAME[source].needs_token else None)


def earthdata_token(s: Settings, blocks: bool = True) -> str | None:
    """The Earthdata token: from the environment (settings), else (`blocks`: a Prefect API is in use) the Prefect
    Secret block `s.sources.earthdata_secret_block` (`prefect block create secret`, or `Secret(value=…).save(name)`);
    None when neither exists. The value is never logged."""
    if s.sources.earthdata_token or not s.sources.earthdata_secret_block or not blocks:
        return s.sources.earthdata_token
    from prefect.blocks.system import Secret

    try:
        return Secret.load(s.sources.earthdata_secret_block).get()
    except ValueError:  # no such block: OSCAR is fetched without a token
        return None


def _recorded_complete(db: Path, c: np.datetime64) -> bool:
    """The warehouse says the cycle is complete: its status is written last, so a run killed after the
    cube write but before the log and status is not mistaken for a finished one."""
    status = ingest_log.cycle_status(db)
    return bool(status["complete"][status["cycle"] == c].any())


DOWNLOAD_WORKERS = 4  # concurrent HTTP downloads (I/O-bound; hashing and file writes release the GIL)
DECODE_WORKERS = 2  # GRIB2 files decoded at once (eccodes is built thread-safe and releases the GIL)


@dataclass
class Listing:
    items: list[Download]
    rejected: list[tuple[str, str]]  # (unsafe name, index URL listing it)
    index_urls: list[str]  # the primary sources' index pages
    gaps: dict[str, list[int]]  # source → leads no listed file covers
    n_expected: int
    problems: list[str] = field(default_factory=list)

    def nothing_listed(self) -> str:
        what = f"no {'/'.join(s.name for s in SOURCES if s.primary)} files listed at {', '.join(self.index_urls)}"
        return "; ".join([what, *self.problems])


def list_sources(base_urls: dict[str, str], cycle: np.datetime64, steps: list[int], opts: dict[str, FetchOptions],
                 optional: Sequence[int] = ()) -> Listing:
    """The files each registered source has for the cycle (`base_urls`: source name → base URL) at the leads it must
    have (`steps`) and at the optional ones it lists (`optional`). Each index page is read once; the secondary
    sources are listed only when a primary one has files for the cycle."""
    pages: dict[str, tuple[list[str], list[str]]] = {}
    problems: list[str] = []

    def names_at(src) -> tuple[str, list[str]]:
        url = src.index_url(base_urls[src.name], cycle)
        if url not in pages:
            try:
                pages[url] = rish.parse_index(read_text(url, opts[src.name]))
            except FileNotFoundError:
                pages[url] = [], []
                root = base_urls[src.name]
                if root.startswith("file://") and not Path(unquote(urlparse(root).path)).is_dir():
                    problems.append(f"{src.name} mirror root {root} does not exist (check the URL)")
            except ConnectionError as exc:  # unreachable, failing, too large or too slow: the cycle is incomplete
                problems.append(f"{src.name} listing unreachable ({exc})")
                return url, []
        return url, pages[url][0]

    items: list[Download] = []
    gaps, n_expected, index_urls = {}, 0, []
    for src in sorted(SOURCES, key=lambda src: not src.primary):  # primary first, registry order kept
        if not src.primary and not items:
            break
        url, names = names_at(src)
        if src.primary and url not in index_urls:
            index_urls.append(url)
        chosen = src.select(names, cycle, steps, optional)
        items += [Download(src.name, name, url + name) for name in chosen.names]
        n_expected += chosen.n_expected
        if chosen.gaps_h is not None:
            gaps[src.name] = chosen.gaps_h
    rejected = [(name, url) for url, (_, bad) in pages.items() for name in bad]
    if not items:
        return Listing([], rejected, index_urls, {}, 0, list(dict.fromkeys(problems)))
    return Listing(items, rejected, index_urls, gaps, n_expected, problems)


def _fetch_one(it: Download, raw_dir: Path, cycle: np.datetime64, opts: dict[str, FetchOptions],
               known: dict[str, str]) -> Download:
    it.started_at = ingest_log.utcnow()
    dest = raw_store.path_for(raw_dir, it.source, cycle, it.name)
    it.result = fetch(it.url, dest, opts[it.source], expected_sha256=known.get(it.name))
    it.status, it.error = it.result.status, it.result.error
    return it


def download_all(items: list[Download], raw_dir: Path, cycle: np.datetime64, opts: dict[str, FetchOptions],
                 known: dict[str, str]) -> list[Download]:
    """Every file, DOWNLOAD_WORKERS at a time. A local write failure (full disk) stops the ingest at once:
    downloads not yet started are cancelled and the error is raised (files already fetched stay, whole)."""
    pool = ThreadPoolExecutor(DOWNLOAD_WORKERS, thread_name_prefix="download")
    try:
        futures = [pool.submit(_fetch_one, it, raw_dir, cycle, opts, known) for it in items]
        for done in as_completed(futures):
            done.result()  # raises LocalWriteError
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
    return items


def _decoded_or_quarantined(it: Download, decode, quarantine_dir: Path):
    """`decode(file)`, or None after marking the file corrupt and moving it to quarantine."""
    path = it.result.path if it.result is not None else None
    assert path is not None, f"{it.url} is decoded before it is fetched"
    try:
        return decode(path)
    except DecodeError as exc:
        it.status, it.error = "corrupt", f"{exc} (from {it.url})"
        raw_store.quarantine(quarantine_dir, it.source, path)
        return None


def _decode_one(it: Download, grid: tuple, quarantine_dir: Path):
    """One file decoded (None when corrupt); a forecast file regridded onto the routing grid at once, current
    analyses later, all together, by the cycle assembly."""
    src = BY_NAME[it.source]
    ds = _decoded_or_quarantined(it, src.decode, quarantine_dir)
    return ds if ds is None or src.role == "currents" else regrid(ds, grid[0], grid[1])


def decode_and_assemble(items: list[Download], cycle: np.datetime64, steps: list[int], grid: tuple, quarantine_dir: Path,
                        optional: Sequence[int] = ()):
    """Files of thread-safe decoders (GRIB2) decoded DECODE_WORKERS at a time, the others (OSCAR NetCDF: HDF5 is not
    thread-safe) in this thread meanwhile; then assembled by the role of their source onto the cube's step axis
    (`steps` and then `optional`, the leads a cycle may add)."""
    usable = [it for it in items if it.status in ("ok", "skipped")]
    pooled = [it for it in usable if BY_NAME[it.source].thread_safe_decode]
    with ThreadPoolExecutor(DECODE_WORKERS, thread_name_prefix="decode") as pool:
        in_pool = pool.map(lambda it: (it, _decode_one(it, grid, quarantine_dir)), pooled)
        serial = [(it, _decode_one(it, grid, quarantine_dir)) for it in usable if not BY_NAME[it.source].thread_safe_decode]
        decoded = list(in_pool) + serial
    by_role: dict[str, list[xr.Dataset]] = {role: [] for role in ROLES}
    for it, ds in decoded:
        if ds is not None:
            by_role[BY_NAME[it.source].role].append(ds)
    currents = xr.concat(by_role["currents"], dim="time").sortby("time") if by_role["currents"] else None
    ds, missing_steps = assemble_cycle(cycle, [*steps, *optional], grid[0], grid[1], by_role["wind"], by_role["waves"],
                                       currents, optional_after_h=max(steps) if optional else None)
    return ds, missing_steps, currents is not None


def write_cycle(layout, cycle: np.datetime64, ds, items: list[Download], complete: bool, n_expected: int, n_ok: int,
                problems: list[str]) -> None:
    """Cube first, then the file log, then the cycle status: the status is written last, so a run killed
    before it is never taken for a complete one."""
    cube.write_cycle(layout.cube_store, ds, complete=complete, lock_dir=layout.cube_lock_dir)
    now = ingest_log.utcnow()
    run_id = uuid.uuid4().hex[:12]
    ingest_log.record_files(layout.warehouse, [
        {"run_id": run_id, "source": it.source, "cycle": cycle, "file_name": it.name, "url": it.url,
         "bytes": it.result.bytes if it.result else None, "sha256": it.result.sha256 if it.result else None,
         "status": it.status, "error": it.error, "started_at": it.started_at or now, "finished_at": now}
        for it in items
    ])
    ingest_log.set_cycle_status(layout.warehouse, cycle, complete=complete, n_expected=n_expected,
                                n_ok=n_ok, missing="; ".join(problems)[:2000])


def record_nothing_listed(layout, cycle: np.datetime64, listing: Listing, why: str) -> None:
    """A cycle whose sources listed no file (unpublished, listing unreachable): one `missing` row per primary source
    in the ingest log (its index URL, the reason) and the cycle's status incomplete; the cube is not touched."""
    now = ingest_log.utcnow()
    run_id = uuid.uuid4().hex[:12]
    primary = [src for src in SOURCES if src.primary]
    ingest_log.record_files(layout.warehouse, [
        {"run_id": run_id, "source": src.name, "cycle": cycle, "file_name": f"{src.name} files of {cycle_label(cycle)}",
         "url": url, "bytes": None, "sha256": None, "status": "missing", "error": why[:2000], "started_at": now,
         "finished_at": now} for src, url in zip(primary, listing.index_urls + listing.index_urls[-1:] * len(primary))
    ])
    if not cube_complete_in_warehouse(layout.warehouse, cycle):  # never overwrite a complete cycle's status
        ingest_log.set_cycle_status(layout.warehouse, cycle, complete=False, n_expected=0, n_ok=0, missing=why[:2000])


def cube_complete_in_warehouse(db: Path, c: np.datetime64) -> bool:
    return Path(db).exists() and _recorded_complete(db, c)


def ingest_cycle(cycle: str | None = None, data_root: str | None = None, rish_url: str | None = None,
                 oscar_url: str | None = None, force: bool = False, *, run=PLAIN) -> dict:
    """Fetch, decode, regrid and write one forecast cycle into the cube; returns a CycleReport dict.

    `cycle` None (or 'latest') is the newest cycle the sources have published by now.
    """
    s = load_settings(data_root=Path(data_root) if data_root else None,
                      **{"sources.rish_url": rish_url, "sources.oscar_url": oscar_url})
    layout = s.layout.ensure()
    if cycle is None or str(cycle).strip().lower() == "latest":
        c = newest_published_cycles(utcnow_h(), s.sources.cycles_utc, s.sources.publish_delay_h)[-1]
    else:
        c = check_cycle_hour(parse_cycle(cycle), cycle)
    label = cycle_label(c)
    with job_lock(layout.locks, f"ingest {label}", say=LOG.info):
        return _ingest_locked(s, layout, c, label, force, run)


def _optional_leads(s: Settings, layout, label: str) -> list[int]:
    """The leads past gsm_max_lead_h a cycle may add (the 00/12 UTC cycles' to 264 h), as far as the cube's step axis
    has room for them: a cube made with shorter leads keeps its axis (start a new cube to keep the longer ones)."""
    wanted = rish.long_gsm_leads(s.sources.gsm_max_lead_h, s.sources.gsm_long_lead_h, s.sources.gsm_long_step_h)
    have = cube.step_axis_h(layout.cube_store)
    if have is None:
        return wanted
    base = rish.expected_gsm_leads(s.sources.gsm_max_lead_h, s.sources.gsm_step_h)
    kept = [h for h in have if h not in base]  # the store's axis is every cycle's: its slots, whatever the settings
    lost = sorted(set(wanted) - set(kept))
    if lost:
        LOG.warning("cycle %s: the cube's step axis ends at %d h, so leads %s h are not kept; to keep them move the cube "
                    "%s aside and ingest again", label, max(have), ", ".join(map(str, lost)), layout.weather_cube_url)
    return kept


def _ingest_locked(s: Settings, layout, c: np.datetime64, label: str, force: bool, run) -> dict:
    if not force and c in cube.complete_cycles(layout.cube_store) and _recorded_complete(layout.warehouse, c):
        bad = cube_damage.corrupt_chunks(layout.cube_store, [c])  # "complete" must also mean readable
        if not bad:
            LOG.info("cycle %s is already complete; skipping", label)
            return CycleReport(label, True, 0, 0, skipped=True).__dict__
        LOG.warning("cycle %s is recorded complete but %d cube chunk(s) are corrupt (first: %s); ingesting it again",
                    label, len(bad), bad[0].chunk)
    token = earthdata_token(s, blocks=run.prefect)
    opts = {src.name: _opts(s, src.name, token) for src in SOURCES}
    steps = rish.expected_gsm_leads(s.sources.gsm_max_lead_h, s.sources.gsm_step_h)
    optional = _optional_leads(s, layout, label)
    timeout = s.sources.step_timeout_s
    base_urls = {src.name: getattr(s.sources, src.url_setting) for src in SOURCES}
    listing = run.step(list_sources, base_urls, c, steps, opts, optional, name="list-sources", retries=2,
                       timeout_s=timeout)
    for name, url in listing.rejected:
        LOG.warning("ignored unsafe name %r listed at %s", name, url)
    if not listing.items:  # unpublished, or the listing unreachable: recorded missing, the cycle incomplete
        why = listing.nothing_listed()
        LOG.warning("cycle %s: %s; the cycle is recorded incomplete", label, why)
        run.step(record_nothing_listed, layout, c, listing, why, name="write-cycle", timeout_s=timeout)
        return CycleReport(label, False, 0, 0, missing=[why]).__dict__
    known = ingest_log.known_checksums(layout.warehouse, [it.name for it in listing.items])
    items = run.step(download_all, listing.items, layout.raw, c, opts, known, name="download", timeout_s=timeout)
    grid = routing_grid(s.grid.res_deg, s.grid.lat_min_deg, s.grid.lat_max_deg)
    ds, missing_steps, have_currents = run.step(decode_and_assemble, items, c, steps, grid, layout.quarantine, optional,
                                                name="decode-and-assemble", timeout_s=timeout)
    problems = listing.problems + [f"{it.source} {it.name}: {it.status}" for it in items if it.status not in ("ok", "skipped")]
    for source, leads in listing.gaps.items():
        if leads:
            problems.append(f"{source} leads not listed: {', '.join(map(str, leads))} h")
    if not have_currents:
        problems.append("no OSCAR analysis at or before the cycle")
    complete = not missing_steps and have_currents and not problems
    n_ok = sum(it.status in ("ok", "skipped") for it in items)
    run.step(write_cycle, layout, c, ds, items, complete, listing.n_expected, n_ok, problems,
             name="write-cycle", timeout_s=timeout)
    for p in problems:
        LOG.warning("cycle %s: %s", label, p)
    if s.cube_retention_days is not None:
        retired = cube.retire_cycles(layout.cube_store, s.cube_retention_days, lock_dir=layout.cube_lock_dir)
        if retired:
            LOG.info("retired %d cube cycle(s) older than %g days before the newest: %s", len(retired),
                     s.cube_retention_days, ", ".join(cycle_label(r) for r in retired))
    return CycleReport(label, complete, len(items), n_ok, missing=problems,
                       corrupt=[it.name for it in items if it.status == "corrupt"]).__dict__
