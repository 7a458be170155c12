"""A routed voyage as a GeoJSON FeatureCollection (RFC 7946 coordinates: [lon, lat]).

Features: one LineString through the waypoints (properties: the route row) and one Point per
waypoint (properties: index, name, eta_utc/etd_utc, and the leg that *starts* there: rpm,
stw_kn, sog_kn, course, fuel and the weather met; null at the arrival point).

Dateline: coordinates are unwrapped along the voyage, so a crossing reads 179.5 → 180.4 rather
than 179.5 → −179.6 and web maps draw one continuous line instead of one across the whole map.
RFC 7946 §3.1.9 recommends cutting such lines at the antimeridian instead; we keep one
LineString because its vertices are exactly the plan's waypoints. Points use the same unwrapped
longitude so they sit on the line; `lon_deg` in their properties is the usual −180..180 value.
All values are JSON-safe: times as ISO 8601 UTC with a Z, NaN/NaT as null.
"""

from __future__ import annotations

import datetime as dt

import numpy as np
import pandas as pd

from pipeline.export.voyage import (finite_or_none, iso_utc, require_legs, unwrap_lon_deg, vessel_label,
                                    waypoint_names, waypoints_deg)

LEG_PROPERTIES = ("leg", "rpm", "stw_kn", "sog_kn", "course_deg", "dist_nm", "hours", "fuel_t", "wind_kn",
                  "wind_dir_deg", "hs_m", "wave_dir_deg", "current_kn", "beyond_forecast")


def json_value(v):
    """A value json.dumps(allow_nan=False) accepts: numbers, str, bool, None; times as ISO UTC."""
    if v is None or isinstance(v, str):
        return v
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        return finite_or_none(v)
    if isinstance(v, (dt.date, np.datetime64)):
        return iso_utc(v)
    if pd.api.types.is_scalar(v) and pd.isna(v):
        return None
    return str(v)


def _round(x: float) -> float:
    return round(float(x), 6)


def route_to_geojson(route: dict, legs: list[dict]) -> dict:
    """FeatureCollection: the route LineString, then one Point per waypoint (index 0..n)."""
    require_legs(route, legs, "GeoJSON")
    lat, lon = waypoints_deg(legs)
    lon_u = unwrap_lon_deg(lon)
    names = waypoint_names(route, len(lat))
    props = {k: json_value(v) for k, v in route.items()}
    props.update(kind="route", vessel_name=vessel_label(route), n_legs=len(legs))
    features = [{
        "type": "Feature",
        "geometry": {"type": "LineString", "coordinates": [[_round(x), _round(y)] for x, y in zip(lon_u, lat)]},
        "properties": props,
    }]
    for i in range(len(lat)):
        leg = legs[i] if i < len(legs) else {}
        p = {"kind": "waypoint", "index": i, "name": names[i], "lat_deg": _round(lat[i]), "lon_deg": _round(lon[i]),
             "eta_utc": iso_utc(legs[i - 1].get("eta_utc")) if i > 0 else None,
             "etd_utc": iso_utc(leg.get("etd_utc"))}
        p.update({k: json_value(leg.get(k)) for k in LEG_PROPERTIES})
        features.append({"type": "Feature",
                         "geometry": {"type": "Point", "coordinates": [_round(lon_u[i]), _round(lat[i])]},
                         "properties": p})
    return {"type": "FeatureCollection", "features": features}
