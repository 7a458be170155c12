"""Validation of noon reports: every row is either good or rejected with a reason.

Nothing is silently dropped. Reasons (first failing check wins, in this order):
  missing <col>                      required value empty / NaN
  not a number in <col>              text where a number belongs
  not a finite number in <col>       inf, or a number beyond float range such as 1e400
  not an integer in imo              e.g. 9140607.9 (never truncated to another vessel's number)
  bad timestamp                      ts_utc not ISO 8601 (pipeline.timestamps; naive = UTC, offsets per value)
  ambiguous timestamp (…)            a day/month/year date such as 01/11/2018 12:00
  timestamp in the future            after the time of the import (+ FUTURE_TOLERANCE)
  unknown vessel                     IMO not in the vessels table
  hours <= 0                         reporting period not positive
  negative <col>                     negative where impossible
  out of range <col>                 outside a physical range (lat, rpm, draft, directions −180..360…)
  speed beyond physics               STW or SOG above 35 kn
  fuel looks like kg                 fuel rate above 20 t/h (a unit mistake)
  speed looks like m/s               SOG disagrees with dist/hours by the m/s factor (1.944 ± 0.05)
  sog inconsistent with distance     SOG disagrees with dist/hours by more than 25 %
  duplicate timestamp in file        a second row with the same (imo, ts_utc)
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from pipeline.timestamps import parse_iso_column

REQUIRED = ("imo", "ts_utc", "rpm", "draft_m", "stw_kn", "hours", "fuel_t")
NUMERIC = ("lat", "lon", "rpm", "draft_m", "trim_m", "stw_kn", "sog_kn", "dist_nm", "hours", "fuel_t", "fuel_hfo_t",
           "fuel_mgo_t", "wind_kn", "wind_dir_rel_deg", "wave_m", "wave_dir_rel_deg", "current_kn",
           "current_dir_rel_deg", "months_since_drydock")
OPTIONAL_DEFAULTS = {"trim_m": 0.0, "wind_kn": 0.0, "wind_dir_rel_deg": 0.0, "wave_m": 0.0, "wave_dir_rel_deg": 0.0,
                     "months_since_drydock": 0.0}
NON_NEGATIVE = ("rpm", "draft_m", "stw_kn", "sog_kn", "dist_nm", "fuel_t", "fuel_hfo_t", "fuel_mgo_t", "wind_kn",
                "wave_m", "current_kn", "months_since_drydock")
RANGES = {
    "lat": (-90, 90), "lon": (-180, 360), "rpm": (1, 250), "draft_m": (1, 25), "trim_m": (-6, 6), "hours": (0, 30),
    "wind_dir_rel_deg": (-180, 360), "wave_dir_rel_deg": (-180, 360), "current_dir_rel_deg": (-180, 360),
    "wind_kn": (0, 120), "wave_m": (0, 25), "current_kn": (0, 8), "months_since_drydock": (0, 240),
}
FOLDED_DIRECTIONS = ("wind_dir_rel_deg", "wave_dir_rel_deg")
MAX_SPEED_KN = 35.0
MAX_FUEL_TPH = 20.0
MS_TO_KN = 1.943844
FUTURE_TOLERANCE = pd.Timedelta(hours=1)  # clock skew between ship and shore


class NoonFileError(ValueError):
    """The file as a whole cannot be read as noon reports (e.g. a required column is absent)."""


def validate_noon(raw: pd.DataFrame, known_imos: set[int] | None = None, source: str = "",
                  now: pd.Timestamp | None = None) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(good rows with typed columns, rejected rows with `reason` and the original `raw` text).

    `now` (naive UTC; default the current time) is the limit for report times."""
    absent = [c for c in REQUIRED if c not in raw.columns]
    if absent:
        raise NoonFileError(f"{source or 'noon report file'}: required columns missing: {', '.join(absent)}")
    df = raw.copy()
    df["raw"] = raw_text(raw)
    reason = pd.Series(pd.NA, index=df.index, dtype="object")

    def flag(mask, text):
        nonlocal reason
        mask = pd.Series(mask, index=df.index).fillna(False).astype(bool) & reason.isna()
        reason = reason.mask(mask, text)

    for c in REQUIRED:
        flag(df[c].isna() | (df[c].astype(str).str.strip().isin(["", "nan", "NaN", "None"])), f"missing {c}")
    for c in NUMERIC:
        if c not in df.columns:
            df[c] = OPTIONAL_DEFAULTS.get(c, np.nan)
            continue
        num = pd.to_numeric(df[c], errors="coerce")
        flag(num.isna() & df[c].notna() & ~df[c].astype(str).str.strip().isin(["", "nan", "NaN", "None"]), f"not a number in {c}")
        flag(np.isinf(num.astype(float)), f"not a finite number in {c}")
        df[c] = num
        if c in OPTIONAL_DEFAULTS:
            df[c] = df[c].fillna(OPTIONAL_DEFAULTS[c])
    imo = pd.to_numeric(df["imo"], errors="coerce")
    flag(imo.isna() & reason.isna(), "not a number in imo")
    flag(imo.notna() & ((imo % 1 != 0) | np.isinf(imo.astype(float))), "not an integer in imo")
    df["imo"] = imo.where(imo.notna() & (imo % 1 == 0) & (imo.abs() < 2**62), 0).astype("int64")
    ts, why = parse_iso_column(df["ts_utc"])
    reason = reason.mask(why.notna() & reason.isna(), why)
    flag(ts > (pd.Timestamp.now("UTC").tz_localize(None) if now is None else pd.Timestamp(now)) + FUTURE_TOLERANCE,
         "timestamp in the future")
    df["ts_utc"] = ts
    if known_imos is not None:
        flag(~df["imo"].isin(list(known_imos)), "unknown vessel")
    flag(df["hours"] <= 0, "hours <= 0")
    for c in NON_NEGATIVE:
        flag(df[c] < 0, f"negative {c}")
    for c, (lo, hi) in RANGES.items():
        flag((df[c] < lo) | (df[c] > hi), f"out of range {c}")
    flag((df["stw_kn"] > MAX_SPEED_KN) | (df["sog_kn"] > MAX_SPEED_KN), "speed beyond physics")
    flag(df["fuel_t"] / df["hours"] > MAX_FUEL_TPH, "fuel looks like kg")
    implied = df["dist_nm"] / df["hours"]
    ratio = implied / df["sog_kn"]
    flag((df["sog_kn"] > 0.5) & (ratio.sub(MS_TO_KN).abs() < 0.05), "speed looks like m/s")
    flag((df["sog_kn"] > 0.5) & ((ratio - 1.0).abs() > 0.25), "sog inconsistent with distance")
    # relative directions: 0..360 clockwise from the bow, or signed −180..180 (negative to port) — both common.
    # Wind and waves are folded to 0..180 (0 head, 90 beam either side, 180 following: the models use no side);
    # the current's relative direction (going-to) is kept whole, as 0..360.
    for c in FOLDED_DIRECTIONS:
        df[c] = fold_rel_deg(df[c])
    df["current_dir_rel_deg"] = df["current_dir_rel_deg"] % 360.0
    still_good = reason.isna()
    dup = df[still_good].duplicated(subset=["imo", "ts_utc"], keep="first").reindex(df.index, fill_value=False)
    flag(dup, "duplicate timestamp in file")
    df["source_file"] = source
    bad = df[reason.notna()].copy()
    bad["reason"] = reason[reason.notna()]
    good = df[reason.isna()].drop(columns=["raw"])
    return good.reset_index(drop=True), bad.reset_index(drop=True)


def fold_rel_deg(rel_deg):
    """Relative directions (degrees, 0..360 or −180..180) folded to 0..180, port and starboard alike:
    |((rel + 180) mod 360) − 180| (as `features.fold_rel_deg`); NaN stays NaN."""
    return np.abs(((np.asarray(rel_deg, dtype=np.float64) + 180.0) % 360.0) - 180.0)


def raw_text(df: pd.DataFrame) -> pd.Series:
    """Each row as 'v1|v2|…' text, as it came in (kept with rejected rows)."""
    cols = [df[c].astype("string").fillna("") for c in df.columns]
    out = cols[0]
    for c in cols[1:]:
        out = out + "|" + c
    return out.astype(object)


def reason_counts(rejected: pd.DataFrame) -> dict[str, int]:
    return rejected["reason"].value_counts().to_dict() if len(rejected) else {}
