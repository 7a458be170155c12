"""Validation of bunker logs (what each vessel received, where, from whom; what remained on board).

One row per bunker delivery note and fuel type. Columns: imo, bill_no, date_utc, port, supplier,
fuel_type, received_t, rob_t (tonnes remaining on board of that fuel before receiving; optional).
Every row is either good or rejected with a reason (first failing check wins):
  missing <col>                    required value empty
  not a number in <col>            text where a number belongs
  bad date                         unparseable date_utc
  unknown vessel                   IMO not in the vessels table
  negative <col>                   tonnes below zero
  received looks like kg           more than MAX_RECEIVED_T tonnes in one delivery
  duplicate bill and fuel in file  a second row with the same (imo, bill_no, fuel_type)
"""

from __future__ import annotations

import pandas as pd

from pipeline.performance.validate import NoonFileError, raw_text

REQUIRED = ("imo", "bill_no", "date_utc", "fuel_type", "received_t")
COLUMNS = ("imo", "bill_no", "date_utc", "port", "supplier", "fuel_type", "received_t", "rob_t")
MAX_RECEIVED_T = 20000.0  # more in one delivery is a unit mistake (kg for t)


def validate_bunker(raw: pd.DataFrame, known_imos: set[int] | None = None, source: str = "") -> tuple[pd.DataFrame, pd.DataFrame]:
    """(good rows with typed columns, rejected rows with `reason` and the original `raw` text)."""
    absent = [c for c in REQUIRED if c not in raw.columns]
    if absent:
        raise NoonFileError(f"{source or 'bunker log file'}: required columns missing: {', '.join(absent)}")
    df = raw.reindex(columns=list(COLUMNS)).copy()
    reason = pd.Series(pd.NA, index=df.index, dtype="object")

    def flag(mask, text):
        nonlocal reason
        mask = pd.Series(mask, index=df.index).fillna(False).astype(bool) & reason.isna()
        reason = reason.mask(mask, text)

    blank = lambda c: df[c].isna() | df[c].astype(str).str.strip().isin(["", "nan", "NaN", "None"])  # noqa: E731
    for c in REQUIRED:
        flag(blank(c), f"missing {c}")
    for c in ("imo", "received_t", "rob_t"):
        num = pd.to_numeric(df[c], errors="coerce")
        flag(num.isna() & ~blank(c), f"not a number in {c}")
        df[c] = num
    date = pd.to_datetime(df["date_utc"], errors="coerce", utc=True)
    flag(date.isna(), "bad date")
    df["date_utc"] = date.dt.tz_localize(None)
    df["imo"] = df["imo"].fillna(0).astype("int64")
    if known_imos is not None:
        flag(~df["imo"].isin(list(known_imos)), "unknown vessel")
    for c in ("received_t", "rob_t"):
        flag(df[c] < 0, f"negative {c}")
    flag(df["received_t"] > MAX_RECEIVED_T, "received looks like kg")
    df["fuel_type"] = df["fuel_type"].astype(str).str.strip().str.upper()
    df["bill_no"] = df["bill_no"].astype(str).str.strip()
    dup = df[reason.isna()].duplicated(subset=["imo", "bill_no", "fuel_type"]).reindex(df.index, fill_value=False)
    flag(dup, "duplicate bill and fuel in file")
    df["source_file"] = source
    bad = df[reason.notna()].copy()
    bad["reason"] = reason[reason.notna()]
    bad["raw"] = raw_text(raw.loc[bad.index])
    return df[reason.isna()].reset_index(drop=True), bad.reset_index(drop=True)
