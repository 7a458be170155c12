"""Time-dependent sailing of one leg, and of a whole route, compiled with numba.

A leg is the great-circle chord between two nodes. The ship steps along it, each step at most
`max_step_h` hours (the last step shorter): at the step's start it samples the weather, takes
the relative wind and wave angles from its course there, gets speed through water and fuel rate
from its performance model at the leg's rpm, adds the current along course (SOG = STW + current
along course), and advances. Hours and fuel (rate × time) accumulate; weather limits (Hs, wind)
make the leg infeasible with a code. Where the wind is missing (a hole in the cube: every corner and both
bracketing times NaN; GSM wind has no land mask, so this is never land) the step is sailed as calm but its
hours are counted in NO_WIND_H, so the plan can say so instead of passing the hole off as calm weather.
Past the weather's last valid time a step is sailed in the field's neutral weather (its mean wind speed and Hs at
BEYOND_REL_DEG off the bow on every course, no current: weather_field.WeatherField.neutral_beyond), never the last
step frozen in place; the fuel burnt there is FUEL_BEYOND, the part of a saving no forecast backs.
The weather met along the leg (mean wind, Hs, directions, current, STW) is what a plan's legs show; the
searches, which sail a leg hundreds of thousands of times a voyage, skip it (`sail_leg_nb` against
`sail_leg_weather_nb`).

A leg of the vessel's `fixed_legs` (a canal's fairway, canal_time.py) is not integrated: it takes its fixed hours and
fuel whatever the rpm and the weather, so every solver and the constant-speed baseline sail a canal alike.

The ship comes as a `Vessel` (its performance model at the voyage's draft and trim, weather limits,
the allowed engine settings and the integration step), the weather as a `weather_field.Weather`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

# The performance functions compiled in here live in another file; numba's cache folder is keyed on the
# digest of every pipeline source (pipeline.compile_cache), so their edits are seen.
from pipeline.performance.features import (DIR_B, DIR_C, FORM_PHYSICAL, fuel_physical_terms_nb, fuel_tph_nb,
                                           stw_kn_nb, stw_physical_terms_nb, weather_terms_nb)
from pipeline.routing import geodesy as geo
from pipeline.routing.weather_field import N_VARS, SWH, U10, UO, V10, VO, WAVE_X, WAVE_Y, sample_nb

OK, WAVE_LIMIT, WIND_LIMIT, NO_HEADWAY, NO_EDGE, TOO_LONG = 0, 1, 2, 3, 4, 5
REASONS = {
    OK: "ok",
    WAVE_LIMIT: "significant wave height above the vessel's limit",
    WIND_LIMIT: "wind above the vessel's limit",
    NO_HEADWAY: "cannot make headway (speed over ground below 0.5 kn)",
    NO_EDGE: "leg crosses land, a limit line or the latitude limits",
    TOO_LONG: "voyage takes longer than the planning horizon",
}
N_LEG_OUT = 16
# columns of Vessel.fixed_legs: the leg's ends (degrees, as the graph's nodes) and its fixed hours and fuel (t)
FIX_LAT0, FIX_LON0, FIX_LAT1, FIX_LON1, FIX_H, FIX_FUEL = range(6)
NO_FIXED_LEGS = np.zeros((0, 6))
FIX_TOL_DEG = 1e-9
# leg_out fields (NO_WIND_H: hours of the leg sailed where the wind is missing; FUEL_BEYOND: the part of FUEL burnt
# after the weather's last valid time, where the leg is sailed in the neutral weather)
(H, FUEL, CODE, BEYOND, WIND_KN, WIND_FX, WIND_FY, HS, WAVE_FX, WAVE_FY, CUR_ALONG_KN, STW_KN, SOG_KN, CUR_KN,
 NO_WIND_H, FUEL_BEYOND) = range(N_LEG_OUT)
MIN_SOG_KN = 0.5
# Past the weather's last valid time wind and waves meet the ship at this angle off the bow, whatever its course: the
# angle at which the physical form's direction weight w(θ) = A + B·cos θ + C·cos² θ equals its mean over all
# headings, A + C/2 (B·c + C·c² = C/2), so the added resistance there is the mean over headings (≈ 82.3°; the thesis
# form, linear in the folded angle, has its mean at 90°)
BEYOND_REL_DEG = math.degrees(math.acos((-DIR_B + math.sqrt(DIR_B * DIR_B + 2.0 * DIR_C * DIR_C)) / (2.0 * DIR_C)))


class Vessel(NamedTuple):
    """The ship as the kernels see it: performance model (form and coefficients, see pipeline.performance), the
    voyage's draft and trim (m), months since dry dock, weather limits (inf: none), the allowed engine settings
    (rpm, increasing) and the longest integration step along a leg (h)."""

    form_id: int
    draft_m: float
    trim_m: float
    months_dd: float
    max_hs_m: float
    max_wind_kn: float
    max_step_h: float
    speed_coef: np.ndarray
    fuel_coef: np.ndarray
    rpm_options: np.ndarray
    fixed_legs: np.ndarray = NO_FIXED_LEGS


class OnRoute(NamedTuple):
    """A fixed route as the kernels sail it: the graph (`search_space.Graph`), the route's node per line, the vessel
    (a `Vessel`) and the weather."""

    g: object
    nodes: np.ndarray
    v: object
    w: object


class Voyage(NamedTuple):
    """The voyage as the kernels sail it: graph, vessel, weather and objective."""

    g: object
    v: object
    w: object
    o: object


def _limit(x: float | None) -> float:
    return math.inf if x is None or math.isnan(x) else float(x)


def vessel(model, *, draft_m: float = 10.0, trim_m: float = 0.0, max_hs_m: float | None = None,
           max_wind_kn: float | None = None, max_step_h: float = 1.0, rpm_options=(100.0,)) -> Vessel:
    """A `Vessel` from a `PerformanceModel` and the voyage's loading, limits and allowed rpm settings."""
    return Vessel(int(model.form_id), float(draft_m), float(trim_m), float(model.months_dd), _limit(max_hs_m),
                  _limit(max_wind_kn), float(max_step_h), np.ascontiguousarray(model.speed_coef, dtype=np.float64),
                  np.ascontiguousarray(model.fuel_coef, dtype=np.float64),
                  np.ascontiguousarray(np.sort(np.asarray(rpm_options, dtype=np.float64))))


@numba.njit(cache=True, inline="always")
def _stw_and_fuel_rate(ves, rpm, wind_kn, wind_rel, hs, wave_rel):
    """(STW kn, fuel rate t/h) of the vessel in one condition: `stw_kn_nb` and `fuel_tph_nb`, the physical form's
    weather loads worked out once for both (the same numbers)."""
    if ves.form_id == FORM_PHYSICAL:
        wind_term, wave_term = weather_terms_nb(wind_kn, wind_rel, hs, wave_rel)
        return (stw_physical_terms_nb(ves.speed_coef, rpm, ves.draft_m, ves.trim_m, ves.months_dd, wind_term, wave_term),
                fuel_physical_terms_nb(ves.fuel_coef, rpm, ves.draft_m, ves.months_dd, wind_term, wave_term))
    return (stw_kn_nb(ves.form_id, ves.speed_coef, rpm, ves.draft_m, ves.trim_m, wind_kn, wind_rel, hs, wave_rel,
                      ves.months_dd),
            fuel_tph_nb(ves.form_id, ves.fuel_coef, rpm, ves.draft_m, ves.trim_m, wind_kn, wind_rel, hs, wave_rel,
                        ves.months_dd))


@numba.njit(cache=True, inline="always")
def _sail_leg(ends, t0_h, rpm, ves, wx, out, weather_met):
    """The leg from (lat0, lon0) to (lat1, lon1) = `ends`, with the weather met accumulated when `weather_met` (a
    constant of each caller)."""
    lat0, lon0, lat1, lon1 = ends
    for k in range(N_LEG_OUT):
        out[k] = 0.0
    dist = geo.gc_distance_nm(lat0, lon0, lat1, lon1)
    if dist < 1e-6:
        return
    horizon_h = wx.times_h[wx.times_h.shape[0] - 1]
    fx = ves.fixed_legs
    for k in range(fx.shape[0]):
        if (abs(lat0 - fx[k, FIX_LAT0]) < FIX_TOL_DEG and abs(lon0 - fx[k, FIX_LON0]) < FIX_TOL_DEG
                and abs(lat1 - fx[k, FIX_LAT1]) < FIX_TOL_DEG and abs(lon1 - fx[k, FIX_LON1]) < FIX_TOL_DEG):
            hours, fuel = fx[k, FIX_H], fx[k, FIX_FUEL]
            out[H] = hours
            out[FUEL] = fuel
            out[SOG_KN] = dist / hours
            out[STW_KN] = dist / hours  # the canal's pace: no weather or current counted inside it
            if t0_h + hours > horizon_h:
                out[BEYOND] = 1.0
                out[FUEL_BEYOND] = fuel * (t0_h + hours - max(t0_h, horizon_h)) / hours
            return
    w = np.empty(N_VARS)
    chord = geo.chord(lat0, lon0, lat1, lon1)  # the leg's trigonometry once, not at every step
    done, t, fuel = 0.0, t0_h, 0.0
    while done < dist - 1e-9:
        lat, lon = geo.chord_point(chord, done / dist)
        hdg = geo.chord_course_deg(chord, lat, lon)
        beyond = sample_nb(wx, t, lat, lon, w)
        if beyond:
            # past the last valid time: the neutral weather (weather_field.WeatherField.neutral_beyond), the same
            # wind speed and Hs at BEYOND_REL_DEG off the bow and no current everywhere, never the last step frozen
            out[BEYOND] = 1.0
            no_wind = False
            wind_from = hdg + BEYOND_REL_DEG
            wave_from = wind_from
            u = -wx.beyond_wind_ms * math.sin(math.radians(wind_from))
            v = -wx.beyond_wind_ms * math.cos(math.radians(wind_from))
            hs = wx.beyond_hs_m
            wave_x, wave_y = math.sin(math.radians(wave_from)), math.cos(math.radians(wave_from))
            uo, vo = 0.0, 0.0
        else:
            no_wind = math.isnan(w[U10]) or math.isnan(w[V10])
            u = 0.0 if math.isnan(w[U10]) else w[U10]
            v = 0.0 if math.isnan(w[V10]) else w[V10]
            hs = 0.0 if math.isnan(w[SWH]) else w[SWH]
            wave_x = 0.0 if math.isnan(w[WAVE_X]) else w[WAVE_X]
            wave_y = 1.0 if math.isnan(w[WAVE_Y]) else w[WAVE_Y]
            uo = 0.0 if math.isnan(w[UO]) else w[UO]
            vo = 0.0 if math.isnan(w[VO]) else w[VO]
            wind_from = math.degrees(math.atan2(-u, -v))
            wave_from = math.degrees(math.atan2(wave_x, wave_y))
        wind_kn = math.sqrt(u * u + v * v) * geo.KN_PER_MS
        if hs > ves.max_hs_m:
            out[CODE] = WAVE_LIMIT
            return
        if wind_kn > ves.max_wind_kn:
            out[CODE] = WIND_LIMIT
            return
        wind_rel = wind_from - hdg
        wave_rel = wave_from - hdg
        stw, fuel_tph = _stw_and_fuel_rate(ves, rpm, wind_kn, wind_rel, hs, wave_rel)
        cur = geo.along_course(uo, vo, hdg) * geo.KN_PER_MS
        sog = stw + cur
        if sog < MIN_SOG_KN:
            out[CODE] = NO_HEADWAY
            return
        ds = min(dist - done, sog * ves.max_step_h)
        dt = ds / sog
        fuel += fuel_tph * dt
        out[FUEL_BEYOND] += fuel_tph * max(0.0, t + dt - max(t, horizon_h))
        if weather_met:
            out[WIND_KN] += wind_kn * dt
            out[WIND_FX] += math.sin(math.radians(wind_from)) * dt
            out[WIND_FY] += math.cos(math.radians(wind_from)) * dt
            out[HS] += hs * dt
            out[WAVE_FX] += wave_x * dt
            out[WAVE_FY] += wave_y * dt
            out[CUR_ALONG_KN] += cur * dt
            out[STW_KN] += stw * dt
            out[CUR_KN] += math.sqrt(uo * uo + vo * vo) * geo.KN_PER_MS * dt
        if no_wind:
            out[NO_WIND_H] += dt
        t += dt
        done += ds
    hours = t - t0_h
    if hours <= 0.0:
        return
    out[H] = hours
    out[FUEL] = fuel
    if weather_met:
        for k in (WIND_KN, WIND_FX, WIND_FY, HS, WAVE_FX, WAVE_FY, CUR_ALONG_KN, STW_KN, CUR_KN):
            out[k] /= hours
    out[SOG_KN] = dist / hours


@numba.njit(cache=True)
def sail_leg_nb(lat0, lon0, lat1, lon1, t0_h, rpm, ves, wx, out):
    """Sail one leg starting at t0_h (hours after the weather's t_ref) at `rpm`; results in out[0:N_LEG_OUT], the
    weather met (WIND_KN … CUR_KN, which no search reads) left 0: `sail_leg_weather_nb` fills those too."""
    _sail_leg((lat0, lon0, lat1, lon1), t0_h, rpm, ves, wx, out, False)


@numba.njit(cache=True)
def sail_leg_weather_nb(lat0, lon0, lat1, lon1, t0_h, rpm, ves, wx, out):
    """`sail_leg_nb` with the weather met along the leg (time-weighted means) in out: what a plan's legs show."""
    _sail_leg((lat0, lon0, lat1, lon1), t0_h, rpm, ves, wx, out, True)


@numba.njit(cache=True)
def sail_route_nb(nodes, rpm_idx, start_line, g, ves, wx, obj, cum_t, cum_f):
    """Sail a route (node per line, rpm index per leg) over the graph `g` from line `start_line`, reusing
    cum_t/cum_f before it; `obj` (an `objectives.Objective`) gives the departure time and the planning horizon.

    cum_t[i], cum_f[i]: hours after t_ref and fuel so far on reaching line i (cum_t[0] = obj.t_dep_h).
    Returns (code, failing leg); code 0 when the whole route was sailed.
    """
    out = np.empty(N_LEG_OUT)
    lat, lon, edge_ok, rpm_options = g.lat, g.lon, g.edge_ok, ves.rpm_options
    if start_line == 0:
        cum_t[0] = obj.t_dep_h
        cum_f[0] = 0.0
    for i in range(start_line, nodes.shape[0] - 1):
        a, b = nodes[i], nodes[i + 1]
        if not edge_ok[i, a, b]:
            return NO_EDGE, i
        sail_leg_nb(lat[i, a], lon[i, a], lat[i + 1, b], lon[i + 1, b], cum_t[i], rpm_options[rpm_idx[i]], ves, wx, out)
        if out[CODE] != OK:
            return int(out[CODE]), i
        cum_t[i + 1] = cum_t[i] + out[H]
        cum_f[i + 1] = cum_f[i] + out[FUEL]
        if cum_t[i + 1] - obj.t_dep_h > obj.max_hours:
            return TOO_LONG, i
    return OK, -1


def sail_leg(lat0, lon0, lat1, lon1, t0_h, rpm, ves: Vessel, field) -> np.ndarray:
    """Python entry: one leg in a `WeatherField`, with the weather met; returns the N_LEG_OUT array."""
    out = np.empty(N_LEG_OUT)
    sail_leg_weather_nb(float(lat0), float(lon0), float(lat1), float(lon1), float(t0_h), float(rpm), ves, field.kernel, out)
    return out


def sail_leg_python(lat0, lon0, lat1, lon1, t0_h, rpm, ves: Vessel, field) -> np.ndarray:
    """The same leg through the interpreted (non-compiled) code path, for verification."""
    out = np.empty(N_LEG_OUT)
    _sail_leg.py_func((float(lat0), float(lon0), float(lat1), float(lon1)), float(t0_h), float(rpm), ves, field.kernel,
                      out, True)
    return out
