"""The land structure (`LandGrid`) and land or sea at a point, in numpy: what a process needs that draws coastlines
but never routes (the picture process, flows/jobs/picture_process.py), so nothing here imports numba.

The grid of the `global-land-mask` package (GEBCO-derived, 1/120° ≈ 0.5 NM; 21600 × 43200 booleans, True = ocean,
row 0 at 90° N, column 0 at 180° W) takes 933 MB decompressed and is never held whole: `build_land_grid` makes
from it a `LandGrid` of about 15 MB, which ships with the code (`land_grid_v1.npz`, 1 MB; `python -m
pipeline.routing.land_mask` writes it again after a change of the mask package) so processes load it instead of building it:

- 1° × 1° tiles (120 × 120 cells), each all sea, all land or mixed; only mixed tiles keep their cells (packed
  bits), so `is_sea` is exact at the grid's resolution;
- for tiles with land in them or next to them, a lower bound of the distance to land per 1/12° block
  (10 × 10 cells, ≈ 5 NM; 0.1 NM units); tiles farther out get the bound one tile of open water gives
  (up to `BOUND_CAP_NM`). The distances are land.py's (numba kernels).
"""

from __future__ import annotations

import importlib.metadata
import importlib.util
import math
import threading
import zipfile
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


def _tile_rows(path: Path):
    """Yield the mask 120 rows (one tile row) at a time as (120, 43200) bool, decompressing as it goes."""
    with zipfile.ZipFile(path) as z, z.open("mask.npy") as f:
        version = np.lib.format.read_magic(f)
        shape, fortran, dtype = (np.lib.format.read_array_header_1_0(f) if version == (1, 0)
                                 else np.lib.format.read_array_header_2_0(f))
        if tuple(shape) != (N_ROWS, N_COLS) or fortran or np.dtype(dtype) != np.bool_:
            raise RuntimeError(f"{path}: expected a C-ordered bool {N_ROWS}×{N_COLS} mask, found {dtype} {shape}")
        for _ in range(N_ROWS // TILE):
            buf = f.read(TILE * N_COLS)
            if len(buf) != TILE * N_COLS:
                raise RuntimeError(f"{path}: the mask ends early")
            yield np.frombuffer(buf, dtype=np.bool_).reshape(TILE, N_COLS)


def _cos_poleward(row: int) -> float:
    """cos of the poleward edge latitude of tile row `row` (row 0: 90°..89° N)."""
    return math.cos(math.radians(max(abs(90.0 - row), abs(89.0 - row))))


def _classify_tile_row(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One tile row of cells (120, 43200; True = sea) → sea cells per tile (360,) and land per block (12, 4320)."""
    tile_sea = rows.reshape(TILE, 360, TILE).sum(axis=(0, 2), dtype=np.int64)
    land_blocks = ~rows.reshape(TILE // BLOCK, BLOCK, N_COLS // BLOCK, BLOCK).all(axis=(1, 3))
    return tile_sea, land_blocks


def build_land_grid(path: Path | None = None) -> LandGrid:
    """Stream the package's mask into a LandGrid (a few seconds; peak about 30 MB above the result)."""
    from scipy.ndimage import binary_dilation, distance_transform_edt

    path = mask_path() if path is None else Path(path)
    nb = TILE // BLOCK
    slot = np.full((180, 360), SEA_TILE, np.int32)
    mixed_tiles: list[np.ndarray] = []  # per tile row, its mixed tiles' packed cells
    n_mixed = 0
    land_blocks = np.zeros((180 * nb, 360 * nb), bool)
    for r, rows in enumerate(_tile_rows(path)):
        tile_sea, land_blocks[r * nb:(r + 1) * nb] = _classify_tile_row(rows)
        slot[r, tile_sea == 0] = LAND_TILE
        mixed = np.flatnonzero((tile_sea > 0) & (tile_sea < TILE * TILE))
        if len(mixed):
            slot[r, mixed] = np.arange(len(mixed), dtype=np.int32) + n_mixed
            n_mixed += len(mixed)
            mixed_tiles.append(np.packbits(rows.reshape(TILE, 360, TILE)[:, mixed, :], axis=-1).transpose(1, 0, 2))
    bits = np.concatenate(mixed_tiles) if mixed_tiles else np.zeros((0, TILE, TILE // 8), np.uint8)
    far_nm = np.array([min(BOUND_CAP_NM, 60.0 * _cos_poleward(r)) for r in range(180)])
    # tiles that need a bound per block: those with land in them or in one of their 8 neighbours
    not_sea = slot != SEA_TILE
    near_mask = ~(slot == LAND_TILE) & binary_dilation(np.pad(not_sea, ((1, 1), (0, 0)), mode="constant")[:, list(range(-1, 360)) + [0]],
                                structure=np.ones((3, 3), bool))[1:-1, 1:-1]
    near = np.full((180, 360), -1, np.int32)
    near[near_mask] = np.arange(int(near_mask.sum()), dtype=np.int32)
    near[slot == LAND_TILE] = LAND_TILE
    bound = np.zeros((int(near_mask.sum()), nb, nb), np.uint8)
    # land grown by one block, then the EDT of block centres gives the gap between blocks (a lower bound of any
    # point-to-land distance); east–west spacing at the tile's poleward edge keeps it a lower bound
    grown = binary_dilation(np.concatenate([land_blocks[:, -nb:], land_blocks, land_blocks[:, :nb]], axis=1),
                            structure=np.ones((3, 3), bool))
    for r in range(180):
        cols = np.flatnonzero(near_mask[r])
        if not len(cols):
            continue
        lo, hi = max(0, (r - 1) * nb), min(180 * nb, (r + 2) * nb)
        band = grown[lo:hi]
        if not (~band).any():
            continue  # bound stays 0: land everywhere
        d_nm = distance_transform_edt(~band, sampling=(BLOCK * CELL_NM, BLOCK * CELL_NM * _cos_poleward(r)))
        top = r * nb - lo
        d_nm = np.minimum(d_nm[top:top + nb, nb:-nb], far_nm[r])  # land beyond the band is a tile away
        q = np.floor(d_nm / BOUND_UNIT_NM).astype(np.uint8)
        bound[near[r, cols]] = q.reshape(nb, 360, nb).transpose(1, 0, 2)[cols]
    return LandGrid(slot=slot, bits=bits, near=near, bound=bound, far_nm=far_nm)



_GRID: LandGrid | None = None
_GRID_LOCK = threading.Lock()  # a worker's threads load it once between them
_CACHE_NAME = "land_grid_v1.npz"
PACKAGED = Path(__file__).with_name(_CACHE_NAME)  # shipped with the code: workers load 1 MB instead of building


def land_grid() -> LandGrid:
    """The process's LandGrid: the one shipped with the code (`land_grid_v1.npz` beside this module) when it was
    made from the installed mask, else built once (`build_land_grid`: a few seconds, about 100 MB at the peak)."""
    global _GRID
    if _GRID is None:
        with _GRID_LOCK:
            if _GRID is None:
                mask = mask_path()
                grid = read_saved(PACKAGED, mask_key(mask))
                if grid is None:
                    grid = build_land_grid(mask)
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


if __name__ == "__main__":  # write the shipped LandGrid from the installed mask
    save_land_grid(build_land_grid(), PACKAGED, mask_key(mask_path()))
    print(f"wrote {PACKAGED} ({PACKAGED.stat().st_size / 1e6:.1f} MB)")
