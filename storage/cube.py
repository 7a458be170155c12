"""The Zarr weather cube: dims (cycle, step, lat, lon), one cycle per region write.

Store contents (names, units and CF attributes from schemas/cube_variables.py):
  u10, v10  m/s   10 m wind (u east, v north)
  swh       m     significant wave height
  mwd       deg   mean wave direction, coming FROM
  mwp       s     mean wave period
  uo, vo    m/s   surface current, going TO (latest OSCAR analysis ≤ valid time)
  current_age_h (cycle, step)  age of that analysis in hours
  cycle_state   (cycle)        0 = being written (hidden), 1 = complete, 2 = incomplete (visible, flagged)
  coordinates: cycle (forecast_reference_time), step (forecast_period, a duration stored in whole hours),
               valid_time (cycle, step) = cycle + step, lat, lon (axes Y, X); none has a fill value

How writes stay idempotent and crash-safe:
1. Under an exclusive file lock (one writer per store; `<store>.lock` beside it), a new cycle is appended as an all-NaN
   template with `cycle_state = 0`; an existing cycle is first set back to 0.
2. Its data variables are written into that cycle's region.
3. `cycle_state` is set last. Readers only see cycles whose state is not 0, so a writer killed
   at any point leaves no partial cycle visible; the next write of the cycle repairs it.
The store itself is created as `<store>.creating` and renamed into place, so a writer killed while
creating it leaves no half store behind. Write failures (a full disk) raise CubeError; the cycle stays hidden.
A half-finished append (arrays of unequal length along `cycle`) is trimmed back on the next
write, or by a reader that meets it (after waiting for the lock, so never under a live writer). The time encoding of
`cycle` and `valid_time` is fixed ("hours since 2000-01-01", int64) so appended cycles never shift.
A store written before `valid_time` existed (step as plain hours, no CF axes) opens as it is (readers take `step`
through `cube_variables.step_hours`) and is upgraded in place, metadata only, by the next write.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import shutil
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import dask.array
import numpy as np
import xarray as xr
import zarr
from zarr.codecs import BloscCodec

from schemas import cube_variables as cv
from schemas.cube_variables import DATA_VARS, STATE_COMPLETE, STATE_HIDDEN, STATE_INCOMPLETE

CYCLE_ENCODING = {"units": "hours since 2000-01-01 00:00:00", "calendar": "proleptic_gregorian", "dtype": "int64"}
TIME_EPOCH = np.datetime64("2000-01-01T00", "ns")  # of CYCLE_ENCODING
STEP_ENCODING = {"units": "hours", "dtype": "int32"}
NO_FILL = {"_FillValue": None}  # CF: coordinates have no missing values
WRITE_WORKERS = 2
SPATIAL_SPLITS = 3  # chunks per spatial axis: (1, all steps, ≈ nlat/3, ≈ nlon/3), e.g. 107 × 240 on the 0.5° grid
# LZ4 after byte shuffle: about as small as zstd on smooth float32 fields, faster to write and ~3× faster to
# read (routing workers read the cube). Fixed when the store is created; appended cycles inherit it.
DATA_CODEC = BloscCodec(cname="lz4", clevel=5, shuffle="shuffle")


class CubeError(RuntimeError):
    pass


class CorruptChunkError(CubeError):
    """A chunk file of the cube cannot be decoded (damaged on disk); the message names it and the fix."""


METADATA_NODES = ("", *DATA_VARS, "cycle", "step", "lat", "lon", "cycle_state", "current_age_h")  # "" is the group
DECODE_ERRORS = (RuntimeError, ValueError, OSError, KeyError)  # what zarr/numcodecs raise for a damaged chunk


@contextlib.contextmanager
def writer_lock(lock_dir: Path | None, store: Path) -> Iterator[None]:
    """Exclusive lock per store (file `<lock_dir or store's folder>/<store name>.lock`)."""
    lock_dir = Path(lock_dir) if lock_dir is not None else Path(store).parent
    lock_dir.mkdir(parents=True, exist_ok=True)
    with open(lock_dir / (Path(store).name + ".lock"), "w") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def spatial_chunks(nlat: int, nlon: int) -> tuple[int, int]:
    """Chunk shape (lat, lon) tiling the grid in SPATIAL_SPLITS near-equal parts per axis: almost no padding in
    the edge chunks (fixed power-of-two chunks padded the 0.5° grid by 27 %) and few, MB-sized chunk files."""
    return -(-nlat // SPATIAL_SPLITS), -(-nlon // SPATIAL_SPLITS)


def _template(cycle_ds: xr.Dataset, cycle: np.datetime64) -> xr.Dataset:
    """One hidden all-NaN cycle. The data variables are lazy and written with `compute=False`: only their
    metadata goes to the store, and chunks never written read as the NaN fill value."""
    nstep, nlat, nlon = cycle_ds.sizes["step"], cycle_ds.sizes["lat"], cycle_ds.sizes["lon"]
    nan = dask.array.full((1, nstep, nlat, nlon), np.nan, dtype=np.float32, chunks=(1, nstep, *spatial_chunks(nlat, nlon)))
    data = {v: (cv.DIMS, nan.astype(cv.BY_NAME[v].dtype), cv.attrs(v)) for v in DATA_VARS}
    age, state = cv.CURRENT_AGE, cv.CYCLE_STATE
    data[age.name] = (age.dims, np.full((1, nstep), np.nan, age.dtype), cv.attrs(age.name))
    data[state.name] = (state.dims, np.array([STATE_HIDDEN], state.dtype), cv.attrs(state.name))
    step = cv.step_duration(cycle_ds["step"].values)
    return xr.Dataset(
        data,
        coords={
            "cycle": ("cycle", np.array([cycle], "datetime64[ns]"), cv.attrs("cycle")),
            "step": ("step", step, cv.attrs("step")),
            "valid_time": (("cycle", "step"), np.datetime64(cycle, "ns") + step[None, :], cv.attrs("valid_time")),
            "lat": ("lat", cycle_ds["lat"].values, cv.attrs("lat")),
            "lon": ("lon", cycle_ds["lon"].values, cv.attrs("lon")),
        },
        attrs={"title": "jitroute weather cube", "Conventions": "CF-1.8",
               "direction_conventions": "wind and waves coming-from; currents going-to"},
    )


def _encoding(ds: xr.Dataset) -> dict:
    nstep = ds.sizes["step"]
    enc = {v: {"chunks": (1, nstep, *spatial_chunks(ds.sizes["lat"], ds.sizes["lon"])), "compressors": (DATA_CODEC,)} for v in DATA_VARS}
    enc["cycle"] = CYCLE_ENCODING | NO_FILL
    enc["step"] = STEP_ENCODING | NO_FILL
    enc["valid_time"] = CYCLE_ENCODING | NO_FILL | {"chunks": (1, nstep)}
    enc["lat"] = enc["lon"] = dict(NO_FILL)
    enc["current_age_h"] = {"chunks": (1, nstep)}
    enc["cycle_state"] = {"chunks": (1,)}
    return enc


def _repair(path: Path) -> None:
    """Trim arrays left longer than the others along `cycle` by an append that was killed."""
    group = zarr.open_group(str(path), mode="r+")
    lengths = {name: arr.shape[0] for name, arr in group.arrays() if "cycle" in (arr.metadata.dimension_names or ())[:1]}
    if lengths and len(set(lengths.values())) > 1:
        n = min(lengths.values())
        for name, arr in group.arrays():
            if name in lengths and arr.shape[0] > n:
                arr.resize((n, *arr.shape[1:]))


def _cycles_in_store(path: Path) -> np.ndarray:
    with xr.open_zarr(path, consolidated=False) as ds:
        return ds["cycle"].values.astype("datetime64[ns]")


def _check_grid(path: Path, cycle_ds: xr.Dataset) -> None:
    with xr.open_zarr(path, consolidated=False) as ds:
        for c in ("step", "lat", "lon"):
            have, new = ((cv.step_hours(ds[c].values), cv.step_hours(cycle_ds[c].values)) if c == "step"
                         else (ds[c].values, cycle_ds[c].values))
            if ds.sizes[c] != cycle_ds.sizes[c] or not np.allclose(have, new):
                raise CubeError(f"{path}: the cycle's {c} axis differs from the cube's; regrid to the cube's grid first")


def write_cycle(path: Path, cycle_ds: xr.Dataset, *, complete: bool, lock_dir: Path | None = None) -> None:
    """Write one cycle (dims (step, lat, lon) + scalar `cycle`) idempotently and crash-safely.

    A failed write (e.g. a full disk) raises CubeError naming the store; the cycle stays hidden.
    """
    try:
        _write_cycle(Path(path), cycle_ds, complete=complete, lock_dir=lock_dir)
    except OSError as exc:
        label = np.datetime_as_string(np.datetime64(cycle_ds["cycle"].values, "h"), unit="h")
        raise CubeError(f"{path}: writing cycle {label} failed ({exc}); no part of it is visible. "
                        "Fix the cause (e.g. free space on the data root) and re-run the ingest") from exc


def _create_store(path: Path, tmpl: xr.Dataset) -> None:
    """Write the first template beside the store and rename it into place: the store exists whole or not
    at all. A creation killed half-way leaves only `<store>.creating`, removed by the next writer."""
    tmp = path.with_name(path.name + ".creating")
    shutil.rmtree(tmp, ignore_errors=True)
    tmpl.to_zarr(tmp, mode="w", encoding=_encoding(tmpl), consolidated=False, zarr_format=3, compute=False)
    os.replace(tmp, path)


def _write_cycle(path: Path, cycle_ds: xr.Dataset, *, complete: bool, lock_dir: Path | None) -> None:
    cycle = np.datetime64(cycle_ds["cycle"].values, "ns")
    missing = [v for v in DATA_VARS if v not in cycle_ds]
    if missing:
        raise CubeError(f"cycle {cycle} lacks variables {missing}")
    with writer_lock(lock_dir, path):
        damaged = metadata_problems(path) if path.exists() else []
        if damaged:
            raise CubeError(f"{path}: the store is damaged ({'; '.join(damaged)}); nothing was written. Run "
                            "`jitroute cube check`, then `jitroute cube repair` (moves the store aside) and re-ingest")
        if not (path / "zarr.json").exists():
            path.parent.mkdir(parents=True, exist_ok=True)
            _create_store(path, _template(cycle_ds, cycle))
            index = 0
        else:
            _repair(path)
            _upgrade(path)
            _check_grid(path, cycle_ds)
            cycles = _cycles_in_store(path)
            hits = np.flatnonzero(cycles == cycle)
            if hits.size:
                index = int(hits[0])
                _set_state(path, index, STATE_HIDDEN)
            else:
                _template(cycle_ds, cycle).to_zarr(path, append_dim="cycle", consolidated=False, compute=False)
                index = cycles.size
        _write_region(path, index, cycle_ds)
        _set_state(path, index, STATE_COMPLETE if complete else STATE_INCOMPLETE)


def _valid_time_hours(cycle: np.datetime64, step) -> np.ndarray:
    """valid_time = cycle + step as stored (CYCLE_ENCODING: int64 hours since TIME_EPOCH)."""
    return ((np.datetime64(cycle, "ns") + cv.step_duration(step)) - TIME_EPOCH) // np.timedelta64(1, "h")


def _upgrade(path: Path) -> None:
    """Bring a store written before `valid_time` existed up to the current layout, in place: CF attributes on the
    coordinates and bookkeeping variables, lat/lon without a fill value, a `valid_time` array for the cycles
    already stored, and last the attribute that makes `step` read as a duration (the mark of an upgraded store,
    so an upgrade killed half-way is redone by the next write). Data chunks are not touched."""
    group = zarr.open_group(str(path), mode="r+")
    step = group["step"]
    if "dtype" in step.attrs:
        return
    hours = group["cycle"][:][:, None] + step[:].astype(np.int64)[None, :]  # both in hours since TIME_EPOCH
    valid = group.create_array("valid_time", shape=hours.shape, chunks=(1, hours.shape[1]), dtype="int64",
                               dimension_names=("cycle", "step"), overwrite=True,
                               attributes=cv.attrs("valid_time") | {k: CYCLE_ENCODING[k] for k in ("units", "calendar")})
    if hours.size:
        valid[:] = hours
    for name in (*DATA_VARS, cv.CURRENT_AGE.name):
        group[name].attrs["coordinates"] = "valid_time"
    for name in ("cycle", "lat", "lon", cv.CURRENT_AGE.name, cv.CYCLE_STATE.name):
        group[name].attrs.update({k: v.tolist() if isinstance(v, np.ndarray) else v for k, v in cv.attrs(name).items()})
    for name in ("lat", "lon"):
        group[name].attrs.pop("_FillValue", None)
    step.attrs.update(cv.attrs("step") | {"dtype": "timedelta64[ns]"})  # xarray decodes a duration by this


def _write_region(path: Path, index: int, cycle_ds: xr.Dataset) -> None:
    """Write the cycle's values into row `index` of every array, straight through zarr (the metadata,
    coordinates and encodings are already in the store): the float32 arrays go in as they are, no copy,
    WRITE_WORKERS variables at a time (Blosc compresses without holding the GIL)."""
    group = zarr.open_group(str(path), mode="r+")
    group["valid_time"][index] = _valid_time_hours(np.datetime64(cycle_ds["cycle"].values, "ns"), cycle_ds["step"].values)
    age = (np.asarray(cycle_ds["current_age_h"].values, np.float32) if "current_age_h" in cycle_ds
           else np.full(cycle_ds.sizes["step"], np.nan, np.float32))
    group["current_age_h"][index] = age

    def put(v: str) -> None:
        group[v][index] = np.asarray(cycle_ds[v].transpose("step", "lat", "lon").values, dtype=np.float32)

    with ThreadPoolExecutor(WRITE_WORKERS, thread_name_prefix="cube-write") as pool:
        list(pool.map(put, DATA_VARS))  # re-raises the first failure (e.g. a full disk)


def _set_state(path: Path, index: int, state: int) -> None:
    arr = zarr.open_array(str(path / "cycle_state"), mode="r+")
    arr[index] = state


def _open_consistent(path: Path, lock_dir: Path | None) -> xr.Dataset:
    try:
        return xr.open_zarr(path, consolidated=False, chunks={})
    except ValueError as exc:
        if "conflicting sizes" not in str(exc):
            raise
    # A writer was killed mid-append (or is appending right now): wait for the lock, trim, reopen.
    with writer_lock(lock_dir, path):
        _repair(path)
    return xr.open_zarr(path, consolidated=False, chunks={})


def open_cube(path: Path, *, include_incomplete: bool = True, lock_dir: Path | None = None) -> xr.Dataset:
    """Lazy (dask) view of every visible cycle, sorted by cycle."""
    path = Path(path)
    if path.exists() and not (path / "zarr.json").exists():
        raise CubeError(f"{path}: the store is damaged ({'; '.join(metadata_problems(path))}): run `jitroute cube check`, "
                        "then `jitroute cube repair`")
    if not (path / "zarr.json").exists():
        raise FileNotFoundError(f"no weather cube at {path}: run `jitroute ingest` (or `jitroute demo`) first")
    ds = _open_consistent(path, lock_dir)
    state = ds["cycle_state"].values
    keep = state == STATE_COMPLETE if not include_incomplete else state != STATE_HIDDEN
    ds = ds.isel(cycle=np.flatnonzero(keep))
    return ds.sortby("cycle")


def cycle_states(path: Path, lock_dir: Path | None = None) -> dict[np.datetime64, int]:
    path = Path(path)
    if not (path / "zarr.json").exists():
        return {}
    with _open_consistent(path, lock_dir) as ds:
        return dict(zip(ds["cycle"].values.astype("datetime64[ns]"), ds["cycle_state"].values.astype(int)))


def complete_cycles(path: Path) -> list[np.datetime64]:
    return sorted(c for c, s in cycle_states(path).items() if s == STATE_COMPLETE)


def latest_complete_cycle(path: Path, at_or_before=None) -> np.datetime64 | None:
    cycles = complete_cycles(path)
    if at_or_before is not None:
        limit = np.datetime64(at_or_before, "ns")
        cycles = [c for c in cycles if c <= limit]
    return cycles[-1] if cycles else None


def load_cycle(path: Path, cycle, lat_range_deg: tuple[float, float] | None = None) -> xr.Dataset:
    """One visible cycle, eager, dims (step, lat, lon); only the latitude band `lat_range_deg` if given.

    A chunk damaged on disk raises CorruptChunkError naming the chunk, the cycle and the re-ingest that fixes it.
    """
    ds = open_cube(path)
    c = np.datetime64(cycle, "ns")
    if c not in ds["cycle"].values:
        raise KeyError(f"cycle {c} is not in the cube at {path} (have {len(ds.cycle)} cycles)")
    one = ds.sel(cycle=c)
    if lat_range_deg is not None:
        lo, hi = sorted(lat_range_deg)
        one = one.sel(lat=slice(lo, hi)) if one.lat.values[0] < one.lat.values[-1] else one.sel(lat=slice(hi, lo))
    try:
        return one.load()
    except DECODE_ERRORS as exc:
        bad = [p for p in corrupt_chunks(path, cycles=[c])] or None
        label = np.datetime_as_string(np.datetime64(c, "h"), unit="h")
        where = ", ".join(str(p.chunk) for p in bad[:3]) if bad else f"(reading failed: {exc})"
        raise CorruptChunkError(f"cube chunk {where} of cycle {label} is corrupt ({type(exc).__name__}: {exc}): "
                                f"run `jitroute ingest --cycle {label} --force`") from exc


# --- checking and repairing a store damaged on disk ---------------------------------------------------------------


def metadata_problems(path: Path) -> list[str]:
    """What is missing or unreadable among the store's metadata files (`zarr.json` of the group and arrays)."""
    import json

    out = []
    for node in METADATA_NODES:
        meta = Path(path) / node / "zarr.json" if node else Path(path) / "zarr.json"
        if not meta.exists():
            out.append(f"{meta.relative_to(Path(path).parent)} is missing")
            continue
        try:
            json.loads(meta.read_text())
        except (OSError, ValueError) as exc:
            out.append(f"{meta.relative_to(Path(path).parent)} is unreadable ({exc})")
    return out


class BadChunk:
    """One chunk that does not decode: `chunk` is its file, `variable` and `cycle` what it holds."""

    def __init__(self, chunk: Path, variable: str, cycle: np.datetime64, error: str):
        self.chunk, self.variable, self.cycle, self.error = chunk, variable, cycle, error

    def __repr__(self) -> str:
        return f"BadChunk({self.chunk}, {self.variable}, {self.cycle})"


def corrupt_chunks(path: Path, cycles: list | None = None) -> list[BadChunk]:
    """Decode every chunk of the data variables (of `cycles`, default all) and list those that fail."""
    path = Path(path)
    group = zarr.open_group(str(path), mode="r")
    times = xr.open_zarr(path, consolidated=False, chunks={})["cycle"].values.astype("datetime64[ns]")
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
                        bad.append(BadChunk(path / v / "c" / str(i) / "0" / str(j) / str(k), v, times[i],
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


def move_aside(path: Path, lock_dir: Path | None = None) -> Path:
    """Move a damaged store to `<store>.damaged-<UTC time>` (kept for inspection), under the writer lock, and
    remove a `<store>.creating` left by a failed creation; the next ingest creates a fresh store."""
    import time

    path = Path(path)
    with writer_lock(lock_dir, path):
        shutil.rmtree(path.with_name(path.name + ".creating"), ignore_errors=True)
        aside = path.with_name(f"{path.name}.damaged-{time.strftime('%Y%m%dT%H%M%S', time.gmtime())}")
        os.replace(path, aside)
    return aside


def hide_cycles(path: Path, cycles: list, lock_dir: Path | None = None) -> None:
    """Set the cycles back to hidden (readers stop seeing them) until a re-ingest writes them again."""
    path = Path(path)
    with writer_lock(lock_dir, path):
        times = _cycles_in_store(path)
        for c in cycles:
            for i in np.flatnonzero(times == np.datetime64(c, "ns")):
                _set_state(path, int(i), STATE_HIDDEN)
