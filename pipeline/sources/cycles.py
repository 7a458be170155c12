"""Forecast cycles: reading them from text, listing a range, and which ones a source has published.

A cycle is a model init time (UTC, whole hour) as datetime64[ns]. JMA issues GSM and GWM runs at
00/06/12/18 UTC; RISH mirrors a run's files a few hours after its init (`publish_delay_h`).
"""

from __future__ import annotations

from datetime import datetime, timezone

import numpy as np


class CycleError(ValueError):
    """Text that is not a cycle; the message says what was given and what is expected."""


CYCLE_HOURS = (0, 6, 12, 18)  # JMA GSM/GWM init hours (UTC)
EARLIEST_DAY = np.datetime64("2000-01-01")  # a backfill range starts no earlier (older days are a typing mistake)
MAX_RANGE_DAYS = 366  # a backfill covers at most this many days; longer ranges are run in pieces


def check_cycle_hour(cycle: np.datetime64, text: str | None = None) -> np.datetime64:
    """The cycle, if its hour is a JMA init hour (00/06/12/18 UTC); a CycleError saying so otherwise."""
    hour = int((np.datetime64(cycle, "h") - np.datetime64(cycle, "D")) / np.timedelta64(1, "h"))
    if hour not in CYCLE_HOURS:
        raise CycleError(f"cycle {text or label(cycle)} is at {hour:02d} UTC; GSM/GWM cycles are at "
                         f"{'/'.join(f'{h:02d}' for h in CYCLE_HOURS)} UTC, e.g. {str(np.datetime64(cycle, 'D'))}T00")
    return cycle


def parse_cycle(text: str) -> np.datetime64:
    """'2020-12-01T00', '2020-12-01T12:00', '2020120112' → datetime64[ns] on a whole hour."""
    t = str(text).strip()
    if t.isdigit() and len(t) == 10:
        t = f"{t[:4]}-{t[4:6]}-{t[6:8]}T{t[8:]}"
    try:
        c = np.datetime64(t, "h")
        if np.isnat(c) or len(t) < 13:
            raise ValueError(t)
        exact = np.datetime64(t, "s")
    except ValueError:
        raise CycleError(f"cannot read cycle {text!r}; use e.g. 2020-12-01T00") from None
    if exact != np.datetime64(c, "s"):
        raise CycleError(f"cycle {text!r} is not on a whole hour; use e.g. 2020-12-01T00")
    return np.datetime64(c, "ns")


def parse_day(text: str, what: str = "date") -> np.datetime64:
    """'2020-12-01' → datetime64[D]; a clear CycleError otherwise (e.g. '2020-1203', '2020-12-1x')."""
    t = str(text).strip()
    try:
        if len(t) != 10:
            raise ValueError(t)
        d = np.datetime64(t, "D")
    except ValueError:
        raise CycleError(f"cannot read {what} {text!r}; use YYYY-MM-DD, e.g. 2020-12-01") from None
    return d


def parse_hours(text) -> list[int]:
    """'00,12' → [0, 12] (also 12 or [0, 12], as a deployment parameter may arrive); every hour must be 0..23."""
    try:
        parts = text if isinstance(text, (list, tuple)) else str(text).split(",")
        hours = [int(str(h).strip()) for h in parts if str(h).strip()]
    except ValueError:
        raise CycleError(f"cannot read cycle hours {text!r}; use e.g. 00,12") from None
    if not hours or any(h < 0 or h > 23 for h in hours):
        raise CycleError(f"cycle hours {text!r} must be hours 00..23, e.g. 00,12")
    if any(h not in CYCLE_HOURS for h in hours):
        raise CycleError(f"cycle hours {text!r}: GSM/GWM cycles are at {'/'.join(f'{h:02d}' for h in CYCLE_HOURS)} UTC, "
                         "e.g. 00,12")
    return hours


def cycles_between(start: str, end: str, hours: list[int]) -> list[np.datetime64]:
    """Every cycle at `hours` from day `start` to day `end` (inclusive)."""
    d0, d1 = parse_day(start, "start"), parse_day(end, "end")
    if d1 < d0:
        raise CycleError(f"end {end} is before start {start}")
    tomorrow = np.datetime64(utcnow_h(), "D") + 1
    if d0 < EARLIEST_DAY or d1 > tomorrow:
        raise CycleError(f"days {start}..{end} are outside {EARLIEST_DAY}..{tomorrow} (today + 1): check the years")
    if (d1 - d0).astype(int) + 1 > MAX_RANGE_DAYS:
        raise CycleError(f"{start}..{end} is {(d1 - d0).astype(int) + 1} days; a backfill covers at most "
                         f"{MAX_RANGE_DAYS} days: run it in pieces")
    days = np.arange(d0, d1 + 1)
    return [np.datetime64(d, "ns") + np.timedelta64(int(h), "h") for d in days for h in sorted(hours)]


def utcnow_h() -> np.datetime64:
    return np.datetime64(datetime.now(timezone.utc).replace(tzinfo=None), "s")


def newest_published_cycles(now_utc, hours_utc: tuple[int, ...], publish_delay_h: float, n: int = 1) -> list[np.datetime64]:
    """The `n` newest cycles (oldest first) whose files are published by `now_utc` (init + delay ≤ now)."""
    now = np.datetime64(now_utc, "s")
    latest_init = now - np.timedelta64(int(round(publish_delay_h * 3600)), "s")
    day = np.datetime64(latest_init, "D")
    out: list[np.datetime64] = []
    while len(out) < n:
        for h in sorted(hours_utc, reverse=True):
            c = np.datetime64(day, "s") + np.timedelta64(int(h), "h")
            if c <= latest_init and len(out) < n:
                out.append(np.datetime64(c, "ns"))
        day -= np.timedelta64(1, "D")
    return sorted(out)


def publication_cron(hours_utc: tuple[int, ...], publish_delay_h: float, minute: int = 0) -> str:
    """Cron (UTC) firing when each cycle's files are published, e.g. '0 5,11,17,23 * * *' for 6-hourly runs + 5 h."""
    fire = sorted({(int(h) + int(np.ceil(publish_delay_h))) % 24 for h in hours_utc})
    return f"{minute} {','.join(map(str, fire))} * * *"


def label(cycle) -> str:
    """'2020-12-01T00' for a cycle."""
    return str(np.datetime_as_string(np.datetime64(cycle, "h"), unit="h"))
