"""Land/sea from the `global-land-mask` grid (GEBCO-derived, 1/120° ≈ 0.5 NM), usable in numba.

`sea_mask()` returns the package's boolean grid (True = ocean, row 0 at 90° N, column 0 at
180° W); `is_sea_nb` looks a point up in it from compiled code.
"""

from __future__ import annotations

import numba
import numpy as np

MASK_RES_DEG = 1.0 / 120.0


def sea_mask() -> np.ndarray:
    from global_land_mask import globe

    return globe._mask


@numba.njit(cache=True)
def is_sea_nb(mask, lat, lon):
    i = int((90.0 - lat) / MASK_RES_DEG)
    lon = ((lon + 180.0) % 360.0) - 180.0
    j = int((lon + 180.0) / MASK_RES_DEG)
    i = min(max(i, 0), mask.shape[0] - 1)
    j = min(max(j, 0), mask.shape[1] - 1)
    return mask[i, j]


def is_sea(lat, lon) -> np.ndarray:
    """Vectorised: True where (lat, lon) is open water."""
    lat = np.asarray(lat, dtype=np.float64)
    lon = np.asarray(lon, dtype=np.float64)
    m = sea_mask()
    i = np.clip(((90.0 - lat) / MASK_RES_DEG).astype(np.int64), 0, m.shape[0] - 1)
    j = np.clip((((lon + 180.0) % 360.0) / MASK_RES_DEG).astype(np.int64), 0, m.shape[1] - 1)
    return m[i, j]
