"""One bad noon-report row per rejection reason, shared by the validation and the CLI import tests."""

from __future__ import annotations


def rejection_cases(base: dict, *, as_text: bool = False) -> dict[str, dict]:
    """{reason `validate_noon` gives: `base` with one fault}. `as_text`: the changed values as CSV text
    (a missing value is then the empty string)."""
    hours, fuel, sog, dist = (float(base[k]) for k in ("hours", "fuel_t", "sog_kn", "dist_nm"))
    faults = {
        "missing stw_kn": {"stw_kn": None},
        "not a number in rpm": {"rpm": "eighty"},
        "bad timestamp": {"ts_utc": "yesterday noon"},
        "unknown vessel": {"imo": 9999999},
        "hours <= 0": {"hours": 0},
        "negative fuel_t": {"fuel_t": -1},
        "out of range draft_m": {"draft_m": 40},
        "speed beyond physics": {"stw_kn": 50, "sog_kn": 50, "dist_nm": 50 * hours},
        "fuel looks like kg": {"fuel_t": fuel * 1000},
        "speed looks like m/s": {"sog_kn": sog / 1.943844},
        "sog inconsistent with distance": {"dist_nm": dist * 1.5},
    }
    if as_text:
        faults = {r: {k: "" if v is None else str(v) for k, v in kw.items()} for r, kw in faults.items()}
    return {reason: {**base, **kw} for reason, kw in faults.items()}
