"""Distance to land, and land or sea, from the `global-land-mask` grid (1/120° ≈ 0.5 NM), usable in numba.

The land structure (`LandGrid`, its loading and `is_sea` in numpy) is pipeline/routing/land_mask.py's, so a process
that only draws coastlines does not load numba; this module builds the structure from the package's mask
(`build_land_grid`) and holds the kernels that read it.

Distance to land (NM) is the distance from a point to the nearest land cell (cells as boxes, in the local flat
metric at the point: a cell is 0.5 NM north–south and 0.5·cos(lat) NM east–west): 0 on land, exact up to the
`limit_nm` asked for (the cells within it are scanned, where the block bound says land may be that near), and
otherwise a value ≥ `limit_nm` that is a true lower bound. Sphere tracing along a leg therefore never steps
over land: from a point at distance d, every point within d − c of it is at least c from land.
"""

from __future__ import annotations

import math
import zipfile
from pathlib import Path

import numba
import numpy as np

# is_sea, land_grid and the file helpers are land_mask's, here too for the routing code and the land tests
from pipeline.routing.land_mask import (BLOCK, BOUND_CAP_NM, BOUND_UNIT_NM, CELL_NM, LAND_TILE, N_COLS, N_ROWS,
                                        PACKAGED, SEA_TILE, TILE, LandGrid, is_sea, land_grid, mask_key,  # noqa: F401
                                        mask_path, read_saved, save_land_grid)  # noqa: F401


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


@numba.njit(cache=True)
def _classify_tile_row(rows, tile_sea, land_blocks):
    """One tile row of cells (120, 43200; 1 = sea) → sea cells per tile (360,) and land per block (12, 4320)."""
    tile_sea[:] = 0
    land_blocks[:] = False
    for i in range(rows.shape[0]):
        for j in range(rows.shape[1]):
            if rows[i, j]:
                tile_sea[j // TILE] += 1
            else:
                land_blocks[i // BLOCK, j // BLOCK] = True


def build_land_grid(path: Path | None = None) -> LandGrid:
    """Stream the package's mask into a LandGrid (a few seconds; peak about 30 MB above the result)."""
    from scipy.ndimage import binary_dilation, distance_transform_edt

    path = mask_path() if path is None else Path(path)
    nb = TILE // BLOCK
    slot = np.full((180, 360), SEA_TILE, np.int32)
    bits, land_blocks = [], np.zeros((180 * nb, 360 * nb), bool)
    tile_sea = np.empty(360, np.int64)
    for r, rows in enumerate(_tile_rows(path)):
        _classify_tile_row(rows.view(np.uint8), tile_sea, land_blocks[r * nb:(r + 1) * nb])
        slot[r, tile_sea == 0] = LAND_TILE
        mixed = np.flatnonzero((tile_sea > 0) & (tile_sea < TILE * TILE))
        if len(mixed):
            slot[r, mixed] = np.arange(len(mixed), dtype=np.int32) + sum(len(b) for b in bits)
            bits.append(np.packbits(rows.reshape(TILE, 360, TILE)[:, mixed, :], axis=-1).transpose(1, 0, 2))
    bits = np.concatenate(bits) if bits else np.zeros((0, TILE, TILE // 8), np.uint8)
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


@numba.njit(cache=True)
def cell_of_nb(lat, lon):
    """(row, column) of the cell holding (lat, lon): row 0 at 90° N, column 0 at 180° W."""
    i = int((90.0 - lat) * 120.0)
    i = min(max(i, 0), N_ROWS - 1)
    j = int((((lon + 180.0) % 360.0)) * 120.0) % N_COLS
    return i, j


@numba.njit(cache=True)
def cell_is_sea_nb(grid, i, j):
    j = j % N_COLS
    s = grid.slot[i // TILE, j // TILE]
    if s == SEA_TILE:
        return True
    if s == LAND_TILE:
        return False
    jj = j % TILE
    return (grid.bits[s, i % TILE, jj >> 3] >> (7 - (jj & 7))) & 1 == 1


@numba.njit(cache=True)
def _bound_nm(grid, i, j):
    r, c = i // TILE, j // TILE
    n = grid.near[r, c]
    if n == SEA_TILE:
        return grid.far_nm[r]
    if n == LAND_TILE:
        return 0.0
    return grid.bound[n, (i % TILE) // BLOCK, (j % TILE) // BLOCK] * BOUND_UNIT_NM


@numba.njit(cache=True)
def _row_distance_nm(grid, ii, jx, x, gy, ew_nm, nj, best):
    """Least distance to a land cell of row `ii`, scanning outwards from column `jx` while it can beat `best`."""
    for side in (1, -1):
        dj = 0 if side == 1 else 1
        while dj <= nj:
            jj = jx + side * dj
            gx = max(0.0, jj - x, x - (jj + 1)) * ew_nm
            if gx >= best:
                break  # farther out only gets farther
            jw = jj % N_COLS
            if grid.slot[ii // TILE, jw // TILE] == SEA_TILE:  # on to the next tile
                dj += TILE - jw % TILE if side == 1 else jw % TILE + 1
                continue
            if not cell_is_sea_nb(grid, ii, jw):
                best = min(best, math.sqrt(gx * gx + gy * gy))
            dj += 1
    return best


@numba.njit(cache=True)
def distance_to_land_nb(grid, lat, lon, limit_nm):
    """Distance (NM) from (lat, lon) to the nearest land cell: exact below `limit_nm`, else a lower bound ≥ it."""
    i, j = cell_of_nb(lat, lon)
    bound = _bound_nm(grid, i, j)
    if bound >= limit_nm:
        return bound
    y = (90.0 - lat) * 120.0  # in cells, continuous
    x = (((lon + 180.0) % 360.0)) * 120.0
    ew_nm = CELL_NM * max(math.cos(math.radians(lat)), 1e-3)  # east–west size of a cell here
    ni = int(limit_nm / CELL_NM) + 1
    nj = min(int(limit_nm / ew_nm) + 1, N_COLS // 2)
    best = limit_nm
    for k in range(2 * ni + 1):  # rows 0, +1, -1, +2, … away, so near land cuts the scan short
        ii = i + ((k + 1) // 2 if k % 2 else -(k // 2))
        if ii < 0 or ii >= N_ROWS:
            continue
        gy = max(0.0, ii - y, y - (ii + 1)) * CELL_NM
        if gy < best:
            best = _row_distance_nm(grid, ii, int(x), x, gy, ew_nm, nj, best)
    return best


@numba.njit(cache=True)
def _distances(grid, lat, lon, limit_nm, out):
    for k in range(lat.size):
        out[k] = distance_to_land_nb(grid, lat[k], lon[k], limit_nm)


def distance_to_land_nm(lat, lon, limit_nm: float = BOUND_CAP_NM) -> np.ndarray:
    """Vectorised distance (NM) to the nearest land cell; values ≥ `limit_nm` mean "at least that far"."""
    lat, lon = np.broadcast_arrays(np.asarray(lat, np.float64), np.asarray(lon, np.float64))
    out = np.empty(lat.shape)
    _distances(land_grid(), np.ascontiguousarray(lat).ravel(), np.ascontiguousarray(lon).ravel(), float(limit_nm),
               out.reshape(-1))
    return out


if __name__ == "__main__":  # write the shipped LandGrid from the installed mask
    save_land_grid(build_land_grid(), PACKAGED, mask_key(mask_path()))
    print(f"wrote {PACKAGED} ({PACKAGED.stat().st_size / 1e6:.1f} MB)")
