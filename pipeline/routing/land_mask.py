"""The land structure (`LandGrid`) and land or sea at a point, in numpy: what a process needs that draws coastlines
but never routes (the picture process, flows/jobs/picture_process.py), so nothing here imports numba.

The grid of the `global-land-mask` package (GEBCO-derived, 1/120° ≈ 0.5 NM; 21600 × 43200 booleans, True = ocean,
row 0 at 90° N, column 0 at 180° W) takes 933 MB decompressed and is never held whole: pipeline/routing/land.py
builds from it a `LandGrid` of about 15 MB, which ships with the code (`land_grid_v1.npz`, 1 MB; `python -m
pipeline.routing.land` writes it again after a change of the mask package) so processes load it instead of building it:

- 1° × 1° tiles (120 × 120 cells), each all sea, all land or mixed; only mixed tiles keep their cells (packed
  bits), so `is_sea` is exact at the grid's resolution;
- for tiles with land in them or next to them, a lower bound of the distance to land per 1/12° block
  (10 × 10 cells, ≈ 5 NM; 0.1 NM units); tiles farther out get the bound one tile of open water gives
  (up to `BOUND_CAP_NM`). The distances are land.py's (numba kernels).
"""

from __future__ import annotations

import importlib.metadata
import importlib.util
import threading
from pathlib import Path
from typing import NamedTuple

import numpy as np

MASK_RES_DEG = 1.0 / 120.0
CELL_NM = 0.5  # north–south size of a cell (60 NM per degree / 120)
TILE = 120  # cells per 1° tile side
BLOCK = 10  # cells per bound block side (1/12°)
N_ROWS, N_COLS = 180 * TILE, 360 * TILE
SEA_TILE, LAND_TILE = -1, -2  # LandGrid.slot for tiles without cells kept
BOUND_UNIT_NM = 0.1
BOUND_CAP_NM = 25.0
_MASK_FILE = "globe_combined_mask_compressed.npz"


class LandGrid(NamedTuple):
    """The land structure as kernels see it (see the module docstring)."""

    slot: np.ndarray  # (180, 360) int32: SEA_TILE, LAND_TILE, or the tile's index into `bits`
    bits: np.ndarray  # (n_mixed, 120, 15) uint8: the mixed tiles' cells, packed big-endian, 1 = sea
    near: np.ndarray  # (180, 360) int32: the tile's index into `bound`, SEA_TILE (use `far_nm` of its row), LAND_TILE
    bound: np.ndarray  # (n_near, 12, 12) uint8: lower bound of the distance to land per block, BOUND_UNIT_NM
    far_nm: np.ndarray  # (180,) float64: lower bound of the distance to land in a tile with open water all round

    @property
    def nbytes(self) -> int:
        return int(sum(a.nbytes for a in self))


def mask_path() -> Path:
    spec = importlib.util.find_spec("global_land_mask")  # finds the package without importing it (its import loads 933 MB)
    if spec is None or not spec.submodule_search_locations:
        raise RuntimeError("the global-land-mask package is not installed; pip install global-land-mask")
    return Path(list(spec.submodule_search_locations)[0]) / _MASK_FILE


def mask_key(path: Path) -> str:
    """What a saved LandGrid was built from: the package version and the mask file's size."""
    return f"global-land-mask {importlib.metadata.version('global-land-mask')}, {path.stat().st_size} bytes"


def save_land_grid(grid: LandGrid, path: Path, key: str) -> None:
    """Write `grid` to `path` (compressed npz, about 1 MB) with the key of the mask it was built from."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.npz")
    np.savez_compressed(tmp, key=key, **grid._asdict())
    tmp.replace(path)


def read_saved(path: Path, key: str) -> LandGrid | None:
    if not path.exists():
        return None
    with np.load(path) as z:
        return LandGrid(**{k: z[k] for k in LandGrid._fields}) if str(z["key"]) == key else None


_GRID: LandGrid | None = None
_GRID_LOCK = threading.Lock()  # a worker's threads load it once between them
_CACHE_NAME = "land_grid_v1.npz"
PACKAGED = Path(__file__).with_name(_CACHE_NAME)  # shipped with the code: workers load 1 MB instead of building


def land_grid() -> LandGrid:
    """The process's LandGrid: the one shipped with the code (`land_grid_v1.npz` beside this module) when it was
    made from the installed mask, else built once (land.build_land_grid: a few seconds, about 100 MB at the peak)."""
    global _GRID
    if _GRID is None:
        with _GRID_LOCK:
            if _GRID is None:
                mask = mask_path()
                grid = read_saved(PACKAGED, mask_key(mask))
                if grid is None:
                    from pipeline.routing import land  # numba: only where the shipped grid does not fit the mask

                    grid = land.build_land_grid(mask)
                _GRID = grid
    return _GRID


def is_sea(lat, lon) -> np.ndarray:
    """Vectorised over arrays that broadcast together: True where (lat, lon) is open water (the mask's cell holding
    it is sea). Latitudes beyond ±90° count as the pole's row; longitudes may be any. A grid asked for as a column
    of latitudes and a row of longitudes (a map's samples) costs a few bytes a point: rows and columns are worked
    out before they are broadcast."""
    lat, lon = np.asarray(lat, np.float64), np.asarray(lon, np.float64)
    shape = np.broadcast_shapes(lat.shape, lon.shape)
    lat, lon = np.atleast_1d(lat), np.atleast_1d(lon)
    grid = land_grid()
    with np.errstate(invalid="ignore"):  # NaN positions: their cells are garbage, as a kernel's would be
        i = np.clip(((90.0 - lat) * 120.0).astype(np.int64), 0, N_ROWS - 1).astype(np.int32)
        j = (((lon + 180.0) % 360.0 * 120.0).astype(np.int64) % N_COLS).astype(np.int32)
    tile_row, cell_row, tile_col, cell_col = np.broadcast_arrays(i // TILE, i % TILE, j // TILE, j % TILE)
    slot = grid.slot[tile_row, tile_col]
    sea = slot == SEA_TILE
    mixed = slot >= 0
    if mixed.any():
        jj = cell_col[mixed]
        sea[mixed] = (grid.bits[slot[mixed], cell_row[mixed], jj >> 3] >> (7 - (jj & 7)).astype(np.uint8)) & 1 == 1
    return sea.reshape(shape)
