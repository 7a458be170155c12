"""Prefect flows `route-fleet`, `verify-plans` and `nightly`; the work is in flows/jobs/fleet.py and flows/jobs/verify.py."""

from __future__ import annotations

from prefect import flow

import flows.ingest  # noqa: F401  (registers the sub-flows the nightly runs)
import flows.refit  # noqa: F401
from flows.jobs.fleet import nightly_job, route_fleet_job
from flows.jobs.verify import verify_plans_job
from flows.runner import InPrefect, register_flow
from flows.settings import refuse_served_overrides


@register_flow
@flow(name="route-fleet")
def route_fleet(cycle: str | None = None, voyages: list[str] | None = None, data_root: str | None = None,
                solver: str | None = None, seed: int | None = None, trigger: str = "manual", exports: bool = True,
                batch_size: int | None = None, nominal_utc: str | None = None) -> dict:
    """Route every upcoming voyage and every voyage at sea (or the given ones) on one cube cycle (default: the
    newest complete one)."""
    refuse_served_overrides(data_root=data_root)
    return route_fleet_job(cycle, voyages, data_root=data_root, solver=solver, seed=seed, trigger=trigger,
                           exports=exports, batch_size=batch_size, nominal_utc=nominal_utc, run=InPrefect())


@register_flow
@flow(name="verify-plans")
def verify_plans(data_root: str | None = None, run_id: str | None = None) -> dict:
    """Re-sail the stored plans and their baselines in the analysed weather of the cube's later cycles
    (plan_verification): realised fuel and arrival against the claim."""
    refuse_served_overrides(data_root=data_root)
    return verify_plans_job(data_root=data_root, run_id=run_id, run=InPrefect())


@register_flow
@flow(name="nightly")
def nightly(date: str | None = None, data_root: str | None = None, rish_url: str | None = None,
            oscar_url: str | None = None, cycles: str | int | list[int] | None = None) -> dict:
    """Ingest the newest published cycles (or a date's) → refit → route the fleet on the newest complete cycle.

    Ends Failed when the weather is too old to route on (StaleWeatherError names the newest cycle and its age), and
    in a Completed state named "Incomplete" when a targeted cycle is not complete (the summary lists them)."""
    refuse_served_overrides(data_root=data_root, rish_url=rish_url, oscar_url=oscar_url)
    summary = nightly_job(date, data_root=data_root, rish_url=rish_url, oscar_url=oscar_url, cycles=cycles,
                          run=InPrefect())
    if summary.get("cycles_missing"):
        from prefect.states import Completed

        return Completed(name="Incomplete", data=summary,
                         message=f"targeted cycles not complete: {', '.join(summary['cycles_missing'])}; "
                                 f"routed on {summary.get('cycle_used')}")
    return summary
