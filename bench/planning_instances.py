"""The fleet-planning measurements' instance: a random fleet of a given size (`pipeline/synthetic/contracts.py`, seed
1) at a fuel price of 600 per tonne, as `bench/planning.py` builds it (`planning_cuts.py`, `planning_plans.py`,
`planning_bounds.py`)."""

from __future__ import annotations

FUEL_PRICE = 600.0


def planning_data(size: str, seed: int = 1):
    """PlanData of the random instance `size` ("vessels x contracts", e.g. "50x200")."""
    from pipeline.planning import problem
    from pipeline.synthetic.contracts import random_instance

    n_vessels, n_contracts = (int(x) for x in size.split("x"))
    return problem.build(*random_instance(n_vessels, n_contracts, seed=seed), fuel_price=FUEL_PRICE)
