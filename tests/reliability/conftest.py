"""Fixtures for the reliability suite: a small real mirror (0–12 h), fast retry settings, ingest runners."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from tests.reliability.ingest_child import FAST_OVERRIDES, fast_load_settings

REPO = Path(__file__).resolve().parents[2]
CYCLE = "2020-12-01T00"
DAY = ("2020", "12", "01")
N_FILES = 5  # 3 GSM leads, 1 GWM file, 1 OSCAR analysis in the small mirror


@pytest.fixture(scope="session")
def small_mirror(tmp_path_factory) -> Path:
    """A generated RISH/OSCAR mirror of one cycle with leads 0, 6, 12 h (3 GSM files, 1 GWM file, OSCAR v1)."""
    from pipeline.synthetic.mirror import write_mirror

    out = tmp_path_factory.mktemp("small_mirror")
    write_mirror(out, "2020-12-01", "2020-12-01", cycles=(0,), seed=0, max_lead_h=FAST_OVERRIDES["sources.gsm_max_lead_h"])
    return out


@pytest.fixture
def mirror(small_mirror, tmp_path) -> Path:
    """A private copy of the small mirror that a test may damage."""
    dst = tmp_path / "mirror"
    shutil.copytree(small_mirror, dst)
    return dst


def day_dir(mirror: Path) -> Path:
    return mirror / "rish" / Path(*DAY)


def gsm_file(mirror: Path, lead_h: int) -> Path:
    from pipeline.synthetic.mirror import gsm_name

    return day_dir(mirror) / gsm_name(np.datetime64(CYCLE), lead_h)


def gwm_file(mirror: Path) -> Path:
    return next(day_dir(mirror).glob("*_GWM_*.bin"))


def oscar_files(mirror: Path) -> list[Path]:
    return sorted((mirror / "oscar").glob("oscar_vel*.nc"))


def mirror_file(mirror: Path, key: str) -> Path:
    """The file of the small mirror that a damage names: gsm0, gsm6, gsm12 (GSM at that lead), gwm, oscar (the second
    analysis)."""
    return {"gsm0": gsm_file(mirror, 0), "gsm6": gsm_file(mirror, 6), "gsm12": gsm_file(mirror, 12), "gwm": gwm_file(mirror),
            "oscar": oscar_files(mirror)[1]}[key]


def ingest_log_rows(root: Path) -> dict[str, tuple[str, str | None]]:
    """file name -> (status, error) of the latest ingest-log row, read from the analysts' snapshot."""
    import duckdb

    from storage.layout import DataLayout

    with duckdb.connect(str(DataLayout(root).warehouse_snapshot), read_only=True) as con:
        rows = con.execute("SELECT file_name, arg_max(status, finished_at), arg_max(error, finished_at) FROM ingest_log "
                           "GROUP BY file_name").fetchall()
    return {name: (status, error) for name, status, error in rows}


@pytest.fixture
def fast_settings(monkeypatch):
    """The flows read the real settings object with short timeouts/retries and 0–12 h leads on top."""
    import flows.jobs.ingest

    monkeypatch.setattr(flows.jobs.ingest, "load_settings", fast_load_settings)
    return FAST_OVERRIDES


@pytest.fixture
def ingest(fast_settings, prefect_harness):
    """Run the real `ingest-weather` flow in this process: ingest(root, rish_url, oscar_url, **kw) -> report dict."""
    from flows.ingest import ingest_weather

    def run(root: Path, rish_url: str, oscar_url: str, **kw) -> dict:
        return ingest_weather(CYCLE, data_root=str(root), rish_url=rish_url, oscar_url=oscar_url, **kw)

    return run


def file_urls(mirror: Path) -> tuple[str, str]:
    return f"file://{mirror}/rish/", f"file://{mirror}/oscar/"


@pytest.fixture(scope="session")
def clean_root(small_mirror, tmp_path_factory, prefect_harness) -> Path:
    """Data root of a fault-free ingest of the small mirror (do not modify; copy it)."""
    import flows.ingest
    import flows.jobs.ingest

    root = tmp_path_factory.mktemp("clean") / "data"
    mp = pytest.MonkeyPatch()
    mp.setattr(flows.jobs.ingest, "load_settings", fast_load_settings)
    try:
        report = flows.ingest.ingest_weather(CYCLE, data_root=str(root), rish_url=file_urls(small_mirror)[0],
                                             oscar_url=file_urls(small_mirror)[1])
    finally:
        mp.undo()
    assert report["complete"], report
    return root


@pytest.fixture(scope="session")
def clean_cube(clean_root) -> xr.Dataset:
    """The cube a fault-free ingest of the small mirror produces (loaded), for comparisons."""
    from storage.layout import DataLayout

    return _contents(DataLayout(clean_root).weather_cube)


def _contents(store: Path) -> xr.Dataset:
    """The store's cycles and values, loaded; not its publication record (every write gives a new version)."""
    ds = xr.open_zarr(store, consolidated=False).load()
    ds.attrs.pop("cycle_versions", None)
    return ds


def assert_same_cube(store: Path, expected: xr.Dataset) -> None:
    """The store at `store` holds exactly the expected cycles and values (NaN where NaN)."""
    got = _contents(store)
    xr.testing.assert_identical(got, expected)
    for v in expected.data_vars:
        np.testing.assert_array_equal(got[v].values, expected[v].values)


def visible_cycles_equal_clean(store: Path, clean) -> int:
    """Every cycle a reader can see holds exactly the clean values; returns how many are visible."""
    from storage import cube

    if not (store / "zarr.json").exists():
        return 0
    vis = cube.open_cube(store).load()
    for c in vis.cycle.values:
        for v in cube.DATA_VARS:
            np.testing.assert_array_equal(vis[v].sel(cycle=c).values, clean[v].isel(cycle=0).values)
    return vis.sizes["cycle"]


def warehouse_knows_cycle(root: Path) -> None:
    """The warehouse (and its snapshot) has the cycle complete and an ok/skipped log row for every file."""
    import duckdb

    from storage import ingest_log
    from storage.layout import DataLayout

    status = ingest_log.cycle_status(DataLayout(root).warehouse)
    assert list(status.cycle) == [np.datetime64(CYCLE, "ns")] and bool(status.complete.iloc[0])
    con = duckdb.connect(str(DataLayout(root).warehouse_snapshot), read_only=True)
    ok = con.execute("SELECT count(DISTINCT file_name) FROM ingest_log WHERE status IN ('ok', 'skipped')").fetchone()[0]
    con.close()
    assert ok == N_FILES


def child_env() -> dict[str, str]:
    """Environment for a child process that runs flows against this session's Prefect API."""
    import prefect.settings

    env = dict(os.environ)
    env["PREFECT_API_URL"] = str(prefect.settings.PREFECT_API_URL.value())
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    return env


def start_child(root: Path, rish_url: str, oscar_url: str, *args: str) -> subprocess.Popen:
    """Start `python -m tests.reliability.ingest_child` (the real ingest flow in its own process)."""
    return subprocess.Popen([sys.executable, "-m", "tests.reliability.ingest_child", str(root), rish_url, oscar_url, *args],
                            cwd=REPO, env=child_env(), stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
