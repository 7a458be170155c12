"""What is damaged in a weather cube on disk: missing or unreadable metadata, chunks that do not decode, and the
errors that name them with the command that repairs them. Reading only; the repairs (moving a store aside, hiding
cycles) are writes, in storage/cube.py."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import zarr

from schemas.cube_variables import DATA_VARS
from storage.cube_location import DECODE_ERRORS, CorruptChunkError, CubeError, Location, locate

METADATA_NODES = ("", *DATA_VARS, "cycle", "step", "lat", "lon", "cycle_state", "current_age_h")  # "" is the group


def cycles_in_store(loc: Location) -> np.ndarray:
    """The store's cycle axis (every row, hidden ones included) as datetime64[ns]."""
    import xarray as xr  # here: routing workers import this module for its errors and never load xarray

    with xr.open_zarr(loc.zarr_store(read_only=True), consolidated=False) as ds:
        return ds["cycle"].values.astype("datetime64[ns]")


def require_store(loc: Location) -> None:
    """Nothing when the store's group metadata is there; else CubeError naming what is damaged (a local folder
    without it), or FileNotFoundError saying the store is missing and how to make one."""
    has_meta = loc.has("zarr.json")
    if loc.local is not None and loc.local.exists() and not has_meta:
        raise CubeError(f"{loc.url}: the store is damaged ({'; '.join(metadata_problems(loc))}): run `jitroute cube check`, "
                        "then `jitroute cube repair`")
    if not has_meta:
        raise FileNotFoundError(f"no weather cube at {loc.url}: run `jitroute ingest` (or `jitroute demo`) first")


def corrupt_chunk_error(loc: Location, c: np.datetime64, exc: Exception) -> CorruptChunkError:
    """The error for a read of cycle `c` that failed with `exc`: the damaged chunks found, and the re-ingest."""
    bad = [p for p in corrupt_chunks(loc, cycles=[c])] or None
    label = np.datetime_as_string(np.datetime64(c, "h"), unit="h")
    where = ", ".join(str(p.chunk) for p in bad[:3]) if bad else f"(reading failed: {exc})"
    return CorruptChunkError(f"cube chunk {where} of cycle {label} is corrupt ({type(exc).__name__}: {exc}): "
                             f"run `jitroute ingest --cycle {label} --force`")


def metadata_problems(path) -> list[str]:
    """What is missing or unreadable among the store's metadata files (`zarr.json` of the group and arrays)."""
    loc = locate(path)
    out = []
    for node in METADATA_NODES:
        key = f"{node}/zarr.json" if node else "zarr.json"
        if not loc.has(key):
            out.append(f"{loc.name}/{key} is missing")
            continue
        try:
            json.loads(loc.read_text(key))
        except (OSError, ValueError) as exc:
            out.append(f"{loc.name}/{key} is unreadable ({exc})")
    return out


class BadChunk:
    """One chunk that does not decode: `chunk` is its file, `variable` and `cycle` what it holds."""

    def __init__(self, chunk: Path | str, variable: str, cycle: np.datetime64, error: str):
        self.chunk, self.variable, self.cycle, self.error = chunk, variable, cycle, error

    def __repr__(self) -> str:
        return f"BadChunk({self.chunk}, {self.variable}, {self.cycle})"


def corrupt_chunks(path, cycles: list | None = None, storage_options: dict | None = None) -> list[BadChunk]:
    """Decode every chunk of the data variables (of `cycles`, default all) and list those that fail."""
    loc = locate(path, storage_options)
    group = zarr.open_group(loc.zarr_store(read_only=True), mode="r", use_consolidated=False)
    times = cycles_in_store(loc)
    wanted = range(len(times)) if cycles is None else [int(i) for c in cycles for i in np.flatnonzero(times == np.datetime64(c, "ns"))]
    bad = []
    for v in DATA_VARS:
        arr = group[v]
        _, _, clat, clon = arr.chunks
        nlat, nlon = arr.shape[2], arr.shape[3]
        for i in wanted:
            for j in range(-(-nlat // clat)):
                for k in range(-(-nlon // clon)):
                    try:
                        arr[i, :, j * clat:(j + 1) * clat, k * clon:(k + 1) * clon]
                    except DECODE_ERRORS as exc:
                        key = f"{v}/c/{i}/0/{j}/{k}"
                        bad.append(BadChunk(loc.local / key if loc.local is not None else f"{loc.url}/{key}", v, times[i],
                                            f"{type(exc).__name__}: {exc}"))
    return bad


def check_store(path: Path) -> tuple[list[str], list[BadChunk]]:
    """(metadata problems, corrupt chunks) of the store; chunks are only read when the metadata is whole."""
    path = Path(path)
    meta = metadata_problems(path)
    if meta:
        return meta, []
    try:
        return [], corrupt_chunks(path)
    except DECODE_ERRORS as exc:  # e.g. the cycle axis itself does not decode
        return [f"{path.name}: the store cannot be read ({type(exc).__name__}: {exc})"], []
