"""What every export reads from a routed voyage: waypoints, names, UTC times, finite numbers.

A voyage is `route: dict` (one row of `routes`) and `legs: list[dict]` (its `route_legs` rows in
order). Waypoint 0 is leg 0's start and waypoint i (i ≥ 1) is leg i−1's end, so n legs give
n + 1 waypoints. Times are naive UTC (datetime, pandas Timestamp or numpy datetime64); nothing here needs
pandas, so a routing worker that exports does not load it.
"""

from __future__ import annotations

import math
from datetime import date, datetime, timedelta, timezone
from typing import Any

import numpy as np


def voyage_id(route: dict) -> str:
    return str(route.get("voyage_id") or "?")


def vessel_label(route: dict) -> str:
    """The vessel's name, or its IMO number when the name is missing."""
    name = route.get("vessel_name")
    if isinstance(name, str) and name.strip():
        return name.strip()
    imo = route.get("imo")
    return f"IMO {imo}" if imo is not None else "unknown vessel"


def require_legs(route: dict, legs: list[dict], what: str) -> None:
    """Raise ValueError naming the voyage when there is no route to export (no legs, bad positions)."""
    if not legs:
        reason = route.get("reason") or "no reason given"
        raise ValueError(
            f"voyage {voyage_id(route)}: cannot write {what}, the plan has no legs "
            f"(status {route.get('status')!r}: {reason}); only voyages with a route can be exported"
        )
    lat, lon = waypoints_deg(legs)
    bad = ~(np.isfinite(lat) & np.isfinite(lon) & (np.abs(lat) <= 90.0))
    if bad.any():
        raise ValueError(f"voyage {voyage_id(route)}: cannot write {what}, waypoint(s) "
                         f"{', '.join(map(str, np.flatnonzero(bad)))} have no valid position")


def waypoints_deg(legs: list[dict]) -> tuple[np.ndarray, np.ndarray]:
    """(lat, lon) of the n + 1 waypoints in degrees, longitudes as given (−180..180)."""
    if not legs:
        return np.empty(0), np.empty(0)
    lat = [legs[0]["lat0"]] + [leg["lat1"] for leg in legs]
    lon = [legs[0]["lon0"]] + [leg["lon1"] for leg in legs]
    return np.asarray(lat, dtype=np.float64), np.asarray(lon, dtype=np.float64)


def waypoint_names(route: dict, n_waypoints: int) -> list[str]:
    """Departure port, WP001 … WPnnn, arrival port (generic names when the ports are missing)."""
    names = [f"WP{i:03d}" for i in range(n_waypoints)]
    if n_waypoints:
        names[0] = route.get("dep_name") or "Departure"
        names[-1] = route.get("arr_name") or "Arrival"
    return names


def unwrap_lon_deg(lon_deg, centre_deg: float | None = None) -> np.ndarray:
    """Longitudes along a track made continuous (no step > 180°), e.g. 179.5, −179.6 → 179.5, 180.4.

    With `centre_deg` the whole track is shifted by a multiple of 360° so its middle lies within
    180° of the centre (several tracks drawn in one frame).
    """
    lon = np.unwrap(np.asarray(lon_deg, dtype=np.float64), period=360.0)
    if centre_deg is not None and lon.size:
        mid = 0.5 * (lon.min() + lon.max())
        lon = lon - 360.0 * np.round((mid - centre_deg) / 360.0)
    return lon


def centre_lon_deg(lon_deg) -> float:
    """Circular mean of longitudes (so 179 and −179 centre on 180, not 0); 0 when there are none."""
    lon = np.radians(np.asarray(lon_deg, dtype=np.float64))
    if lon.size == 0:
        return 0.0
    return float(np.degrees(np.arctan2(np.sin(lon).mean(), np.cos(lon).mean())))


def utc_datetime(t) -> datetime | None:
    """A naive UTC datetime from a datetime (pandas Timestamps are ones), numpy datetime64 or ISO string; None for
    None, NaT and NaN. Aware times are converted to UTC."""
    if t is None or (isinstance(t, float) and math.isnan(t)):
        return None
    if isinstance(t, str):
        t = datetime.fromisoformat(t)
    elif isinstance(t, np.datetime64):
        return None if np.isnat(t) else t.astype("datetime64[us]").item()
    elif isinstance(t, date) and not isinstance(t, datetime):
        return datetime(t.year, t.month, t.day)
    if not isinstance(t, datetime):
        raise TypeError(f"not a time: {t!r}")
    if t != t:  # pandas NaT
        return None
    if t.tzinfo is not None:
        t = t.astimezone(timezone.utc).replace(tzinfo=None)
    return datetime(t.year, t.month, t.day, t.hour, t.minute, t.second, t.microsecond)


def iso_utc(t) -> str | None:
    """ISO 8601 UTC with a Z, rounded to the second (what ECDIS and JSON readers expect)."""
    d = utc_datetime(t)
    if d is None:
        return None
    return (d + timedelta(microseconds=500_000)).replace(microsecond=0).strftime("%Y-%m-%dT%H:%M:%SZ")


def finite_or_none(x: Any) -> float | None:
    """A plain float, or None for None/NaN/inf/non-numbers."""
    if x is None or isinstance(x, (bool, np.bool_)):
        return None
    try:
        v = float(x)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def spread_text(route: dict) -> str | None:
    """The plan's spread across the lagged ensemble (routes.ensemble_members, p_on_time, savings_p10/p90_pct) in one
    phrase for maps and tables, e.g. "across 4 forecasts: on time 75 %, saving P10–P90 -0.4 to 2.1 %"; None when
    not computed."""
    n, p = finite_or_none(route.get("ensemble_members")), finite_or_none(route.get("p_on_time"))
    if n is None or p is None:
        return None
    s10, s90 = finite_or_none(route.get("savings_p10_pct")), finite_or_none(route.get("savings_p90_pct"))
    saving = f", saving P10–P90 {s10:.1f} to {s90:.1f} %" if s10 is not None and s90 is not None else ""
    return f"across {int(n)} forecast{'s' if n != 1 else ''}: on time {100 * p:.0f} %{saving}"
