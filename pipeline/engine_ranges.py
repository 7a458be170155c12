"""An engine's barred speed ranges as written in the vessels file: 'low-high' rpm, several separated by ';'.

Light to import (no pandas, no numba): the fleet import validates the column with it, and routing workers read it."""

from __future__ import annotations

import math
import re

_EMPTY = ("", "nan", "NaN", "None", "<NA>")
_RANGE = re.compile(r"^\s*(\d+(?:\.\d*)?)\s*-\s*(\d+(?:\.\d*)?)\s*$")


def parse_barred_rpm(text) -> tuple[tuple[float, float], ...]:
    """A vessel's barred rpm ranges from 'low-high' texts separated by ';' (empty: none); ValueError saying why."""
    if text is None or (isinstance(text, float) and math.isnan(text)) or str(text).strip() in _EMPTY:
        return ()
    out = []
    for part in str(text).split(";"):
        if not part.strip():
            continue
        m = _RANGE.match(part)
        if not m or not float(m.group(1)) < float(m.group(2)):
            raise ValueError(f"bad barred_rpm {part.strip()!r} (expected low-high rpm, e.g. 52-60, separated by ';')")
        out.append((float(m.group(1)), float(m.group(2))))
    return tuple(sorted(out))
