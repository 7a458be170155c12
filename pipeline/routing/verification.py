"""What happened: a plan and its constant-speed baseline re-sailed in the analysed weather, against the claim.

A plan's saving is claimed on the forecast it was made on. Once newer cycles have arrived, the weather the ship met
is known far better: each cycle's shortest leads (its analysis and first step, `ANALYSIS_LEAD_H`) are the best
estimate of the weather valid then. `verification_weather` makes one field of several cycles: at every valid time
the cycle valid then with the shortest lead (the newest one), so the voyage's past lies in analysed weather and its
rest in the newest forecast; past the newest cycle's last step its neutral weather applies, as in planning
(engine/leg.py). `verify` sails the plan as the master executes it (its waypoints, the rpm of each leg and its waits,
leaving at its departure) and its baseline (the base route at the constant rpm that arrived at the RTA in the
forecast) through that field with the same leg kernel (ensemble.sail_plan) and gives their realised fuel and
arrival, and the realised saving.

Coverage is said, never assumed: only the hours of the plan's realised passage that lie between two analysed valid
times count as verified (`hours_analysed`); a plan whose passage is not wholly analysed is "partly verified", its
realised figures then the analysed part plus the newest forecast of the rest.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pipeline.routing.engine import leg as lk
from pipeline.routing.ensemble import sail_plan
from pipeline.routing.weather_field import WeatherField

ANALYSIS_LEAD_H = 6.0  # a cycle's leads this short count as analysed weather (its analysis and its first step)
WHOLE_TOL_H = 0.01  # a passage analysed to within this many hours is wholly verified
VERIFIED, PARTLY, NOT_VERIFIED = "verified", "partly verified", "not verified"


class VerificationError(ValueError):
    """The cycles' fields cannot be merged (different grids): the message says which."""


@dataclass(frozen=True)
class VerificationWeather:
    field: WeatherField  # at every valid time, the cycle valid then with the shortest lead
    cycles: tuple  # the cycles (datetime64[s]) that gave at least one valid time, oldest first
    analysed: np.ndarray  # (nt,) bool: the valid time's lead is ≤ the analysis lead

    def analysed_hours(self, from_utc, to_utc) -> float:
        """Hours of from_utc..to_utc lying between two consecutive analysed valid times."""
        t = self.field.times_h
        a, b = self.field.hours_after_ref(from_utc), self.field.hours_after_ref(to_utc)
        both = self.analysed[:-1] & self.analysed[1:]
        lo, hi = np.maximum(t[:-1], a), np.minimum(t[1:], b)
        return float(np.sum(np.clip(hi - lo, 0.0, None)[both]))

    @property
    def analysed_until_utc(self) -> np.datetime64 | None:
        """The last analysed valid time (None: none)."""
        k = np.flatnonzero(self.analysed)
        if not k.size:
            return None
        return self.field.t_ref + np.timedelta64(int(round(self.field.times_h[k[-1]] * 3600)), "s")


def verification_weather(fields: list[WeatherField], analysis_lead_h: float = ANALYSIS_LEAD_H) -> VerificationWeather:
    """One field of several cycles' fields (each with its `cycle`, all on the same grid, e.g. one voyage's window of
    each): at every valid time any of them has, the values of the cycle with the shortest lead there; a valid time is
    analysed when that lead is ≤ `analysis_lead_h`. Raises VerificationError when the grids differ."""
    fields = [f for f in fields if f.times_h.size]
    if not fields:
        raise VerificationError("no cycle to verify with: ingest newer cycles first (`jitroute ingest --cycle latest`)")
    g0 = fields[0]
    for f in fields[1:]:
        if f.grid != g0.grid:
            raise VerificationError(f"cycle {f.cycle}'s window lies on another grid than cycle {g0.cycle}'s "
                                    f"({f.grid} vs {g0.grid}): read every cycle with the same window")
    best: dict[int, tuple[float, int, int]] = {}  # valid time (s since epoch) → (lead h, field, step)
    for i, f in enumerate(fields):
        cyc = np.datetime64(f.cycle if f.cycle is not None else f.t_ref, "s")
        ref = np.datetime64(f.t_ref, "s")
        for k, h in enumerate(f.times_h):
            valid = ref + np.timedelta64(int(round(h * 3600)), "s")
            lead_h = float((valid - cyc) / np.timedelta64(1, "s")) / 3600.0
            if lead_h < -1e-9:
                continue  # before its cycle: not a forecast of that time
            key = int(valid.astype(np.int64))
            if key not in best or lead_h < best[key][0]:
                best[key] = (lead_h, i, k)
    keys = sorted(best)
    t_ref = np.datetime64(keys[0], "s")
    times_h = (np.asarray(keys, np.float64) - keys[0]) / 3600.0
    cells = np.empty(g0.cells.shape[:2] + (len(keys), g0.cells.shape[3]), np.float32)
    for n, key in enumerate(keys):
        _, i, k = best[key]
        cells[:, :, n, :] = fields[i].cells[:, :, k, :]
    used = sorted({i for _, i, _ in best.values()})
    newest = max((np.datetime64(fields[i].cycle, "s") for i in used if fields[i].cycle is not None), default=None)
    field = WeatherField(cells=np.ascontiguousarray(cells), times_h=times_h, grid=g0.grid, t_ref=t_ref, cycle=newest)
    analysed = np.array([best[key][0] <= analysis_lead_h + 1e-9 for key in keys])
    cycles = tuple(sorted(np.datetime64(fields[i].cycle, "s") for i in used if fields[i].cycle is not None))
    return VerificationWeather(field, cycles, analysed)


def constant_rpm_legs(lat_deg, lon_deg, rpm) -> list[dict]:
    """The legs between consecutive waypoints, each at its rpm (`rpm`: one per leg, or one for all), no waits: how a
    baseline is stored (routes.baseline_lat_deg/lon_deg/rpm)."""
    lat, lon = np.asarray(lat_deg, np.float64), np.asarray(lon_deg, np.float64)
    rpm = np.broadcast_to(np.asarray(rpm, np.float64), (max(lat.size - 1, 0),))
    return [{"lat0": float(lat[k]), "lon0": float(lon[k]), "lat1": float(lat[k + 1]), "lon1": float(lon[k + 1]),
             "rpm": float(rpm[k])} for k in range(lat.size - 1)]


@dataclass(frozen=True)
class Verification:
    hours_total: float  # the plan's realised passage, hours
    hours_analysed: float  # of which in analysed weather
    plan_fuel_t: float  # realised
    plan_hours: float
    plan_eta_utc: np.datetime64 | None
    baseline_fuel_t: float  # realised (NaN: no baseline, or it cannot be sailed)
    baseline_hours: float
    baseline_eta_utc: np.datetime64 | None
    claimed_savings_pct: float  # the saving claimed on the forecast (NaN: none)

    @property
    def coverage(self) -> str:
        if not (self.hours_analysed > WHOLE_TOL_H):
            return NOT_VERIFIED
        return VERIFIED if self.hours_analysed >= self.hours_total - WHOLE_TOL_H else PARTLY

    @property
    def realised_savings_pct(self) -> float:
        if not (self.baseline_fuel_t > 0 and math.isfinite(self.plan_fuel_t)):
            return math.nan
        return 100.0 * (self.baseline_fuel_t - self.plan_fuel_t) / self.baseline_fuel_t


def _eta(depart_utc, hours: float) -> np.datetime64 | None:
    return np.datetime64(depart_utc, "s") + np.timedelta64(int(round(hours * 3600)), "s") if math.isfinite(hours) else None


def verify(plan_legs: list[dict], baseline_legs: list[dict] | None, depart_utc, weather: VerificationWeather,
           vessel: lk.Vessel, claimed_savings_pct: float = math.nan) -> Verification | None:
    """The plan (its legs with rpm and waits) and its baseline sailed in `weather` leaving at `depart_utc`; the ship
    keeps to the plan whatever the weather (its weather limits do not stop it: this is what happens, not a plan).
    None when the plan has no legs or cannot be sailed there (no headway)."""
    if not plan_legs:
        return None
    sailing = vessel._replace(max_hs_m=math.inf, max_wind_kn=math.inf)
    h, f = sail_plan(plan_legs, depart_utc, weather.field, sailing)
    if not math.isfinite(h):
        return None
    bh, bf = sail_plan(baseline_legs, depart_utc, weather.field, sailing) if baseline_legs else (math.nan, math.nan)
    if not math.isfinite(bh):
        bh, bf = math.nan, math.nan
    arrive = np.datetime64(depart_utc, "s") + np.timedelta64(int(round(h * 3600)), "s")
    return Verification(hours_total=h, hours_analysed=weather.analysed_hours(depart_utc, arrive), plan_fuel_t=f,
                        plan_hours=h, plan_eta_utc=_eta(depart_utc, h), baseline_fuel_t=bf, baseline_hours=bh,
                        baseline_eta_utc=_eta(depart_utc, bh),
                        claimed_savings_pct=float(claimed_savings_pct) if claimed_savings_pct is not None else math.nan)


def describe(v: Verification | None) -> str:
    """One line for people."""
    if v is None:
        return "verification: n/a"
    saving = v.realised_savings_pct
    return (f"{v.coverage} ({v.hours_analysed:.0f} of {v.hours_total:.0f} h in analysed weather): fuel "
            f"{v.plan_fuel_t:.1f} t, saving {saving:.1f} % realised vs {v.claimed_savings_pct:.1f} % claimed"
            if math.isfinite(saving) else f"{v.coverage}: fuel {v.plan_fuel_t:.1f} t (no baseline to compare)")


def sailing_vessel(voyage: dict, model_json: dict, rpm_max: float | None = None) -> lk.Vessel:
    """The ship as the leg kernel sees it on `voyage` (a voyages row; `depart_utc` the plan's start, for the hull's
    fouling then) with the performance model the plan was made with (`model_json`, PerformanceModel.to_json)."""
    from pipeline.performance.model import PerformanceModel
    from pipeline.routing.voyage import problem_from_voyage

    return problem_from_voyage(voyage, PerformanceModel.from_json(model_json), rpm_max=rpm_max).kernel_vessel()


SLOWER_MARGIN = 0.5  # the window reaches this share of the planned passage past it (a passage slower than planned)


def verification_window(tracks: list[list[dict]], depart_utc, planned_hours: float):
    """The weather window a plan and its baseline (`tracks`: their legs) can meet when re-sailed: from the departure
    to the planned passage plus `SLOWER_MARGIN` of it and a day, over the box of every waypoint."""
    from pipeline.routing.problem import WeatherWindow, lon_span_deg

    lats = [x for legs in tracks for leg in legs for x in (leg["lat0"], leg["lat1"])]
    lons = [x for legs in tracks for leg in legs for x in (leg["lon0"], leg["lon1"])]
    start = np.datetime64(depart_utc, "s")
    end = start + np.timedelta64(int(math.ceil((planned_hours * (1 + SLOWER_MARGIN) + 24.0) * 3600)), "s")
    return WeatherWindow(start, end, (float(min(lats)), float(max(lats))), lon_span_deg(lons))
