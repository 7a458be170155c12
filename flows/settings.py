"""The one typed settings object: every path, URL, grid and solver parameter, with defaults.

Values come from (lowest to highest priority) the defaults below, environment variables
(`JITROUTE_DATA`, `JITROUTE_OBJECT_ROOT`, `JITROUTE_STORAGE_OPTIONS`, `JITROUTE_RISH_URL`, `JITROUTE_OSCAR_URL`,
`JITROUTE_ALLOWED_REDIRECT_HOSTS`, `JITROUTE_DASK_ADDRESS`, `JITROUTE_DASK_WORKERS`, `JITROUTE_EARTHDATA_TOKEN`,
`JITROUTE_CUBE_RETENTION_DAYS`, `JITROUTE_EXPORT_RETENTION_DAYS`, `JITROUTE_AVOID_PASSAGES`) and
explicit overrides from the CLI. Lower layers never read this object; flows pass the values they need as plain arguments.

Object storage: `JITROUTE_OBJECT_ROOT` (e.g. `s3://bucket/jitroute`) puts the cube and the run exports there.
Credentials and endpoint come the usual fsspec/botocore way (`AWS_ACCESS_KEY_ID`, `AWS_SECRET_ACCESS_KEY`,
`AWS_ENDPOINT_URL`, `~/.aws/…`), or as fsspec storage options in `JITROUTE_STORAGE_OPTIONS` (JSON, e.g.
`{"endpoint_url": "http://minio:9000"}`); storage options are never logged (they may hold keys).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, overload

from pipeline.routing.options import RoutingOptions
from storage.layout import DataLayout
from storage.schema_routes import ARRIVAL_NM

RISH_URL_DEFAULT = "https://database.rish.kyoto-u.ac.jp/arch/jmadata/data/gpv/original/"
OSCAR_URL_DEFAULT = "https://podaac-opendap.jpl.nasa.gov/opendap/allData/oscar/"

if TYPE_CHECKING:
    from pipeline.performance.refit import Gate


@dataclass(frozen=True)
class GridSettings:
    """Routing grid of the weather cube (degrees). Longitudes are 0..360 east."""

    res_deg: float = 0.5
    lat_min_deg: float = -80.0
    lat_max_deg: float = 80.0


@dataclass(frozen=True)
class SourceSettings:
    """Where forecasts come from. `https://`, `http://` and `file://` all work."""

    rish_url: str = RISH_URL_DEFAULT
    oscar_url: str = OSCAR_URL_DEFAULT
    cycles_utc: tuple[int, ...] = (0, 6, 12, 18)
    # RISH mirrors a GSM/GWM run's files about this long after its init time; the 6-hourly ingest fires then
    # and "the newest cycle" means the newest one published by now. OSCAR analyses lag days behind: the cube
    # persists the latest one forward and records its age.
    publish_delay_h: float = 5.0
    nightly_cycles: int = 4  # the nightly ingests the newest this many published cycles (complete ones are skipped)
    step_timeout_s: float = 3600.0  # Prefect task timeout of each ingest step
    gsm_max_lead_h: int = 132
    gsm_step_h: int = 6
    # JMA runs GSM (and GWM) on to 264 h on the 00 and 12 UTC cycles, 12-hourly past 132 h (FD0600…FD1100). These
    # longer leads are fetched and kept whenever a cycle lists them, and never required: a cycle without them (06 and
    # 18 UTC, an archive that lacks them) is complete with its leads to gsm_max_lead_h. 0 (or None): not fetched.
    gsm_long_lead_h: int | None = 264
    gsm_long_step_h: int = 12
    allowed_redirect_hosts: tuple[str, ...] = ()
    http_timeout_s: float = 60.0
    http_retries: int = 3
    http_backoff_s: float = 1.0
    # `http_timeout_s` bounds each read; these bound a whole file (a server dripping bytes never times out)
    http_deadline_s: float = 1800.0  # per file, all attempts
    http_min_rate_bps: float = 4096.0  # average over each window below, else the attempt fails
    http_rate_window_s: float = 30.0
    # size caps: an announced Content-Length above the cap is refused, a body past it is stopped
    gsm_max_bytes: int = 256 << 20  # a global 0.5° GSM lead is tens of MB
    gwm_max_bytes: int = 512 << 20
    oscar_max_bytes: int = 512 << 20
    index_max_bytes: int = 16 << 20  # listing pages
    # Never logged or stored; read from the environment, else from the Prefect Secret block named below.
    earthdata_token: str | None = field(default=None, repr=False)
    earthdata_secret_block: str = "jitroute-earthdata-token"


@dataclass(frozen=True)
class RoutingSettings(RoutingOptions):
    """Defaults for the route solvers (RoutingOptions, see pipeline.routing for their meaning) and how a fleet run
    is spread."""

    lookahead_h: float = 120.0  # route voyages departing within this many hours of the cycle
    voyages_per_task: int | None = None  # None: about three batches per dask worker thread, ≤ 16 voyages each
    task_timeout_s: float = 6 * 3600.0  # Prefect task timeout of a fleet's routing
    # a fleet run stores the batches finished since its last store at most this often (and at its end): a killed run
    # loses at most this long of finished voyages; each store costs its process about 0.1–0.2 s CPU
    store_every_s: float = 60.0
    # voyages at sea (pipeline/enroute.py): re-planned from their latest position; a report older than this at the
    # run's time is advanced along the current plan; a position this close to the destination means arrived
    max_report_age_h: float = 30.0
    arrived_within_nm: float = ARRIVAL_NM  # the arrival voyage_performance counts plan against actual to
    # routing on a cycle older than this at the run's nominal time is refused (the nightly fails naming it)
    max_cycle_age_h: float = 36.0


@dataclass(frozen=True)
class Settings:
    data_root: Path = Path("data")
    object_root: str | None = None  # URL of the cube and the exports (s3://bucket/prefix); None: under data_root
    storage_options: dict = field(default_factory=dict, repr=False)  # fsspec options for object_root; may hold keys
    gate: "Gate | None" = None  # what a refitted model must pass to become active; None: the defaults (`performance`)
    grid: GridSettings = field(default_factory=GridSettings)
    sources: SourceSettings = field(default_factory=SourceSettings)
    routing: RoutingSettings = field(default_factory=RoutingSettings)
    dask_address: str | None = None  # None: a local cluster
    dask_workers: int = 2
    timezone: str = "UTC"
    # Retention of the weather cube: after each ingest, cycles initialised more than this many days before the
    # newest one are retired (storage.cube.retire_cycles: hidden, their chunks deleted). None keeps every cycle.
    cube_retention_days: float | None = None
    # A fleet run's exports are the operator's set (RTZ, GeoJSON, route map, fleet and weather maps); with
    # debug_plots (JITROUTE_DEBUG_PLOTS=1) each voyage's BFOA convergence plot is written beside them.
    debug_plots: bool = False
    # Retention of the run exports (RTZ, GeoJSON, maps of each route-fleet run, under the object root or exports/):
    # after each run, runs started more than this many days before it are deleted
    # (storage.export_store.RunExports.retire_runs). None keeps every run.
    export_retention_days: float | None = None

    @property
    def performance(self) -> "Gate":
        """What a refitted model must pass to become active: `gate`, or Gate's defaults, made when first read, so a
        command that does not refit (a noon import) does not load the refit's numba and scipy (~100 MB)."""
        if self.gate is not None:
            return self.gate
        from pipeline.performance.refit import Gate

        return Gate()

    @property
    def layout(self) -> DataLayout:
        return DataLayout(Path(self.data_root), self.object_root, dict(self.storage_options))

    def with_overrides(self, **overrides) -> "Settings":
        """Return a copy with top-level or `section.name` overrides; None values are ignored."""
        s = self
        for key, value in overrides.items():
            if value is None:
                continue
            if "." in key:
                section, name = key.split(".", 1)
                s = replace(s, **{_FIELD_OF.get(section, section): replace(getattr(s, section), **{name: value})})
            else:
                s = replace(s, **{_FIELD_OF.get(key, key): value})
        return s


_FIELD_OF = {"performance": "gate"}  # a section read through a property, and the field that holds it


class SettingsError(ValueError):
    """A setting from the environment that cannot be read; the message names the variable."""


def storage_options_from_env(text: str | None) -> dict | None:
    """`JITROUTE_STORAGE_OPTIONS` as a dict (JSON object); the error never repeats the value (it may hold keys)."""
    if not text:
        return None
    try:
        value = json.loads(text)
    except ValueError:
        value = None
    if not isinstance(value, dict):
        raise SettingsError("JITROUTE_STORAGE_OPTIONS is not a JSON object of fsspec storage options, "
                            'e.g. {"endpoint_url": "http://127.0.0.1:9000"}')
    return value


def _flag(env, name: str) -> bool | None:
    """A yes/no from the environment: 1/true/yes or 0/false/no (unset or empty: None)."""
    text = env.get(name, "").strip().lower()
    if not text:
        return None
    if text in ("1", "true", "yes", "on"):
        return True
    if text in ("0", "false", "no", "off"):
        return False
    raise SettingsError(f"{name}={text!r} is not 1 or 0 (true or false)")


def _days(env, name: str) -> float | None:
    """A number of days ≥ 0 from the environment (unset or empty: None)."""
    text = env.get(name, "").strip()
    if not text:
        return None
    try:
        days = float(text)
    except ValueError:
        days = -1.0
    if not days >= 0:
        raise SettingsError(f"{name}={text!r} is not a number of days ≥ 0 (unset it to keep every cycle)")
    return days


SERVED_ENV = "JITROUTE_SERVED"  # set by `jitroute serve` for the flow runs it starts


def pin_for_serving(data_root: str | None = None, rish_url: str | None = None, oscar_url: str | None = None) -> None:
    """Make this process (and the flow runs it starts, which inherit its environment) a served deployment: the data
    root and source URLs given here (or already in its environment) are the only ones its flow runs accept."""
    for var, value in (("JITROUTE_DATA", data_root), ("JITROUTE_RISH_URL", rish_url), ("JITROUTE_OSCAR_URL", oscar_url)):
        if value:
            os.environ[var] = str(value)
    os.environ[SERVED_ENV] = "1"


def is_served() -> bool:
    """This flow run takes its parameters from a Prefect API caller: it was started from a deployment (by
    `jitroute serve`, or by a work-pool worker for deploy/prefect.yaml), or runs under `jitroute serve`. A flow called
    in-process by the CLI has no deployment: its parameters are the operator's own."""
    if os.environ.get(SERVED_ENV):
        return True
    from prefect.context import FlowRunContext

    ctx = FlowRunContext.get()
    return ctx is not None and ctx.flow_run is not None and ctx.flow_run.deployment_id is not None


_ENV_OF = {"data_root": "JITROUTE_DATA", "rish_url": "JITROUTE_RISH_URL", "oscar_url": "JITROUTE_OSCAR_URL"}


def refuse_served_overrides(**given: str | None) -> None:
    """On a served deployment (`is_served`), a flow-run parameter (`data_root`, `rish_url`, `oscar_url`) that differs
    from the settings of the process running it (`jitroute serve`'s, or the work-pool job's environment) is refused
    (SettingsError): anyone who can reach the Prefect API could otherwise point the ingest at another data root, or the
    OSCAR fetch — which carries the Earthdata token — at their own server. Elsewhere (the CLI, tests) parameters are
    the operator's own and pass."""
    if not is_served():
        return
    s = load_settings()
    pinned = {"data_root": s.data_root, "rish_url": s.sources.rish_url, "oscar_url": s.sources.oscar_url}
    for name, value in given.items():
        if value is None or name not in pinned:
            continue
        if name == "data_root":
            same = Path(str(value)).expanduser().resolve() == Path(str(pinned[name])).expanduser().resolve()
        else:
            same = str(value).rstrip("/") == str(pinned[name]).rstrip("/")
        if not same:
            raise SettingsError(f"parameter {name}={str(value)[:200]!r} refused: a served deployment takes {name} from the "
                                f"settings of the flow host ({pinned[name]}); to change it, restart `jitroute serve` "
                                f"with it, or change the work pool's environment ({_ENV_OF[name]})")


@overload
def served_input_file(name: str, value: str) -> str: ...
@overload
def served_input_file(name: str, value: None) -> None: ...
def served_input_file(name: str, value: str | None) -> str | None:
    """The input file a flow-run parameter names (`contracts`, a noon-report file, a fleet folder…). On a served
    deployment it must lie inside `<data root>/inbox/` (a relative name is taken from there; symbolic links are
    followed before the check): a Prefect API caller could otherwise make the flow read any file of the flow host and
    echo its lines into the run's logs as refused rows. Elsewhere the path is returned as given."""
    if value is None or not is_served():
        return value
    inbox = load_settings().layout.inbox.resolve()
    path = Path(str(value)).expanduser()
    path = (path if path.is_absolute() else inbox / path).resolve()
    if not path.is_relative_to(inbox):
        raise SettingsError(f"parameter {name}={str(value)[:200]!r} refused: a served flow reads input files only "
                            f"under {inbox}/; copy the file there and give its name")
    return str(path)


def load_settings(**overrides) -> Settings:
    """Defaults, then environment, then `overrides` (e.g. `data_root=...`, `sources.rish_url=...`)."""
    env = os.environ
    s = Settings().with_overrides(
        data_root=Path(env["JITROUTE_DATA"]) if env.get("JITROUTE_DATA") else None,
        object_root=env.get("JITROUTE_OBJECT_ROOT") or None,
        storage_options=storage_options_from_env(env.get("JITROUTE_STORAGE_OPTIONS")),
        dask_address=env.get("JITROUTE_DASK_ADDRESS") or None,
        dask_workers=int(env["JITROUTE_DASK_WORKERS"]) if env.get("JITROUTE_DASK_WORKERS") else None,
        cube_retention_days=_days(env, "JITROUTE_CUBE_RETENTION_DAYS"),
        debug_plots=_flag(env, "JITROUTE_DEBUG_PLOTS"),
        export_retention_days=_days(env, "JITROUTE_EXPORT_RETENTION_DAYS"),
        **{
            "sources.rish_url": env.get("JITROUTE_RISH_URL") or None,
            "sources.oscar_url": env.get("JITROUTE_OSCAR_URL") or None,
            "sources.earthdata_token": env.get("JITROUTE_EARTHDATA_TOKEN") or None,
            "sources.allowed_redirect_hosts": tuple(h.strip() for h in env.get("JITROUTE_ALLOWED_REDIRECT_HOSTS", "").split(",")
                                                    if h.strip()) or None,
            "routing.avoid_passages": tuple(p.strip() for p in env.get("JITROUTE_AVOID_PASSAGES", "").split(",")
                                            if p.strip()) or None,
        },
    )
    return s.with_overrides(**overrides)


__all__ = ["Settings", "SettingsError", "GridSettings", "SourceSettings", "RoutingSettings", "load_settings",
           "pin_for_serving", "refuse_served_overrides", "is_served", "served_input_file"]
