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
  `cycle` and `cycle_state` hold CYCLE_INDEX_ROWS rows per chunk, so listing the cycles and their states is one
  read of each, whatever the number of cycles (on S3 the flow host's open costs the same GETs for a year of cycles
  as for a day); a store written with one chunk per row is rechunked in place by its next write.

Where it lives: a local path, or a URL (`s3://bucket/…/weather.zarr` through s3fs, `file://…`) with fsspec
`storage_options` (for S3 e.g. {"endpoint_url": …, "key": …, "secret": …}). One writer per store (the ingest of the
flow process) under an exclusive fcntl lock: `<store>.lock` beside a local store, in the given `lock_dir` (the
data root's `locks/`) for a URL.

How writes stay idempotent and crash-safe:
1. Under the writer lock, a new cycle is appended as an all-NaN hidden row (`cycle_state = 0`), array by array
   through zarr; an existing cycle is first set back to 0.
2. Its data variables are written into that cycle's region.
3. `cycle_state` is set, then the cycle is published (below). Readers that know `cycle_state` only see cycles
   whose state is not 0, so a writer killed at any point leaves no partial cycle visible; the next write of the
   cycle repairs it.
A local store is created as `<store>.creating` and renamed into place, so a writer killed while creating it leaves
no half store behind; an object store has no rename: it is created in place under the lock and readers ignore it
until its first publication. Write failures (a full disk) raise CubeError; the cycle stays hidden.
A half-finished append (arrays of unequal length along `cycle`) is trimmed back on the next
write, or by a reader that meets it (after waiting for the lock, so never under a live writer). The time encoding of
`cycle` and `valid_time` is fixed ("hours since 2000-01-01", int64) so appended cycles never shift.
A store written before `valid_time` existed (step as plain hours, no CF axes) opens as it is (readers take `step`
through `cube_variables.step_hours`) and is upgraded in place, metadata only, by the next write.

Publication, for readers that know nothing of `cycle_state` (a plain `xr.open_zarr(store)`): the Zarr
consolidated metadata in the root `zarr.json` is the publication point. It is rewritten (one atomic write: a
rename on a local disk, one PUT on S3) only when a cycle becomes visible, together with the root attribute
`cycle_versions` (ISO cycle → content version, a new one at every write of the cycle). Until then a consolidated
reader keeps the array shapes of the last publication, so it does not see a cycle being appended (its chunks
lie past those shapes), and `xr.open_zarr` opens the store without a warning. Appends therefore go through zarr
array by array (xarray's append rewrites the root metadata, dropping the consolidated view). The published view
is what routing workers read (storage/cube_window.py), one metadata read per store even on S3.
The hard case is the in-place re-write of an existing cycle (`ingest --force`, or incomplete → complete): its
chunks are overwritten where they are, so while it runs a plain reader may read a mix of old and new chunks of
that cycle (the `cycle_state` it can read says 0, hidden, but a plain reader does not look). Readers that know
`cycle_state` never see it, and workers key their caches on the content version, so they read the new values
as soon as it is published. Writing the new values to a fresh row and swapping would make the cycle axis
carry duplicates for plain readers; not done.
Icechunk (transactional commits and snapshots over the same object store) would make every write, the
re-write included, atomic for every reader of its repository, but only for readers that open it through
Icechunk, not for a plain `xr.open_zarr` of the Zarr store; it would replace the lock and the state bookkeeping
with its own and add a dependency. Not adopted: consolidated metadata gives plain readers what they need short
of the re-write case above.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import shutil
import time
import warnings
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import dask.array  # imported here, not in a writer thread: concurrent first imports of dask fail
import numpy as np
import xarray as xr
import zarr
from zarr.codecs import BloscCodec

from schemas import cube_variables as cv
from schemas.cube_variables import DATA_VARS, STATE_COMPLETE, STATE_HIDDEN, STATE_INCOMPLETE
from storage.cube_location import DECODE_ERRORS, CubeError, Location, fs_options, locate
from storage.cube_damage import corrupt_chunk_error, cycles_in_store, metadata_problems, require_store
from storage.cube_window import cycle_times
from storage.cube_window import cycle_versions  # noqa: F401  (zarr alone; flows ask the cube module for it)

CYCLE_ENCODING = {"units": "hours since 2000-01-01 00:00:00", "calendar": "proleptic_gregorian", "dtype": "int64"}
TIME_EPOCH = np.datetime64("2000-01-01T00", "ns")  # of CYCLE_ENCODING
STEP_ENCODING = {"units": "hours", "dtype": "int32"}
NO_FILL: dict[str, object] = {"_FillValue": None}  # CF: coordinates have no missing values
WRITE_WORKERS = 2
# Chunks per spatial axis: (1, all steps, ≈ nlat/8, ≈ nlon/8), e.g. 41 × 90 (20.5° × 45°) on the 0.5° grid.
# Chosen by bench/cube_chunks.py on the demo fleet's 200 voyage windows: against 3 splits (107 × 240) a voyage's
# first read fetches 0.71 MB instead of 4.6 MB in as many chunk files (12) and costs 6.7 instead of 20.5 ms CPU;
# 16 splits fetch a little less (0.42 MB) but in twice the files (22 GETs on S3) for no less CPU.
SPATIAL_SPLITS = 8
# LZ4 after byte shuffle: about as small as zstd on smooth float32 fields, faster to write and ~3× faster to
# read (routing workers read the cube). Fixed when the store is created; appended cycles inherit it.
DATA_CODEC = BloscCodec(cname="lz4", clevel=5, shuffle="shuffle")
# Rows of the per-cycle index arrays (`cycle`, `cycle_state`) per chunk: listing the cycles and their states is one
# read of each whatever the archive's length (one chunk per row cost 2 GETs per cycle ever written on S3). Rows are
# never removed (retention empties them), so this is ~45 years of 4 cycles a day; the chunks stay a few kB stored.
CYCLE_INDEX_ROWS = 1 << 16
CYCLE_INDEX_ARRAYS = ("cycle", "cycle_state")
CYCLE_INDEX_MOVING = "cycle_index_moving"  # root attribute: the index values while _rechunk_cycle_index moves them




@contextlib.contextmanager
def writer_lock(lock_dir: Path | None, store) -> Iterator[None]:
    """Exclusive lock per store (file `<lock_dir or store's folder>/<store name>.lock`). A store at a URL has no
    folder to lock in: its lock lives in `lock_dir` (the data root's `locks/`), on the one host that writes."""
    loc = locate(store)
    if lock_dir is None:
        if loc.local is None:
            raise CubeError(f"{loc.url}: a cube at a URL is written under a local lock; give its lock_dir")
        lock_dir = loc.local.parent
    lock_dir = Path(lock_dir)
    lock_dir.mkdir(parents=True, exist_ok=True)
    with open(lock_dir / (loc.name + ".lock"), "w") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def spatial_chunks(nlat: int, nlon: int) -> tuple[int, int]:
    """Chunk shape (lat, lon) tiling the grid in SPATIAL_SPLITS near-equal parts per axis: almost no padding in
    the edge chunks (fixed power-of-two chunks padded the 0.5° grid by 27 %) and few, MB-sized chunk files."""
    return -(-nlat // SPATIAL_SPLITS), -(-nlon // SPATIAL_SPLITS)


def _template(cycle_ds: xr.Dataset, cycle: np.datetime64, chunks: tuple[int, int, int] | None = None) -> xr.Dataset:
    """One hidden all-NaN cycle. The data variables are lazy and written with `compute=False`: only their
    metadata goes to the store, and chunks never written read as the NaN fill value."""
    nstep, nlat, nlon = cycle_ds.sizes["step"], cycle_ds.sizes["lat"], cycle_ds.sizes["lon"]
    nan = dask.array.full((1, nstep, nlat, nlon), np.nan, dtype=np.float32,
                          chunks=(1, *(chunks or (nstep, *spatial_chunks(nlat, nlon)))))
    data: dict[str, tuple] = {v: (cv.DIMS, nan.astype(cv.BY_NAME[v].dtype), cv.attrs(v)) for v in DATA_VARS}
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
    chunks = tuple(ds[DATA_VARS[0]].data.chunksize)  # the template's: (1, steps, lat, lon)
    enc: dict[str, dict] = {v: {"chunks": chunks, "compressors": (DATA_CODEC,)} for v in DATA_VARS}
    enc["cycle"] = CYCLE_ENCODING | NO_FILL | {"chunks": (CYCLE_INDEX_ROWS,)}
    enc["step"] = STEP_ENCODING | NO_FILL
    enc["valid_time"] = CYCLE_ENCODING | NO_FILL | {"chunks": (1, nstep)}
    enc["lat"] = enc["lon"] = dict(NO_FILL)
    enc["current_age_h"] = {"chunks": (1, nstep)}
    enc["cycle_state"] = {"chunks": (CYCLE_INDEX_ROWS,)}
    return enc


def _repair(loc: Location) -> None:
    """Trim arrays left longer than the others along `cycle` by an append that was killed."""
    group = zarr.open_group(loc.zarr_store(), mode="r+", use_consolidated=False)
    lengths = {name: arr.shape[0] for name, arr in group.arrays() if "cycle" in (arr.metadata.dimension_names or ())[:1]}
    if lengths and len(set(lengths.values())) > 1:
        n = min(lengths.values())
        for name, arr in group.arrays():
            if name in lengths and arr.shape[0] > n:
                arr.resize((n, *arr.shape[1:]))


def _check_grid(loc: Location, cycle_ds: xr.Dataset) -> None:
    with xr.open_zarr(loc.zarr_store(read_only=True), consolidated=False) as ds:
        for c in ("step", "lat", "lon"):
            have, new = ((cv.step_hours(ds[c].values), cv.step_hours(cycle_ds[c].values)) if c == "step"
                         else (ds[c].values, cycle_ds[c].values))
            if ds.sizes[c] != cycle_ds.sizes[c] or not np.allclose(have, new):
                raise CubeError(f"{loc.url}: the cycle's {c} axis differs from the cube's; regrid to the cube's grid first")


def write_cycle(path, cycle_ds: xr.Dataset, *, complete: bool, lock_dir: Path | None = None,
                storage_options: dict | None = None, chunks: tuple[int, int, int] | None = None) -> None:
    """Write one cycle (dims (step, lat, lon) + scalar `cycle`) idempotently and crash-safely, then publish it.

    `path` is a local path or a URL (`s3://bucket/…/weather.zarr`, with fsspec `storage_options`; its writer lock
    then lives in `lock_dir`). A failed write (e.g. a full disk) raises CubeError naming the store; the cycle stays
    hidden. `chunks`: the (step, lat, lon) chunk shape of a store this write creates (default: all steps,
    spatial_chunks); a store keeps the chunking it was created with.
    """
    loc = locate(path, storage_options)
    try:
        _write_cycle(loc, cycle_ds, complete=complete, lock_dir=lock_dir, chunks=chunks)
    except OSError as exc:
        label = np.datetime_as_string(np.datetime64(cycle_ds["cycle"].values, "h"), unit="h")
        raise CubeError(f"{loc.url}: writing cycle {label} failed ({exc}); no part of it is visible. "
                        "Fix the cause (e.g. free space on the data root) and re-run the ingest") from exc


def _create_store(loc: Location, tmpl: xr.Dataset) -> None:
    """Create the store with its first (hidden) cycle. On a local path it is written beside the store and renamed
    into place: the store exists whole or not at all, and a creation killed half-way leaves only `<store>.creating`,
    removed by the next writer. An object store has no rename: it is written in place under the writer lock, and
    readers ignore it until its first publication (no consolidated metadata before)."""
    if loc.local is None:
        tmpl.to_zarr(loc.zarr_store(), mode="w", encoding=_encoding(tmpl), consolidated=False, zarr_format=3,
                     compute=False)
        return
    loc.local.parent.mkdir(parents=True, exist_ok=True)
    tmp = loc.local.with_name(loc.local.name + ".creating")
    shutil.rmtree(tmp, ignore_errors=True)
    tmpl.to_zarr(tmp, mode="w", encoding=_encoding(tmpl), consolidated=False, zarr_format=3, compute=False)
    os.replace(tmp, loc.local)


def _append_hidden(loc: Location, tmpl: xr.Dataset) -> int:
    """Grow every array along `cycle` by the template's one hidden cycle; returns its index. Written through zarr,
    array by array: the group's own metadata (with the published view) is left as it is, so plain readers keep
    seeing the published cycles only. Data chunks never written read as the NaN fill value."""
    group = zarr.open_group(loc.zarr_store(), mode="r+", use_consolidated=False)
    index = group["cycle"].shape[0]
    for name, arr in group.arrays():
        if "cycle" not in (arr.metadata.dimension_names or ())[:1]:
            continue
        arr.resize((index + 1, *arr.shape[1:]))
        data = tmpl[name].variable.data
        if isinstance(data, np.ndarray):  # coordinates, state and age; the data variables stay at the fill value
            arr[index] = (_encoded_times(data, arr) if np.issubdtype(data.dtype, np.datetime64) else data)[0]
    return index


def _encoded_times(values: np.ndarray, arr) -> np.ndarray:
    """Datetimes in the stored encoding of `arr` (its `units`/`calendar` attributes, e.g. hours since 2000)."""
    from xarray.coding.times import encode_cf_datetime

    encoded, _, _ = encode_cf_datetime(values, arr.attrs["units"], arr.attrs.get("calendar"), dtype=arr.dtype)
    return encoded


def _write_cycle(loc: Location, cycle_ds: xr.Dataset, *, complete: bool, lock_dir: Path | None,
                 chunks: tuple[int, int, int] | None = None) -> None:
    cycle = np.datetime64(cycle_ds["cycle"].values, "ns")
    missing = [v for v in DATA_VARS if v not in cycle_ds]
    if missing:
        raise CubeError(f"cycle {cycle} lacks variables {missing}")
    with writer_lock(lock_dir, loc):
        exists = loc.local.exists() if loc.local is not None else loc.has("zarr.json")
        damaged = metadata_problems(loc) if exists else []
        if damaged:
            raise CubeError(f"{loc.url}: the store is damaged ({'; '.join(damaged)}); nothing was written. Run "
                            "`jitroute cube check`, then `jitroute cube repair` (moves the store aside) and re-ingest")
        if not loc.has("zarr.json"):
            _create_store(loc, _template(cycle_ds, cycle, chunks))
            index = 0
        else:
            _repair(loc)
            _upgrade(loc)
            _rechunk_cycle_index(loc)
            _check_grid(loc, cycle_ds)
            cycles = cycles_in_store(loc)
            hits = np.flatnonzero(cycles == cycle)
            if hits.size:
                index = int(hits[0])
                _set_state(loc, index, STATE_HIDDEN)
            else:
                index = _append_hidden(loc, _template(cycle_ds, cycle))
        _write_region(loc, index, cycle_ds)
        _set_state(loc, index, STATE_COMPLETE if complete else STATE_INCOMPLETE)
        _publish(loc, cycle)


def _valid_time_hours(cycle: np.datetime64, step) -> np.ndarray:
    """valid_time = cycle + step as stored (CYCLE_ENCODING: int64 hours since TIME_EPOCH)."""
    return ((np.datetime64(cycle, "ns") + cv.step_duration(step)) - TIME_EPOCH) // np.timedelta64(1, "h")


def _upgrade(loc: Location) -> None:
    """Bring a store written before `valid_time` existed up to the current layout, in place: CF attributes on the
    coordinates and bookkeeping variables, lat/lon without a fill value, a `valid_time` array for the cycles
    already stored, and last the attribute that makes `step` read as a duration (the mark of an upgraded store,
    so an upgrade killed half-way is redone by the next write). Data chunks are not touched."""
    group = zarr.open_group(loc.zarr_store(), mode="r+", use_consolidated=False)
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


def _rechunk_cycle_index(loc: Location) -> None:
    """Give `cycle` and `cycle_state` of a store written with one chunk per cycle row CYCLE_INDEX_ROWS rows per
    chunk, in place, values and attributes kept, then republish (the consolidated metadata holds the chunk shape).
    Crash-safe: the values are first kept in the root attribute CYCLE_INDEX_MOVING (one atomic write of the root
    `zarr.json`), the arrays are rewritten from it, and it is dropped last; a write killed in between leaves it, and
    the next write redoes the move from it. Meanwhile (a few small writes, once per store) a reader may find an index
    array being replaced; the flows read the cube after the ingest, not during it."""
    group = zarr.open_group(loc.zarr_store(), mode="r+", use_consolidated=False)
    moving = group.attrs.get(CYCLE_INDEX_MOVING)
    if moving is None:
        if all(group[name].chunks[0] >= CYCLE_INDEX_ROWS for name in CYCLE_INDEX_ARRAYS):
            return
        moving = {name: np.asarray(group[name][:]).tolist() for name in CYCLE_INDEX_ARRAYS}
        zarr.open_group(loc.zarr_store(), mode="r+").attrs[CYCLE_INDEX_MOVING] = moving  # keeps the published view
    for name, values in moving.items():
        arr = group[name]
        new = group.create_array(name, shape=(len(values),), chunks=(CYCLE_INDEX_ROWS,), dtype=arr.dtype,
                                 dimension_names=arr.metadata.dimension_names, attributes=arr.attrs.asdict(),
                                 fill_value=arr.metadata.fill_value, compressors=arr.compressors, overwrite=True)
        if values:
            new[:] = np.asarray(values, arr.dtype)
    root = zarr.open_group(loc.zarr_store(), mode="r+")
    del root.attrs[CYCLE_INDEX_MOVING]
    _consolidate(loc)


def _write_region(loc: Location, index: int, cycle_ds: xr.Dataset) -> None:
    """Write the cycle's values into row `index` of every array, straight through zarr (the metadata,
    coordinates and encodings are already in the store): the float32 arrays go in as they are, no copy,
    WRITE_WORKERS variables at a time (Blosc compresses without holding the GIL)."""
    group = zarr.open_group(loc.zarr_store(), mode="r+", use_consolidated=False)
    group["valid_time"][index] = _valid_time_hours(np.datetime64(cycle_ds["cycle"].values, "ns"), cycle_ds["step"].values)
    age = (np.asarray(cycle_ds["current_age_h"].values, np.float32) if "current_age_h" in cycle_ds
           else np.full(cycle_ds.sizes["step"], np.nan, np.float32))
    group["current_age_h"][index] = age

    def put(v: str) -> None:
        group[v][index] = np.asarray(cycle_ds[v].transpose("step", "lat", "lon").values, dtype=np.float32)

    with ThreadPoolExecutor(WRITE_WORKERS, thread_name_prefix="cube-write") as pool:
        list(pool.map(put, DATA_VARS))  # re-raises the first failure (e.g. a full disk)


def _set_state(loc: Location, index: int, state: int) -> None:
    group = zarr.open_group(loc.zarr_store(), mode="r+", use_consolidated=False)
    group["cycle_state"][index] = state


def _publish(loc: Location, cycle: np.datetime64) -> None:
    """Make the store's present shape the published view: give the cycle a new content version (root attribute
    `cycle_versions`, ISO cycle → int, nanoseconds since 1970 at publication, always increasing), then rewrite the
    consolidated metadata. Each is one atomic write of the root `zarr.json`. The root attribute `cycle_rows`
    (ISO cycle → row) lets readers open the newest cycle without reading the `cycle` coordinate (one chunk per
    cycle: its cost would grow with the archive). `cycle` None republishes without a new version (retention)."""
    group = zarr.open_group(loc.zarr_store(), mode="r+")
    versions = dict(group.attrs.get("cycle_versions", {}))
    if cycle is not None:
        label = _version_label(cycle)
        versions[label] = max(time.time_ns(), int(versions.get(label, 0)) + 1)
    group.attrs.update({"cycle_versions": versions, "cycle_rows": _cycle_rows(loc, versions)})
    _consolidate(loc)


def _cycle_rows(loc: Location, versions: dict) -> dict:
    """ISO cycle → its row along `cycle`, for the cycles that have a content version (published, not retired):
    readers find a cycle's row from the root metadata without reading the `cycle` coordinate."""
    labels = [_version_label(c) for c in cycles_in_store(loc)]
    return {lab: row for row, lab in enumerate(labels) if lab in versions}


def _consolidate(loc: Location) -> None:
    with warnings.catch_warnings():  # zarr notes that consolidated metadata is not in the Zarr 3 spec (yet)
        warnings.filterwarnings("ignore", message="Consolidated metadata is currently not part", category=UserWarning)
        zarr.consolidate_metadata(loc.zarr_store())


def _version_label(cycle) -> str:
    return str(np.datetime_as_string(np.datetime64(cycle, "s"), unit="s"))


def _open_consistent(loc: Location, lock_dir: Path | None) -> xr.Dataset:
    try:
        return xr.open_zarr(loc.zarr_store(read_only=True), consolidated=False, chunks={})
    except ValueError as exc:
        if "conflicting sizes" not in str(exc):
            raise
    # A writer was killed mid-append (or is appending right now): wait for the lock, trim, reopen.
    with writer_lock(lock_dir, loc):
        _repair(loc)
    return xr.open_zarr(loc.zarr_store(read_only=True), consolidated=False, chunks={})


def open_cube(path, *, include_incomplete: bool = True, lock_dir: Path | None = None,
              storage_options: dict | None = None) -> xr.Dataset:
    """Lazy (dask) view of every visible cycle, sorted by cycle."""
    loc = locate(path, storage_options)
    require_store(loc)
    ds = _open_consistent(loc, lock_dir)
    state = ds["cycle_state"].values
    keep = state == STATE_COMPLETE if not include_incomplete else state != STATE_HIDDEN
    ds = ds.isel(cycle=np.flatnonzero(keep))
    ds.attrs.pop("cycle_versions", None)  # the publications' bookkeeping, read with cycle_versions()
    return ds.sortby("cycle")


def cycle_states(path, lock_dir: Path | None = None, storage_options: dict | None = None) -> dict[np.datetime64, int]:
    loc = locate(path, storage_options)
    if not loc.has("zarr.json"):
        return {}
    """Every cycle row's state (hidden rows included), read with zarr alone: the `cycle` and `cycle_state` arrays, one
    chunk each (no xarray open of every array's metadata: on S3 a handful of GETs whatever the number of cycles)."""
    group = zarr.open_group(loc.zarr_store(read_only=True), mode="r", use_consolidated=False)
    if group["cycle"].shape != group["cycle_state"].shape:
        # A writer was killed mid-append (or is appending right now): wait for the lock, trim, reopen.
        with writer_lock(lock_dir, loc):
            _repair(loc)
        group = zarr.open_group(loc.zarr_store(read_only=True), mode="r", use_consolidated=False)
    return dict(zip(cycle_times(group["cycle"]), np.asarray(group["cycle_state"][:]).astype(int)))


def step_axis_h(path, storage_options: dict | None = None) -> list[int] | None:
    """The cube's step axis in whole hours (every cycle's slots); None when there is no cube yet."""
    loc = locate(path, storage_options)
    if not loc.has("zarr.json"):
        return None
    group = zarr.open_group(loc.zarr_store(read_only=True), mode="r", use_consolidated=False)
    return [int(h) for h in cv.step_hours(np.asarray(group["step"][:]))]


def complete_cycles(path, storage_options: dict | None = None) -> list[np.datetime64]:
    return sorted(c for c, s in cycle_states(path, storage_options=storage_options).items() if s == STATE_COMPLETE)


def latest_complete_cycle(path, at_or_before=None, storage_options: dict | None = None) -> np.datetime64 | None:
    cycles = complete_cycles(path, storage_options)
    if at_or_before is not None:
        limit = np.datetime64(at_or_before, "ns")
        cycles = [c for c in cycles if c <= limit]
    return cycles[-1] if cycles else None


def load_cycle(path, cycle, lat_range_deg: tuple[float, float] | None = None,
               storage_options: dict | None = None) -> xr.Dataset:
    """One visible cycle, eager, dims (step, lat, lon); only the latitude band `lat_range_deg` if given.

    A chunk damaged on disk raises CorruptChunkError naming the chunk, the cycle and the re-ingest that fixes it.
    """
    loc = locate(path, storage_options)
    ds = open_cube(loc)
    c = np.datetime64(cycle, "ns")
    if c not in ds["cycle"].values:
        raise KeyError(f"cycle {c} is not in the cube at {loc.url} (have {len(ds.cycle)} cycles)")
    one = ds.sel(cycle=c)
    if lat_range_deg is not None:
        lo, hi = sorted(lat_range_deg)
        one = one.sel(lat=slice(lo, hi)) if one.lat.values[0] < one.lat.values[-1] else one.sel(lat=slice(hi, lo))
    try:
        return one.load()
    except DECODE_ERRORS as exc:
        raise corrupt_chunk_error(loc, c, exc) from exc


# --- repairing a store damaged on disk (what is damaged: storage/cube_damage.py) -------------------------------


def move_aside(path: Path, lock_dir: Path | None = None) -> Path:
    """Move a damaged store to `<store>.damaged-<UTC time>` (kept for inspection), under the writer lock, and
    remove a `<store>.creating` left by a failed creation; the next ingest creates a fresh store."""
    path = Path(path)
    with writer_lock(lock_dir, path):
        shutil.rmtree(path.with_name(path.name + ".creating"), ignore_errors=True)
        aside = path.with_name(f"{path.name}.damaged-{time.strftime('%Y%m%dT%H%M%S', time.gmtime())}")
        os.replace(path, aside)
    return aside


def hide_cycles(path: Path, cycles: list, lock_dir: Path | None = None) -> None:
    """Set the cycles back to hidden (readers stop seeing them) until a re-ingest writes them again."""
    loc = locate(path)
    with writer_lock(lock_dir, loc):
        times = cycles_in_store(loc)
        for c in cycles:
            for i in np.flatnonzero(times == np.datetime64(c, "ns")):
                _set_state(loc, int(i), STATE_HIDDEN)


# a retention longer than this (~146 years) keeps every cycle of any forecast archive, and past it the limit below
# would overflow datetime64[ns]
_LONGEST_SPAN_S = 2.0 ** 62 / 1e9


def retire_cycles(path, keep_days: float, lock_dir: Path | None = None, storage_options: dict | None = None) -> list:
    """Retention: retire every cycle initialised more than `keep_days` days before the newest cycle in the store.

    Under the writer lock a retired cycle is hidden (`cycle_state` 0), its data chunks are deleted (the space they
    held is freed; its row stays, reading as the fill value, as arrays cannot lose a leading row without rewriting
    every chunk) and it leaves the published `cycle_versions` and `cycle_rows`, so routing workers and `open_cube`
    no longer see it; a plain `xr.open_zarr` still lists the row, all NaN. A retired cycle ingested again is
    written back into its row. Returns the retired cycles (datetime64[ns]), oldest first."""
    loc = locate(path, storage_options)
    if not keep_days >= 0:  # also NaN
        raise CubeError(f"cube retention of {keep_days} days: give a number of days ≥ 0")
    if keep_days * 86400 > _LONGEST_SPAN_S:  # inf, 1e300: keep every cycle
        return []
    if not loc.has("zarr.json"):
        return []
    with writer_lock(lock_dir, loc):
        _repair(loc)
        group = zarr.open_group(loc.zarr_store(), mode="r+", use_consolidated=False)
        cycles = cycles_in_store(loc)
        state = np.asarray(group["cycle_state"][:])
        versions = dict(group.attrs.get("cycle_versions", {}))
        if not cycles.size:
            return []
        limit = cycles.max() - np.timedelta64(int(round(keep_days * 86400)), "s")
        old = [i for i, c in enumerate(cycles) if c < limit and (state[i] != STATE_HIDDEN or _version_label(c) in versions)]
        if not old:
            return []
        for i in old:
            _set_state(loc, i, STATE_HIDDEN)
            versions.pop(_version_label(cycles[i]), None)
        group.attrs.update({"cycle_versions": versions})
        _publish(loc, None)  # readers stop seeing them before their chunks go
        for i in old:
            for v in DATA_VARS:
                _delete_prefix(loc, f"{v}/c/{i}")
        return [cycles[i] for i in old]


def _delete_prefix(loc: Location, prefix: str) -> None:
    """Delete every object under `prefix` of the store (nothing there is fine)."""
    if loc.local is not None:
        shutil.rmtree(loc.local / prefix, ignore_errors=True)
        return
    import fsspec

    fs, root = fsspec.core.url_to_fs(loc.url, **fs_options(loc.url, loc.options))
    try:
        fs.rm(f"{root}/{prefix}", recursive=True)
    except FileNotFoundError:
        pass
