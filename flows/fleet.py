"""Prefect flows `route-fleet` and `nightly`; the work is in flows/jobs/fleet.py."""

from __future__ import annotations

from prefect import flow

import flows.ingest  # noqa: F401  (registers the sub-flows the nightly runs)
import flows.refit  # noqa: F401
from flows.jobs.fleet import nightly_job, route_fleet_job
from flows.runner import InPrefect, register_flow
from flows.settings import refuse_served_overrides


@register_flow
@flow(name="route-fleet")
def route_fleet(cycle: str | None = None, voyages: list[str] | None = None, data_root: str | None = None,
                solver: str | None = None, seed: int | None = None, trigger: str = "manual", exports: bool = True,
                batch_size: int | None = None) -> dict:
    """Route every upcoming voyage (or the given ones) on one cube cycle (default: the newest complete one)."""
    refuse_served_overrides(data_root=data_root)
    return route_fleet_job(cycle, voyages, data_root=data_root, solver=solver, seed=seed, trigger=trigger,
                           exports=exports, batch_size=batch_size, run=InPrefect())


@register_flow
@flow(name="nightly")
def nightly(date: str | None = None, data_root: str | None = None, rish_url: str | None = None,
            oscar_url: str | None = None, cycles: str | int | list[int] | None = None) -> dict:
    """Ingest the newest published cycles (or a date's) → refit → route the fleet on the newest complete cycle."""
    refuse_served_overrides(data_root=data_root, rish_url=rish_url, oscar_url=oscar_url)
    return nightly_job(date, data_root=data_root, rish_url=rish_url, oscar_url=oscar_url, cycles=cycles, run=InPrefect())
