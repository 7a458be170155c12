"""Prefect flow `plan-fleet`; the work is in flows/jobs/planning.py."""

from __future__ import annotations

from prefect import flow

from flows.jobs.planning import DEFAULT_FUEL_PRICE, plan_fleet_job
from flows.runner import InPrefect, register_flow
from flows.settings import refuse_served_overrides, served_input_file
from pipeline.planning.voyages import DEFAULT_PENALTY


@register_flow
@flow(name="plan-fleet")
def plan_fleet(contracts: str, availability: str | None = None, ports: str | None = None, as_of: str | None = None,
               data_root: str | None = None, fuel_price: float = DEFAULT_FUEL_PRICE, penalty: float = DEFAULT_PENALTY,
               effort: float = 1.0, time_limit_s: float | None = None) -> dict:
    """Assign cargo contracts to vessels as of `as_of` (default now); the plan's legs become planned voyages. The
    search gets `effort` (1: the default; counted in work, not time); `time_limit_s` is an optional wall-clock
    safety cap."""
    refuse_served_overrides(data_root=data_root)
    contracts = served_input_file("contracts", contracts)
    availability = served_input_file("availability", availability)
    ports = served_input_file("ports", ports)
    return plan_fleet_job(contracts, availability, ports, as_of, data_root=data_root, fuel_price=fuel_price,
                          penalty=penalty, effort=effort, time_limit_s=time_limit_s, run=InPrefect())
