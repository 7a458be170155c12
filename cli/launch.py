"""How a command runs its job: as a Prefect flow run when a Prefect API is configured, else as plain functions.

With `PREFECT_API_URL` set (in the environment or the active Prefect profile) a command's work is
recorded as a flow run on that server. Without it nothing of Prefect is imported or started: no
temporary server, no orphaned processes, and a quick command costs what its work costs.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable

from flows.runner import prefect_api_url


def run_job(flow_module: str, flow_name: str, job: Callable, **kwargs):
    """`flows.<module>.<flow>(**kwargs)` when a Prefect API is configured, else `job(**kwargs)` in this process."""
    if prefect_api_url():
        flow = getattr(importlib.import_module(flow_module), flow_name)
        return flow(**kwargs)
    return job(**kwargs)
