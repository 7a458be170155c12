"""Shared fixtures. Tests never touch the network beyond 127.0.0.1 and never write outside tmp."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import settings as hypothesis_settings

# CI runs every property test on the same examples (reproducible); elsewhere hypothesis explores anew each run.
hypothesis_settings.register_profile("ci", derandomize=True, print_blob=True)
if os.environ.get("CI"):
    hypothesis_settings.load_profile("ci")

JMA_FIXTURES = Path(__file__).resolve().parent / "fixtures" / "jma"
TESTS = Path(__file__).resolve().parent

# Whole files marked `slow` (`make test-fast`, `pytest -m "not slow"`, leaves them out; `make test` runs them): they
# start servers, clusters or flows, run the nightly or the fleet end to end, or route bench-sized voyages. Single
# slow tests in other files carry @pytest.mark.slow themselves. Paths relative to tests/.
SLOW_FILES = (
    "reliability/",  # crashes, kills, hostile servers, damaged stores: child processes and real servers
    "test_cluster.py", "test_schedule_e2e.py", "test_object_root.py", "test_worker_memory.py",  # clusters, servers
    "test_operable.py", "test_fleet.py", "test_enroute.py", "test_warehouse_recovery.py",  # nightly or fleet runs
    "test_ingest.py", "test_served_parameters.py", "test_export_store.py",  # Prefect API, served flows, S3 server
    "test_readme_examples.py", "test_routing_suite.py",  # the README's commands; the bench suite's voyages
    "test_routing_twin.py",  # every search again with the JIT off, in a child process
    "test_console_browser.py",  # a served console on a routed demo data root, driven in a real browser
)


def _slow_file(rel: str) -> bool:
    return any(rel == f or (f.endswith("/") and (rel + "/").startswith(f)) for f in SLOW_FILES)


def pytest_ignore_collect(collection_path, config):
    """Under `-m "not slow"` (`make test-fast`) the files that are slow as a whole are not even imported: their imports
    and assertion rewriting are a few seconds of the fast run. Any other selection collects them as usual."""
    if config.getoption("markexpr", "").replace(" ", "") != "notslow":
        return None
    try:
        rel = collection_path.resolve().relative_to(TESTS).as_posix()
    except ValueError:
        return None
    return True if _slow_file(rel) else None


# Files whose tests run for a minute or more in all (servers, schedulers, flows in flight), run first: under
# `pytest -n auto` a worker that picks one of them up last keeps the whole suite waiting after the other is done.
LONG_FILES_FIRST = ("test_schedule_e2e.py", "test_serve_sigterm.py", "test_served_worker.py", "test_enroute.py",
                    "test_cluster.py", "test_routing_twin.py")


def pytest_collection_modifyitems(config, items):
    for item in items:
        if _slow_file(item.path.resolve().relative_to(TESTS).as_posix()):
            item.add_marker(pytest.mark.slow)
    rank = {name: k for k, name in enumerate(LONG_FILES_FIRST)}  # a file's tests stay together (its module fixtures)
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))


@pytest.fixture(scope="session", autouse=True)
def warehouse_templates(tmp_path_factory):
    """Every new warehouse of the session is a copy of one migrated once (storage.warehouse.use_templates) rather than
    migrated again (about 0.3 s CPU each); `migrated_from_scratch` turns it off for a test of the migrations."""
    from storage import warehouse

    warehouse.use_templates(tmp_path_factory.mktemp("warehouse_templates"))
    yield
    warehouse.use_templates(None)


@pytest.fixture
def migrated_from_scratch():
    """New warehouses in this test run every migration (no template copy)."""
    from storage import warehouse

    folder = warehouse._TEMPLATE_FOLDER
    warehouse.use_templates(None)
    yield
    warehouse.use_templates(folder)


@pytest.fixture(scope="session")
def jma_fixtures() -> Path:
    """Real JMA GRIB2 files written by others (tests/fixtures/jma/README.md)."""
    return JMA_FIXTURES


@pytest.fixture
def data_root(tmp_path, monkeypatch) -> Path:
    root = tmp_path / "data"
    monkeypatch.setenv("JITROUTE_DATA", str(root))
    return root


@pytest.fixture(scope="session")
def prefect_harness(tmp_path_factory):
    """One throw-away Prefect API (SQLite) for every flow test in the session."""
    os.environ.setdefault("PREFECT_HOME", str(tmp_path_factory.mktemp("prefect_home")))
    os.environ.setdefault("PREFECT_SERVER_ANALYTICS_ENABLED", "false")
    os.environ.setdefault("PREFECT_LOGGING_LEVEL", "WARNING")
    from prefect.testing.utilities import prefect_test_harness

    with prefect_test_harness(server_startup_timeout=120):
        yield


@pytest.fixture(scope="session")
def demo_mirror(tmp_path_factory) -> Path:
    """A generated RISH/OSCAR mirror with one full cycle (2020-12-01T00, 23 GSM leads + GWM + OSCAR)."""
    from pipeline.synthetic.mirror import write_mirror

    out = tmp_path_factory.mktemp("mirror")
    write_mirror(out, "2020-12-01", "2020-12-01", cycles=(0,), seed=0)
    return out


def route_demo_cycle(root: Path) -> None:
    """The fleet of `root` routed on the 2020-12-01T00 cycle as the demo does (gc, no exports, as of 06 UTC), in one
    dask worker."""
    from flows.jobs.fleet import route_fleet_job

    old = os.environ.get("JITROUTE_DASK_WORKERS")
    os.environ["JITROUTE_DASK_WORKERS"] = "1"
    try:
        route_fleet_job(cycle="2020-12-01T00", data_root=str(root), solver="gc", exports=False,
                        nominal_utc="2020-12-01T06")
    finally:
        os.environ.pop("JITROUTE_DASK_WORKERS") if old is None else os.environ.__setitem__("JITROUTE_DASK_WORKERS", old)


def mirror_urls(mirror: Path) -> dict[str, str]:
    return {"rish_url": (mirror / "rish").as_uri() + "/", "oscar_url": (mirror / "oscar").as_uri() + "/"}


def fleet_data_root(base: Path, mirror: Path, *, n_vessels: int, days: int, seed: int, refit: bool,
                    at_sea: tuple[int, ...] = ()) -> Path:
    """`base/data`: the mirror's 2020-12-01T00 cycle ingested and a generated fleet imported (optionally refitted),
    all through the plain jobs (no Prefect)."""
    from cli.fleet import _import_fleet
    from flows.jobs.ingest import ingest_cycle
    from flows.jobs.refit import refit_job
    from pipeline.synthetic.fleet import generate_fleet, write_fleet

    root = base / "data"
    assert ingest_cycle("2020-12-01T00", data_root=str(root), **mirror_urls(mirror))["complete"]
    write_fleet(generate_fleet("2020-12-01T00", n_vessels=n_vessels, days=days, seed=seed, at_sea=at_sea), base / "fleet")
    _import_fleet(base / "fleet", root)
    if refit:
        refit_job(data_root=str(root))
    return root


S3_CREDENTIALS = {"AWS_ACCESS_KEY_ID": "testing", "AWS_SECRET_ACCESS_KEY": "testing", "AWS_DEFAULT_REGION": "us-east-1"}


@pytest.fixture
def s3_endpoint(tmp_path):
    """An S3-compatible server (moto's server mode) on a free loopback port, with an empty bucket `jitroute`.
    Yields the environment variables a client needs (endpoint and dummy credentials); killed at teardown."""
    from tests.processes import VENV_BIN, describe, free_port, new_tag, poll, port_open, start, stop, tagged_env

    tag, port = new_tag(), free_port()
    log = tmp_path / "moto.log"
    server = start([str(VENV_BIN / "moto_server"), "-H", "127.0.0.1", "-p", str(port)], tagged_env(tag), log)
    try:
        poll("the S3 server", lambda: port_open(port, server, log), 60, 0.2)
        env = {"AWS_ENDPOINT_URL": f"http://127.0.0.1:{port}", **S3_CREDENTIALS}
        import boto3

        boto3.client("s3", endpoint_url=env["AWS_ENDPOINT_URL"], aws_access_key_id="testing",
                     aws_secret_access_key="testing", region_name="us-east-1").create_bucket(Bucket="jitroute")
        yield env
    finally:
        left = stop([server], tag)
        assert not left, describe(left)


@pytest.fixture
def dask_cluster(tmp_path, s3_endpoint):
    """`dask scheduler` and two `dask worker --nthreads 1` processes (no nanny: a killed worker stays dead), started
    in an empty folder with no JITROUTE_DATA: they see the S3 endpoint, not the data root. Yields
    (scheduler address, the processes by name); all stopped at teardown, none left behind."""
    from tests.processes import TAG_VAR, VENV_BIN, describe, free_port, new_tag, poll, port_open, start, stop, tagged_env

    tag, port = new_tag(), free_port()
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    env = {k: v for k, v in tagged_env(tag, **s3_endpoint).items() if not k.startswith("JITROUTE_") or k == TAG_VAR}
    address = f"tcp://127.0.0.1:{port}"
    procs = {"scheduler": start([str(VENV_BIN / "dask"), "scheduler", "--host", "127.0.0.1", "--port", str(port),
                                 "--no-dashboard"], env, tmp_path / "scheduler.log", cwd=elsewhere)}
    try:
        poll("the dask scheduler", lambda: port_open(port, procs["scheduler"], tmp_path / "scheduler.log"), 60, 0.2)
        for k in (1, 2):
            procs[f"worker{k}"] = start([str(VENV_BIN / "dask"), "worker", address, "--nthreads", "1", "--no-nanny",
                                         "--no-dashboard", "--name", f"worker{k}", "--local-directory", str(elsewhere)],
                                        env, tmp_path / f"worker{k}.log", cwd=elsewhere)
        yield address, procs
    finally:
        left = stop(list(procs.values()), tag)
        assert not left, describe(left)
