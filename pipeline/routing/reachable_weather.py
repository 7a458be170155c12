"""The weather a ship can meet on each leg over the times it can sail it: the ranges the exact DP's fuel-to-finish
bound is priced in (bound_tables.finish_bounds with `windows`), much tighter than the strongest weather near a node at any time.

A ship is at node (i, a) no earlier than its earliest arrival there (`earliest_arrival_nb`: legs are first-in-first-
out and the fastest setting is at least as fast in every condition, so sailing the fastest from the earliest time
reaches each node first) and, when the plan must make the RTA, no later than the latest departure from there
(bound_tables.latest_departures). A leg (i, a) → (i + 1, b) is therefore sailed between the first's earliest arrival and the
second's latest departure; over the valid times a sample then reads and the grid cells the leg reads (`_edge_box`),
the weather met lies in ranges that hold for every sample the leg kernel takes (`_box_ranges`):

  wind, current   a sample is a convex combination of the corner vectors it reads (bilinear in space, linear in
                  time, NaN corners left out and the others re-weighted; all NaN: calm). Its speed is at most the
                  largest corner's (with a NaN component in the box: the hypot of the largest components, since
                  the components are then interpolated over different corners), and at least the distance from the
                  origin to the corners' convex hull, bounded below by the least projection of the corners on
                  their mean direction (0 with a NaN in the box: a sample could be calm). While that is > 0 the
                  sample's direction lies between the corners' extreme directions. The current along the course is
                  at most the largest of the corners' along any course in the leg's range.
  Hs              between the least and largest corner (0 when a corner is NaN).
  wave direction  from the interpolated (sin, cos) components: between the corners' extreme directions as for
                  wind (free with a NaN in the box: the kernel then takes a wave from the north).
  course          along a great-circle chord the course turns monotonically (its rate is sin(course)·tan(lat)),
                  so it lies between the chord's first and last courses while it does not cross the equator.

The relative directions (from − course) then lie in intervals, and bound_tables._corner_bounds evaluates the model at the
corners of speed × folded relative direction, where both model forms take their extremes.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from pipeline.routing import geodesy as geo
from pipeline.routing.engine.leg import BEYOND_REL_DEG, N_LEG_OUT, sail_leg_nb
from pipeline.routing.weather_field import SWH, U10, UO, V10, VO, WAVE_X, WAVE_Y

WINDOW_SLACK_H = 1.0  # widening of every window (h): covers rounding in the kernels' time sums
BOX_MARGIN_CELLS = 0.02  # widening of a leg's box (in cells) beyond the chord points it was found from
COURSE_SLACK_DEG = 0.5  # widening of every course range: the kernel's course at a step is computed, not exact


@numba.njit(cache=True)
def _fastest_arrival(lat0, lon0, lat1, lon1, t, v, w, rpms, out):
    """Earliest arrival leaving at t at any of rpms; `t` itself when no setting makes headway then (a later start
    might: the node is still not reached before t)."""
    best = np.inf
    for r in range(rpms.shape[0]):
        sail_leg_nb(lat0, lon0, lat1, lon1, t, rpms[r], v, w, out)
        if out[2] == 0:  # engine.leg.CODE == OK
            best = min(best, t + out[0])  # engine.leg.H
    return best if best < np.inf else t


@numba.njit(cache=True)
def earliest_arrival_nb(g, v, w, rpms, t_dep_h, ea):
    """ea[i, a] ≤ the earliest time any plan reaches (i, a) (inf: unreachable through the graph's edges)."""
    lat, lon, edge_ok, max_shift = g.lat, g.lon, g.edge_ok, g.max_shift
    L2, P = lat.shape
    out = np.empty(N_LEG_OUT)
    ea[:] = np.inf
    ea[0, P // 2] = t_dep_h
    for i in range(L2 - 1):
        for a in range(P):
            if ea[i, a] == np.inf:
                continue
            for b in range(max(0, a - max_shift), min(P, a + max_shift + 1)):
                if edge_ok[i, a, b]:
                    t1 = _fastest_arrival(lat[i, a], lon[i, a], lat[i + 1, b], lon[i + 1, b], ea[i, a], v, w, rpms, out)
                    ea[i + 1, b] = min(ea[i + 1, b], t1)


@numba.njit(cache=True)
def _course_range_nb(la0, lo0, la1, lo1):
    """(lowest, highest) course (deg, the highest possibly above 360) along the chord; (0, 360) when it crosses the
    equator or comes near a pole."""
    if la0 * la1 <= 0.0 or abs(la0) > 85.0 or abs(la1) > 85.0:
        return 0.0, 360.0
    first = geo.gc_bearing_deg(la0, lo0, la1, lo1)
    last = (geo.gc_bearing_deg(la1, lo1, la0, lo0) + 180.0) % 360.0
    d = (last - first + 180.0) % 360.0 - 180.0  # as an offset from the first course: no jump across north
    return first + min(d, 0.0) - COURSE_SLACK_DEG, first + max(d, 0.0) + COURSE_SLACK_DEG


@numba.njit(cache=True)
def _edge_box(lat0, lon0, lat1, lon1, grid):
    """(y0, y1, c0, nc): rows y0:y1 and columns c0 + 0..nc (mod nlon when the grid wraps) holding every cell corner
    `sample_nb` reads anywhere on the chord (lat0, lon0) → (lat1, lon1). The chord is followed in steps of at most a
    quarter cell, along which its fractional grid coordinates move monotonically but for a bulge far below the
    BOX_MARGIN_CELLS they are widened by."""
    nlat, nlon = grid.nlat, grid.nlon
    ch = geo.chord(lat0, lon0, lat1, lon1)
    n = max(8, int(math.degrees(ch.d) / (0.25 * min(grid.dlat, grid.dlon))) + 1)
    fy_lo, fy_hi = np.inf, -np.inf
    fx_first, fx_lo, fx_hi = np.nan, np.inf, -np.inf
    for k in range(n + 1):
        la, lo = geo.chord_point(ch, k / n)
        fy = (la - grid.lat0) / grid.dlat
        fy_lo, fy_hi = min(fy_lo, fy), max(fy_hi, fy)
        fx = ((lo - grid.lon0) % 360.0) / grid.dlon
        if math.isnan(fx_first):
            fx_first = fx
        fx = fx_first + (fx - fx_first + 0.5 * (360.0 / grid.dlon)) % (360.0 / grid.dlon) - 0.5 * (360.0 / grid.dlon)
        fx_lo, fx_hi = min(fx_lo, fx), max(fx_hi, fx)
    # rows read at fy: min(int(clip(fy, 0, nlat − 1)), nlat − 2) and the one above, monotone in fy
    y0 = min(int(min(max(fy_lo - BOX_MARGIN_CELLS, 0.0), nlat - 1.0)), nlat - 2)
    y1 = min(int(min(max(fy_hi + BOX_MARGIN_CELLS, 0.0), nlat - 1.0)), nlat - 2) + 2
    if grid.wraps:
        c0 = int(math.floor(fx_lo - BOX_MARGIN_CELLS))
        nc = min(int(math.floor(fx_hi + BOX_MARGIN_CELLS)) - c0 + 2, nlon)
        return y0, y1, c0 % nlon, nc
    if fx_lo - BOX_MARGIN_CELLS < 0.0 or fx_hi + BOX_MARGIN_CELLS > nlon - 1.0:
        return y0, y1, 0, nlon  # off the grid's columns (clamped, or taken from the nearer edge): all of them
    c0 = min(int(fx_lo - BOX_MARGIN_CELLS), nlon - 2)  # columns read: as the rows
    return y0, y1, c0, min(int(fx_hi + BOX_MARGIN_CELLS), nlon - 2) + 2 - c0


@numba.njit(cache=True)
def _box_ranges(cells, grid, rows_cols, k0, k1, crs_lo, crs_hi, out):
    """Over the `rows_cols` (y0, y1, c0, nc: rows y0:y1, columns c0 + 0..nc, mod the grid's nlon when it wraps) and
    valid times k0..k1 of `cells`: out = (wind lo, hi (m/s), wind towards-direction lo, hi (deg; 0, 360 when free), Hs
    lo, hi (m), wave from-direction lo, hi, current along a course in crs_lo..crs_hi hi (m/s)), bounds on every sample that reads only these corners (see
    the module docstring). Two passes: sums and extremes over the cells, then projections of the wind and wave
    vectors kept from the first on their mean directions."""
    y0, y1, c0, nc = rows_cols
    nlon, wraps = grid.nlon, grid.wraps
    wsx, wsy, w_hi2, w_nan = 0.0, 0.0, 0.0, False
    ssx, ssy, s_nan = 0.0, 0.0, False
    h_lo, h_hi = np.inf, 0.0
    cur_hi, c_nan = -np.inf, False
    # largest |component| of wind and current: a component NaN at a corner where the other is not interpolates
    # over other corners than the other one, so only the components' own ranges bound the speed then
    wx_hi, wy_hi, cx_hi, cy_hi = 0.0, 0.0, 0.0, 0.0
    whole = crs_hi - crs_lo >= 180.0
    elx, ely = math.sin(math.radians(crs_lo)), math.cos(math.radians(crs_lo))
    ehx, ehy = math.sin(math.radians(crs_hi)), math.cos(math.radians(crs_hi))
    seen = np.empty(((y1 - y0) * nc * (k1 - k0 + 1), 4))  # the corners' wind and wave vectors, for the second pass
    n_seen = 0
    for y in range(y0, y1):
        for q in range(nc):
            x = (c0 + q) % nlon if wraps else c0 + q
            for k in range(k0, k1 + 1):
                c = cells[y, x, k]
                u, v = np.float64(c[U10]), np.float64(c[V10])
                sx, sy = np.float64(c[WAVE_X]), np.float64(c[WAVE_Y])
                seen[n_seen, 0], seen[n_seen, 1], seen[n_seen, 2], seen[n_seen, 3] = u, v, sx, sy
                n_seen += 1
                if math.isnan(u) or math.isnan(v):
                    w_nan = True
                    u = 0.0 if math.isnan(u) else u
                    v = 0.0 if math.isnan(v) else v
                wsx += u
                wsy += v
                w_hi2 = max(w_hi2, u * u + v * v)
                wx_hi, wy_hi = max(wx_hi, abs(u)), max(wy_hi, abs(v))
                if math.isnan(sx) or math.isnan(sy):
                    s_nan = True
                else:
                    ssx += sx
                    ssy += sy
                h = np.float64(c[SWH])
                if math.isnan(h):
                    h_lo = 0.0
                else:
                    h_lo, h_hi = min(h_lo, h), max(h_hi, h)
                cx, cy = np.float64(c[UO]), np.float64(c[VO])
                if not math.isnan(cx):
                    cx_hi = max(cx_hi, abs(cx))
                if not math.isnan(cy):
                    cy_hi = max(cy_hi, abs(cy))
                if math.isnan(cx) or math.isnan(cy):
                    c_nan = True
                    continue
                # along a course between the range's ends: the end's, or all of it when it points inside the range
                inside = whole or (cx * ely - cy * elx >= 0.0 and cy * ehx - cx * ehy >= 0.0)
                along = math.sqrt(cx * cx + cy * cy) if inside else max(cx * elx + cy * ely, cx * ehx + cy * ehy)
                cur_hi = max(cur_hi, along)
    out[0], out[1], out[2], out[3] = 0.0, math.hypot(wx_hi, wy_hi) if w_nan else math.sqrt(w_hi2), 0.0, 360.0
    out[4], out[5] = min(h_lo, h_hi), h_hi
    out[6], out[7] = 0.0, 360.0
    out[8] = math.hypot(cx_hi, cy_hi) if c_nan else cur_hi
    wn = math.hypot(wsx, wsy)
    sn = math.hypot(ssx, ssy)
    if (w_nan or wn == 0.0) and (s_nan or sn == 0.0):
        return
    # least projection on the mean direction (a lower bound on the distance from 0 to the corners' hull) and the
    # extreme directions as offsets from the mean (tan of the offset: every corner within 90° of the mean then)
    wnx, wny = (wsx / wn, wsy / wn) if wn > 0.0 else (0.0, 1.0)
    snx, sny = (ssx / sn, ssy / sn) if sn > 0.0 else (0.0, 1.0)
    w_lo, w_tlo, w_thi = np.inf, np.inf, -np.inf
    s_lo, s_tlo, s_thi = np.inf, np.inf, -np.inf
    for n in range(n_seen):
        u, v, sx, sy = seen[n, 0], seen[n, 1], seen[n, 2], seen[n, 3]
        dot = wnx * u + wny * v
        w_lo = min(w_lo, dot)
        if dot > 0.0:
            t = (u * wny - v * wnx) / dot
            w_tlo, w_thi = min(w_tlo, t), max(w_thi, t)
        dot = snx * sx + sny * sy
        s_lo = min(s_lo, dot)
        if dot > 0.0:
            t = (sx * sny - sy * snx) / dot
            s_tlo, s_thi = min(s_tlo, t), max(s_thi, t)
    if not w_nan and wn > 0.0 and w_lo > 0.0:
        base = math.degrees(math.atan2(wnx, wny))
        out[0] = w_lo
        out[2], out[3] = base + math.degrees(math.atan(w_tlo)), base + math.degrees(math.atan(w_thi))
    if not s_nan and sn > 0.0 and s_lo > 0.0:
        base = math.degrees(math.atan2(snx, sny))
        out[6], out[7] = base + math.degrees(math.atan(s_tlo)), base + math.degrees(math.atan(s_thi))


@numba.njit(cache=True)
def _cos_range(lo_deg, hi_deg):
    """(least, largest) cosine over the angles lo_deg..hi_deg (hi ≥ lo)."""
    if hi_deg - lo_deg >= 360.0:
        return -1.0, 1.0
    c0, c1 = math.cos(math.radians(lo_deg)), math.cos(math.radians(hi_deg))
    c_lo, c_hi = min(c0, c1), max(c0, c1)
    if 360.0 * math.floor(hi_deg / 360.0) >= lo_deg:  # a multiple of 360° inside: head-on
        c_hi = 1.0
    if 360.0 * math.floor((hi_deg - 180.0) / 360.0) + 180.0 >= lo_deg:  # an odd multiple of 180° inside: astern
        c_lo = -1.0
    return c_lo, c_hi


@numba.njit(cache=True)
def reachable_ranges_nb(w, g, t_lo, t_hi, out):
    """Per leg (i, a) → (i + 1, a + s − max_shift): out[i, a, s] = (wind lo, wind hi (m/s), wind relative direction
    lo, hi (folded deg 0..180), Hs lo, hi (m), wave relative direction lo, hi, current along course hi (m/s)) over
    the leg's cells (`_edge_box`) and the valid times a sample at t_lo[i, a]..t_hi[i + 1, b] (h) reads, widened to
    the neutral weather past the last valid time (beyond_wind_ms and beyond_hs_m at BEYOND_REL_DEG, no current) when the
    window reaches past it; NaN when that window is empty (no plan within the windows sails the leg); legs that are
    not edges are left as they are. `w`: the weather (weather_field.Weather), `g`: the graph (search_space.Graph)."""
    cells, times_h, grid, beyond_wind_ms, beyond_hs_m = w.cells, w.times_h, w.grid, w.beyond_wind_ms, w.beyond_hs_m
    lat, lon, edge_ok, max_shift = g.lat, g.lon, g.edge_ok, g.max_shift
    nt = times_h.shape[0]
    L2, P = lat.shape
    box = np.empty(9)
    for i in range(L2 - 1):
        for a in range(P):
            for b in range(max(0, a - max_shift), min(P, a + max_shift + 1)):
                if not edge_ok[i, a, b]:
                    continue
                s_ = b - a + max_shift
                rows_cols = _edge_box(lat[i, a], lon[i, a], lat[i + 1, b], lon[i + 1, b], grid)
                t0, t1 = t_lo[i, a], t_hi[i + 1, b]
                if not t0 <= t1:  # no plan within the windows sails this leg
                    out[i, a, s_, :] = np.nan
                    continue
                # valid times a sample in the window reads: the last ≤ t0 up to the first ≥ t1
                k0 = max(np.searchsorted(times_h, t0, side="right") - 1, 0)
                k1 = max(min(np.searchsorted(times_h, t1, side="left"), nt - 1), k0)
                crs_lo, crs_hi = _course_range_nb(lat[i, a], lon[i, a], lat[i + 1, b], lon[i + 1, b])
                _box_ranges(cells, grid, rows_cols, k0, k1, crs_lo, crs_hi, box)
                wlo, whi, wdlo, wdhi, h_lo, h_hi, sdlo, sdhi, cur_hi = box
                # wind comes FROM the opposite of where it blows: from = towards + 180; relative = from − course
                c_lo, c_hi = _cos_range(wdlo + 180.0 - crs_hi, wdhi + 180.0 - crs_lo)
                w_lo, w_hi = _cos_range(sdlo - crs_hi, sdhi - crs_lo)
                o = out[i, a, s_]
                o[0], o[1] = wlo, whi
                o[2], o[3] = math.degrees(math.acos(min(c_hi, 1.0))), math.degrees(math.acos(max(c_lo, -1.0)))
                o[4], o[5] = h_lo, h_hi
                o[6], o[7] = math.degrees(math.acos(min(w_hi, 1.0))), math.degrees(math.acos(max(w_lo, -1.0)))
                o[8] = cur_hi
                if t1 > times_h[nt - 1]:  # the leg may be sailed past the last valid time: the neutral weather too
                    o[0], o[1] = min(o[0], beyond_wind_ms), max(o[1], beyond_wind_ms)
                    o[2], o[3] = min(o[2], BEYOND_REL_DEG), max(o[3], BEYOND_REL_DEG)
                    o[4], o[5] = min(o[4], beyond_hs_m), max(o[5], beyond_hs_m)
                    o[6], o[7] = min(o[6], BEYOND_REL_DEG), max(o[7], BEYOND_REL_DEG)
                    o[8] = max(o[8], 0.0)
