"""A deterministic demo fleet: vessels, a year of noon reports from known "true" models, voyages.

The true models are physical-form `PerformanceModel`s, so a refit should recover them. A few bad
rows of every kind the validator knows are mixed in. Voyages run between real port approaches
in the western Pacific and depart inside the demo weather window.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from pipeline.performance.model import PerformanceModel

PORTS = {  # approach points at sea (lat, lon east)
    "Tokyo Bay": (34.85, 139.85), "Busan": (34.95, 129.15), "Shanghai": (30.9, 122.75), "Kaohsiung": (22.5, 120.15),
    "Hong Kong": (22.1, 114.35), "Manila": (14.4, 120.3), "Guam": (13.45, 144.55), "Naha": (26.2, 127.55),
    "Keelung": (25.25, 121.85), "Qingdao": (35.9, 120.65), "Nagoya": (34.5, 137.0), "Yokohama": (35.3, 139.8),
}
ROUTES = [("Tokyo Bay", "Guam"), ("Busan", "Shanghai"), ("Shanghai", "Kaohsiung"), ("Kaohsiung", "Hong Kong"),
          ("Hong Kong", "Manila"), ("Naha", "Tokyo Bay"), ("Keelung", "Naha"), ("Guam", "Naha"), ("Qingdao", "Busan"),
          ("Nagoya", "Naha"), ("Shanghai", "Naha"), ("Manila", "Kaohsiung")]
TYPES = [("container", 14000, 21.0, 95.0, 4.2), ("bulker", 82000, 14.0, 105.0, 1.4), ("tanker", 115000, 14.5, 100.0, 1.8),
         ("ro-ro", 12000, 19.0, 120.0, 2.6), ("general cargo", 9000, 13.5, 140.0, 0.9), ("car carrier", 18000, 20.0, 110.0, 2.9)]


def imo_with_check_digit(six_digits: int) -> int:
    d = [int(c) for c in f"{six_digits:06d}"]
    return six_digits * 10 + sum(x * w for x, w in zip(d, range(7, 1, -1))) % 10


def is_valid_imo(imo: int) -> bool:
    return 1_000_000 <= imo <= 9_999_999 and imo_with_check_digit(imo // 10) == imo


@dataclass(frozen=True)
class DemoFleet:
    vessels: pd.DataFrame
    noon: pd.DataFrame
    voyages: pd.DataFrame
    true_models: dict[int, PerformanceModel]


def true_model(design_speed_kn: float, rpm_max: float, design_fuel_tph: float, rng: np.random.Generator) -> PerformanceModel:
    """Physical-form truth: speed ∝ rpm with draft/trim/fouling losses; fuel ∝ rpm³ with draft and fouling."""
    a_rpm = design_speed_kn / rpm_max * rng.uniform(1.02, 1.08)
    speed = np.array([0.6, a_rpm, -0.06, -0.05, 1.0 / 700.0, 0.09, -0.012])
    r3 = (rpm_max / 100.0) ** 3
    fuel = np.array([0.05, design_fuel_tph / r3 * 0.8, design_fuel_tph / r3 * 0.02, design_fuel_tph / r3 * 0.002, 0.0003, 0.012])
    return PerformanceModel(form="physical", speed_coef=speed, fuel_coef=fuel)


def _reports(imo: int, vt: tuple, model: PerformanceModel, start: np.datetime64, days: int, rng) -> pd.DataFrame:
    _, _, design_kn, rpm_max, _ = vt
    ts = start - np.timedelta64(days, "D") + np.arange(days).astype("timedelta64[D]") + np.timedelta64(12, "h")
    rpm = rpm_max * rng.uniform(0.55, 1.0, days)
    draft = np.where(rng.random(days) < 0.5, rng.uniform(6.0, 8.5, days), rng.uniform(10.0, 13.0, days))
    trim = rng.normal(0.5, 0.6, days).clip(-2, 3)
    wind = rng.gamma(3.0, 5.0, days).clip(0, 60)
    wind_rel = rng.uniform(0, 180, days)
    wave = (0.3 + 0.02 * wind**1.5 * rng.uniform(0.7, 1.3, days)).clip(0, 12)
    wave_rel = (wind_rel + rng.normal(0, 20, days)) % 180
    months = 6.0 + np.arange(days) / 30.4
    m = PerformanceModel(form="physical", speed_coef=model.speed_coef, fuel_coef=model.fuel_coef)
    X = dict(rpm=rpm, draft_m=draft, trim_m=trim, wind_kn=wind, wind_rel_deg=wind_rel, hs_m=wave, wave_rel_deg=wave_rel)
    from pipeline.performance import features

    Xs = features.design_matrix(1, "speed", rpm, draft, trim, wind, wind_rel, wave, wave_rel, months)
    Xf = features.design_matrix(1, "fuel", rpm, draft, trim, wind, wind_rel, wave, wave_rel, months)
    stw = np.maximum(Xs @ m.speed_coef, 0.5) + rng.normal(0, 0.15, days)
    rate = np.maximum(Xf @ m.fuel_coef, 0.05) * rng.normal(1.0, 0.02, days)
    hours = np.where(rng.random(days) < 0.1, 23.0, 24.0)
    current = rng.gamma(1.5, 0.3, days).clip(0, 3)
    current_rel = rng.uniform(0, 360, days)
    sog = stw + current * np.cos(np.radians(current_rel))
    lat = rng.uniform(-30, 40, days)
    lon = rng.uniform(100, 200, days)
    del X
    return pd.DataFrame({
        "imo": imo, "ts_utc": pd.to_datetime(ts).strftime("%Y-%m-%dT%H:%M:%SZ"), "lat": lat.round(3), "lon": lon.round(3),
        "rpm": rpm.round(2), "draft_m": draft.round(2), "trim_m": trim.round(2), "stw_kn": stw.round(3), "sog_kn": sog.round(3),
        "dist_nm": (sog * hours).round(2), "hours": hours, "fuel_t": (rate * hours).round(4), "wind_kn": wind.round(2),
        "wind_dir_rel_deg": wind_rel.round(1), "wave_m": wave.round(2), "wave_dir_rel_deg": wave_rel.round(1),
        "current_kn": current.round(2), "current_dir_rel_deg": current_rel.round(1), "months_since_drydock": months.round(2),
    })


def _spoil(df: pd.DataFrame, rng) -> pd.DataFrame:
    """A few bad rows of each kind the validator rejects."""
    bad = []
    pick = lambda: df.iloc[int(rng.integers(len(df)))].copy()  # noqa: E731
    r = pick(); r["stw_kn"] = np.nan; bad.append(r)
    r = pick(); r["fuel_t"] = -3.0; bad.append(r)
    r = pick(); r["hours"] = 0.0; bad.append(r)
    r = pick(); r["draft_m"] = 42.0; bad.append(r)
    r = pick(); r["stw_kn"] = 61.0; r["sog_kn"] = 61.0; r["dist_nm"] = 61.0 * r["hours"]; bad.append(r)
    r = pick(); r["fuel_t"] = r["fuel_t"] * 1000.0; bad.append(r)
    r = pick(); r["sog_kn"] = round(r["sog_kn"] / 1.943844, 3); bad.append(r)
    r = pick(); r["rpm"] = "n/a"; bad.append(r)
    dup = pick(); dup["ts_utc"] = df["ts_utc"].iloc[5]; bad.append(dup)
    return pd.concat([df.astype(object), pd.DataFrame(bad)], ignore_index=True)


def _gc_nm(a, b) -> float:
    la1, lo1, la2, lo2 = map(np.radians, (a[0], a[1], b[0], b[1]))
    h = np.sin((la2 - la1) / 2) ** 2 + np.cos(la1) * np.cos(la2) * np.sin((lo2 - lo1) / 2) ** 2
    return float(2 * np.arcsin(np.sqrt(h)) * 3440.065)


AT_SEA_DEPART_H = -20  # voyages at sea departed this many hours after `start` (before it)


def _at_sea_reports(reports: pd.DataFrame, dep, arr, depart, speed_kn: float, start) -> pd.DataFrame:
    """The vessel's noon reports after departure moved onto its great circle at `speed_kn`, plus one at `start` + 12 h
    (a copy of its last report at the position then): a ship at sea, 32 h out, for the en-route re-planning."""
    from pipeline.routing.geodesy import gc_interpolate

    extra = reports.iloc[[-1]].copy()
    extra["ts_utc"] = pd.Timestamp(start + np.timedelta64(12, "h")).strftime("%Y-%m-%dT%H:%M:%SZ")
    out = pd.concat([reports, extra], ignore_index=True)
    dist = _gc_nm(dep, arr)
    ts = pd.to_datetime(out["ts_utc"]).dt.tz_localize(None)
    for k in np.flatnonzero((ts > pd.Timestamp(depart)).to_numpy()):
        frac = min(0.9, (ts.iloc[k] - pd.Timestamp(depart)).total_seconds() / 3600.0 * speed_kn / dist)
        lat, lon = gc_interpolate(dep[0], dep[1], arr[0], arr[1], frac)
        out.loc[k, "lat"], out.loc[k, "lon"] = round(float(lat), 3), round(float(lon) % 360.0, 3)
    return out


def generate_fleet(start, *, n_vessels: int = 12, days: int = 365, seed: int = 7, at_sea: tuple[int, ...] = ()) -> DemoFleet:
    """Fleet whose reports end at `start` and whose voyages depart 13–35 h after `start`; the voyages numbered in
    `at_sea` (0-based) instead departed 20 h before `start` and are at sea, their vessels' reports after departure
    on their way (the last at `start` + 12 h)."""
    rng = np.random.default_rng(seed)
    start = np.datetime64(start, "h")
    vessels, noon, voyages, truths = [], [], [], {}
    for i in range(n_vessels):
        vt = TYPES[i % len(TYPES)]
        imo = imo_with_check_digit(914060 + 7 * i)
        name = f"JIT {vt[0].split()[0].upper()} {i + 1:02d}"
        dwt = vt[1] * rng.uniform(0.8, 1.25)
        design_fuel = vt[4] * rng.uniform(0.9, 1.1)
        truth = true_model(vt[2], vt[3], design_fuel, rng)
        truths[imo] = truth
        vessels.append({"imo": imo, "name": name, "type": vt[0], "dwt": round(dwt), "design_speed_kn": vt[2],
                        "mcr_kw": round(dwt * 0.35 + 4000), "rpm_max": vt[3], "design_fuel_tph": round(design_fuel, 3)})
        reports = _reports(imo, vt, truth, start, days, rng)
        dep, arr = ROUTES[i % len(ROUTES)]
        dist = _gc_nm(PORTS[dep], PORTS[arr])
        depart = start + np.timedelta64(int(13 + 2 * i), "h")  # after the 12 UTC cycle of the start day
        speed = vt[2] * (0.80 if i != n_vessels - 1 else 1.9)  # the last voyage's RTA is impossibly tight
        if i in at_sea:
            depart = start + np.timedelta64(AT_SEA_DEPART_H, "h")
            reports = _at_sea_reports(reports, PORTS[dep], PORTS[arr], depart, speed * 0.95, start)
        noon.append(_spoil(reports, rng) if i % 3 == 0 else reports)
        hours = dist * 1.08 / speed
        rpm_opts = [round(vt[3] * f, 1) for f in (0.6, 0.7, 0.8, 0.9, 1.0)]
        voyages.append({"voyage_id": f"V{int(str(start)[:4]) % 100:02d}{i + 1:03d}", "imo": imo, "dep_name": dep,
                        "dep_lat": PORTS[dep][0], "dep_lon": PORTS[dep][1], "arr_name": arr, "arr_lat": PORTS[arr][0],
                        "arr_lon": PORTS[arr][1], "depart_utc": pd.Timestamp(depart), "rta_utc": pd.Timestamp(depart + np.timedelta64(int(hours * 60), "m")),
                        "draft_m": 11.0, "trim_m": 0.5, "rpm_options": rpm_opts, "max_hs_m": 7.0, "max_wind_kn": 50.0,
                        "status": "planned"})
    return DemoFleet(pd.DataFrame(vessels), pd.concat(noon, ignore_index=True), pd.DataFrame(voyages), truths)


def write_fleet(fleet: DemoFleet, out_dir) -> dict[str, str]:
    """vessels.csv, noon_reports.csv, voyages.csv in the import formats."""
    from pathlib import Path

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    fleet.vessels.to_csv(out / "vessels.csv", index=False)
    fleet.noon.to_csv(out / "noon_reports.csv", index=False)
    v = fleet.voyages.copy()
    v["rpm_options"] = v["rpm_options"].map(lambda r: "[" + ",".join(map(str, r)) + "]")
    v.to_csv(out / "voyages.csv", index=False)
    return {k: str(out / f"{k}.csv") for k in ("vessels", "noon_reports", "voyages")}
