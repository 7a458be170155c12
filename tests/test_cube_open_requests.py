"""Opening the cube on the flow host (what route-fleet does before routing: the newest complete cycle, the cycles
the cube has, the cycle's content version) costs the same number of S3 requests whatever the number of cycles the
cube has ever held; a cube written before that (one chunk per cycle row) still opens, and its next write moves it
to the new layout. Counted on bench/s3_counting_server.py (moto on loopback)."""

from __future__ import annotations

import json
import sys
import urllib.request
from pathlib import Path

import boto3
import numpy as np
import pytest
import xarray as xr
import zarr

from storage import cube

REPO = Path(__file__).resolve().parents[1]
FIRST = np.datetime64("2021-03-01T00", "ns")
LAT = np.arange(-10.0, 10.01, 5.0)
LON = np.arange(0.0, 360.0, 60.0)
STEPS = np.arange(0, 13, 6)


def cycle_ds(cycle) -> xr.Dataset:
    dims = ("step", "lat", "lon")
    ones = np.ones((STEPS.size, LAT.size, LON.size), np.float32)
    data = {v: (dims, ones * (k + 1)) for k, v in enumerate(cube.DATA_VARS)}
    data["current_age_h"] = (("step",), np.zeros(STEPS.size, np.float32))
    return xr.Dataset(data, coords={"cycle": cycle, "step": STEPS, "lat": LAT, "lon": LON})


@pytest.fixture
def counting_s3(tmp_path):
    """bench/s3_counting_server.py on a free loopback port with an empty bucket `jitroute`; yields (fsspec options,
    a function returning the GET requests served since the previous call)."""
    from tests.conftest import S3_CREDENTIALS
    from tests.processes import describe, free_port, new_tag, poll, port_open, start, stop, tagged_env

    tag, port = new_tag(), free_port()
    log = tmp_path / "s3.log"
    server = start([sys.executable, str(REPO / "bench" / "s3_counting_server.py"), str(port)], tagged_env(tag), log)
    endpoint = f"http://127.0.0.1:{port}"
    try:
        poll("the counting S3 server", lambda: port_open(port, server, log), 60, 0.2)
        boto3.client("s3", endpoint_url=endpoint, aws_access_key_id="testing", aws_secret_access_key="testing",
                     region_name="us-east-1").create_bucket(Bucket="jitroute")

        def gets_since_last() -> int:
            with urllib.request.urlopen(f"{endpoint}/__counts") as resp:
                counts = json.load(resp)
            urllib.request.urlopen(urllib.request.Request(f"{endpoint}/__reset", method="POST")).close()
            return sum(v["requests"] for k, v in counts.items() if k.startswith("GET "))

        yield {"endpoint_url": endpoint, "key": S3_CREDENTIALS["AWS_ACCESS_KEY_ID"],
               "secret": S3_CREDENTIALS["AWS_SECRET_ACCESS_KEY"]}, gets_since_last
    finally:
        left = stop([server], tag)
        assert not left, describe(left)


def cube_on_s3(tmp_path: Path, url: str, options: dict, n: int, *, one_row_chunks: bool = False) -> list:
    """A cube of `n` complete cycles written locally by storage/cube.py (fast) and uploaded to `url` file by file, as
    written there; `one_row_chunks`: with `cycle` and `cycle_state` in one chunk per row, as stores written before."""
    import s3fs

    local = tmp_path / url.split("/")[3] / "weather.zarr"
    cycles = [FIRST + np.timedelta64(6 * k, "h") for k in range(n)]
    for c in cycles:
        cube.write_cycle(local, cycle_ds(c), complete=True, chunks=(STEPS.size, LAT.size, LON.size))  # few files
    if one_row_chunks:
        to_one_row_chunks(local)
    fs = s3fs.S3FileSystem(**options)
    fs.put(str(local), url.removeprefix("s3://"), recursive=True)
    assert fs.exists(url.removeprefix("s3://") + "/cycle_state/zarr.json")
    return cycles


def flow_host_open(url: str, options: dict):
    """What route_fleet_job (flows/jobs/fleet.py) reads of the cube before routing, in a fresh filesystem as a new
    flow process has: the newest complete cycle, the cycles the cube has, the cycle's content version."""
    import s3fs

    s3fs.S3FileSystem.clear_instance_cache()
    loc = cube.locate(url, options)
    c = cube.latest_complete_cycle(loc)
    assert c in cube.cycle_states(loc)
    return c, cube.cycle_versions(loc).get(c)


def to_one_row_chunks(path: Path) -> None:
    """Give `cycle` and `cycle_state` one chunk per cycle row, as every store written before had."""
    group = zarr.open_group(str(path), mode="r+", use_consolidated=False)
    for name in ("cycle", "cycle_state"):
        old = group[name]
        values, attrs, dims = old[:], old.attrs.asdict(), old.metadata.dimension_names
        new = group.create_array(name, shape=values.shape, chunks=(1,), dtype=values.dtype, dimension_names=dims,
                                 attributes=attrs, fill_value=old.fill_value, overwrite=True)
        new[:] = values
    cube._consolidate(cube.locate(path))
    assert group["cycle_state"].chunks == (1,)


@pytest.mark.slow  # an S3 server
def test_the_flow_hosts_open_costs_the_same_gets_for_3_and_12_cycles(counting_s3, tmp_path):
    options, gets = counting_s3
    cost = {}
    for n in (3, 12):
        url = f"s3://jitroute/n{n}/cubes/weather.zarr"
        cycles = cube_on_s3(tmp_path, url, options, n)
        gets()
        assert flow_host_open(url, options)[0] == cycles[-1]
        cost[n] = gets()
    assert cost[12] == cost[3], f"GETs of one open: {cost}"
    assert 0 < cost[3] <= 32, cost  # the root, and `cycle`, `cycle_state` (metadata and one chunk each) per read


@pytest.mark.slow  # an S3 server
def test_a_cube_with_one_chunk_per_cycle_still_opens_and_its_next_write_bounds_the_open(counting_s3, tmp_path):
    options, gets = counting_s3
    bounded = {}
    for n in (3, 12):
        url = f"s3://jitroute/old{n}/cubes/weather.zarr"
        cycles = cube_on_s3(tmp_path, url, options, n, one_row_chunks=True)
        c, version = flow_host_open(url, options)
        assert c == cycles[-1] and version is not None
        assert cube.cycle_states(cube.locate(url, options)) == {c: cube.STATE_COMPLETE for c in cycles}
        later = cycles[-1] + np.timedelta64(6, "h")
        cube.write_cycle(url, cycle_ds(later), complete=True, lock_dir=tmp_path / "locks", storage_options=options)
        gets()
        assert flow_host_open(url, options)[0] == later
        bounded[n] = gets()
        assert list(xr.open_zarr(url, storage_options=options)["cycle"].values) == [*cycles, later]
    assert bounded[12] == bounded[3], f"GETs of one open after the next write: {bounded}"


@pytest.mark.slow
def test_a_rechunking_cut_short_hides_the_cycles_and_the_next_write_finishes_it(tmp_path, monkeypatch):
    store = tmp_path / "weather.zarr"
    cycles = [FIRST + np.timedelta64(6 * k, "h") for k in range(3)]
    for c in cycles:
        cube.write_cycle(store, cycle_ds(c), complete=True)
    to_one_row_chunks(store)
    real = zarr.Group.create_array

    def disk_full_after_creating_cycle_state(self, name, **kw):
        arr = real(self, name, **kw)
        if name == "cycle_state":  # created, its values not written yet
            raise OSError(28, "No space left on device")
        return arr

    later = cycles[-1] + np.timedelta64(6, "h")
    with monkeypatch.context() as m:
        m.setattr(zarr.Group, "create_array", disk_full_after_creating_cycle_state)
        with pytest.raises(cube.CubeError, match="No space left"):
            cube.write_cycle(store, cycle_ds(later), complete=True)
    assert cube.CYCLE_INDEX_MOVING in zarr.open_group(str(store), mode="r").attrs  # the values kept for the redo
    assert cube.complete_cycles(store) == []  # states lost meanwhile read as hidden: nothing half-known is used
    cube.write_cycle(store, cycle_ds(later), complete=True)
    assert cube.complete_cycles(store) == [*cycles, later]
    group = zarr.open_group(str(store), mode="r")
    assert cube.CYCLE_INDEX_MOVING not in group.attrs
    assert group["cycle"].chunks == group["cycle_state"].chunks == (cube.CYCLE_INDEX_ROWS,)
    assert list(xr.open_zarr(store)["cycle"].values) == [*cycles, later]  # the consolidated view is whole
