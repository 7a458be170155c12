"""How the steps of a job run: plainly in this process, or as Prefect tasks of the current flow run.

Each job in `flows/jobs/` is written once against this small interface and takes `run=`:

- `PLAIN` calls each step as a function (no Prefect import, no API, no server): the CLI uses it
  when no Prefect API is configured, so a quick command costs no more than its work.
- `InPrefect()` (used by the flows in `flows/*.py`) wraps each step in a Prefect task with the
  step's retries and timeout, runs sub-jobs as sub-flows, publishes artifacts and sends the
  `jitroute.*` module loggers to the flow run's logs.
"""

from __future__ import annotations

import logging
import os
import time
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

LOG = logging.getLogger("jitroute.runner")

# Sub-flows by name; each module of flows/ registers its flows here when it is imported.
FLOWS: dict[str, Any] = {}


class Plain:
    """Steps are function calls; retries are honoured, timeouts are not (nothing to cancel a thread with)."""

    prefect = False

    def step(self, fn: Callable, *args, name: str, retries: int = 0, retry_delay_s: float = 1.0,
             timeout_s: float | None = None, **kwargs):
        for attempt in range(retries + 1):
            try:
                return fn(*args, **kwargs)
            except Exception as exc:
                if attempt == retries:
                    raise
                LOG.warning("%s failed (%s); retry %d of %d", name, exc, attempt + 1, retries)
                time.sleep(retry_delay_s)

    def subflow(self, name: str, job: Callable, **kwargs):
        return job(run=self, **kwargs)

    def publish(self, *, key: str, markdown: str, table: list[dict] | None = None, description: str = "") -> None:
        """Artifacts exist only in Prefect; a plain run's summary is printed by the CLI instead."""


class InPrefect(Plain):
    """Inside a Prefect flow run: steps are tasks (no input hashing), sub-jobs are sub-flows."""

    prefect = True

    def __init__(self) -> None:
        self._tasks: dict[tuple, Any] = {}
        route_module_logs_to_prefect()

    def step(self, fn: Callable, *args, name: str, retries: int = 0, retry_delay_s: float = 1.0,
             timeout_s: float | None = None, **kwargs):
        from prefect import task
        from prefect.cache_policies import NO_CACHE

        key = (fn, name, retries, retry_delay_s, timeout_s)
        if key not in self._tasks:  # the step's inputs are whole decoded cycles: never hashed for a cache
            self._tasks[key] = task(fn, name=name, retries=retries, retry_delay_seconds=retry_delay_s,
                                    timeout_seconds=timeout_s, cache_policy=NO_CACHE)
        return self._tasks[key](*args, **kwargs)

    def subflow(self, name: str, job: Callable, **kwargs):
        return FLOWS[name](**kwargs)

    def publish(self, *, key: str, markdown: str, table: list[dict] | None = None, description: str = "") -> None:
        from prefect.artifacts import create_markdown_artifact, create_table_artifact

        try:
            create_markdown_artifact(markdown, key=key, description=description)
            if table:
                create_table_artifact(table, key=f"{key}-table", description=description)
        except Exception as exc:  # an artifact is a convenience; the run's data is already stored
            LOG.warning("could not publish the %s artifact: %s", key, exc)


PLAIN = Plain()


def route_module_logs_to_prefect() -> None:
    """Send `jitroute.*` records to the current Prefect run's logs (once per process)."""
    from prefect.context import FlowRunContext, TaskRunContext
    from prefect.logging.handlers import APILogHandler

    class RunLogHandler(APILogHandler):
        """Only records made inside a flow or task run (elsewhere Prefect would warn about each one)."""

        def emit(self, record):
            if FlowRunContext.get() is not None or TaskRunContext.get() is not None:
                super().emit(record)

    root = logging.getLogger("jitroute")
    if not any(isinstance(h, APILogHandler) for h in root.handlers):
        root.addHandler(RunLogHandler())
    if root.level == logging.NOTSET or root.level > logging.INFO:
        root.setLevel(logging.INFO)


def register_flow(flow_obj):
    """Make a flow available to `InPrefect.subflow` under its name; returns it (use as a decorator)."""
    FLOWS[flow_obj.name] = flow_obj
    return flow_obj


def _profiles_path() -> Path:
    if os.environ.get("PREFECT_PROFILES_PATH"):
        return Path(os.environ["PREFECT_PROFILES_PATH"]).expanduser()
    home = Path(os.environ.get("PREFECT_HOME") or "~/.prefect").expanduser()
    return home / "profiles.toml"


def prefect_api_url() -> str | None:
    """The configured Prefect API: $PREFECT_API_URL, else the active profile's PREFECT_API_URL, else None."""
    if "PREFECT_API_URL" in os.environ:
        return os.environ["PREFECT_API_URL"].strip() or None
    try:
        data = tomllib.loads(_profiles_path().read_text())
    except (OSError, tomllib.TOMLDecodeError):
        return None
    active = os.environ.get("PREFECT_PROFILE") or data.get("active")
    url = (data.get("profiles", {}).get(active, {}) or {}).get("PREFECT_API_URL") if active else None
    return str(url).strip() or None if url else None
