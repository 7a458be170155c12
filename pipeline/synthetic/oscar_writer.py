"""Write OSCAR surface-current NetCDF files in the real v1 and v2 layouts (netCDF4).

v1 (`oscar_vel{N}.nc`): dims (time, depth, latitude, longitude), latitude 80→-80 descending,
longitude 20→420 with a repeated overlap band, time in days since 1992-10-05, 1/3° by default.
v2 (`oscar_currents_{final|interim|nrt}_YYYYMMDD.nc`): dims (time, longitude, latitude) with
coordinate variables `lon`/`lat` that are not dimension names, _FillValue -999, time in days
since 1990-01-01, 0.25° by default. Currents are going-to u (east) / v (north) in m/s.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import netCDF4
import numpy as np

from pipeline.routing.land import is_sea

V1_EPOCH = np.datetime64("1992-10-05T00:00", "ns")
V2_EPOCH = np.datetime64("1990-01-01T00:00", "ns")


def _days(times, epoch) -> np.ndarray:
    return (np.asarray(times, dtype="datetime64[ns]") - epoch) / np.timedelta64(1, "D")


def _land(lat2d, lon2d) -> np.ndarray:
    return ~is_sea(lat2d, lon2d)


def write_oscar_v1(path: Path, times: Sequence[np.datetime64], uv: Callable, res_deg: float = 1 / 3) -> Path:
    """`uv(time, lat2d, lon2d) -> (u, v)` gives the currents; land points are NaN fill."""
    lat = np.linspace(80.0, -80.0, int(round(160 / res_deg)) + 1)
    lon = np.linspace(20.0, 420.0, int(round(400 / res_deg)) + 1)
    L, O = np.meshgrid(lat, lon, indexing="ij")
    land = _land(L, O % 360.0)
    path = Path(path)
    tmp = path.with_name(path.name + ".part")
    with netCDF4.Dataset(tmp, "w", format="NETCDF4") as nc:
        nc.createDimension("time", None)
        nc.createDimension("depth", 1)
        nc.createDimension("latitude", lat.size)
        nc.createDimension("longitude", lon.size)
        t = nc.createVariable("time", "i4", ("time",))
        t.units = "day since 1992-10-05 00:00:00"
        t[:] = np.round(_days(times, V1_EPOCH)).astype("i4")
        d = nc.createVariable("depth", "f4", ("depth",))
        d.units = "meter"
        d[:] = [15.0]
        nc.createVariable("latitude", "f8", ("latitude",))[:] = lat
        nc.createVariable("longitude", "f8", ("longitude",))[:] = lon
        for name, idx in (("u", 0), ("v", 1)):
            var = nc.createVariable(name, "f4", ("time", "depth", "latitude", "longitude"), fill_value=np.float32(np.nan), zlib=True)
            var.units = "meter/sec"
            var.long_name = ("Ocean Surface Zonal Currents", "Ocean Surface Meridional Currents")[idx]
            for k, tm in enumerate(times):
                field = np.asarray(uv(tm, L, O % 360.0)[idx], dtype=np.float32)
                var[k, 0] = np.where(land, np.nan, field)
        nc.title = "OSCAR third degree (synthetic, jitroute demo)"
    tmp.replace(path)
    return path


def write_oscar_v2(path: Path, time: np.datetime64, uv: Callable, res_deg: float = 0.25) -> Path:
    """One daily v2 file. Land points hold the -999 fill value."""
    lat = np.arange(-89.75, 89.75 + res_deg / 2, res_deg)
    lon = np.arange(int(round(360 / res_deg))) * res_deg
    O, L = np.meshgrid(lon, lat, indexing="ij")  # (longitude, latitude) order as in v2
    land = _land(L, O)
    path = Path(path)
    tmp = path.with_name(path.name + ".part")
    with netCDF4.Dataset(tmp, "w", format="NETCDF4") as nc:
        nc.createDimension("time", 1)
        nc.createDimension("longitude", lon.size)
        nc.createDimension("latitude", lat.size)
        t = nc.createVariable("time", "f8", ("time",))
        t.units = "days since 1990-01-01"
        t[:] = _days([time], V2_EPOCH)
        nc.createVariable("lon", "f4", ("longitude",))[:] = lon
        nc.createVariable("lat", "f4", ("latitude",))[:] = lat
        for name, idx in (("u", 0), ("v", 1)):
            var = nc.createVariable(name, "f4", ("time", "longitude", "latitude"), fill_value=np.float32(-999.0), zlib=True)
            var.units = "m s-1"
            field = np.asarray(uv(time, L, O)[idx], dtype=np.float32)
            var[0] = np.where(land, -999.0, field)
        nc.title = "OSCAR v2.0 (synthetic, jitroute demo)"
    tmp.replace(path)
    return path
