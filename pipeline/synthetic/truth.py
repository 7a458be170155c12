"""A vessel whose true speed and fuel lie outside every fitted form, for honest model benchmarks.

`generate_fleet` draws its reports from the physical form itself, so fitting that form recovers
it by construction. Here the truth has shapes none of the forms has:
  speed = Vd·(rpm/rpm_max)^0.85 − 0.05·(D − 9) − 0.04·T² − fouling(months)^1.3
          − Vw²·h(θw)·k_w − Hs²·h(θs)·k_s          (quadratic losses)
  fuel  = Fd·(rpm/rpm_max)^2.8·(D/9)^(2/3)·(1 + 0.004·months) + load(Vw, θw, Hs, θs)
with a direction dependence h(θ) = 0.5 + 0.4·cos θ + 0.1·cos² θ − 0.1·sin² 2θ (the last term abaft
the beam only): head 1, beam 0.5, following 0.2 with a dip near 135° that the physical form's Kwon
shape does not have; 5 % noise on speed and fuel, and 2 % speed outliers (a misread log). Reports come with the truth beside
them, so held-out scores can be set against the noise floor.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd


@dataclass(frozen=True)
class TrueVessel:
    imo: int
    design_speed_kn: float = 15.0
    rpm_max: float = 100.0
    design_fuel_tph: float = 1.6
    k_wind: float = 1.0 / 800.0  # kn lost per kn² of head wind
    k_wave: float = 0.11  # kn lost per m² of head seas
    fouling_kn: float = 0.01  # kn lost per month^1.3 since dry dock
    draft_m: tuple[float, float, float, float] = (6.0, 8.5, 10.0, 13.0)  # ballast from–to, laden from–to (m)
    log_factor: float = 1.0  # the speed log reads this share of the true STW ...
    log_from_day: int | None = None  # ... from this day of the reports on (None: a sound log)
    name: str = ""


def fleet_of_five(imo0: int = 9150000) -> list[TrueVessel]:
    """Five ships none of whose truths any form has: a slow tanker, a fast container ship, a bulker that fouls fast,
    a bulker with a wide draft range and a ship whose speed log reads 12 % low from day 250 on."""
    return [
        TrueVessel(imo0, design_speed_kn=11.5, rpm_max=85.0, design_fuel_tph=1.1, k_wave=0.13, name="slow tanker"),
        TrueVessel(imo0 + 1, design_speed_kn=22.0, rpm_max=100.0, design_fuel_tph=5.5, k_wind=1.0 / 600.0, k_wave=0.16,
                   name="fast container ship"),
        TrueVessel(imo0 + 2, design_speed_kn=14.0, design_fuel_tph=1.5, fouling_kn=0.05, name="fouling bulker"),
        TrueVessel(imo0 + 3, design_speed_kn=14.0, design_fuel_tph=1.6, draft_m=(4.5, 7.0, 11.0, 16.0),
                   name="wide-draft bulker"),
        TrueVessel(imo0 + 4, design_speed_kn=14.5, design_fuel_tph=1.7, log_factor=0.88, log_from_day=250,
                   name="broken speed log"),
    ]


def direction_shape(rel_deg) -> np.ndarray:
    """Share of the head-on loss: 1 head, 0.5 beam, 0.2 following, with a dip near 135° (no form has it)."""
    th = np.radians(np.abs(((np.asarray(rel_deg, dtype=float) + 180.0) % 360.0) - 180.0))
    return 0.5 + 0.4 * np.cos(th) + 0.1 * np.cos(th) ** 2 - 0.1 * np.sin(2 * th) ** 2 * (th > np.pi / 2)


def speed_kn(v: TrueVessel, rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m, wave_rel_deg, months):
    calm = v.design_speed_kn * (rpm / v.rpm_max) ** 0.85 - 0.05 * (draft_m - 9.0) - 0.04 * trim_m ** 2 - v.fouling_kn * months ** 1.3
    loss = v.k_wind * wind_kn ** 2 * direction_shape(wind_rel_deg) + v.k_wave * hs_m ** 2 * direction_shape(wave_rel_deg)
    return calm - np.minimum(loss, 0.6 * calm)


def fuel_tph(v: TrueVessel, rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m, wave_rel_deg, months):
    calm = v.design_fuel_tph * (rpm / v.rpm_max) ** 2.8 * (draft_m / 9.0) ** (2 / 3) * (1 + 0.004 * months)
    load = 0.00025 * wind_kn ** 2 * direction_shape(wind_rel_deg) + 0.012 * hs_m ** 2 * direction_shape(wave_rel_deg)
    return calm + load * (rpm / v.rpm_max) ** 1.5


def reports(v: TrueVessel, end_utc: str, days: int, seed: int, *, noise: float = 0.05,
            outliers: float = 0.02) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(daily noon reports ending at `end_utc`, in the noon-report columns; the true stw_kn and fuel_tph of each)."""
    rng = np.random.default_rng(seed)
    end = np.datetime64(pd.Timestamp(end_utc).tz_localize(None), "h")
    ts = end - np.arange(days)[::-1].astype("timedelta64[D]").astype("timedelta64[h]")
    rpm = v.rpm_max * rng.uniform(0.5, 1.0, days)
    b0, b1, l0, l1 = v.draft_m
    draft = np.where(rng.random(days) < 0.5, rng.uniform(b0, b1, days), rng.uniform(l0, l1, days))
    trim = rng.normal(0.5, 0.6, days).clip(-2, 3)
    wind = rng.gamma(3.0, 5.0, days).clip(0, 55)
    wind_rel = rng.uniform(0, 360, days)
    wave = (0.3 + 0.02 * wind ** 1.5 * rng.uniform(0.7, 1.3, days)).clip(0, 10)
    wave_rel = (wind_rel + rng.normal(0, 25, days)) % 360
    months = 3.0 + np.arange(days) / 30.4
    args = (rpm, draft, trim, wind, wind_rel, wave, wave_rel, months)
    true_stw, true_fuel = speed_kn(v, *args), fuel_tph(v, *args)
    stw = true_stw * rng.normal(1.0, noise, days)
    rate = true_fuel * rng.normal(1.0, noise, days)
    bad = rng.random(days) < outliers
    stw = np.where(bad, stw * rng.choice([0.7, 1.3], days), stw)
    if v.log_from_day is not None:  # the log reads wrong from then on (what the truth beside it does not)
        stw = np.where(np.arange(days) >= v.log_from_day, stw * v.log_factor, stw)
    hours = np.full(days, 24.0)
    df = pd.DataFrame({
        "imo": v.imo, "ts_utc": pd.to_datetime(ts), "lat": 10.0, "lon": 150.0, "rpm": rpm.round(2), "draft_m": draft.round(2),
        "trim_m": trim.round(2), "stw_kn": stw.round(3), "sog_kn": stw.round(3), "dist_nm": (stw * hours).round(2), "hours": hours,
        "fuel_t": (rate * hours).round(4), "wind_kn": wind.round(2), "wind_dir_rel_deg": wind_rel.round(1), "wave_m": wave.round(2),
        "wave_dir_rel_deg": wave_rel.round(1), "months_since_drydock": months.round(2),
    })
    return df, pd.DataFrame({"stw_kn": true_stw, "fuel_tph": true_fuel})
