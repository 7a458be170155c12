"""The voyage plan a solve returns: waypoints, rpm per leg, ETAs, the weather met, totals, status."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from datetime import datetime
from typing import TYPE_CHECKING

import numpy as np

from pipeline.routing import geodesy as geo
from pipeline.routing.engine import leg as lk

if TYPE_CHECKING:
    from pipeline.routing.engine_limits import EngineLimits

STATUSES = ("ok", "late", "infeasible", "failed")
SAVINGS_COLUMNS = ("honest_baseline_rpm", "honest_baseline_fuel_t", "honest_baseline_hours", "profile_fuel_t",
                   "savings_total_pct", "savings_speed_profile_pct", "savings_route_pct", "fuel_beyond_forecast_t",
                   "honest_baseline_fuel_beyond_forecast_t", "savings_forecast_pct", "savings_beyond_forecast_pct",
                   "margin_cost_pct")
LIMITS_COLUMNS = ("min_engine_hold_h", "engine_change_cost_t", "n_engine_changes", "unlimited_fuel_t", "limits_fuel_t")
BASELINE_TRACK_COLUMNS = ("baseline_lat_deg", "baseline_lon_deg", "baseline_leg_rpm")
ENSEMBLE_COLUMNS = ("ensemble_members", "p_on_time", "baseline_p_on_time", "fuel_p10_t", "fuel_p50_t", "fuel_p90_t",
                    "savings_p10_pct", "savings_p50_pct", "savings_p90_pct")


@dataclass(frozen=True)
class Spread:
    n_members: int  # members that could sail both the plan and its baseline
    p_on_time: float  # share of those members in which the plan arrives by the RTA (+ ON_TIME_TOL_H)
    baseline_p_on_time: float
    fuel_p10_t: float
    fuel_p50_t: float
    fuel_p90_t: float
    savings_p10_pct: float  # the saving against the baseline sailed in the same member, percent
    savings_p50_pct: float
    savings_p90_pct: float


@dataclass(frozen=True)
class SavingsSplit:
    baseline_rpm: float  # the constant rpm of the honest baseline
    baseline_fuel_t: float
    baseline_hours: float
    profile_fuel_t: float  # the best engine plan on the base route
    plan_fuel_t: float
    speed_profile_pct: float
    route_pct: float
    total_pct: float
    baseline_fuel_beyond_t: float = math.nan  # the baseline's fuel burnt past the forecast's last valid time
    plan_fuel_beyond_t: float = math.nan  # the plan's
    forecast_pct: float = math.nan  # the part of total_pct burnt within the forecast's valid times
    beyond_forecast_pct: float = math.nan  # the part burnt past them (total_pct − forecast_pct)
    margin_cost_pct: float = 0.0  # what aiming before the RTA costs (with_margin_cost); total = profile + route − this


def _utc(t) -> datetime | None:
    """A time as a naive UTC datetime to the second (what rows carry: no pandas needed where plans are made)."""
    return None if t is None else np.datetime64(t, "s").item()


@dataclass
class Plan:
    voyage_id: str
    imo: int | None
    solver: str
    objective: str
    status: str
    reason: str | None
    depart_utc: np.datetime64
    rta_utc: np.datetime64
    legs: list[dict] = field(default_factory=list)
    cost: float = math.inf
    seed: int | None = None
    runtime_s: float = 0.0
    baseline: "Plan | None" = None
    history: np.ndarray | None = None
    n_evals: int = 0
    model_version: int | None = None
    cycle: np.datetime64 | None = None
    min_land_clearance_nm: float = math.nan  # least distance to land outside the port approaches (to 0.1 NM or 4 %)
    # engine-change limits (engine_limits.py): the limits the legs obey (None: none), and the fuel (t) of the
    # best engine plan on the same route without them, for what the limits cost
    limits: "EngineLimits | None" = None
    unlimited_fuel_t: float = math.nan
    # the savings against the honest constant-rpm baseline, split (savings.py; None: not computed)
    savings: "SavingsSplit | None" = None
    # the plan and its baseline sailed through a lagged ensemble (ensemble.py; None: not computed)
    spread: "Spread | None" = None

    def add_reason(self, note: str | None) -> None:
        """Add `note` to what the plan's reason says ("; " between notes); nothing for no note."""
        if note:
            self.reason = f"{self.reason}; {note}" if self.reason else note

    @property
    def hours(self) -> float:
        """Hours from departure to arrival: the legs sailed and the waits at their start nodes."""
        return float(sum(leg["hours"] + leg.get("wait_h", 0.0) for leg in self.legs)) if self.legs else math.nan

    @property
    def fuel_t(self) -> float:
        """Fuel of the voyage: the legs sailed and the waits at their start nodes."""
        return float(sum(leg["fuel_t"] + leg.get("wait_fuel_t", 0.0) for leg in self.legs)) if self.legs else math.nan

    @property
    def wait_h(self) -> float:
        """Hours the plan waits at nodes (hove to in front of weather; 0 for a wait-free plan)."""
        return float(sum(leg.get("wait_h", 0.0) for leg in self.legs))

    @property
    def distance_nm(self) -> float:
        return float(sum(leg["dist_nm"] for leg in self.legs)) if self.legs else math.nan

    @property
    def eta_utc(self) -> datetime | None:
        return self.legs[-1]["eta_utc"] if self.legs else None

    @property
    def n_beyond_forecast(self) -> int:
        return int(sum(bool(leg["beyond_forecast"]) for leg in self.legs))

    @property
    def hours_beyond_forecast(self) -> float:
        """Hours of the voyage sailed after the weather's last valid time (its last step persisted)."""
        return float(sum(leg.get("hours_beyond_forecast", 0.0) for leg in self.legs))

    @property
    def fuel_beyond_forecast_t(self) -> float:
        """Fuel (t) burnt after the weather's last valid time (sailing and waiting), where the plan meets the neutral
        weather of engine.leg, not a forecast."""
        return float(sum(leg.get("fuel_beyond_forecast_t", 0.0) for leg in self.legs)) if self.legs else math.nan

    @property
    def hours_before_cycle(self) -> float:
        """Hours of the voyage sailed before the forecast cycle's analysis time (weather of the cycle's first step)."""
        return float(sum(leg.get("hours_before_cycle", 0.0) for leg in self.legs))

    @property
    def forecast_flag(self) -> str | None:
        """'beyond horizon', 'before cycle', 'weather missing' (a hole in the wind), comma separated, or None when
        the whole voyage lies inside the forecast with its weather."""
        no_wind_h = sum(leg.get("hours_without_wind", 0.0) for leg in self.legs)
        flags = [name for name, h in (("beyond horizon", self.hours_beyond_forecast),
                                      ("before cycle", self.hours_before_cycle), ("weather missing", no_wind_h)) if h > 1e-9]
        return ", ".join(flags) or None

    @property
    def n_engine_changes(self) -> int:
        return sum(a["rpm"] != b["rpm"] for a, b in zip(self.legs, self.legs[1:]))

    @property
    def limits_fuel_t(self) -> float:
        """Fuel the engine-change limits cost: this plan's minus the best engine plan on the same route without them
        (solve._with_limits)."""
        return self.fuel_t - self.unlimited_fuel_t if self.limits is not None and self.legs else math.nan

    @property
    def savings_pct(self) -> float:
        """Saving against the discrete-rpm baseline (`baseline`), which usually arrives early; see `savings`."""
        b = self.baseline
        if b is None or not b.legs or not self.legs or not (b.fuel_t > 0):
            return math.nan
        return 100.0 * (b.fuel_t - self.fuel_t) / b.fuel_t

    @property
    def waypoints(self) -> list[tuple[float, float]]:
        if not self.legs:
            return []
        return [(self.legs[0]["lat0"], self.legs[0]["lon0"])] + [(leg["lat1"], leg["lon1"]) for leg in self.legs]

    def route_row(self, run_id: str | None = None) -> dict:
        b = self.baseline
        return {
            "run_id": run_id, "voyage_id": self.voyage_id, "imo": self.imo, "solver": self.solver,
            "objective": self.objective, "status": self.status, "reason": self.reason,
            "depart_utc": _utc(self.depart_utc), "eta_utc": self.eta_utc, "rta_utc": _utc(self.rta_utc),
            "hours": self.hours, "fuel_t": self.fuel_t,
            "baseline_fuel_t": b.fuel_t if b is not None else math.nan,
            "baseline_hours": b.hours if b is not None else math.nan,
            "savings_pct": self.savings_pct, "distance_nm": self.distance_nm,
            "cost": self.cost if math.isfinite(self.cost) else None, "model_version": self.model_version,
            "cycle": _utc(self.cycle), "seed": self.seed, "runtime_s": self.runtime_s, "n_legs": len(self.legs),
            "n_legs_beyond_forecast": self.n_beyond_forecast, "forecast_flag": self.forecast_flag,
            "hours_beyond_forecast": self.hours_beyond_forecast, "hours_before_cycle": self.hours_before_cycle,
            "min_land_clearance_nm": self.min_land_clearance_nm,
            **self._savings_row(), **self._limits_row(), **self._ensemble_row(), **self._baseline_track_row(),
        }

    def _baseline_track_row(self) -> dict:
        """The baseline's waypoints and the rpm of each leg, so it can be sailed again in the weather that came
        (verification.py); empty without a baseline."""
        b = self.baseline
        if b is None or not b.legs:
            return dict.fromkeys(BASELINE_TRACK_COLUMNS)
        return {"baseline_lat_deg": [float(p[0]) for p in b.waypoints],
                "baseline_lon_deg": [float(p[1]) for p in b.waypoints],
                "baseline_leg_rpm": [float(leg["rpm"]) for leg in b.legs]}

    def _ensemble_row(self) -> dict:
        s = self.spread
        if s is None:
            return dict.fromkeys(ENSEMBLE_COLUMNS)
        return {"ensemble_members": s.n_members, "p_on_time": s.p_on_time, "baseline_p_on_time": s.baseline_p_on_time,
                "fuel_p10_t": s.fuel_p10_t, "fuel_p50_t": s.fuel_p50_t, "fuel_p90_t": s.fuel_p90_t,
                "savings_p10_pct": s.savings_p10_pct, "savings_p50_pct": s.savings_p50_pct,
                "savings_p90_pct": s.savings_p90_pct}

    def _savings_row(self) -> dict:
        s = self.savings
        if s is None:
            return dict.fromkeys(SAVINGS_COLUMNS)

        def known(x: float) -> float | None:
            return x if math.isfinite(x) else None
        return {"honest_baseline_rpm": s.baseline_rpm, "honest_baseline_fuel_t": s.baseline_fuel_t,
                "honest_baseline_hours": s.baseline_hours, "profile_fuel_t": s.profile_fuel_t,
                "savings_total_pct": s.total_pct, "savings_speed_profile_pct": s.speed_profile_pct,
                "savings_route_pct": s.route_pct, "fuel_beyond_forecast_t": known(s.plan_fuel_beyond_t),
                "honest_baseline_fuel_beyond_forecast_t": known(s.baseline_fuel_beyond_t),
                "savings_forecast_pct": known(s.forecast_pct), "savings_beyond_forecast_pct": known(s.beyond_forecast_pct),
                "margin_cost_pct": known(s.margin_cost_pct)}

    def _limits_row(self) -> dict:
        lim = self.limits
        return {"min_engine_hold_h": lim.min_hold_h if lim else None,
                "engine_change_cost_t": lim.change_cost_t if lim else None,
                "n_engine_changes": self.n_engine_changes if self.legs else None,
                "unlimited_fuel_t": self.unlimited_fuel_t if lim and self.legs else None,
                "limits_fuel_t": self.limits_fuel_t if lim and self.legs else None}

    def leg_rows(self, run_id: str | None = None) -> list[dict]:
        return [{"run_id": run_id, "voyage_id": self.voyage_id, **leg} for leg in self.legs]

    def to_json(self) -> dict:
        """JSON-safe summary for scripts (`jitroute route --json`)."""
        def clean(v):
            if isinstance(v, datetime):
                return v.strftime("%Y-%m-%dT%H:%M:%SZ")
            if isinstance(v, (np.floating, float)):
                return None if not math.isfinite(float(v)) else round(float(v), 6)
            if isinstance(v, np.integer):
                return int(v)
            if isinstance(v, np.bool_):
                return bool(v)
            return v
        row = self.route_row()
        keys = ("voyage_id", "imo", "status", "reason", "solver", "objective", "fuel_t", "hours", "eta_utc", "rta_utc",
                "depart_utc", "baseline_fuel_t", "savings_pct", "distance_nm", "runtime_s", "seed", "n_legs_beyond_forecast",
                "forecast_flag", "hours_beyond_forecast", "hours_before_cycle", "min_land_clearance_nm") + SAVINGS_COLUMNS + LIMITS_COLUMNS \
            + ENSEMBLE_COLUMNS
        out = {k: clean(row[k]) for k in keys}
        out["legs"] = [{k: clean(v) for k, v in leg.items()} for leg in self.legs]
        return out


def legs_of_route(inst, nodes: np.ndarray, rpm_idx: np.ndarray, wait_h: np.ndarray | None = None,
                  wait_tph: float = 0.0) -> tuple[list[dict], int, int]:
    """Sail the route leg by leg and describe each leg; returns (legs, failure code, failing leg). With `wait_h`
    the ship waits wait_h[i] hours at line i's node before leg i (hove to, burning `wait_tph` t/h): the leg's
    `etd_utc` is after the wait, its `wait_h` and `wait_fuel_t` say what the wait took."""
    lat, lon = inst.space.lat, inst.space.lon
    t = inst.t_dep_h
    legs = []
    for i in range(len(nodes) - 1):
        a, b = int(nodes[i]), int(nodes[i + 1])
        if not inst.space.edge_ok[i, a, b]:
            return legs, lk.NO_EDGE, i
        rpm = float(inst.rpm_options[rpm_idx[i]])
        wait = max(0.0, float(wait_h[i])) if wait_h is not None else 0.0
        t += wait
        o = lk.sail_leg(lat[i, a], lon[i, a], lat[i + 1, b], lon[i + 1, b], t, rpm, inst.vessel, inst.weather)
        if o[lk.CODE] != lk.OK:
            return legs, int(o[lk.CODE]), i
        legs.append(leg_record(i, (lat[i, a], lon[i, a], lat[i + 1, b], lon[i + 1, b]), rpm, o, t, wait,
                               float(wait_tph), inst.weather))
        t += o[lk.H]
    return legs, lk.OK, -1


def leg_record(i: int, ends, rpm: float, o: np.ndarray, t_h: float, wait_h: float, wait_tph: float, weather) -> dict:
    """A plan's leg: the leg `ends` = (lat0, lon0, lat1, lon1) sailed at `rpm` from t_h (hours after the weather's
    t_ref, after a wait of wait_h hove to burning wait_tph t/h) with the leg kernel's output `o`."""
    lat0, lon0, lat1, lon1 = (float(x) for x in ends)
    horizon_h = float(weather.times_h[-1])  # hours after t_ref of the last valid time
    cycle_h = weather.hours_after_ref(weather.cycle) if weather.cycle is not None else 0.0
    wait_beyond_h = max(0.0, t_h - max(t_h - wait_h, horizon_h))  # the part of the wait past the last valid time
    etd = weather.t_ref + np.timedelta64(int(round(t_h * 3600)), "s")
    t = t_h + o[lk.H]
    eta = weather.t_ref + np.timedelta64(int(round(t * 3600)), "s")
    return {
        "leg": i, "lat0": lat0, "lon0": lon0, "lat1": lat1, "lon1": lon1,
        "course_deg": float(geo.gc_bearing_deg(lat0, lon0, lat1, lon1)),
        "dist_nm": float(geo.gc_distance_nm(lat0, lon0, lat1, lon1)),
        "rpm": rpm, "stw_kn": float(o[lk.STW_KN]), "sog_kn": float(o[lk.SOG_KN]), "hours": float(o[lk.H]),
        "fuel_t": float(o[lk.FUEL]), "etd_utc": _utc(etd), "eta_utc": _utc(eta),
        "wait_h": wait_h, "wait_fuel_t": wait_h * wait_tph,
        "wind_kn": float(o[lk.WIND_KN]),
        "wind_dir_deg": float(np.degrees(np.arctan2(o[lk.WIND_FX], o[lk.WIND_FY])) % 360.0),
        "hs_m": float(o[lk.HS]),
        "wave_dir_deg": float(np.degrees(np.arctan2(o[lk.WAVE_FX], o[lk.WAVE_FY])) % 360.0),
        "current_kn": float(o[lk.CUR_KN]), "beyond_forecast": bool(o[lk.BEYOND] > 0),
        "hours_beyond_forecast": max(0.0, t - max(t - o[lk.H], horizon_h)),
        "fuel_beyond_forecast_t": float(o[lk.FUEL_BEYOND]) + wait_beyond_h * wait_tph,
        "hours_before_cycle": max(0.0, min(t, cycle_h) - (t - o[lk.H])),
        "hours_without_wind": float(o[lk.NO_WIND_H]),  # a hole in the cube's wind (sailed as calm): in the reason
    }
