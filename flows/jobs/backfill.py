"""The backfill job: every cycle of a range of days through the ingest job, skipping complete ones, then
optionally the route-fleet job on each cycle it completed. Its own module because it runs both jobs: the ingest job
knows nothing of routing."""

from __future__ import annotations

import logging
from pathlib import Path

from flows.jobs.ingest import CycleReport, ingest_cycle
from flows.runner import PLAIN
from flows.settings import load_settings
from pipeline.sources.cycles import cycles_between, label as cycle_label, parse_hours
from storage.run_lock import job_lock

LOG = logging.getLogger("jitroute.ingest")


def backfill_range(start: str, end: str, cycles: str | int | list[int] = "00,12", data_root: str | None = None, rish_url: str | None = None,
                   oscar_url: str | None = None, route: bool = False, *, run=PLAIN,
                   progress=None) -> list[dict]:
    """Ingest every cycle from start to end (inclusive days), skipping complete ones; optionally re-route.

    `progress(done, total, label)` is called after each cycle (the CLI draws a bar with it).
    """
    todo = cycles_between(start, end, parse_hours(cycles))
    s = load_settings(data_root=Path(data_root) if data_root else None)
    reports = []
    with job_lock(s.layout.ensure().locks, f"backfill {start}..{end}", say=LOG.info):
        for c in todo:
            label = cycle_label(c)
            try:
                reports.append(run.subflow("ingest-weather", ingest_cycle, cycle=label, data_root=data_root,
                                           rish_url=rish_url, oscar_url=oscar_url))
            except Exception as exc:  # one cycle failing is reported; the backfill goes on with the next
                LOG.error("backfill: cycle %s failed: %s: %s", label, type(exc).__name__, exc)
                reports.append(CycleReport(label, False, 0, 0, missing=[f"ingest failed: {type(exc).__name__}: {exc}"]).__dict__)
            LOG.info("backfill: %d/%d cycles done (%s)", len(reports), len(todo), label)
            if progress is not None:
                progress(len(reports), len(todo), label)
        if route:
            from flows.jobs.fleet import route_fleet_job  # routing's imports only when a backfill re-routes

            for r in reports:
                if r["complete"]:
                    summary = run.subflow("route-fleet", route_fleet_job, cycle=r["cycle"], data_root=data_root,
                                          trigger="backfill")
                    r["route_run"] = summary.get("run_id")
    return reports
