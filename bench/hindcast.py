"""Hindcast bench: plans sailed through the weather that actually happened (issue 41, item 5).

truth        an analytic North-Pacific "truth" (lat 5..62 N, lon 130 E..110 W, 1° grid, 3-hourly valid times over
             40 days from 2021-01-01 00 UTC): trades (easterlies south of 28 N) and westerlies (35..50 N), a Kuroshio-
             extension current jet along 35.5 N (to 1.3 m/s, fading east of 165 E) and a weak North-Pacific current,
             and moving extratropical cyclones (seeded: genesis every 18..42 h at 28..42 N 135..175 E, moving east-
             north-east at 15..30 kn, living 3..6 days, peak wind 16..25 m/s at 100..200 NM from the centre,
             counter-clockwise). Waves: Hs = 0.8 + 0.0112·w² m (Hs 7.8 m at 25 m/s), coming from where the wind comes.
forecasts    a cycle every 12 h (00 and 12 UTC), valid every 6 h to 132 h then every 12 h to 264 h (`--max-lead 132`
             for the short horizon), each the truth with its storms displaced and scaled: position error σ(L) =
             50 NM · L/24 to 24 h, then growing linearly to 300 NM at 120 h (and on, 675 NM at 264 h), a fixed random
             normal direction per storm and cycle (so errors grow smoothly along the leads); intensity error factor
             1 + ε(L)·z, ε = 8 % at 0 h growing to 22 % at 120 h (and held), z ~ N(0, 1) per storm and cycle; storms
             born after the cycle are missing. Trades, westerlies and currents are forecast exactly. A cycle is used
             from its nominal time (no latency).
voyages      ≥ 24 (`--voyages`; 8 with `--quick`), seeded: half along the storm belt (west-east or east-west between
             30 and 46 N), half across it (south-west to north-east and back), 1,600–4,000 NM great circle, leaving at a
             cycle time between day 1 and day 10; tight RTAs (the great circle at 12 kn) and loose ones (10.5 kn)
             alternate. Vessel: reference_model(14 kn at 100 rpm, 28 t/h), rpm 70/85/100, draft 10 m.
strategies   each sailed on the TRUTH with the product's leg kernel (engine/leg.py sail_leg, max step 1 h):
             master   the great circle at one constant rpm, reset every 12 h (at each cycle) to the rpm that arrives at
                      the RTA sailing the rest of the great circle in the newest forecast (bisection);
             once     the product's `solve()` (default solver and options, as `jitroute route`) on the cycle at
                      departure, sailed as made (legs, rpm, waits);
             replan   the same at departure, then every 12 h from the ship's position on the truth on the new cycle
                      (as route-fleet re-plans a ship at sea: the voyage from its position and time, same RTA,
                      pipeline/enroute.voyage_from), until less than 12 h or 60 NM are left;
             perfect  `solve()` on the truth itself, sailed as made.
             once/replan calibrated   the same with the arrival margin of the product's forecast-error model
                      (pipeline/routing/calibration.py): aim bias + k·σ_eta(hours ahead) before the RTA (k =
                      `--margin-sigmas` 1.65, at most `--margin-max-share` 0.15 of the hours ahead; re-planned at sea
                      each cycle, so it shrinks as the voyage nears its end), the model's calm or stormy part for
                      the route's severity where the fit split it (mean Hs along the plan made for the RTA,
                      calibration.route_hs_mean_m), claiming the saving the model expects the plan to realise (its
                      P50: skill × the gain, less the margin's cost) against the constant speed arriving at the RTA
                      (robust.margin_charged, as job.robust_plan). The model is fitted first on
                      TRAINING voyages of their own seed (`--train-seed`, default --seed + 1000: another truth, other
                      storms, other forecasts and voyages; `--train-voyages` 12, 8 with --quick): each re-planned every
                      cycle, every plan made (at departure and at sea) re-sailed as made on that truth with the
                      product's verification.verify, as `jitroute verify` fills plan_verification; never on the voyages
                      it is scored on. `--margin-sigmas 0` leaves them out.
             `--robust` adds the robust decisions (pipeline/routing/robust.py) over a lagged ensemble of the newest
             4 cycles: (a) margin and (b) win share alone to `once`; each alone and all three to `replan`.
measures     fleet fuel saving vs the master: Σ(F_master − F) / Σ F_master; arrival-corrected: each voyage's fuel
             scaled by (passage hours / RTA hours)² (fuel ∝ speed² over a fixed distance), so arriving late saves
             nothing and early costs nothing; voyages worse than the master by > 1 % (corrected); on time: arrival
             ≤ RTA + 0.5 h; |claimed − realised|: the plan at departure's claimed saving (savings_total_pct, vs its
             constant-speed baseline on the forecast) against the realised saving vs the master, in points; for the
             calibrated strategies also each plan they made (at departure and at sea) against its own baseline, both
             re-sailed as made on the truth, as `jitroute verify` fills plan_verification (out of sample: the model
             is fitted on the training seed); and, per re-planned voyage, `late_from_h`: the hours after departure
             when a plan first said the RTA cannot be met (status late) in the newest forecast.
targets      (issue 41) replan realises ≥ half of what perfect realises (corrected, aggregate); no replan voyage
             > 1 % worse than the master; on time ≥ 95 %; mean |claimed − realised| ≤ 1 point.

Searches are paced by work only (the solvers' iteration counts), so results do not depend on the machine's load;
numba single-threaded. Prints the table and the targets; writes bench/out/hindcast.json; always exits 0.

    .venv/bin/python bench/hindcast.py [--quick] [--voyages 24] [--seed 41] [--max-lead 264] [--robust]
        [--train-seed 1041] [--train-voyages 12] [--margin-sigmas 1.65] [--margin-max-share 0.15]
        [--margin-horizon-h H]
"""

from __future__ import annotations

import os

os.environ.setdefault("NUMBA_NUM_THREADS", "1")  # before numba is imported anywhere

import argparse  # noqa: E402
import functools  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from pipeline.performance.model import reference_model  # noqa: E402
from pipeline.routing.engine import leg as lk  # noqa: E402
from pipeline.routing import calibration, robust  # noqa: E402
from pipeline.routing import verification as ver  # noqa: E402
from pipeline.routing import weather_field as wf  # noqa: E402
from pipeline.routing.ensemble import ON_TIME_TOL_H  # noqa: E402
from pipeline.routing.geodesy import gc_distance_nm, gc_interpolate  # noqa: E402
from pipeline.routing.problem import RoutingInputError, RoutingProblem  # noqa: E402
from pipeline.routing.search_space import VoyageGeometryError  # noqa: E402
from pipeline.routing.solve import solve  # noqa: E402

T0 = np.datetime64("2021-01-01T00:00", "s")
TRUTH_DAYS = 40
LAT = np.arange(5.0, 62.0 + 1e-9, 1.0)
LON = np.arange(130.0, 250.0 + 1e-9, 1.0)
MODEL = reference_model(14.0, 100.0, 28.0)
RPM = (70.0, 85.0, 100.0)
CYCLE_H = 12
N_MEMBERS = 4  # the lagged ensemble of --robust (the product's default routing.ensemble_members)
WORSE_PCT = 1.0
TARGET_ON_TIME = 0.95
TARGET_CLAIM_PTS = 1.0


# ---------------------------------------------------------------------------------------------- truth and forecasts
@dataclass(frozen=True)
class Storm:
    born_h: float  # hours after T0
    life_h: float
    lat0: float
    lon0: float
    speed_kn: float
    heading_deg: float  # course of the track, degrees true
    peak_ms: float
    rmax_nm: float

    def centre(self, t_h):
        d_nm = self.speed_kn * (t_h - self.born_h)
        h = math.radians(self.heading_deg)
        lat = self.lat0 + d_nm * math.cos(h) / 60.0
        lon = self.lon0 + d_nm * math.sin(h) / (60.0 * math.cos(math.radians(lat)))
        return lat, lon

    def strength(self, t_h) -> float:
        """0..1: grows over the first third of its life, decays over the last third."""
        a = (t_h - self.born_h) / self.life_h
        if a <= 0.0 or a >= 1.0:
            return 0.0
        return float(min(1.0, 3.0 * a, 3.0 * (1.0 - a)))


def storms(seed: int) -> list[Storm]:
    rng = np.random.default_rng(seed)
    out, t = [], -72.0
    while t < TRUTH_DAYS * 24.0:
        out.append(Storm(t, rng.uniform(72.0, 144.0), rng.uniform(28.0, 42.0), rng.uniform(135.0, 175.0),
                         rng.uniform(15.0, 30.0), rng.uniform(55.0, 85.0), rng.uniform(16.0, 25.0),
                         rng.uniform(100.0, 200.0)))
        t += rng.uniform(18.0, 42.0)
    return out


LA, LO = np.meshgrid(LAT, LON, indexing="ij")


def _background():
    u = -7.0 * np.clip((28.0 - np.abs(LA)) / 10.0, 0.0, 1.0) * (np.abs(LA) < 28.0) \
        + 9.0 * np.clip(np.sin(np.radians((LA - 35.0) * 12.0)), 0.0, 1.0) * ((LA >= 35.0) & (LA <= 50.0))
    v = 1.5 * np.sin(np.radians(LO) * 3.0) * np.cos(np.radians(LA))
    jet = 1.3 * np.exp(-((LA - 35.5) / 1.2) ** 2) * np.exp(-np.clip(LO - 165.0, 0.0, None) / 20.0) * (LO >= 138.0)
    uo = jet + 0.2 * np.exp(-((LA - 43.0) / 3.0) ** 2) - 0.25 * np.exp(-((LA - 15.0) / 4.0) ** 2)
    vo = 0.1 * np.sin(np.radians(LO) * 4.0) * np.exp(-((LA - 35.5) / 3.0) ** 2)
    return u, v, uo, vo


BG = _background()


def _add_storm(u, v, clat, clon, peak_ms, rmax_nm):
    dy = (LA - clat) * 60.0
    dx = ((LO - clon + 180.0) % 360.0 - 180.0) * 60.0 * np.cos(np.radians(LA))
    r = np.hypot(dx, dy)
    speed = peak_ms * (r / rmax_nm) * np.exp(1.0 - r / rmax_nm)
    with np.errstate(invalid="ignore", divide="ignore"):
        u += speed * np.where(r > 0, -dy / r, 0.0)  # counter-clockwise
        v += speed * np.where(r > 0, dx / r, 0.0)


def _state(t_h: float, storm_list, displace=None):
    """(u10, v10, swh, mwd_deg, uo, vo) at t_h; `displace(storm, t_h)` → (dlat, dlon, factor) for forecasts."""
    u, v, uo, vo = (a.copy() for a in BG)
    for s in storm_list:
        k = s.strength(t_h)
        if k <= 0.0:
            continue
        clat, clon = s.centre(t_h)
        dlat, dlon, f = displace(s, t_h) if displace is not None else (0.0, 0.0, 1.0)
        _add_storm(u, v, clat + dlat, clon + dlon, s.peak_ms * k * f, s.rmax_nm)
    w = np.hypot(u, v)
    swh = 0.8 + 0.0112 * w ** 2
    mwd = (np.degrees(np.arctan2(-u, -v)) + 360.0) % 360.0
    return u, v, swh, mwd, uo, vo


def _field(hours: np.ndarray, t_ref, states, cycle=None) -> wf.WeatherField:
    arr = [np.stack(x) for x in zip(*states)]
    times = t_ref + (hours * 3600).astype("timedelta64[s]")
    return wf.from_arrays(LAT, LON, times, u10=arr[0], v10=arr[1], swh=arr[2], mwd_deg=arr[3], uo=arr[4], vo=arr[5],
                          cycle=cycle, t_ref=t_ref)


def truth_field(storm_list) -> wf.WeatherField:
    hours = np.arange(0.0, TRUTH_DAYS * 24.0 + 1e-9, 3.0)
    return _field(hours, T0, [_state(h, storm_list) for h in hours])


def position_error_nm(lead_h: float) -> float:
    return 50.0 * lead_h / 24.0 if lead_h <= 24.0 else 50.0 + 250.0 * (lead_h - 24.0) / 96.0


def intensity_error(lead_h: float) -> float:
    return 0.08 + 0.14 * min(lead_h, 120.0) / 120.0


def lead_hours(max_lead_h: int) -> np.ndarray:
    short = np.arange(0, min(max_lead_h, 132) + 1, 6)
    return np.concatenate([short, np.arange(144, max_lead_h + 1, 12)]).astype(np.float64)


class Forecasts:
    """Forecast cycles made on demand (cached), and the truth."""

    def __init__(self, seed: int, max_lead_h: int):
        self.seed, self.max_lead_h = seed, max_lead_h
        self.storms = storms(seed)
        self.truth = truth_field(self.storms)

    @functools.lru_cache(maxsize=48)  # noqa: B019 (one instance per run)
    def cycle(self, cycle_h: int) -> wf.WeatherField:
        rng = np.random.default_rng([self.seed, 7, int(cycle_h)])
        known = [s for s in self.storms if s.born_h <= cycle_h]
        z = {id(s): rng.standard_normal(3) for s in known}

        def displace(s, t_h):
            lead = t_h - cycle_h
            e_nm, zz = position_error_nm(lead), z[id(s)]
            dlat = e_nm * zz[0] / 60.0
            dlon = e_nm * zz[1] / (60.0 * math.cos(math.radians(s.centre(t_h)[0])))
            return dlat, dlon, max(0.3, 1.0 + intensity_error(lead) * zz[2])
        leads = lead_hours(self.max_lead_h)
        t_ref = T0 + np.timedelta64(int(cycle_h) * 3600, "s")
        return _field(leads, t_ref, [_state(cycle_h + L, known, displace) for L in leads], cycle=t_ref)

    def analysed(self) -> ver.VerificationWeather:
        """The truth as the weather that came: analysed at every valid time (what verification re-sails plans in)."""
        return ver.VerificationWeather(self.truth, (), np.ones(self.truth.times_h.size, bool))

    def newest_at(self, t_h: float) -> int:
        """The newest cycle (hours after T0) issued at or before t_h."""
        return int(math.floor(t_h / CYCLE_H + 1e-9) * CYCLE_H)

    def members(self, t_h: float, n: int = N_MEMBERS) -> list[wf.WeatherField]:
        c = self.newest_at(t_h)
        return [self.cycle(c - CYCLE_H * k) for k in range(n) if c - CYCLE_H * k >= 0]


# ------------------------------------------------------------------------------------------------------- voyages
@dataclass(frozen=True)
class Voyage:
    vid: str
    dep: tuple
    arr: tuple
    depart_h: float
    rta_h: float
    kind: str  # along / across, tight / loose

    @property
    def dist_nm(self) -> float:
        return gc_distance_nm(*self.dep, *self.arr)


def voyages(n: int, seed: int) -> list[Voyage]:
    rng = np.random.default_rng([seed, 1])
    out = []
    while len(out) < n:
        k = len(out)
        along = k % 2 == 0
        if along:
            lat_a, lat_b = rng.uniform(30.0, 46.0, 2)
            lon_a, lon_b = rng.uniform(150.0, 175.0), rng.uniform(195.0, 232.0)
        else:
            lat_a, lat_b = rng.uniform(20.0, 28.0), rng.uniform(42.0, 50.0)
            lon_a, lon_b = rng.uniform(150.0, 180.0), rng.uniform(190.0, 220.0)
        a, b = (lat_a, lon_a), (lat_b, lon_b)
        if (k // 2) % 2 == 1:
            a, b = b, a
        d = gc_distance_nm(*a, *b)
        if not 1600.0 <= d <= 4000.0:
            continue
        tight = (k // 4) % 2 == 0
        speed = 12.0 if tight else 10.5
        depart = float(CYCLE_H * rng.integers(2, 20))
        out.append(Voyage(f"H{k + 1:02d}", a, b, depart, depart + d / speed,
                          f"{'along' if along else 'across'}/{'tight' if tight else 'loose'}"))
    return out


def utc(t_h: float) -> np.datetime64:
    return T0 + np.timedelta64(int(round(t_h * 3600.0)), "s")


def problem(v: Voyage, dep, t_h: float, rta_h: float | None = None) -> RoutingProblem:
    return RoutingProblem(dep=tuple(dep), arr=v.arr, depart_utc=utc(t_h), rta_utc=utc(v.rta_h if rta_h is None else rta_h),
                          model=MODEL, rpm_options=RPM, voyage_id=v.vid)


VESSEL = lk.vessel(MODEL, draft_m=10.0, trim_m=0.0, max_step_h=1.0, rpm_options=RPM)


# --------------------------------------------------------------------------------------------- sailing on the truth
@dataclass
class Ship:
    lat: float
    lon: float
    t_h: float  # hours after T0
    fuel_t: float = 0.0


def sail_until(ship: Ship, legs: list[dict], truth: wf.WeatherField, stop_h: float = math.inf) -> list[dict]:
    """Sail `legs` (waits, then the leg at its rpm) on the truth from the ship's state until `stop_h`; the ship is
    moved; returns the legs still ahead (the one cut short from the ship's position)."""
    legs = list(legs)
    while legs:
        g = legs[0]
        wait = float(g.get("wait_h", 0.0) or 0.0)
        if wait > 0:
            w = min(wait, max(0.0, stop_h - ship.t_h))
            rate = float(g.get("wait_fuel_t", 0.0) or 0.0) / wait
            ship.t_h += w
            ship.fuel_t += w * rate
            left = wait - w
            legs[0] = g = {**g, "wait_h": left, "wait_fuel_t": left * rate}
            if left > 1e-9:
                return legs
        if ship.t_h >= stop_h - 1e-9:
            return legs
        o = lk.sail_leg(ship.lat, ship.lon, g["lat1"], g["lon1"], ship.t_h, g["rpm"], VESSEL, truth)
        if o[lk.CODE] != lk.OK:
            raise RuntimeError(f"leg cannot be sailed on the truth: {lk.REASONS.get(int(o[lk.CODE]))}")
        if ship.t_h + o[lk.H] <= stop_h + 1e-9:
            ship.t_h += o[lk.H]
            ship.fuel_t += o[lk.FUEL]
            ship.lat, ship.lon = g["lat1"], g["lon1"]
            legs.pop(0)
            continue
        frac = (stop_h - ship.t_h) / o[lk.H]
        plat, plon = gc_interpolate(ship.lat, ship.lon, g["lat1"], g["lon1"], frac)
        o = lk.sail_leg(ship.lat, ship.lon, plat, plon, ship.t_h, g["rpm"], VESSEL, truth)
        ship.t_h += o[lk.H]
        ship.fuel_t += o[lk.FUEL]
        ship.lat, ship.lon = plat, plon % 360.0
        legs[0] = {**g, "lat0": ship.lat, "lon0": ship.lon}
        return legs
    return legs


def gc_legs(a, b, rpm: float, seg_nm: float = 60.0) -> list[dict]:
    n = max(1, int(math.ceil(gc_distance_nm(*a, *b) / seg_nm)))
    pts = [gc_interpolate(*a, *b, k / n) for k in range(n + 1)]
    pts = [(la, lo % 360.0) for la, lo in pts]
    return [{"lat0": p[0], "lon0": p[1], "lat1": q[0], "lon1": q[1], "rpm": rpm} for p, q in zip(pts, pts[1:])]


def hours_at(legs, t_h, field) -> float:
    t = field.hours_after_ref(utc(t_h))
    t0 = t
    for g in legs:
        o = lk.sail_leg(g["lat0"], g["lon0"], g["lat1"], g["lon1"], t, g["rpm"], VESSEL, field)
        if o[lk.CODE] != lk.OK:
            return math.inf
        t += o[lk.H]
    return t - t0


def master_rpm(ship: Ship, v: Voyage, field: wf.WeatherField) -> float:
    """The one constant rpm between the lowest and highest setting that brings the ship in at the RTA along the rest
    of the great circle in `field` (bisection on the hours)."""
    need = v.rta_h - ship.t_h
    lo, hi = RPM[0], RPM[-1]
    if need <= 0 or hours_at(gc_legs((ship.lat, ship.lon), v.arr, hi), ship.t_h, field) > need:
        return hi
    if hours_at(gc_legs((ship.lat, ship.lon), v.arr, lo), ship.t_h, field) <= need:
        return lo
    for _ in range(18):
        mid = 0.5 * (lo + hi)
        if hours_at(gc_legs((ship.lat, ship.lon), v.arr, mid), ship.t_h, field) > need:
            lo = mid
        else:
            hi = mid
    return hi


@dataclass
class Outcome:
    fuel_t: float
    hours: float
    late_h: float
    claimed_pct: float = math.nan
    n_plans: int = 0
    n_kept: int = 0  # re-plans not taken (rule c) or baselines kept (rule b)
    margin_h: float = 0.0
    late_from_h: float = math.nan  # hours after departure when a plan first said the RTA cannot be met (NaN: never)


def outcome(ship: Ship, v: Voyage, **kw) -> Outcome:
    return Outcome(ship.fuel_t, ship.t_h - v.depart_h, ship.t_h - v.rta_h, **kw)


def sail_master(v: Voyage, fc: Forecasts) -> Outcome:
    ship = Ship(*v.dep, v.depart_h)
    while gc_distance_nm(ship.lat, ship.lon, *v.arr) > 1e-3:
        rpm = master_rpm(ship, v, fc.cycle(fc.newest_at(ship.t_h)))
        sail_until(ship, gc_legs((ship.lat, ship.lon), v.arr, rpm), fc.truth, ship.t_h + CYCLE_H)
    return outcome(ship, v)


@dataclass(frozen=True)
class Rules:
    margin_sigmas: float = 0.0
    min_win_share: float = 0.0
    replan_gain_sigmas: float = 0.0
    # with a model: the margin is margin_sigmas × its σ of the arrival error by the hours ahead (plus its bias), and
    # the claim is the saving it expects the plan to realise (the product's calibration.py); None: the lagged spread
    model: calibration.ErrorModel | None = None
    margin_max_share: float = 0.05
    margin_horizon_h: float | None = None  # the margin covers the error of at most this many hours ahead (None: all)

    @property
    def any(self) -> bool:
        return bool((self.margin_sigmas or self.min_win_share or self.replan_gain_sigmas) and self.model is None)


def plan_at(v: Voyage, ship: Ship, field: wf.WeatherField, members, rules: Rules):
    """The product's plan for the voyage from the ship's state on `field`, with the robust rules over `members`:
    (plan or None, margin h, baseline kept)."""
    try:
        prob = problem(v, (ship.lat, ship.lon), ship.t_h)
        plan = solve(prob, field)
        margin = 0.0
        if plan.legs and rules.margin_sigmas > 0 and rules.model is not None:
            # as job.robust_plan: the model's part for the route's severity, the claim against the RTA's baseline
            model = rules.model.given(calibration.route_hs_mean_m(plan.legs))
            reserve = robust.speed_reserve_h(plan, field, VESSEL) if rules.margin_horizon_h is not None else 0.0
            margin = calibration.arrival_margin_h(model, v.rta_h - ship.t_h, rules.margin_sigmas,
                                                  rules.margin_max_share, rules.margin_horizon_h, reserve)
            if margin > 0.05:
                aimed = solve(problem(v, (ship.lat, ship.lon), ship.t_h, v.rta_h - margin), field)
                if robust.aim_reached(aimed, utc(v.rta_h)):
                    plan = robust.margin_charged(aimed, plan)
                    plan.status = "ok"
                else:
                    margin = 0.0
        elif plan.legs and rules.margin_sigmas > 0:
            margin = robust.arrival_margin_h(plan, members, VESSEL, rules.margin_sigmas)
            if margin > 0.05:
                plan = solve(problem(v, (ship.lat, ship.lon), ship.t_h, v.rta_h - margin), field)
        kept = False
        if plan.legs and rules.min_win_share > 0:
            w = robust.wins_across(plan, members, VESSEL)
            if not w.preferred(rules.min_win_share) and plan.baseline is not None and plan.baseline.legs:
                plan, kept = robust.baseline_kept(plan, w, rules.min_win_share), True
    except (RoutingInputError, VoyageGeometryError):
        return None, 0.0, False
    return (plan if plan.legs else None), margin, kept


def claimed(plan, rules: Rules = Rules()) -> float:
    """The plan's claimed saving; with a calibrated model, the saving it expects the plan to realise (P50)."""
    c = plan.savings.total_pct if plan is not None and plan.savings is not None else 0.0
    if rules.model is None or plan is None or not plan.legs:
        return c
    planned_h = float((np.datetime64(plan.legs[-1]["eta_utc"], "s") - np.datetime64(plan.depart_utc, "s"))
                      / np.timedelta64(1, "s")) / 3600.0
    model = rules.model.given(calibration.route_hs_mean_m(plan.legs))
    return calibration.expected_saving_pct(model, c, planned_h, plan.savings.margin_cost_pct if plan.savings else 0.0)[1]


def sail_once(v: Voyage, fc: Forecasts, rules: Rules = Rules(), field=None, made: list | None = None) -> Outcome:
    ship = Ship(*v.dep, v.depart_h)
    field = field if field is not None else fc.cycle(fc.newest_at(ship.t_h))
    plan, margin, kept = plan_at(v, ship, field, fc.members(ship.t_h) if rules.any else [], rules)
    if made is not None and plan is not None:
        made.append((plan, claimed(plan, rules)))
    legs = plan.legs if plan is not None else gc_legs(v.dep, v.arr, master_rpm(ship, v, field))
    sail_until(ship, legs, fc.truth)
    return outcome(ship, v, claimed_pct=claimed(plan, rules), n_plans=1, n_kept=int(kept), margin_h=margin)


def sail_replan(v: Voyage, fc: Forecasts, rules: Rules = Rules(), made: list | None = None) -> Outcome:
    """The voyage re-planned every cycle; each plan made is appended to `made` (when given) as (plan, its claim)."""
    ship = Ship(*v.dep, v.depart_h)
    field = fc.cycle(fc.newest_at(ship.t_h))
    plan, margin, kept = plan_at(v, ship, field, fc.members(ship.t_h) if rules.any else [], rules)
    first_claim, n_plans, n_kept, margins = claimed(plan, rules), 1, int(kept), [margin]
    if made is not None and plan is not None:
        made.append((plan, first_claim))
    legs = plan.legs if plan is not None else gc_legs(v.dep, v.arr, master_rpm(ship, v, field))
    late_from = 0.0 if plan is not None and plan.status == "late" else math.nan
    while legs:
        legs = sail_until(ship, legs, fc.truth, ship.t_h + CYCLE_H)
        if not legs or v.rta_h - ship.t_h < CYCLE_H or gc_distance_nm(ship.lat, ship.lon, *v.arr) < 60.0:
            continue
        members = fc.members(ship.t_h) if rules.any else []
        new, margin, kept = plan_at(v, ship, fc.cycle(fc.newest_at(ship.t_h)), members, rules)
        if new is None:
            continue
        if made is not None:
            made.append((new, claimed(new, rules)))
        if new.status == "late" and math.isnan(late_from):
            late_from = ship.t_h - v.depart_h
        n_plans += 1
        n_kept += int(kept)
        if rules.replan_gain_sigmas > 0:
            ahead = [{**g, "lat0": ship.lat, "lon0": ship.lon} if i == 0 else g for i, g in enumerate(legs)]
            ahead = robust.retimed(ahead, new.depart_utc, new.rta_utc, fc.cycle(fc.newest_at(ship.t_h)), VESSEL)
            d = robust.replan_decision(ahead, new, members, VESSEL, rules.replan_gain_sigmas)
            if not d.take_new:
                n_kept += 1
                legs = ahead  # the current route, re-timed to the RTA (as route-fleet keeps it)
                continue
        legs = new.legs
        margins.append(margin)
    return outcome(ship, v, claimed_pct=first_claim, n_plans=n_plans, n_kept=n_kept, margin_h=float(np.mean(margins)),
                   late_from_h=late_from)


# ------------------------------------------------------------------------------------------- calibration (training)
def verification_row(plan, truth_weather: ver.VerificationWeather) -> dict | None:
    """The plan and its baseline re-sailed as made on the truth (verification.verify, as `jitroute verify` re-sails a
    stored plan in the analysed weather): a row with plan_verification's columns that calibration reads."""
    base = plan.baseline.legs if plan.baseline is not None else None
    claim = plan.savings.total_pct if plan.savings is not None else math.nan
    r = ver.verify(plan.legs, base, plan.depart_utc, truth_weather, VESSEL, claim)
    if r is None:
        return None
    return {"coverage": r.coverage, "hours_total": r.hours_total, "claimed_eta_utc": plan.legs[-1]["eta_utc"],
            "realised_eta_utc": r.plan_eta_utc, "claimed_fuel_t": plan.fuel_t, "realised_fuel_t": r.plan_fuel_t,
            "claimed_savings_pct": claim, "realised_savings_pct": r.realised_savings_pct,
            "route_hs_mean_m": calibration.route_hs_mean_m(plan.legs)}


def calibrate(seed: int, n: int, max_lead_h: int) -> tuple[calibration.ErrorModel, list[dict]]:
    """The error model fitted on `n` training voyages of their own truth, forecasts and voyages (`seed`): each
    re-planned every cycle, every plan made (at departure and at sea) verified on the truth."""
    fc = Forecasts(seed, max_lead_h)
    truth = fc.analysed()
    rows = []
    for v in voyages(n, seed):
        made: list = []
        sail_replan(v, fc, made=made)
        rows += [r for r in (verification_row(p, truth) for p, _ in made if p.legs) if r is not None]
    return calibration.fit_error_model(calibration.verification_errors(rows)), rows


def claim_errors(m: calibration.ErrorModel, rows: list[dict]) -> dict:
    """On the training plans (in-sample), as `plan_verification` measures it (realised against the plan's own baseline,
    both re-sailed): mean |claimed − realised| of the raw claims and of the expected realisations (calibration P50)."""
    pairs = [(r["claimed_savings_pct"], r["realised_savings_pct"], r["hours_total"]) for r in rows
             if math.isfinite(r["claimed_savings_pct"]) and math.isfinite(r["realised_savings_pct"])]
    if not pairs:
        return {}
    raw = float(np.mean([abs(c - x) for c, x, _ in pairs]))
    honest = float(np.mean([abs(calibration.expected_saving_pct(m, c, h)[1] - x) for c, x, h in pairs]))
    return {"train_mean_claimed_pct": round(float(np.mean([c for c, _, _ in pairs])), 3),
            "train_mean_realised_pct": round(float(np.mean([x for _, x, _ in pairs])), 3),
            "train_claim_error_pts": round(raw, 3), "train_expected_claim_error_pts": round(honest, 3)}


def plan_claims(made: list, truth: ver.VerificationWeather) -> dict:
    """Each plan a strategy made (at departure and at sea) re-sailed as made on the truth with its own baseline, as
    `jitroute verify` fills plan_verification, on the voyages scored (out of sample for the calibration): mean
    |claimed − realised| of the plans' claims (the calibrated P50 where the strategy has a model), in points."""
    pairs = []
    for plan, claim in made:
        r = verification_row(plan, truth) if plan.legs else None
        if r is not None and math.isfinite(claim) and math.isfinite(r["realised_savings_pct"]):
            pairs.append((claim, r["realised_savings_pct"]))
    if not pairs:
        return {}
    return {"plans_verified": len(pairs),
            "plan_claim_error_pts": round(float(np.mean([abs(c - x) for c, x in pairs])), 3),
            "plan_mean_claimed_pct": round(float(np.mean([c for c, _ in pairs])), 3),
            "plan_mean_realised_pct": round(float(np.mean([x for _, x in pairs])), 3)}


def model_json(m: calibration.ErrorModel) -> dict:
    return {"n_plans": m.n_plans, "source": m.source, "eta_bias_share": round(m.eta_bias_share, 5),
            "eta_sd_h": [round(m.eta_sd_h.a, 5), round(m.eta_sd_h.b, 3)], "fuel_bias_share": round(m.fuel_bias_share, 5),
            "fuel_sd_share": [round(m.fuel_sd_share.a, 6), round(m.fuel_sd_share.b, 3)], "skill": round(m.skill, 3),
            "saving_sd_pts": [round(m.saving_sd_pts.a, 5), round(m.saving_sd_pts.b, 3)]} | (
        {"severity_split_m": round(m.severity_split_m, 3), "calm": model_json(m.calm), "stormy": model_json(m.stormy)}
        if m.calm is not None and m.stormy is not None else {})


# --------------------------------------------------------------------------------------------------------- report
def corrected(o: Outcome, v: Voyage) -> float:
    """Fuel scaled to an arrival at the RTA: × (passage hours / RTA hours)²."""
    return o.fuel_t * (o.hours / (v.rta_h - v.depart_h)) ** 2


def summarise(name: str, runs: list[tuple[Voyage, Outcome, Outcome]]) -> dict:
    fm = sum(m.fuel_t for _, m, _ in runs)
    fs = sum(o.fuel_t for _, _, o in runs)
    cm = sum(corrected(m, v) for v, m, _ in runs)
    cs = sum(corrected(o, v) for v, _, o in runs)
    per = [100.0 * (corrected(m, v) - corrected(o, v)) / corrected(m, v) for v, m, o in runs]
    realised = [100.0 * (m.fuel_t - o.fuel_t) / m.fuel_t for _, m, o in runs]
    claims = [(o.claimed_pct, r) for (_, _, o), r in zip(runs, realised) if math.isfinite(o.claimed_pct)]
    return {"strategy": name, "n": len(runs), "saving_pct": 100.0 * (fm - fs) / fm,
            "saving_corrected_pct": 100.0 * (cm - cs) / cm, "n_worse": int(sum(p < -WORSE_PCT for p in per)),
            "worst_pct": float(min(per)), "on_time": int(sum(o.late_h <= ON_TIME_TOL_H for _, _, o in runs)),
            "max_late_h": float(max(o.late_h for _, _, o in runs)),
            "claim_error_pts": float(np.mean([abs(c - r) for c, r in claims])) if claims else math.nan,
            "mean_claimed_pct": float(np.mean([c for c, _ in claims])) if claims else math.nan,
            "n_plans": int(sum(o.n_plans for _, _, o in runs)), "n_kept": int(sum(o.n_kept for _, _, o in runs)),
            "mean_margin_h": float(np.mean([o.margin_h for _, _, o in runs]))}


def table(rows: list[dict]) -> str:
    head = (f"{'strategy':<22}{'saving':>8}{'corr.':>8}{'worse>1%':>10}{'worst':>8}{'on time':>9}{'max late':>10}"
            f"{'claimed':>9}{'|c−r|':>7}{'kept':>6}{'margin':>8}")
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(f"{r['strategy']:<22}{r['saving_pct']:>7.2f}%{r['saving_corrected_pct']:>7.2f}%"
                     f"{r['n_worse']:>5d}/{r['n']:<4d}{r['worst_pct']:>7.1f}%{r['on_time']:>5d}/{r['n']:<3d}"
                     f"{r['max_late_h']:>8.1f} h{r['mean_claimed_pct']:>8.2f}%{r['claim_error_pts']:>7.2f}"
                     f"{r['n_kept']:>6d}{r['mean_margin_h']:>6.1f} h")
    return "\n".join(lines)


def targets(rows: dict) -> list[str]:
    pf = rows.get("perfect")
    half = 0.5 * pf["saving_corrected_pct"] if pf is not None else math.nan
    out = []
    for name in [k for k in ("replan", "replan calibrated") if k in rows and pf is not None]:
        rp = rows[name]
        ok = rp["saving_corrected_pct"] >= half
        out.append(f"{name} realises ≥ half of perfect (corrected): {rp['saving_corrected_pct']:.2f} % vs half of "
                   f"{pf['saving_corrected_pct']:.2f} % = {half:.2f} %: " + ("met" if ok else
                   f"MISSED by {half - rp['saving_corrected_pct']:.2f} points"))
        out.append(f"no {name} voyage > {WORSE_PCT:g} % worse than the master (corrected): {rp['n_worse']} worse, "
                   f"worst {rp['worst_pct']:.2f} %: " + ("met" if rp["n_worse"] == 0 else
                   f"MISSED by {-WORSE_PCT - rp['worst_pct']:.2f} points on the worst"))
    for name in [k for k in ("once", "replan", "once calibrated", "replan calibrated") if k in rows]:
        r = rows[name]
        share = r["on_time"] / r["n"]
        out.append(f"{name}: on time {r['on_time']}/{r['n']} = {100 * share:.0f} % (target ≥ {100 * TARGET_ON_TIME:.0f} %): "
                   + ("met" if share >= TARGET_ON_TIME else f"MISSED by {100 * (TARGET_ON_TIME - share):.0f} points"))
        out.append(f"{name}: mean |claimed − realised| {r['claim_error_pts']:.2f} points (target ≤ {TARGET_CLAIM_PTS:g}): "
                   + ("met" if r["claim_error_pts"] <= TARGET_CLAIM_PTS else
                      f"MISSED by {r['claim_error_pts'] - TARGET_CLAIM_PTS:.2f} points"))
        if "plan_claim_error_pts" in r:
            e = r["plan_claim_error_pts"]
            out.append(f"{name}: each plan against its own baseline, both re-sailed as made ({r['plans_verified']} plans, "
                       f"as plan_verification): mean |claimed − realised| {e:.2f} points (target ≤ "
                       f"{TARGET_CLAIM_PTS:g}): " + ("met" if e <= TARGET_CLAIM_PTS else
                                                    f"MISSED by {e - TARGET_CLAIM_PTS:.2f} points"))
    return out


ROBUST = {"a margin 1.65σ": Rules(margin_sigmas=1.65), "b win ≥ 75 %": Rules(min_win_share=0.75),
          "c gain > 1σ": Rules(replan_gain_sigmas=1.0),
          "a+b+c": Rules(margin_sigmas=1.65, min_win_share=0.75, replan_gain_sigmas=1.0)}


def write(a, n: int, runs: dict, per_voyage: list, t_start: float, verified: dict | None = None) -> dict:
    """The summary of the voyages sailed so far, written to `a.out` (JSON), with each strategy's `verified` plan
    claims (plan_claims) when given; returns it by strategy."""
    rows = {k: summarise(k, r) | (verified or {}).get(k, {}) for k, r in runs.items()}
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"conditions": {"voyages": n, "sailed": len(per_voyage), "seed": a.seed,
                                              "max_lead_h": a.max_lead, "cycle_h": CYCLE_H,
                                              "margin_sigmas": a.margin_sigmas,
                                              "margin_max_share": a.margin_max_share,
                                              "margin_horizon_h": a.margin_horizon_h, "train_seed": a.train_seed,
                                              "train_voyages": a.train_voyages, "error_model": a.model,
                                              "cpu_s": round(time.process_time() - t_start, 1)},
                               "summary": rows, "targets": targets(rows), "table": table(list(rows.values())),
                               "voyages": per_voyage}, indent=1))
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="8 voyages (a smoke run)")
    ap.add_argument("--voyages", type=int, default=24)
    ap.add_argument("--seed", type=int, default=41)
    ap.add_argument("--max-lead", type=int, default=264, choices=(132, 264))
    ap.add_argument("--robust", action="store_true", help="also each robust decision and all three")
    ap.add_argument("--train-seed", type=int, default=None,
                    help="seed of the calibration's training voyages, truth and forecasts (default: --seed + 1000)")
    ap.add_argument("--train-voyages", type=int, default=None, help="training voyages (default 12; 8 with --quick)")
    ap.add_argument("--margin-sigmas", type=float, default=1.65,
                    help="k of the calibrated margin: k × σ of the arrival error by the hours ahead (0: no calibration)")
    ap.add_argument("--margin-max-share", type=float, default=0.15,
                    help="the calibrated margin is at most this share of the hours ahead")
    ap.add_argument("--margin-horizon-h", type=float, default=None,
                    help="the calibrated margin covers the arrival error of at most this many hours ahead (the hours "
                         "after a re-planned voyage's last re-plan; default: the whole passage)")
    ap.add_argument("--only", default=None,
                    help="comma-separated strategies to run (e.g. 'replan calibrated'); default: all")
    ap.add_argument("--out", default=str(ROOT / "bench" / "out" / "hindcast.json"))
    a = ap.parse_args(argv)
    n = 8 if a.quick else a.voyages
    t_start = time.process_time()
    a.train_seed = a.seed + 1000 if a.train_seed is None else a.train_seed
    if a.train_seed == a.seed:
        ap.error("--train-seed must differ from --seed: the model is never calibrated on the voyages it is scored on")
    a.train_voyages = (8 if a.quick else 12) if a.train_voyages is None else a.train_voyages
    a.model = None
    if a.margin_sigmas > 0:
        model, train_rows = calibrate(a.train_seed, a.train_voyages, a.max_lead)
        a.model = model_json(model) | {"training_voyages": a.train_voyages, "training_seed": a.train_seed,
                                       "plans": len(train_rows)} | claim_errors(model, train_rows)
        print(f"calibrated on {len(train_rows)} plans of {a.train_voyages} training voyages (seed {a.train_seed}): "
              f"{json.dumps(a.model)}  [CPU {time.process_time() - t_start:.0f} s]", flush=True)
    fc = Forecasts(a.seed, a.max_lead)
    vs = voyages(n, a.seed)
    strategies = {"once": lambda v: sail_once(v, fc), "replan": lambda v: sail_replan(v, fc),
                  "perfect": lambda v: sail_once(v, fc, field=fc.truth)}
    made: dict[str, list] = {}  # the plans each calibrated strategy made, verified on the truth (plan_claims)
    if a.margin_sigmas > 0:
        cal = Rules(margin_sigmas=a.margin_sigmas, model=model, margin_max_share=a.margin_max_share,
                    margin_horizon_h=a.margin_horizon_h)
        made = {"once calibrated": [], "replan calibrated": []}
        strategies["once calibrated"] = functools.partial(sail_once, fc=fc, rules=cal, made=made["once calibrated"])
        strategies["replan calibrated"] = functools.partial(sail_replan, fc=fc, rules=cal,
                                                            made=made["replan calibrated"])
    if a.robust:
        for label, rules in ROBUST.items():
            if (rules.margin_sigmas > 0) != (rules.min_win_share > 0):  # each alone (c acts only at sea)
                strategies[f"once {label}"] = functools.partial(sail_once, fc=fc, rules=rules)
            strategies[f"replan {label}"] = functools.partial(sail_replan, fc=fc, rules=rules)
    if a.only:
        keep = [x.strip() for x in a.only.split(",")]
        unknown = sorted(set(keep) - set(strategies))
        if unknown:
            ap.error(f"unknown strategies {unknown}; known: {sorted(strategies)}")
        strategies = {k: f for k, f in strategies.items() if k in keep}
    runs = {k: [] for k in strategies}
    per_voyage = []
    for v in vs:
        m = sail_master(v, fc)
        row = {"voyage": v.vid, "kind": v.kind, "dist_nm": round(v.dist_nm), "rta_h": round(v.rta_h - v.depart_h, 1),
               "master_fuel_t": round(m.fuel_t, 2), "master_late_h": round(m.late_h, 2)}
        for name, fn in strategies.items():
            o = fn(v)
            runs[name].append((v, m, o))
            row[name] = {"fuel_t": round(o.fuel_t, 2), "late_h": round(o.late_h, 2),
                         "saving_pct": round(100.0 * (m.fuel_t - o.fuel_t) / m.fuel_t, 2),
                         "saving_corrected_pct": round(100.0 * (corrected(m, v) - corrected(o, v)) / corrected(m, v), 2),
                         "claimed_pct": round(o.claimed_pct, 2) if math.isfinite(o.claimed_pct) else None,
                         "n_plans": o.n_plans, "n_kept": o.n_kept, "margin_h": round(o.margin_h, 2),
                         "late_from_h": round(o.late_from_h, 1) if math.isfinite(o.late_from_h) else None}
        per_voyage.append(row)
        print(f"{v.vid} {v.kind:<13} {v.dist_nm:6.0f} NM  master {m.fuel_t:7.1f} t (late {m.late_h:+5.1f} h)  " +
              "  ".join(f"{k} {row[k]['saving_corrected_pct']:+5.1f}%/{row[k]['late_h']:+.1f}h"
                        for k in ("once", "replan", "perfect", "replan calibrated") if k in row), flush=True)
        write(a, n, runs, per_voyage, t_start)  # after every voyage: a run stopped early keeps what it measured
    truth = fc.analysed()
    rows = write(a, n, runs, per_voyage, t_start, {k: plan_claims(m, truth) for k, m in made.items() if k in runs})
    master_on_time = sum(r[1].late_h <= ON_TIME_TOL_H for r in next(iter(runs.values())))
    print()
    print(f"hindcast: {n} voyages, seed {a.seed}, leads to {a.max_lead} h, cycles every {CYCLE_H} h; master on time "
          f"{master_on_time}/{n}; savings vs the master (corr.: fuel × (passage h / RTA h)²)")
    print(table(list(rows.values())))
    print()
    for line in targets(rows):
        print(line)
    print(f"\nCPU {time.process_time() - t_start:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
