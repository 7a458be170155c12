"""Validation of the fleet files `vessels.csv` and `voyages.csv`: every row is good or rejected with a reason.

Rows come in as text (as read from the file); good rows leave typed. The first failing check gives the
reason. A refused row is kept with its raw text (`raw`) so it can be fixed and re-imported.

Vessels: missing imo/name; `not an integer in imo`; `IMO number fails its check digit`
(`pipeline.validate_ids.is_valid_imo`); `not a number in <col>`; `not a finite number in <col>`;
`negative <col>`; `control characters or a line break in <col>` (any text column); `bad barred_rpm` (not
low-high rpm ranges separated by ';'); `duplicate imo in file`.

Voyages: the voyage ID (`pipeline.validate_ids.voyage_id_problem`); `not an integer in imo`;
`unknown vessel`; timestamps (ISO 8601 only, `pipeline.timestamps`); positions; `bad rpm_options`;
`control characters or a line break in <col>` (port names and any other text column);
`implausible voyage length` (RTA more than MAX_VOYAGE_DAYS after departure); `duplicate voyage_id in file`.
An RTA not after departure is left to routing, which records the voyage `failed` naming both times.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pandas as pd

from pipeline.engine_ranges import parse_barred_rpm
from pipeline.timestamps import parse_iso_column
from pipeline.validate_ids import has_control_characters, is_valid_imo, voyage_id_problem

MAX_VOYAGE_DAYS = 90.0  # the longest plausible single voyage (a slow round-the-world passage is ~60 days)
VESSEL_NUMERIC = ("dwt", "design_speed_kn", "mcr_kw", "rpm_max", "design_fuel_tph")
VOYAGE_NUMERIC = ("dep_lat", "dep_lon", "arr_lat", "arr_lon", "draft_m", "trim_m", "max_hs_m", "max_wind_kn")
VOYAGE_REQUIRED = ("voyage_id", "imo", "dep_lat", "dep_lon", "arr_lat", "arr_lon", "depart_utc", "rta_utc")
_EMPTY = ("", "nan", "NaN", "None", "<NA>")
_INTEGER = re.compile(r"^\s*[+]?\d+(\.0*)?\s*$")


class FleetFileError(ValueError):
    """The file as a whole cannot be read as vessels/voyages (e.g. a required column is absent)."""


def raw_rows(df: pd.DataFrame) -> pd.Series:
    """Each row as 'v1|v2|…' text, as it came in."""
    cols = [df[c].astype("string").fillna("") for c in df.columns]
    out = cols[0] if cols else pd.Series("", index=df.index, dtype="string")
    for c in cols[1:]:
        out = out + "|" + c
    return out.astype(object)


class _Reasons:
    """The first reason per row wins."""

    def __init__(self, index):
        self.reason = pd.Series(pd.NA, index=index, dtype="object")

    def flag(self, mask, text) -> None:
        mask = pd.Series(mask, index=self.reason.index).fillna(False).astype(bool) & self.reason.isna()
        self.reason = self.reason.mask(mask, text)

    def flag_each(self, reasons: pd.Series, prefix: str = "") -> None:
        """Per-row reasons (NA where fine)."""
        todo = reasons.notna() & self.reason.isna()
        self.reason = self.reason.mask(todo, prefix + reasons[todo].astype(str) if prefix else reasons[todo])


def _is_empty(s: pd.Series) -> pd.Series:
    return s.isna() | s.astype(str).str.strip().isin(_EMPTY)


def _integer_imo(df: pd.DataFrame, r: _Reasons) -> pd.Series:
    text = df["imo"].astype(str)
    r.flag(~_is_empty(df["imo"]) & ~text.str.match(_INTEGER), "not an integer in imo")
    return pd.to_numeric(text.where(text.str.match(_INTEGER)), errors="coerce").fillna(0).astype("int64")


def _numbers(df: pd.DataFrame, cols, r: _Reasons) -> None:
    for c in cols:
        if c not in df.columns:
            df[c] = np.nan
            continue
        num = pd.to_numeric(df[c], errors="coerce")
        r.flag(num.isna() & ~_is_empty(df[c]), f"not a number in {c}")
        r.flag(np.isinf(num.astype(float)), f"not a finite number in {c}")
        df[c] = num


def _clean_text(df: pd.DataFrame, columns, r: _Reasons) -> None:
    for c in columns:
        if c in df.columns:
            r.flag(df[c].map(has_control_characters), f"control characters or a line break in {c}")


def _split(df: pd.DataFrame, r: _Reasons, raw: pd.Series, source: str) -> tuple[pd.DataFrame, pd.DataFrame]:
    df["source_file"] = source
    bad = df[r.reason.notna()].copy().astype(object)
    bad["raw"] = raw[r.reason.notna()]
    bad["reason"] = r.reason[r.reason.notna()]
    good = df[r.reason.isna()]
    return good.reset_index(drop=True), bad.reset_index(drop=True)


def _barred_problem(text) -> str | None:
    try:
        parse_barred_rpm(text)
    except ValueError as e:
        return str(e)
    return None


def validate_vessels(raw: pd.DataFrame, source: str = "") -> tuple[pd.DataFrame, pd.DataFrame]:
    """(good vessel rows, typed; rejected rows with `raw`, `reason`, `source_file`)."""
    absent = [c for c in ("imo", "name") if c not in raw.columns]
    if absent:
        raise FleetFileError(f"{source or 'vessels file'}: required columns missing: {', '.join(absent)}")
    df = raw.copy()
    r = _Reasons(df.index)
    for c in ("imo", "name"):
        r.flag(_is_empty(df[c]), f"missing {c}")
    imo = _integer_imo(df, r)
    r.flag(~imo.map(lambda i: 0 < i <= 9_999_999 and is_valid_imo(i)), "IMO number fails its check digit")
    df["imo"] = imo
    _numbers(df, VESSEL_NUMERIC, r)
    for c in VESSEL_NUMERIC:
        r.flag(df[c] < 0, f"negative {c}")
    _clean_text(df, [c for c in df.columns if c not in ("imo", *VESSEL_NUMERIC)], r)
    if "barred_rpm" in df.columns:
        r.flag_each(df["barred_rpm"].map(_barred_problem))
    r.flag(df["imo"].duplicated(keep="first") & r.reason.isna(), "duplicate imo in file")
    df["name"] = df["name"].astype(str)
    return _split(df, r, raw_rows(raw), source)


def _rpm_options(value) -> tuple[list[float] | None, str | None]:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return None, None
    if isinstance(value, (list, tuple, np.ndarray)):
        items = list(value)
    else:
        text = str(value).strip()
        if text in _EMPTY or text == "[]":
            return None, None
        items = [x for x in text.strip("[]").split(",") if x.strip()]
    try:
        rpm = [float(x) for x in items]
    except (TypeError, ValueError):
        return None, "bad rpm_options (a list of numbers, e.g. [60,70,80])"
    if not all(math.isfinite(x) and x > 0 for x in rpm):
        return None, "bad rpm_options (a list of numbers, e.g. [60,70,80])"
    return rpm, None


def validate_voyages(raw: pd.DataFrame, known_imos: set[int] | None = None,
                     source: str = "", plan_voyages: dict[str, str] | None = None) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(good voyage rows, typed: timestamps naive UTC, rpm_options lists; rejected rows with `raw`, `reason`).
    `plan_voyages` (voyage_id → plan_id of the voyages fleet plans made): a row with one of those IDs is refused —
    it would silently replace the plan's voyage (and the cargo it carries); plan voyages change by re-planning."""
    absent = [c for c in VOYAGE_REQUIRED if c not in raw.columns]
    if absent:
        raise FleetFileError(f"{source or 'voyages file'}: required columns missing: {', '.join(absent)}")
    df = raw.copy()
    r = _Reasons(df.index)
    r.flag_each(df["voyage_id"].map(voyage_id_problem))
    df["voyage_id"] = df["voyage_id"].astype(str)
    for c in VOYAGE_REQUIRED[1:]:
        r.flag(_is_empty(df[c]), f"missing {c}")
    imo = _integer_imo(df, r)
    df["imo"] = imo
    if known_imos is not None:
        r.flag(~imo.isin(list(known_imos)), "unknown vessel")
    for c in ("depart_utc", "rta_utc"):
        ts, why = parse_iso_column(df[c])
        r.flag_each(why.where(~_is_empty(df[c]), pd.NA), prefix=f"{c}: ")
        df[c] = ts
    _numbers(df, VOYAGE_NUMERIC, r)
    for c, lim in (("dep_lat", 90), ("arr_lat", 90)):
        r.flag(df[c].abs() > lim, f"out of range {c}")
    for c in ("dep_lon", "arr_lon"):
        r.flag((df[c] < -180) | (df[c] > 360), f"out of range {c}")
    if "rpm_options" in df.columns:
        parsed = df["rpm_options"].map(_rpm_options)
        r.flag_each(parsed.map(lambda p: p[1]).where(parsed.map(lambda p: p[1] is not None), pd.NA))
        df["rpm_options"] = parsed.map(lambda p: p[0])
    else:
        df["rpm_options"] = None
    days = (df["rta_utc"] - df["depart_utc"]) / pd.Timedelta(days=1)
    r.flag(days > MAX_VOYAGE_DAYS,
           f"implausible voyage length: RTA more than {MAX_VOYAGE_DAYS:g} days after departure (check the year of rta_utc)")
    _clean_text(df, [c for c in df.columns if c not in ("voyage_id", "imo", "depart_utc", "rta_utc", "rpm_options",
                                                        *VOYAGE_NUMERIC)], r)
    r.flag(df["voyage_id"].duplicated(keep="first") & r.reason.isna(), "duplicate voyage_id in file")
    if plan_voyages:
        r.flag_each(df["voyage_id"].map(lambda v: f"voyage_id {v} is a voyage of fleet plan {plan_voyages[v]}: a voyages "
                                                  "file may not replace it; give this voyage another ID (plan voyages "
                                                  "change by re-planning, `jitroute plan fleet`)"
                                        if v in plan_voyages else pd.NA))
    for c in ("dep_name", "arr_name", "status"):
        if c in df.columns:
            df[c] = df[c].where(~_is_empty(df[c]), None)
    return _split(df, r, raw_rows(raw), source)
