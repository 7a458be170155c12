"""Write real GRIB2 files with eccodes, laid out like JMA's GSM and GWM products.

Grids are JMA-like: regular lat/lon, first point 90N 0E, scanning north→south, west→east.
GSM files hold several fields per file (10 m wind plus MSL pressure and 2 m temperature) so
readers must select by discipline/category/number/level. GWM files hold several lead times;
land is a bitmap (newer products) or a fill value (older products).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import eccodes
import numpy as np

CENTRE_RJTD = 34
GWM_FILL_VALUE = 9999.0

# (discipline, category, number, level type, level value) per field we write
GSM_FIELDS = {
    "prmsl": (0, 3, 1, 101, 0),
    "u10": (0, 2, 2, 103, 10),
    "v10": (0, 2, 3, 103, 10),
    "t2m": (0, 0, 0, 103, 2),
}
GWM_FIELDS = {
    "swh": (10, 0, 3, 1, 0),
    "mwd": (10, 0, 14, 1, 0),  # direction of combined wind waves and swell
    "mwp": (10, 0, 15, 1, 0),  # mean period of combined wind waves and swell
}


def jma_grid(res_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """(lat descending 90..-90, lon 0..360-res) of a global JMA grid."""
    nlat = int(round(180.0 / res_deg)) + 1
    nlon = int(round(360.0 / res_deg))
    return np.linspace(90.0, -90.0, nlat), np.arange(nlon) * res_deg


def _new_message(cycle: np.datetime64, step_h: int, res_deg: float, field: tuple[int, int, int, int, int],
                 bits_per_value: int = 16, lat_span: tuple[float, float] = (90.0, -90.0), packing: str = "grid_simple") -> int:
    disc, cat, num, ltype, lvalue = field
    h = eccodes.codes_grib_new_from_samples("GRIB2")
    ts = np.datetime64(cycle, "m").astype(object)
    _, lon = jma_grid(res_deg)
    lat = np.linspace(lat_span[0], lat_span[1], int(round(abs(lat_span[1] - lat_span[0]) / res_deg)) + 1)
    eccodes.codes_set(h, "centre", CENTRE_RJTD)
    eccodes.codes_set(h, "dataDate", int(ts.strftime("%Y%m%d")))
    eccodes.codes_set(h, "dataTime", int(ts.strftime("%H%M")))
    eccodes.codes_set(h, "significanceOfReferenceTime", 1)
    eccodes.codes_set(h, "typeOfProcessedData", 1)
    eccodes.codes_set(h, "Ni", lon.size)
    eccodes.codes_set(h, "Nj", lat.size)
    eccodes.codes_set(h, "latitudeOfFirstGridPointInDegrees", float(lat[0]))
    eccodes.codes_set(h, "longitudeOfFirstGridPointInDegrees", 0.0)
    eccodes.codes_set(h, "latitudeOfLastGridPointInDegrees", float(lat[-1]))
    eccodes.codes_set(h, "longitudeOfLastGridPointInDegrees", float(lon[-1]))
    eccodes.codes_set(h, "iDirectionIncrementInDegrees", res_deg)
    eccodes.codes_set(h, "jDirectionIncrementInDegrees", res_deg)
    eccodes.codes_set(h, "jScansPositively", int(lat[-1] > lat[0]))
    eccodes.codes_set(h, "discipline", disc)
    eccodes.codes_set(h, "parameterCategory", cat)
    eccodes.codes_set(h, "parameterNumber", num)
    eccodes.codes_set(h, "typeOfFirstFixedSurface", ltype)
    if ltype in (103, 101) and lvalue:
        eccodes.codes_set(h, "scaleFactorOfFirstFixedSurface", 0)
        eccodes.codes_set(h, "scaledValueOfFirstFixedSurface", lvalue)
    eccodes.codes_set(h, "indicatorOfUnitOfTimeRange", 1)  # hours
    eccodes.codes_set(h, "forecastTime", int(step_h))
    eccodes.codes_set(h, "packingType", packing)
    if packing == "grid_simple":
        eccodes.codes_set(h, "bitsPerValue", bits_per_value)
    return h


def _write(fout, h: int, values: np.ndarray, *, bitmap_mask: np.ndarray | None = None) -> None:
    vals = np.asarray(values, dtype=np.float64).ravel()
    if bitmap_mask is not None:
        eccodes.codes_set(h, "bitmapPresent", 1)
        eccodes.codes_set(h, "missingValue", GWM_FILL_VALUE)
        vals = np.where(bitmap_mask.ravel(), GWM_FILL_VALUE, vals)
    eccodes.codes_set_values(h, vals)
    eccodes.codes_write(h, fout)
    eccodes.codes_release(h)


def write_gsm_file(path: Path, cycle: np.datetime64, step_h: int, fields: dict[str, np.ndarray], res_deg: float = 0.5,
                   order: Sequence[str] | None = None, lat_span: tuple[float, float] = (90.0, -90.0),
                   packing: str = "grid_simple") -> Path:
    """One GSM lead time: every array in `fields` (keys of GSM_FIELDS, shape (nlat, nlon) on jma_grid, or on the
    latitudes `lat_span` first → last in scan order). `packing="grid_ieee"` stores floats as they are (NaN, inf)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".part")
    with open(tmp, "wb") as fout:
        for name in order or fields:
            h = _new_message(cycle, step_h, res_deg, GSM_FIELDS[name], lat_span=lat_span, packing=packing)
            _write(fout, h, fields[name])
    tmp.replace(path)
    return path


def write_gwm_file(path: Path, cycle: np.datetime64, steps_h: Sequence[int], fields: dict[str, np.ndarray],
                   land: np.ndarray, res_deg: float = 0.5, land_as: str = "bitmap") -> Path:
    """Several GWM lead times: arrays (nstep, nlat, nlon); `land` (nlat, nlon) bool becomes a bitmap
    (`land_as="bitmap"`) or the fill value 9999 without a bitmap (`land_as="fill"`)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".part")
    with open(tmp, "wb") as fout:
        for i, step in enumerate(steps_h):
            for name, arr in fields.items():
                # a 9999 fill value stretches the packing range: more bits keep the sea values exact
                h = _new_message(cycle, int(step), res_deg, GWM_FIELDS[name], 16 if land_as == "bitmap" else 24)
                if land_as == "bitmap":
                    _write(fout, h, arr[i], bitmap_mask=land)
                else:
                    _write(fout, h, np.where(land, GWM_FILL_VALUE, arr[i]))
    tmp.replace(path)
    return path
