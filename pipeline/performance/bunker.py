"""Validation of bunker logs (what each vessel received, where, from whom; what remained on board).

One row per bunker delivery note and fuel type. Columns: imo, bill_no, date_utc, port, supplier,
fuel_type, received_t, rob_t (tonnes remaining on board of that fuel before receiving; optional).
As strict as the noon-report import; every row is either good or rejected with a reason (first failing check wins),
rejected rows keep their raw text (`bunker_logs_rejected`):
  missing <col>                                    required value empty
  not a number in <col> / not a finite number in <col>   text, `inf` or `1e400` where a number belongs
  not an integer in imo                            a fractional IMO (9140607.9 is not 9140607)
  IMO number fails its check digit                 `pipeline.validate_ids.is_valid_imo`
  date_utc: bad timestamp / ambiguous timestamp …  ISO 8601 only, read value by value (`pipeline.timestamps`)
  date in the future                               later than now (+ FUTURE_TOLERANCE)
  unknown vessel                                   IMO not in the vessels table
  negative <col>                                   tonnes below zero
  received looks like kg                           more than MAX_RECEIVED_T tonnes in one delivery
  received more than the vessel's deadweight       more than its `dwt` (when known)
  control characters or a line break in <col>      in bill_no, port, supplier or fuel_type
  duplicate bill and fuel in file                  a second row with the same (imo, bill_no, fuel_type)
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from pipeline.performance.validate import FUTURE_TOLERANCE, NoonFileError, raw_text
from pipeline.timestamps import parse_iso_column
from pipeline.validate_ids import has_control_characters, is_valid_imo

REQUIRED = ("imo", "bill_no", "date_utc", "fuel_type", "received_t")
COLUMNS = ("imo", "bill_no", "date_utc", "port", "supplier", "fuel_type", "received_t", "rob_t")
TEXT = ("bill_no", "port", "supplier", "fuel_type")
MAX_RECEIVED_T = 20000.0  # more in one delivery is a unit mistake (kg for t)
_EMPTY = ["", "nan", "NaN", "None", "<NA>"]


def validate_bunker(raw: pd.DataFrame, known_imos: set[int] | None = None, source: str = "",
                    dwt_t: dict[int, float] | None = None,
                    now: pd.Timestamp | None = None) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(good rows with typed columns, rejected rows with `reason` and the original `raw` text).

    `dwt_t`: vessel deadweight (t) by IMO, the most one delivery can be; `now` (naive UTC; default the current
    time) is the limit for delivery dates."""
    absent = [c for c in REQUIRED if c not in raw.columns]
    if absent:
        raise NoonFileError(f"{source or 'bunker log file'}: required columns missing: {', '.join(absent)}")
    df = raw.reindex(columns=list(COLUMNS)).copy()
    reason = pd.Series(pd.NA, index=df.index, dtype="object")

    def flag(mask, text):
        nonlocal reason
        mask = pd.Series(mask, index=df.index).fillna(False).astype(bool) & reason.isna()
        reason = reason.mask(mask, text)

    blank = lambda c: df[c].isna() | df[c].astype(str).str.strip().isin(_EMPTY)  # noqa: E731
    for c in REQUIRED:
        flag(blank(c), f"missing {c}")
    for c in ("imo", "received_t", "rob_t"):
        num = pd.to_numeric(df[c], errors="coerce")
        flag(num.isna() & ~blank(c), f"not a number in {c}")
        flag(np.isinf(num.astype(float)), f"not a finite number in {c}")
        df[c] = num.where(np.isfinite(num.astype(float)))
    imo = df["imo"]
    flag(imo.notna() & (imo % 1 != 0), "not an integer in imo")
    whole = imo.notna() & (imo % 1 == 0) & (imo.abs() < 2**62)
    df["imo"] = imo.where(whole, 0).astype("int64")
    flag(whole & ~df["imo"].map(lambda i: 0 < i <= 9_999_999 and is_valid_imo(i)), "IMO number fails its check digit")
    date, why = parse_iso_column(df["date_utc"])
    flag(why.notna() & ~blank("date_utc"), "date_utc: " + why.fillna("").astype(str))
    limit = (pd.Timestamp.now("UTC").tz_localize(None) if now is None else pd.Timestamp(now)) + FUTURE_TOLERANCE
    flag(date > limit, "date in the future")
    df["date_utc"] = date
    if known_imos is not None:
        flag(~df["imo"].isin(list(known_imos)), "unknown vessel")
    for c in ("received_t", "rob_t"):
        flag(df[c] < 0, f"negative {c}")
    flag(df["received_t"] > MAX_RECEIVED_T, "received looks like kg")
    if dwt_t:
        dwt = df["imo"].map({int(k): float(v) for k, v in dwt_t.items() if v is not None and v == v and v > 0})
        flag(dwt.notna() & (df["received_t"] > dwt),
             "received more than the vessel's deadweight (" + dwt.round(0).astype("Int64").astype(str) + " t)")
    for c in TEXT:
        flag(df[c].map(has_control_characters), f"control characters or a line break in {c}")
    df["fuel_type"] = df["fuel_type"].astype(str).str.strip().str.upper()
    df["bill_no"] = df["bill_no"].astype(str).str.strip()
    dup = df[reason.isna()].duplicated(subset=["imo", "bill_no", "fuel_type"]).reindex(df.index, fill_value=False)
    flag(dup, "duplicate bill and fuel in file")
    df["source_file"] = source
    bad = df[reason.notna()].copy()
    bad["reason"] = reason[reason.notna()]
    bad["raw"] = raw_text(raw.loc[bad.index])
    return df[reason.isna()].reset_index(drop=True), bad.reset_index(drop=True)
