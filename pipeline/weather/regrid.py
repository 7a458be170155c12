"""NaN-aware bilinear regridding onto the routing grid, with longitude wrap-around.

A target point takes the weighted mean of the valid (non-NaN) corners of its source cell, so
coastal sea points keep a value while points whose four corners are land stay NaN. Directions
(`mwd`, degrees) are interpolated through their unit-vector components, never as angles.
"""

from __future__ import annotations

import numba
import numpy as np
import xarray as xr

DIRECTION_VARS = ("mwd",)


def _axis_weights(src: np.ndarray, dst: np.ndarray, periodic: bool):
    """Indices i0, i1 and weight w1 of `dst` within ascending `src` (periodic: 360° wrap)."""
    if periodic:
        ext = np.concatenate([src, [src[0] + 360.0]])
        x = np.mod(dst - src[0], 360.0) + src[0]
        i0 = np.clip(np.searchsorted(ext, x, side="right") - 1, 0, ext.size - 2)
        w1 = (x - ext[i0]) / (ext[i0 + 1] - ext[i0])
        i1 = (i0 + 1) % src.size
        return i0, i1, np.clip(w1, 0.0, 1.0), np.ones(dst.shape, bool)
    inside = (dst >= src[0] - 1e-9) & (dst <= src[-1] + 1e-9)
    i0 = np.clip(np.searchsorted(src, dst, side="right") - 1, 0, src.size - 2)
    w1 = np.clip((dst - src[i0]) / (src[i0 + 1] - src[i0]), 0.0, 1.0)
    return i0, i0 + 1, w1, inside


def _aligned(src: np.ndarray, dst: np.ndarray, periodic: bool) -> np.ndarray | None:
    """Indices of `dst` in `src` when every destination point is a source point (else None)."""
    x = np.mod(dst - src[0], 360.0) + src[0] if periodic else dst
    i = np.clip(np.searchsorted(src, x - 1e-9), 0, src.size - 1)
    return i if np.all(np.abs(src[i] - x) <= 1e-9) else None


def subset_if_aligned(values: np.ndarray, src_lat, src_lon, dst_lat, dst_lon) -> np.ndarray | None:
    """`values` (..., nlat, nlon) at the destination points when they all lie on source points — what
    `bilinear` gives there, without interpolating — else None. Latitudes outside the source are NaN."""
    src_lat, dst_lat = np.asarray(src_lat, float), np.asarray(dst_lat, float)
    inside = (dst_lat >= src_lat[0] - 1e-9) & (dst_lat <= src_lat[-1] + 1e-9)
    j = _aligned(src_lat, np.where(inside, dst_lat, src_lat[0]), periodic=False)
    i = _aligned(np.asarray(src_lon, float), np.asarray(dst_lon, float), periodic=True)
    if j is None or i is None:
        return None
    out = np.asarray(values, dtype=np.float32)[..., j[:, None], i[None, :]]
    out[..., ~inside, :] = np.nan
    return out


def bilinear(values: np.ndarray, src_lat, src_lon, dst_lat, dst_lon) -> np.ndarray:
    """Regrid `values` (..., nlat, nlon) from ascending src axes to dst axes; NaN-aware (float32)."""
    j0, j1, wj, inside = _axis_weights(np.asarray(src_lat, float), np.asarray(dst_lat, float), periodic=False)
    i0, i1, wi, _ = _axis_weights(np.asarray(src_lon, float), np.asarray(dst_lon, float), periodic=True)
    v = np.asarray(values, dtype=np.float32)
    lead = v.shape[:-2]
    out = np.empty((int(np.prod(lead, dtype=np.int64)), j0.size, i0.size), dtype=np.float32)
    _bilinear_nb(v.reshape(-1, *v.shape[-2:]), np.stack([j0, j1]), np.stack([i0, i1]), np.stack([1.0 - wj, wj]),
                 np.stack([1.0 - wi, wi]), out)
    out = out.reshape(lead + out.shape[-2:])
    out[..., ~inside, :] = np.nan
    return out


@numba.njit(cache=True, nogil=True)  # decode workers regrid in threads
def _bilinear_nb(v, jj, ii, wy, wx, out):
    """out[t, a, b] = Σ w·v over the valid corners / Σ w over them (NaN if that is ≤ 1e-6).

    Corner weight w = wy·wx (float64, rounded to float32); corners are summed in the order
    (j0,i0), (j0,i1), (j1,i0), (j1,i1) in float32.
    """
    zero = np.float32(0.0)
    one = np.float32(1.0)
    tiny = np.float32(1e-6)
    nan = np.float32(np.nan)
    for t in range(v.shape[0]):
        for a in range(out.shape[1]):
            for b in range(out.shape[2]):
                acc = zero
                wsum = zero
                for cy in range(2):
                    for cx in range(2):
                        val = v[t, jj[cy, a], ii[cx, b]]
                        wc = np.float32(wy[cy, a] * wx[cx, b])
                        if np.isnan(val):
                            acc = acc + zero * wc
                        else:
                            acc = acc + val * wc
                            wsum = wsum + one * wc
                out[t, a, b] = acc / wsum if wsum > tiny else nan


def _same_axis(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == np.shape(b) and bool(np.array_equal(a, b))


def regrid(ds: xr.Dataset, lat: np.ndarray, lon: np.ndarray) -> xr.Dataset:
    """Regrid every (…, lat, lon) variable of a canonical dataset onto (lat, lon). A dataset already on
    exactly that grid is returned as it is (values as float32, no copy)."""
    if _same_axis(ds.lat.values, lat) and _same_axis(ds.lon.values, lon) and all(
            da.dtype == np.float32 for da in ds.data_vars.values() if da.dims[-2:] == ("lat", "lon")):
        return ds
    out = {}
    for name, da in ds.data_vars.items():
        if da.dims[-2:] != ("lat", "lon"):
            continue
        same = subset_if_aligned(da.values, ds.lat.values, ds.lon.values, lat, lon)
        if same is not None:  # e.g. 0.5° GSM onto the 0.5° routing grid: no interpolation, directions kept exactly
            vals = same
        elif name in DIRECTION_VARS:
            rad = np.radians(da.values)
            s = bilinear(np.sin(rad), ds.lat.values, ds.lon.values, lat, lon)
            c = bilinear(np.cos(rad), ds.lat.values, ds.lon.values, lat, lon)
            vals = (np.degrees(np.arctan2(s, c)) + 360.0) % 360.0
        else:
            vals = bilinear(da.values, ds.lat.values, ds.lon.values, lat, lon)
        out[name] = (da.dims, vals.astype(np.float32, copy=False), da.attrs)
    coords = {k: v for k, v in ds.coords.items() if "lat" not in v.dims and "lon" not in v.dims}
    coords.update(lat=("lat", np.asarray(lat), {"units": "degrees_north"}), lon=("lon", np.asarray(lon), {"units": "degrees_east"}))
    return xr.Dataset(out, coords=coords, attrs=ds.attrs)
