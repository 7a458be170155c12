"""One voyage's window of a published cube cycle, read with zarr alone (no xarray, pandas or dask): what a routing
worker reads, so its process stays small.

`open_published` opens the store's published view (its consolidated metadata, one read even on S3) and decodes
the coordinates; `read_window` reads the steps and the lat/lon box a voyage can meet, only the chunks inside it.
The coordinates are decoded from their CF attributes as storage/cube.py writes them: `cycle` in "<unit> since
<epoch>", `step` in hours.

Opening costs the same whatever the archive's length: the published cycles, their rows and content versions are
root attributes of the consolidated metadata (`cycle_rows`, `cycle_versions`, written at publication), so the
`cycle` coordinate is not read. A store published before `cycle_rows` existed is read the old way (the whole `cycle`
coordinate: one read since storage/cube.py keeps it in one chunk, one per cycle before) until its next publication.

Chunk cache: every data chunk a process reads goes through one process-wide cache (CHUNK_CACHE), bounded in bytes
(`JITROUTE_CUBE_CACHE_MB`, default 64) and keyed by store, variable, cycle, the cycle's content version and chunk:
a worker fetches each chunk of a cycle version once, however many voyages need it; a re-ingested cycle has a new
version, so its new chunks are fetched afresh. It holds the chunks as stored (compressed).
"""

from __future__ import annotations

import os
import re
import threading
from collections import OrderedDict
from typing import NamedTuple

import numpy as np
import zarr
from zarr.storage import WrapperStore

from schemas.cube_variables import DATA_VARS, STATE_COMPLETE, STATE_HIDDEN, step_hours
from storage.cube_damage import corrupt_chunk_error, require_store
from storage.cube_location import DECODE_ERRORS, CubeError, Location, locate

_UNITS = {"days": "D", "hours": "h", "minutes": "m", "seconds": "s"}


class Published(NamedTuple):
    """The published view of a store: its zarr group (reading data chunks through CHUNK_CACHE), where each published
    cycle lies, and the decoded coordinates."""

    group: zarr.Group
    rows: dict  # datetime64[ns] cycle → its row along `cycle`
    step_h: np.ndarray  # int64 lead times in hours
    lat: np.ndarray  # degrees north, as stored
    lon: np.ndarray  # degrees east, as stored


class ChunkCache:
    """Chunks as stored (compressed bytes), least recently used dropped first once `max_bytes` is passed; safe
    across threads. `fetched_bytes`/`fetched_chunks` count what came from the store, `hit_chunks` what did not;
    `distinct_bytes` the stored size of the distinct chunks fetched (each counted once), so
    fetched_bytes / distinct_bytes is how often a chunk was fetched again after being dropped (1.0: never)."""

    SEEN_MAX = 1 << 16  # distinct chunk keys remembered for `distinct_bytes` (a few MB at most)

    def __init__(self, max_bytes: int):
        self.max_bytes = int(max_bytes)
        self._items: OrderedDict = OrderedDict()
        self._seen: set = set()
        self._lock = threading.Lock()
        self.held_bytes = self.fetched_bytes = self.fetched_chunks = self.hit_chunks = self.distinct_bytes = 0

    def get(self, key) -> bytes | None:
        with self._lock:
            data = self._items.get(key)
            if data is not None:
                self._items.move_to_end(key)
                self.hit_chunks += 1
            return data

    def put(self, key, data: bytes) -> None:
        with self._lock:
            self.fetched_bytes += len(data)
            self.fetched_chunks += 1
            if key not in self._seen and len(self._seen) < self.SEEN_MAX:
                self._seen.add(key)
                self.distinct_bytes += len(data)
            if len(data) > self.max_bytes or key in self._items:
                return
            self._items[key] = data
            self.held_bytes += len(data)
            while self.held_bytes > self.max_bytes:
                _, old = self._items.popitem(last=False)
                self.held_bytes -= len(old)

    def clear(self) -> None:
        with self._lock:
            self._items.clear()
            self._seen.clear()
            self.held_bytes = self.fetched_bytes = self.fetched_chunks = self.hit_chunks = self.distinct_bytes = 0

    def stats(self) -> dict:
        """The counters and the bound, as plain numbers (what a bench asks a worker for)."""
        with self._lock:
            return {"max_bytes": self.max_bytes, "held_bytes": self.held_bytes, "fetched_bytes": self.fetched_bytes,
                    "fetched_chunks": self.fetched_chunks, "hit_chunks": self.hit_chunks,
                    "distinct_bytes": self.distinct_bytes}


CHUNK_CACHE = ChunkCache(int(float(os.environ.get("JITROUTE_CUBE_CACHE_MB", "64")) * (1 << 20)))


class _CachedChunks(WrapperStore):
    """A read-only store whose data chunks (`<variable>/c/<row>/…`) of published cycles go through CHUNK_CACHE,
    keyed by (store URL, variable, cycle, content version, chunk); everything else (metadata, `cycle_state`, read
    live) goes straight to the store."""

    def __init__(self, store, url: str = "", by_row: dict | None = None):
        super().__init__(store)
        self._url = url
        self._by_row = by_row if by_row is not None else {}  # row → (cycle label, content version); shared, filled after open

    def _with_store(self, store):
        return type(self)(store, self._url, self._by_row)

    def _cache_key(self, key: str):
        parts = key.split("/")
        if len(parts) < 4 or parts[0] not in DATA_VARS or parts[1] != "c" or not parts[2].isdigit():
            return None
        known = self._by_row.get(int(parts[2]))
        return None if known is None else (self._url, parts[0], *known, "/".join(parts[3:]))

    async def get(self, key, prototype, byte_range=None):
        ck = self._cache_key(key) if byte_range is None else None
        if ck is None:
            return await self._store.get(key, prototype, byte_range)
        data = CHUNK_CACHE.get(ck)
        if data is not None:
            return prototype.buffer.from_bytes(data)
        buf = await self._store.get(key, prototype, byte_range)
        if buf is not None:
            CHUNK_CACHE.put(ck, buf.to_bytes())
        return buf


class Window(NamedTuple):
    """A cycle's weather in a box: `data` maps a variable to its (step, lat, lon) float32 values."""

    cycle: np.datetime64
    step_h: np.ndarray
    lat: np.ndarray
    lon: np.ndarray  # continuous and increasing (past 360 for a box across the grid's seam)
    data: dict


def cycle_times(arr) -> np.ndarray:
    """A CF time coordinate ("hours since 2000-01-01 …") as datetime64[ns]."""
    m = re.fullmatch(r"\s*(\w+) since (\S+)(?: (\S+))?\s*", str(arr.attrs.get("units", "")))
    if m is None or m.group(1) not in _UNITS:
        raise CubeError(f"cube coordinate {arr.name} has units {arr.attrs.get('units')!r}, not '<unit> since <time>'")
    epoch = np.datetime64(m.group(2) + ("T" + m.group(3) if m.group(3) else ""), "ns")
    return epoch + np.asarray(arr[:]).astype(np.int64).astype(f"timedelta64[{_UNITS[m.group(1)]}]")


def _lead_hours(arr) -> np.ndarray:
    """The `step` coordinate in whole hours (storage/cube.py stores it in hours, as older stores did)."""
    if str(arr.attrs.get("units", "hours")) != "hours":
        raise CubeError(f"cube coordinate step has units {arr.attrs.get('units')!r}, not 'hours'")
    return step_hours(np.asarray(arr[:]))


def open_published(path, storage_options: dict | None = None, cache_chunks: bool = True) -> Published:
    """The published view of the store at `path` (a local path or URL with fsspec options). A local store written
    before publication existed is read as it is (cycle_state still hides unfinished cycles) until its next ingest
    publishes it; a store never published raises FileNotFoundError naming the fix. `cache_chunks=False`: its data
    chunks bypass CHUNK_CACHE (a read of the whole grid, e.g. a weather map, would fill a routing worker's cache)."""
    loc = locate(path, storage_options)
    if loc.local is not None and not loc.has("zarr.json"):
        require_store(loc)
    by_row: dict = {}
    store = _CachedChunks(_store_object(loc), loc.url, by_row)
    try:
        group = zarr.open_consolidated(store, mode="r")
    except (FileNotFoundError, ValueError, KeyError, TypeError) as exc:
        if loc.local is not None and loc.has("zarr.json"):
            group = zarr.open_group(store, mode="r")
        else:
            raise FileNotFoundError(f"no published weather cube at {loc.url} ({type(exc).__name__}: {exc}): "
                                    "run `jitroute ingest` (or `jitroute demo`) first") from exc
    attrs = group.attrs.asdict()
    if "cycle_rows" in attrs:  # written at publication: no read of the `cycle` coordinate, whatever its length
        n = group["cycle_state"].shape[0]  # rows past the published shapes are a publication under way
        rows = {np.datetime64(k, "ns"): int(r) for k, r in dict(attrs["cycle_rows"]).items() if int(r) < n}
    else:  # published before `cycle_rows` existed (or opened without consolidated metadata)
        rows = {c: i for i, c in enumerate(cycle_times(group["cycle"]))}
    versions = {np.datetime64(k, "ns"): int(v) for k, v in dict(attrs.get("cycle_versions", {})).items()}
    if cache_chunks:  # a chunk whose row is not known here is read from the store every time
        by_row.update({r: (str(np.datetime64(c, "s")), versions[c]) for c, r in rows.items() if c in versions})
    return Published(group, rows, _lead_hours(group["step"]), np.asarray(group["lat"][:]), np.asarray(group["lon"][:]))


def _store_object(loc: Location):
    """The zarr Store of `loc`, read-only (zarr opens a local path given as a string itself)."""
    store = loc.zarr_store(read_only=True)
    if isinstance(store, str):
        from zarr.storage import LocalStore

        return LocalStore(store, read_only=True)
    return store


def cycle_versions(path, storage_options: dict | None = None) -> dict[np.datetime64, int]:
    """The content version of every published cycle: a re-ingest gives its cycle a new one. A store never
    published (or written before versions existed) has none."""
    loc = locate(path, storage_options)
    if not loc.has("zarr.json"):
        return {}
    attrs = zarr.open_group(loc.zarr_store(read_only=True), mode="r").attrs
    return {np.datetime64(k, "ns"): int(v) for k, v in dict(attrs.get("cycle_versions", {})).items()}


def newest_complete_cycle(path, storage_options: dict | None = None) -> np.datetime64 | None:
    """The newest complete cycle of the published view (None: none, or no store), for readers such as
    `jitroute route`; a writer asks storage.cube.latest_complete_cycle, which also repairs a half-finished append."""
    return next(complete_cycles_newest_first(path, storage_options), None)


def complete_cycles_newest_first(path, storage_options: dict | None = None):
    """The complete cycles of the published view, newest first, each state read only when the caller asks for the
    next (nothing when there is no store)."""
    loc = locate(path, storage_options)
    if not loc.has("zarr.json"):
        return
    pub = open_published(loc)
    state = pub.group["cycle_state"]
    for c in sorted(pub.rows, reverse=True):
        if int(state[pub.rows[c]]) == STATE_COMPLETE:
            yield c


def _step_slice(valid: np.ndarray, t_from, t_to) -> slice:
    """The steps whose valid times bracket t_from..t_to (the step at or before t_from to the one at or after
    t_to), clipped to the cycle's steps."""
    n = valid.size
    i0 = int(np.clip(np.searchsorted(valid, np.datetime64(t_from, "ns"), side="right") - 1, 0, n - 1))
    i1 = int(np.clip(np.searchsorted(valid, np.datetime64(t_to, "ns"), side="left"), i0, n - 1))
    return slice(i0, i1 + 1)


def _lat_slice(lat: np.ndarray, lat_deg: tuple[float, float], pad_deg: float) -> slice:
    """Rows covering lat_deg ± pad_deg (at least 2), whatever the order of the cube's latitudes."""
    lo, hi = min(lat_deg) - pad_deg, max(lat_deg) + pad_deg
    rows = np.flatnonzero((lat >= lo) & (lat <= hi))
    if rows.size < 2:  # a box at or beyond the grid's edge: the two nearest rows
        rows = np.sort(np.argsort(np.abs(lat - 0.5 * (lo + hi)))[:2])
    return slice(int(rows[0]), int(rows[-1]) + 1)


def _lon_slices(lon: np.ndarray, lon_deg: tuple[float, float], pad_deg: float) -> tuple[list[slice], np.ndarray]:
    """Column slices covering west..east (degrees east, east ≥ west, any turn) ± pad_deg on a regular grid, and
    the longitudes they give, continuous and increasing (a box across the grid's seam reads two slices; their
    longitudes go on past 360). A box about as wide as the globe reads every column."""
    n, dlon = lon.size, float(lon[1] - lon[0])
    west, east = lon_deg[0] - pad_deg, lon_deg[1] + pad_deg
    if not abs(n * dlon - 360.0) < 1e-6:  # a regional grid: clip, never wrap
        cols = np.flatnonzero((lon >= west) & (lon <= east))
        cols = cols if cols.size >= 2 else np.sort(np.argsort(np.abs(lon - 0.5 * (west + east)))[:2])
        return [slice(int(cols[0]), int(cols[-1]) + 1)], lon[cols[0]:cols[-1] + 1]
    if east - west >= 360.0 - 2 * dlon:
        return [slice(0, n)], lon
    k0 = int(np.floor(((west - lon[0]) % 360.0) / dlon))
    count = int(np.ceil((east - west) / dlon)) + 2
    first = slice(k0, min(n, k0 + count))
    slices = [first] if k0 + count <= n else [first, slice(0, k0 + count - n)]
    return slices, lon[k0] + dlon * np.arange(count)


def cycle_steps_h(pub: Published, cycle) -> np.ndarray:
    """The cycle's own leads (h): the cube's step axis up to the cycle's last step with wind. The axis has room for
    the longest leads any cycle has (the 00/12 UTC cycles' to 264 h); a cycle with shorter ones leaves the rest all
    NaN (pipeline/weather/assemble.py). GSM wind has no land mask, so one grid point (one chunk) tells."""
    ci = pub.rows[np.datetime64(cycle, "ns")]
    wind = np.asarray(pub.group["u10"][ci, :, len(pub.lat) // 2, 0])
    have = np.flatnonzero(np.isfinite(wind))
    return pub.step_h[: int(have[-1]) + 1] if have.size else pub.step_h


def read_window(path, cycle, *, valid_utc: tuple, lat_deg: tuple[float, float], lon_deg: tuple[float, float],
                variables: tuple[str, ...] = DATA_VARS, margin_cells: int = 3, storage_options: dict | None = None,
                published: Published | None = None) -> Window:
    """One visible cycle's weather in a window: the steps whose valid times cover `valid_utc` = (from, to), and the
    box `lat_deg` (south, north) × `lon_deg` (west, east in degrees east; east ≥ west, e.g. (170, 200) across 180°)
    padded by `margin_cells` grid cells. Only the chunks in the window are read.

    `path` is a local path or URL (`s3://bucket/…/weather.zarr` with fsspec `storage_options`); `published` is an
    already opened `open_published(path)` to read from (its caller then keeps it). Raises KeyError for a cycle not
    published or hidden, CorruptChunkError for a chunk that does not decode.
    """
    loc = locate(path, storage_options)
    pub = published if published is not None else open_published(loc)
    c = np.datetime64(cycle, "ns")
    ci = pub.rows.get(c)
    if ci is None or int(pub.group["cycle_state"][ci]) == STATE_HIDDEN:  # the state is read live
        raise KeyError(f"cycle {c} is not in the cube at {loc.url} (or is being re-written)")
    steps = _step_slice(c + pub.step_h.astype("timedelta64[h]"), *valid_utc)
    lats = _lat_slice(pub.lat, lat_deg, margin_cells * abs(float(pub.lat[1] - pub.lat[0])))
    lon_parts, lon_out = _lon_slices(pub.lon, lon_deg, margin_cells * float(pub.lon[1] - pub.lon[0]))
    try:
        data = {v: np.concatenate([pub.group[v][ci, steps, lats, part] for part in lon_parts], axis=-1)
                for v in variables}
    except DECODE_ERRORS as exc:
        raise corrupt_chunk_error(loc, c, exc) from exc
    return Window(c, pub.step_h[steps], pub.lat[lats], lon_out, data)


