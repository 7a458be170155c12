"""Distance to land, and land or sea, from the `global-land-mask` grid (1/120° ≈ 0.5 NM), usable in numba.

The land structure (`LandGrid`, its loading and `is_sea` in numpy) is pipeline/routing/land_mask.py's, so a process
that only draws coastlines does not load numba, and so is its building from the package's mask
(`land_mask.build_land_grid`); this module holds the kernels that read it.

Distance to land (NM) is the distance from a point to the nearest land cell (cells as boxes, in the local flat
metric at the point: a cell is 0.5 NM north–south and 0.5·cos(lat) NM east–west): 0 on land, exact up to the
`limit_nm` asked for (the cells within it are scanned, where the block bound says land may be that near), and
otherwise a value ≥ `limit_nm` that is a true lower bound. Sphere tracing along a leg therefore never steps
over land: from a point at distance d, every point within d − c of it is at least c from land.
"""

from __future__ import annotations

import math

import numba
import numpy as np

# is_sea, land_grid and the file helpers are land_mask's, here too for the routing code and the land tests
from pipeline.routing.land_mask import (BLOCK, BOUND_CAP_NM, BOUND_UNIT_NM, CELL_NM, LAND_TILE, N_COLS, N_ROWS,  # noqa: F401
                                        PACKAGED, SEA_TILE, TILE, LandGrid, is_sea, land_grid, mask_key,  # noqa: F401
                                        mask_path, read_saved, save_land_grid)  # noqa: F401


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


