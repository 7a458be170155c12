"""A routed voyage as a GeoJSON FeatureCollection (RFC 7946: [lon, lat], longitudes in −180..180).

Features: the route (properties: the route row) and one Point per waypoint (properties: index,
name, eta_utc/etd_utc, and the leg that *starts* there: rpm, stw_kn, sog_kn, course, fuel and the
weather met; null at the arrival point).

Dateline (RFC 7946 §3.1.9): a route that crosses the antimeridian is cut there into a
MultiLineString whose parts meet at ±180° (the crossing latitude interpolated along the leg), so
every longitude stays in −180..180 and web maps draw it without a line across the whole map. The
collection and each feature carry a `bbox` (§5); one that crosses the antimeridian has west > east
(§5.2). All values are JSON-safe: times as ISO 8601 UTC with a Z, NaN/NaT as null.
"""

from __future__ import annotations

import datetime as dt

import numpy as np

from pipeline.export.voyage import (finite_or_none, iso_utc, require_legs, unwrap_lon_deg, vessel_label,
                                    waypoint_names, waypoints_deg)

LEG_PROPERTIES = ("leg", "rpm", "stw_kn", "sog_kn", "course_deg", "dist_nm", "hours", "fuel_t", "wind_kn",
                  "wind_dir_deg", "hs_m", "wave_dir_deg", "current_kn", "beyond_forecast")


def json_value(v):
    """A value json.dumps(allow_nan=False) accepts: numbers, str, bool, None, lists of them; times as ISO UTC."""
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
    if isinstance(v, (list, tuple, np.ndarray)):  # a list column (e.g. routes.baseline_lat_deg)
        return [json_value(x) for x in v]
    if v != v:  # NaN-like (pandas NA, NaT)
        return None
    return str(v)


def _round(x: float) -> float:
    return round(float(x), 6)


def _wrap(lon_deg: float) -> float:
    """−180..180 (180 stays 180, so a part ending at the antimeridian reads 180)."""
    w = (lon_deg + 180.0) % 360.0 - 180.0
    return 180.0 if w == -180.0 and lon_deg > 0 else w


def split_at_antimeridian(lat, lon_unwrapped) -> list[list[list[float]]]:
    """Parts of a line given by continuous (unwrapped) longitudes, cut where it crosses ±180°; [lon, lat] pairs."""
    parts = [[[_wrap(lon_unwrapped[0]), float(lat[0])]]]
    for i in range(1, len(lat)):
        u0, u1, y0, y1 = float(lon_unwrapped[i - 1]), float(lon_unwrapped[i]), float(lat[i - 1]), float(lat[i])
        k0, k1 = np.floor((u0 + 180.0) / 360.0), np.floor((u1 + 180.0) / 360.0)
        if k0 != k1:  # crosses the antimeridian at u = 180 + 360·min(k0, k1)
            edge = 180.0 + 360.0 * min(k0, k1)
            y = y0 + (y1 - y0) * (edge - u0) / (u1 - u0)
            east = u1 > u0
            parts[-1].append([180.0 if east else -180.0, y])
            parts.append([[-180.0 if east else 180.0, y]])
        parts[-1].append([_wrap(u1), y1])
    return [[[_round(x), _round(y)] for x, y in part] for part in parts]


def bbox_of(lat, lon_unwrapped) -> list[float]:
    """[west, south, east, north]; west > east when the extent crosses the antimeridian (RFC 7946 §5.2)."""
    lo, hi = float(np.min(lon_unwrapped)), float(np.max(lon_unwrapped))
    west, east = (-180.0, 180.0) if hi - lo >= 360.0 else (_wrap(lo), _wrap(hi))
    if west == 180.0:
        west = -180.0
    return [_round(west), _round(float(np.min(lat))), _round(east), _round(float(np.max(lat)))]


def route_to_geojson(route: dict, legs: list[dict]) -> dict:
    """FeatureCollection: the route (LineString, or MultiLineString cut at the antimeridian), then one Point per
    waypoint (index 0..n)."""
    require_legs(route, legs, "GeoJSON")
    lat, lon = waypoints_deg(legs)
    lon_u = unwrap_lon_deg(lon)
    names = waypoint_names(route, len(lat))
    props = {k: json_value(v) for k, v in route.items()}
    props.update(kind="route", vessel_name=vessel_label(route), n_legs=len(legs))
    parts = split_at_antimeridian(lat, lon_u)
    geometry = ({"type": "LineString", "coordinates": parts[0]} if len(parts) == 1
                else {"type": "MultiLineString", "coordinates": parts})
    box = bbox_of(lat, lon_u)
    features = [{"type": "Feature", "bbox": box, "geometry": geometry, "properties": props}]
    for i in range(len(lat)):
        leg = legs[i] if i < len(legs) else {}
        p = {"kind": "waypoint", "index": i, "name": names[i], "lat_deg": _round(lat[i]), "lon_deg": _round(lon[i]),
             "eta_utc": iso_utc(legs[i - 1].get("eta_utc")) if i > 0 else None,
             "etd_utc": iso_utc(leg.get("etd_utc"))}
        p.update({k: json_value(leg.get(k)) for k in LEG_PROPERTIES})
        features.append({"type": "Feature",
                         "geometry": {"type": "Point", "coordinates": [_round(_wrap(lon_u[i])), _round(lat[i])]},
                         "properties": p})
    return {"type": "FeatureCollection", "bbox": box, "features": features}
