"""Prefect deployments of jitroute: nightly (cron, time zone), ingest every 6 hours, backfill on demand.

`jitroute serve` calls `serve_all(build_deployments(...))`; this process then polls the Prefect
server (PREFECT_API_URL) and runs scheduled and triggered flow runs. See deploy/README.md.
"""

from __future__ import annotations

from datetime import timedelta

from prefect.schedules import Cron, Interval

NIGHTLY_CRON = "30 2 * * *"
INGEST_EVERY = timedelta(hours=6)


def build_deployments(*, timezone: str = "UTC", nightly_cron: str = NIGHTLY_CRON, data_root: str | None = None) -> list:
    """The three deployments as RunnerDeployment objects (not yet registered)."""
    from zoneinfo import ZoneInfo

    from flows.fleet import nightly
    from flows.ingest import backfill, ingest_weather

    ZoneInfo(timezone)  # a clear error for an unknown zone, before anything is registered
    common = {"data_root": data_root} if data_root else {}
    return [
        nightly.to_deployment(name="nightly", schedule=Cron(nightly_cron, timezone=timezone), parameters=dict(common),
                              description="Ingest the day's cycles, refit performance models, route the fleet.",
                              tags=["jitroute", "nightly"]),
        ingest_weather.to_deployment(name="ingest-6h", schedule=Interval(INGEST_EVERY, timezone=timezone),
                                     parameters={"cycle": "latest", **common},
                                     description="Fetch the newest forecast cycle into the cube.", tags=["jitroute", "ingest"]),
        backfill.to_deployment(name="backfill", parameters={"cycles": "00,12", "route": False, **common},
                               description="Operators: ingest (and with route=true re-route) past dates start..end.",
                               tags=["jitroute", "backfill"]),
    ]


def serve_all(deployments: list) -> None:
    from prefect import serve

    serve(*deployments)


if __name__ == "__main__":
    serve_all(build_deployments())
