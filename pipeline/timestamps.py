"""Timestamps in imported files: ISO 8601 only, read value by value.

Accepted: `YYYY-MM-DD`, `YYYY-MM-DDTHH:MM[:SS[.fff]]` (a space for the `T` too), each optionally followed by
`Z` or an offset `±HH:MM` / `±HHMM`. Values without an offset are UTC. Each value carries its own offset,
so a file may mix `+09:00`, `Z` and naive values. Anything else is refused with a reason rather than
guessed: `01/11/2018 12:00` could be 1 November or 11 January.
"""

from __future__ import annotations

import re
from datetime import datetime, timezone

import numpy as np
import pandas as pd

_ISO = re.compile(r"^\d{4}-\d{2}-\d{2}([T ]\d{2}:\d{2}(:\d{2}(\.\d{1,9})?)?)?(Z|[+-]\d{2}:?\d{2})?$")
_DAY_MONTH = re.compile(r"^\d{1,2}[/.\-]\d{1,2}[/.\-]\d{2,4}\b")

BAD = "bad timestamp"
OUT_OF_RANGE = "timestamp out of range (give one between 1677-09-22 and 2262-04-11)"
AMBIGUOUS = "ambiguous timestamp (day/month order unknown; use ISO 8601, e.g. 2020-12-01T12:00Z)"


def parse_iso_utc(value) -> tuple[pd.Timestamp | None, str | None]:
    """(naive UTC timestamp, None) or (None, reason) for one value."""
    if value is None or (isinstance(value, float) and value != value):
        return None, BAD
    if isinstance(value, (pd.Timestamp, datetime, np.datetime64)):
        ts = pd.Timestamp(value)
        return (ts.tz_convert("UTC").tz_localize(None) if ts.tzinfo else ts), None
    text = str(value).strip()
    if _DAY_MONTH.match(text):
        return None, AMBIGUOUS
    if not _ISO.match(text):
        return None, BAD
    if text.endswith("Z"):
        text = text[:-1] + "+00:00"
    text = re.sub(r"([+-]\d{2})(\d{2})$", r"\1:\2", text)
    frac = re.search(r"\.(\d{7,9})", text)
    if frac:  # datetime reads at most microseconds
        text = text.replace(frac.group(0), "." + frac.group(1)[:6])
    try:
        dt = datetime.fromisoformat(text)
    except ValueError:  # e.g. month 13 or hour 25
        return None, BAD
    if dt.tzinfo is not None:
        try:
            dt = dt.astimezone(timezone.utc).replace(tzinfo=None)
        except OverflowError:  # 9999-12-31T23:00-05:00
            return None, OUT_OF_RANGE
    try:  # every table and frame holds nanoseconds: 1677-09-22 … 2262-04-11
        return pd.Timestamp(dt).as_unit("ns"), None
    except (pd.errors.OutOfBoundsDatetime, OverflowError):
        return None, OUT_OF_RANGE


def parse_iso_column(values: pd.Series) -> tuple[pd.Series, pd.Series]:
    """(datetime64[ns] naive-UTC series, NaT where refused; reason series, NA where accepted)."""
    parsed = [parse_iso_utc(v) for v in values]
    ts = pd.Series(pd.to_datetime([p[0] for p in parsed]), index=values.index, dtype="datetime64[ns]")
    reason = pd.Series([p[1] for p in parsed], index=values.index, dtype="object")
    return ts, reason.where(reason.notna(), pd.NA)
