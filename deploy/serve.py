"""Prefect deployments of jitroute: nightly (cron in a time zone), ingest when each cycle is published, backfill.

`jitroute serve` checks that a Prefect API is reachable, builds the deployments below and serves them:
this process registers them, the server's scheduler creates their runs, and this process runs them in
subprocesses. See deploy/README.md.
"""

from __future__ import annotations

NIGHTLY_CRON = "30 2 * * *"


class ServeError(RuntimeError):
    """Serving cannot start (no reachable Prefect API, bad time zone or cron); the message says what to do."""


def check_api(timeout_s: float = 5.0) -> str:
    """The configured Prefect API URL if its /health answers; else ServeError saying how to start one."""
    import httpx

    from flows.runner import prefect_api_url

    how = ("start one with `.venv/bin/prefect server start` and set "
           "PREFECT_API_URL=http://127.0.0.1:4200/api (deploy/README.md)")
    url = prefect_api_url()
    if not url:
        raise ServeError(f"no Prefect API configured: {how}")
    try:
        r = httpx.get(url.rstrip("/") + "/health", timeout=timeout_s)
        r.raise_for_status()
    except httpx.HTTPError as exc:
        raise ServeError(f"the Prefect API at {url} does not answer ({type(exc).__name__}): {how}") from None
    return url


def build_deployments(*, timezone: str = "UTC", nightly_cron: str = NIGHTLY_CRON, ingest_cron: str | None = None,
                      data_root: str | None = None, rish_url: str | None = None, oscar_url: str | None = None) -> list:
    """The three deployments as RunnerDeployment objects (not yet registered).

    The ingest runs when each cycle's files are published (cron in UTC from the cycle hours and the publish
    delay in the settings), so a restart of `serve` never shifts it; its default cycle is the newest published.
    The nightly ingests the newest published cycles, refits and routes. Sources and data root given here are
    the deployments' default parameters.
    """
    from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

    from datetime import datetime

    from cronsim import CronSim, CronSimError
    from prefect.deployments.runner import EntrypointType
    from prefect.schedules import Cron

    from flows.fleet import nightly
    from flows.ingest import backfill, ingest_weather
    from flows.settings import load_settings
    from pipeline.sources.cycles import publication_cron

    try:
        ZoneInfo(timezone)
    except (ZoneInfoNotFoundError, ValueError):
        raise ServeError(f"unknown time zone {timezone!r}; use an IANA name such as UTC or Europe/Oslo") from None
    s = load_settings()
    ingest_cron = ingest_cron or publication_cron(s.sources.cycles_utc, s.sources.publish_delay_h)
    for name, expr in (("--nightly-cron", nightly_cron), ("--ingest-cron", ingest_cron)):
        try:
            CronSim(expr, datetime(2020, 1, 1))
        except CronSimError as exc:
            raise ServeError(f"{name} {expr!r} is not a cron expression ({exc})") from None
    common = {k: v for k, v in (("data_root", data_root), ("rish_url", rish_url), ("oscar_url", oscar_url)) if v}
    module = EntrypointType.MODULE_PATH  # runs from any working directory where jitroute is installed
    return [
        nightly.to_deployment(name="nightly", schedule=Cron(nightly_cron, timezone=timezone), parameters=dict(common),
                              description="Ingest the newest published cycles, refit performance models, route the fleet.",
                              tags=["jitroute", "nightly"], entrypoint_type=module),
        ingest_weather.to_deployment(name="ingest", schedule=Cron(ingest_cron, timezone="UTC"), parameters=dict(common),
                                     description="Fetch the newest published forecast cycle into the cube.",
                                     tags=["jitroute", "ingest"], entrypoint_type=module),
        backfill.to_deployment(name="backfill", parameters={"cycles": "00,12", "route": False, **common},
                               description="Operators: ingest (and with route=true re-route) past days start..end.",
                               tags=["jitroute", "backfill"], entrypoint_type=module),
    ]


DRAIN_S = 1800.0  # how long a stopping `serve` lets its flow runs finish before it cancels them


def draining_runner(drain_s: float = DRAIN_S):
    """A Prefect Runner that on SIGTERM stops taking new flow runs, lets those in flight finish (up to `drain_s`), then
    cancels what is left (Prefect's cancellation: the run ends Cancelled, not Crashed) and returns. Prefect's own
    Runner cancels every run in flight at once, and the CLI's SIGTERM grace (cli/signals.py) would end the process
    before even that was recorded."""
    import asyncio
    import logging
    import sys
    import time

    from prefect.runner import Runner

    log = logging.getLogger("jitroute.serve")

    class DrainingRunner(Runner):
        stopping: bool  # Runner's own flag, declared for the type checker (Prefect is read as untyped)

        def handle_sigterm(self, *args, **kwargs) -> None:
            if not self.started or self.stopping or self._loop is None:
                sys.exit(0)
            self.stopping = True  # no new runs from here on
            poller = getattr(self, "_scheduled_run_poller", None)
            if poller is not None:
                poller.stopping = True
            self.execute_in_background(self._drain_then_stop)

        def _in_flight(self) -> int:
            return len(getattr(self._process_manager, "_process_map", {}))

        async def _drain_then_stop(self) -> None:
            deadline = time.monotonic() + drain_s
            n = self._in_flight()
            if n:
                log.info("SIGTERM: no new flow runs; waiting up to %.0f s for %d in flight to finish", drain_s, n)
            while self._in_flight() and time.monotonic() < deadline:
                await asyncio.sleep(0.5)
            if self._in_flight():
                log.warning("SIGTERM: %d flow run(s) still running after %.0f s: cancelling them", self._in_flight(),
                            drain_s)
            await self.astop()

    return DrainingRunner(pause_on_shutdown=True)


def serve_deployments(*, drain_s: float = DRAIN_S, **kwargs) -> None:
    """Register the deployments and run their flow runs until stopped (Ctrl-C, or SIGTERM: in-flight runs finish
    first, up to `drain_s`, then the rest are cancelled). The data root and source URLs given here (or in this
    process's environment) are pinned: a flow run asking for others is refused, and secrets (the Earthdata token) come
    from this process's environment or Prefect Secret block only."""
    import asyncio

    from cli import signals
    from flows.settings import pin_for_serving

    pin_for_serving(kwargs.get("data_root"), kwargs.get("rish_url"), kwargs.get("oscar_url"))
    signals.set_grace_s(drain_s + 60.0)  # the drain, then Prefect's cancellation of what is left
    runner = draining_runner(drain_s)
    for deployment in build_deployments(**kwargs):
        runner.add_deployment(deployment)
    try:
        asyncio.run(runner.start())
    except KeyboardInterrupt:
        pass


if __name__ == "__main__":
    check_api()
    serve_deployments()
