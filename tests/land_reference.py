"""The tests' independent land reference: the grid of the `global-land-mask` package (21600 × 43200 cells, True =
ocean), read without importing the package. Its import decompresses the whole grid (933 MB, about 4 s CPU) in every
test process; here the first use in a machine writes the grid once as packed bits (117 MB) in the temporary folder
(`$TMPDIR/jitroute-test-land-mask`, beside the sea graph's cache), named by the package's version and file size,
and every later use memory-maps it and reads only the cells it asks for.

`is_ocean`, `is_land` and `ocean_cells` answer exactly as `globe.is_ocean`, `globe.is_land` and
`globe._mask[np.ix_(rows, cols)]` do (tests/test_land_reference.py holds them to it): the same index arithmetic on
the same grid."""

from __future__ import annotations

import importlib.metadata
import os
import tempfile
from pathlib import Path

import numpy as np

from pipeline.routing.land_mask import mask_path

N_COLS = 43200
_STATE: dict = {}


def _cache_file(mask: Path) -> Path:
    version = importlib.metadata.version("global-land-mask")
    return Path(tempfile.gettempdir()) / "jitroute-test-land-mask" / f"globe-{version}-{mask.stat().st_size}-packed.npy"


def _grid() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(packed ocean bits (21600, 5400) uint8, big-endian bit order, memory-mapped; the cells' latitudes; longitudes)."""
    if not _STATE:
        mask = mask_path()
        cached = _cache_file(mask)
        with np.load(mask) as z:  # an npz member is decompressed only when read: lat and lon are small
            lat, lon = z["lat"], z["lon"]
            if not cached.exists():
                cached.parent.mkdir(parents=True, exist_ok=True)
                tmp = cached.with_name(cached.name + f".tmp{os.getpid()}.npy")
                try:
                    np.save(tmp, np.packbits(z["mask"], axis=1))
                    os.replace(tmp, cached)
                finally:
                    tmp.unlink(missing_ok=True)
        _STATE.update(bits=np.load(cached, mmap_mode="r"), lat=lat, lon=lon)
    return _STATE["bits"], _STATE["lat"], _STATE["lon"]


def _index(values, axis: np.ndarray, name: str, limit: float) -> np.ndarray:
    """globe.lat_to_index / lon_to_index: the value clipped to the axis, then truncated to its cell."""
    values = np.array(values)  # its own dtype, as the package does: integers clipped to the axis stay integers
    if np.any(values > limit) or np.any(values < -limit):
        raise ValueError(f"{name} must be within ±{limit}")
    values[values > axis.max()] = axis.max()
    values[values < axis.min()] = axis.min()
    return ((values - axis[0]) / (axis[1] - axis[0])).astype("int")


def ocean_cells(rows, cols) -> np.ndarray:
    """`globe._mask[np.ix_(rows, cols)]`: True where the cell (row, column) is ocean."""
    bits = _grid()[0]
    rows, cols = np.asarray(rows, np.int64), np.asarray(cols, np.int64)
    packed = np.asarray(bits[rows][:, cols >> 3])
    return ((packed >> (7 - (cols & 7)).astype(np.uint8)) & 1).astype(bool)


def is_ocean(lat, lon):
    """`globe.is_ocean`: True where (lat, lon) (degrees, longitude within ±180) is ocean."""
    bits, lat_axis, lon_axis = _grid()
    i, j = np.broadcast_arrays(_index(lat, lat_axis, "latitude", 90.0), _index(lon, lon_axis, "longitude", 180.0))
    return ((bits[i, j >> 3] >> (7 - (j & 7)).astype(np.uint8)) & 1).astype(bool)[()]


def is_land(lat, lon):
    """`globe.is_land`."""
    return np.logical_not(is_ocean(lat, lon))
