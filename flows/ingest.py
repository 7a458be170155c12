"""Prefect flows `ingest-weather` (one cycle) and `backfill` (a range of cycles); the work is in flows/jobs/ingest.py and
flows/jobs/backfill.py."""

from __future__ import annotations

from prefect import flow

from flows.jobs.backfill import backfill_range
from flows.jobs.ingest import ingest_cycle
from flows.runner import InPrefect, register_flow
from flows.settings import refuse_served_overrides


@register_flow
@flow(name="ingest-weather", log_prints=False)
def ingest_weather(cycle: str | None = None, data_root: str | None = None, rish_url: str | None = None,
                   oscar_url: str | None = None, force: bool = False) -> dict:
    """Fetch, decode, regrid and write one forecast cycle into the cube (default: the newest published one)."""
    refuse_served_overrides(data_root=data_root, rish_url=rish_url, oscar_url=oscar_url)
    return ingest_cycle(cycle, data_root=data_root, rish_url=rish_url, oscar_url=oscar_url, force=force, run=InPrefect())


@register_flow
@flow(name="backfill")
def backfill(start: str, end: str, cycles: str | int | list[int] = "00,12", data_root: str | None = None, rish_url: str | None = None,
             oscar_url: str | None = None, route: bool = False) -> list[dict]:
    """Ingest every cycle from start to end (inclusive days, YYYY-MM-DD), skipping complete ones; optionally re-route."""
    refuse_served_overrides(data_root=data_root, rish_url=rish_url, oscar_url=oscar_url)
    return backfill_range(start, end, cycles, data_root=data_root, rish_url=rish_url, oscar_url=oscar_url, route=route,
                          run=InPrefect())
