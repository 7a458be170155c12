"""The Earth and the speed unit routing measures with, and points along great circles in numpy: what a process that
draws routes but never routes needs of geodesy.py (numba), without loading numba (the picture process,
flows/jobs/picture_process.py).

Angles in degrees, distances in nautical miles; longitudes in −180..180 or 0..360, results in −180..180.
"""

from __future__ import annotations

import numpy as np

EARTH_RADIUS_NM = 3440.065
KN_PER_MS = 1.943844


def gc_points(lat1, lon1, lat2, lon2, frac) -> tuple[np.ndarray, np.ndarray]:
    """(lat, lon) at fraction `frac` of the way along the great circle from point 1 to point 2 (the short way round),
    for arrays that broadcast together: the numbers of geodesy.gc_interpolate, many at once."""
    p1, l1, p2, l2 = (np.radians(np.asarray(a, np.float64)) for a in (lat1, lon1, lat2, lon2))
    frac = np.asarray(frac, np.float64)
    dl = np.radians((np.asarray(lon2, np.float64) - lon1 + 180.0) % 360.0 - 180.0)
    a = np.sin((p2 - p1) / 2) ** 2 + np.cos(p1) * np.cos(p2) * np.sin(dl / 2) ** 2
    d = 2.0 * EARTH_RADIUS_NM * np.arcsin(np.minimum(1.0, np.sqrt(a))) / EARTH_RADIUS_NM  # angular length, as geodesy's
    same = d < 1e-12
    with np.errstate(invalid="ignore", divide="ignore"):
        ka = np.sin((1 - frac) * d) / np.sin(d)
        kb = np.sin(frac * d) / np.sin(d)
    x = ka * np.cos(p1) * np.cos(l1) + kb * np.cos(p2) * np.cos(l2)
    y = ka * np.cos(p1) * np.sin(l1) + kb * np.cos(p2) * np.sin(l2)
    z = ka * np.sin(p1) + kb * np.sin(p2)
    lat = np.where(same, np.asarray(lat1, np.float64), np.degrees(np.arctan2(z, np.sqrt(x * x + y * y))))
    lon = np.where(same, np.asarray(lon1, np.float64), np.degrees(np.arctan2(y, x)))
    return lat, (lon + 180.0) % 360.0 - 180.0
