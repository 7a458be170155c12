"""The routing grid every source is regridded to (regular lat/lon, lon 0..360 east)."""

from __future__ import annotations

import numpy as np


def routing_grid(res_deg: float = 0.5, lat_min_deg: float = -80.0, lat_max_deg: float = 80.0) -> tuple[np.ndarray, np.ndarray]:
    """(lat ascending inclusive of both limits, lon 0..360-res) as float64."""
    nlat = int(round((lat_max_deg - lat_min_deg) / res_deg)) + 1
    lat = lat_min_deg + np.arange(nlat) * res_deg
    lon = np.arange(int(round(360.0 / res_deg))) * res_deg
    return lat.astype(np.float64), lon.astype(np.float64)
