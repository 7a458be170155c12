"""The operator's console's data: pure functions turning warehouse rows (pandas) and cube steps (numpy) into the
JSON each page draws. No I/O here: storage/console_reads.py reads, cli/console_app serves.

Conventions of the JSON: times ISO 8601 UTC with a Z; positions [lat, lon] in degrees, longitudes unwrapped around
the map's centre (a fleet across the date line draws as one piece, e.g. 179.5 then 180.4); speeds in knots, fuel in
tonnes, Hs in metres. Weather arrows point where the air, the waves or the water *go* (wind and waves are stored
coming-from, so they are turned by 180°).
"""

from __future__ import annotations

import math
import struct
import zlib
from datetime import datetime, timedelta

import numpy as np
import pandas as pd

from pipeline.export.geojson import json_value
from pipeline.export.voyage import finite_or_none, iso_utc, unwrap_lon_deg, utc_datetime
from pipeline.export.weather_map import VARIABLES, magnitude_and_flow

# beyond this, "now" is far past the data (a demo or an archive): positions are shown at the latest run's time
STALE_DATA_DAYS = 7
# a cycle older than this at the latest run's time is an attention item (routing.max_cycle_age_h's default)
OLD_CYCLE_H = 36.0
# the weather grid sent to a map: at most this many cells across and down (the map thins its arrows further)
WEATHER_MAX_X, WEATHER_MAX_Y = 72, 48
# land picture: at most this many pixels across
LAND_MAX_PX = 1600
UNITS = {"wind": "kn", "waves": "m", "currents": "kn"}
LABELS = {"wind": "10 m wind", "waves": "significant wave height Hs", "currents": "surface current"}


def _iso(t) -> str | None:
    try:
        return iso_utc(t)
    except (TypeError, ValueError):
        return None


def _num(x, decimals: int = 3) -> float | None:
    v = finite_or_none(x)
    return None if v is None else round(v, decimals)


def plain(v):
    """A JSON-ready value (see geojson.json_value); pandas' missing values (NA, NaT) become None."""
    if v is pd.NA or v is pd.NaT:
        return None
    return json_value(v)


def _plain_dict(d: dict, drop: tuple[str, ...] = ()) -> dict:
    return {k: plain(v) for k, v in d.items() if k not in drop}


def records(df: pd.DataFrame, columns: list[str] | None = None) -> list[dict]:
    """Rows as JSON-ready dicts: times ISO UTC, NaN/NaT None, numpy scalars plain."""
    out = []
    cols = list(df.columns) if columns is None else [c for c in columns if c in df.columns]
    for row in df[cols].itertuples(index=False, name=None):
        out.append({c: plain(v) for c, v in zip(cols, row)})
    return out


def as_of_time(now_utc: datetime, latest_run: dict | None, at_utc: datetime | None = None) -> tuple[datetime, str]:
    """The time positions are shown at, and why: `at_utc` when asked; else now, unless the newest run's time is more
    than STALE_DATA_DAYS before now (demo or archive data): then that run's time."""
    if at_utc is not None:
        return at_utc, "as asked"
    run_t = None
    if latest_run:
        run_t = utc_datetime(latest_run.get("nominal_utc")) or utc_datetime(latest_run.get("started_at"))
    if run_t is not None and now_utc - run_t > timedelta(days=STALE_DATA_DAYS):
        return run_t, f"the newest run's time: the data is more than {STALE_DATA_DAYS} days older than now"
    return now_utc, "now"


def centre_lon_deg(lon_deg) -> float:
    """The circular mean of longitudes (degrees east, −180..180]: the middle of a fleet across the date line."""
    lon = np.radians(np.asarray(lon_deg, dtype=np.float64))
    lon = lon[np.isfinite(lon)]
    if lon.size == 0:
        return 0.0
    return float(np.degrees(np.arctan2(np.sin(lon).mean(), np.cos(lon).mean())))


def extent_of(lat_deg, lon_deg, pad_frac: float = 0.08, min_span_deg: float = 6.0) -> dict:
    """The map box around points (longitudes already unwrapped): west, east, south, north in degrees, padded and at
    least `min_span_deg` each way, latitudes within ±85°."""
    lat, lon = np.asarray(lat_deg, float), np.asarray(lon_deg, float)
    ok = np.isfinite(lat) & np.isfinite(lon)
    if not ok.any():
        return {"west": -180.0, "east": 180.0, "south": -70.0, "north": 75.0}
    lat, lon = lat[ok], lon[ok]
    w, e, s, n = lon.min(), lon.max(), lat.min(), lat.max()
    dx, dy = max(e - w, min_span_deg), max(n - s, min_span_deg)
    cx, cy = 0.5 * (w + e), 0.5 * (s + n)
    dx, dy = dx * (1 + 2 * pad_frac), dy * (1 + 2 * pad_frac)
    s2, n2 = max(-85.0, cy - dy / 2), min(85.0, cy + dy / 2)
    return {"west": round(cx - dx / 2, 3), "east": round(cx + dx / 2, 3), "south": round(s2, 3), "north": round(n2, 3)}


def _waypoints(legs: pd.DataFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(lat, lon, time as datetime64[s]) of a plan's n + 1 waypoints: each leg's start, then the last leg's end."""
    return _waypoints_of(_leg_arrays(legs), slice(0, len(legs)))


def _leg_arrays(legs: pd.DataFrame) -> dict[str, np.ndarray]:
    """The legs' positions and times as numpy arrays (one conversion for a whole fleet's legs)."""
    out = {c: legs[c].to_numpy(float) for c in ("lat0", "lon0", "lat1", "lon1")}
    out.update({c: legs[c].to_numpy("datetime64[s]") for c in ("etd_utc", "eta_utc")})
    return out


def _waypoints_of(a: dict[str, np.ndarray], rows: slice) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    last = slice(rows.stop - 1, rows.stop)
    return (np.concatenate([a["lat0"][rows], a["lat1"][last]]), np.concatenate([a["lon0"][rows], a["lon1"][last]]),
            np.concatenate([a["etd_utc"][rows], a["eta_utc"][last]]))


def _runs_of(ids: np.ndarray) -> dict:
    """id → slice of its rows, for rows sorted (grouped) by id."""
    if ids.size == 0:
        return {}
    change = np.flatnonzero(ids[1:] != ids[:-1]) + 1
    starts, ends = np.r_[0, change], np.r_[change, ids.size]
    return {ids[a]: slice(int(a), int(b)) for a, b in zip(starts, ends)}


def position_on_plan(lat, lon, t, when) -> tuple[float, float, int]:
    """Where a plan puts the ship at `when`: (lat, lon, index of the next waypoint), interpolated linearly in time
    along the leg sailed then (lon unwrapped); before the start the first waypoint (index 0), after the end the last
    (index n + 1). Waits at a node count as time at that node."""
    when = np.datetime64(when, "s")
    if when <= t[0]:
        return float(lat[0]), float(lon[0]), 0
    if when >= t[-1]:
        return float(lat[-1]), float(lon[-1]), len(lat)
    k = int(np.searchsorted(t, when, side="right"))  # t[k-1] <= when < t[k]
    span = (t[k] - t[k - 1]).astype(np.int64)
    f = 0.0 if span <= 0 else float((when - t[k - 1]).astype(np.int64)) / float(span)
    return float(lat[k - 1] + f * (lat[k] - lat[k - 1])), float(lon[k - 1] + f * (lon[k] - lon[k - 1])), k


def _text(x) -> str | None:
    x = plain(x)
    return x if isinstance(x, str) and x else None


def _true(x) -> bool:
    return x is not None and x is not pd.NA and not (isinstance(x, float) and math.isnan(x)) and bool(x)


def attention_items(route: dict, run: dict | None) -> list[str]:
    """What an operator should look at for a voyage's shown plan, one short line each (empty: nothing)."""
    items = []
    status = route.get("status")
    eta, rta = utc_datetime(route.get("eta_utc")), utc_datetime(route.get("rta_utc"))
    if status == "late" and eta and rta:
        items.append(f"late: ETA {(eta - rta).total_seconds() / 3600:.1f} h after the RTA")
    elif status not in ("ok", "late"):
        items.append(f"no plan ({status}): {_text(route.get('reason')) or 'no reason recorded'}")
    if _true(route.get("stale")):
        items.append(_text(route.get("stale_reason")) or "voyage changed since the plan: re-plan it")
    if _true(route.get("newer_attempt_failed")):
        items.append(f"a newer run could not re-plan it ({route.get('newer_attempt_status')}): "
                     f"{_text(route.get('newer_attempt_reason')) or ''}".rstrip(": "))
    flag = _text(route.get("forecast_flag"))
    if flag:
        past = finite_or_none(route.get("hours_beyond_forecast"))
        before = finite_or_none(route.get("hours_before_cycle"))
        items.append(flag + (f": {past:.1f} h sailed past the forecast's last step" if past else "")
                     + (f": {before:.1f} h sailed before the forecast cycle's init time" if before else ""))
    clearance = finite_or_none(route.get("min_land_clearance_nm"))
    if clearance is not None and clearance < 2.0:
        items.append(f"passes {clearance:.1f} NM from land")
    age = finite_or_none((run or {}).get("cycle_age_h"))
    if age is not None and age > OLD_CYCLE_H and route.get("run_id") == (run or {}).get("run_id"):
        items.append(f"planned on a cycle {age:.0f} h old")
    return items


def _pairs(lat, lon, decimals: int = 3) -> list[list[float]]:
    return np.round(np.column_stack([np.asarray(lat, float), np.asarray(lon, float)]), decimals).tolist()


def fleet_view(routes: pd.DataFrame, legs: pd.DataFrame, reports: pd.DataFrame, as_of: datetime, as_of_note: str,
               run: dict | None) -> dict:
    """The fleet page: each voyage's shown plan (latest_routes rows), where its ship is at `as_of` (on the plan, and
    its newest reported position), the track behind (reports, then the plan up to now) and the plan ahead."""
    # legs grouped by voyage (and reports by voyage, in time), as slices of arrays: a thousand voyages' legs are
    # converted once, not per voyage
    legs = legs.sort_values(["voyage_id", "leg"], kind="stable") if not legs.empty else legs
    leg_arrays = _leg_arrays(legs) if not legs.empty else {}
    by_voyage = _runs_of(legs["voyage_id"].to_numpy(object)) if not legs.empty else {}
    if not reports.empty:
        reports = reports.sort_values(["voyage_id", "ts_utc"], kind="stable")
        rep_lat, rep_lon = reports["lat"].to_numpy(float), reports["lon"].to_numpy(float)
        rep_t, rep_source = reports["ts_utc"].to_numpy("datetime64[s]"), reports["source"].to_numpy(object)
    rep_by_voyage = _runs_of(reports["voyage_id"].to_numpy(object)) if not reports.empty else {}
    centre = centre_lon_deg(np.r_[legs["lon0"].to_numpy(float)] if not legs.empty else
                            routes[["dep_lon", "arr_lon"]].to_numpy(float).ravel())
    all_lat, all_lon, voyages = [], [], []
    when = np.datetime64(as_of, "s")
    for r in routes.to_dict("records"):
        vid = r["voyage_id"]
        rows = by_voyage.get(vid)
        item = {"voyage_id": vid, "vessel_name": plain(r.get("vessel_name")), "imo": plain(r.get("imo")),
                "dep_name": plain(r.get("dep_name")), "arr_name": plain(r.get("arr_name")), "status": plain(r.get("status")),
                "reason": plain(r.get("reason")), "run_id": plain(r.get("run_id")), "etd_utc": _iso(r.get("depart_utc")),
                "eta_utc": _iso(r.get("eta_utc")), "rta_utc": _iso(r.get("rta_utc")),
                "fuel_t": _num(r.get("fuel_t"), 2), "savings_pct": _num(r.get("savings_total_pct"), 2),
                "attention": attention_items(r, run), "ahead": [], "behind": [], "position": None, "report": None}
        eta, rta = utc_datetime(r.get("eta_utc")), utc_datetime(r.get("rta_utc"))
        item["eta_minus_rta_h"] = None if not (eta and rta) else round((eta - rta).total_seconds() / 3600.0, 2)
        if rows is not None:
            lat, lon, t = _waypoints_of(leg_arrays, rows)
            lon = unwrap_lon_deg(lon, centre)
            plat, plon, k = position_on_plan(lat, lon, t, when)
            departed = utc_datetime(r.get("voyage_depart_utc")) or utc_datetime(r.get("depart_utc"))
            phase = ("arrived" if k > len(lat) - 1 else
                     "not sailed" if departed is None or as_of < departed else "at sea")
            item["position"] = {"lat": round(plat, 3), "lon": round(plon, 3), "phase": phase, "source": "plan"}
            ahead_lat = np.r_[plat, lat[k:]] if k <= len(lat) - 1 else np.array([])
            ahead_lon = np.r_[plon, lon[k:]] if k <= len(lat) - 1 else np.array([])
            item["ahead"] = _pairs(ahead_lat, ahead_lon) if ahead_lat.size > 1 else []
            # behind: the departure port and the positions reported before the plan's start (a plan re-made at sea
            # starts from one), then the plan's waypoints passed, then where the plan puts the ship now
            behind_lat, behind_lon = lat[:k], lon[:k]
            rep = rep_by_voyage.get(vid)
            if rep is not None:
                rlon = unwrap_lon_deg(rep_lon[rep], centre)
                rlat = rep_lat[rep]
                before = rep_t[rep] < t[0]
                behind_lat, behind_lon = np.r_[rlat[before], behind_lat], np.r_[rlon[before], behind_lon]
                item["report"] = {"lat": round(float(rlat[-1]), 3), "lon": round(float(rlon[-1]), 3),
                                  "utc": _iso(rep_t[rep][-1]), "source": rep_source[rep][-1]}
            if phase != "not sailed" and t[0] > np.datetime64(departed, "s") and finite_or_none(r.get("dep_lat")) is not None:
                dlon = float(unwrap_lon_deg([r["dep_lon"]], centre)[0])
                dlon = dlon - 360.0 * round((dlon - (behind_lon[0] if behind_lon.size else plon)) / 360.0)
                behind_lat, behind_lon = np.r_[r["dep_lat"], behind_lat], np.r_[dlon, behind_lon]
            if behind_lat.size:
                behind_lat, behind_lon = np.r_[behind_lat, plat], np.r_[behind_lon, plon]
            item["behind"] = _pairs(behind_lat, behind_lon) if behind_lat.size > 1 else []
            all_lat += [lat, behind_lat]
            all_lon += [lon, behind_lon]
        else:  # no plan: where the ship last reported, else its departure port
            rep = rep_by_voyage.get(vid)
            if rep is not None:
                k = rep.stop - 1
                plon = float(unwrap_lon_deg([rep_lon[k]], centre)[0])
                item["report"] = {"lat": round(float(rep_lat[k]), 3), "lon": round(plon, 3), "utc": _iso(rep_t[k]),
                                  "source": rep_source[k]}
                item["position"] = {"lat": round(float(rep_lat[k]), 3), "lon": round(plon, 3), "phase": "no plan",
                                    "source": rep_source[k]}
            elif finite_or_none(r.get("dep_lat")) is not None:
                plon = float(unwrap_lon_deg([r["dep_lon"]], centre)[0])
                item["position"] = {"lat": round(float(r["dep_lat"]), 3), "lon": round(plon, 3), "phase": "no plan",
                                    "source": "departure port"}
            if item["position"]:
                all_lat.append(np.array([item["position"]["lat"]]))
                all_lon.append(np.array([item["position"]["lon"]]))
        voyages.append(item)
    mark_current_voyages(voyages)
    lat = np.concatenate(all_lat) if all_lat else np.array([])
    lon = np.concatenate(all_lon) if all_lon else np.array([])
    counts = routes["status"].value_counts().to_dict() if not routes.empty else {}
    return {"as_of_utc": _iso(as_of), "as_of_note": as_of_note, "extent": extent_of(lat, lon),
            "run": _run_summary(run), "counts": {k: int(v) for k, v in counts.items()},
            "n_attention": sum(1 for v in voyages if v["attention"]), "voyages": voyages}


_PHASE_RANK = {"at sea": 0, "not sailed": 1, "arrived": 2, "no plan": 3}


def mark_current_voyages(voyages: list[dict]) -> None:
    """Set `current` on each voyage: True for the one voyage per vessel whose position is the ship's now (the one at
    sea; else the next to sail; else the last arrived; else one without a plan), False for the vessel's others
    (a ship is in one place; its other voyages are drawn as plans only)."""
    best: dict = {}
    for i, v in enumerate(voyages):
        if not v.get("position"):
            v["current"] = False
            continue
        phase = v["position"]["phase"]
        etd = utc_datetime(v["etd_utc"].rstrip("Z")) if v.get("etd_utc") else None
        t = etd.timestamp() if etd else 0.0
        key = (_PHASE_RANK.get(phase, 9), -t if phase == "arrived" else t)  # next to sail: earliest; arrived: latest
        k = v.get("imo") if v.get("imo") is not None else v["voyage_id"]
        if k not in best or key < best[k][0]:
            best[k] = (key, i)
    chosen = {i for _, i in best.values()}
    for i, v in enumerate(voyages):
        v["current"] = i in chosen


def _run_summary(run: dict | None) -> dict | None:
    if not run:
        return None
    return {"run_id": run.get("run_id"), "started_at": _iso(run.get("started_at")), "cycle": _iso(run.get("cycle")),
            "cycle_age_h": _num(run.get("cycle_age_h"), 1), "status": run.get("status"),
            "nominal_utc": _iso(run.get("nominal_utc"))}


def valid_times(cycle, steps_h) -> list[dict]:
    """The slider's stops: [{step_h, valid_utc}] of a cycle's lead times."""
    c = np.datetime64(cycle, "s")
    return [{"step_h": int(s), "valid_utc": _iso(c + np.timedelta64(int(s), "h"))} for s in steps_h]


def nearest_step(cycle, steps_h, when) -> int | None:
    """The lead time (hours) whose valid time is nearest `when`."""
    if steps_h is None or len(steps_h) == 0 or when is None:
        return None
    valid = np.datetime64(cycle, "s") + np.asarray(steps_h, dtype=np.int64).astype("timedelta64[h]")
    return int(np.asarray(steps_h)[int(np.argmin(np.abs((valid - np.datetime64(when, "s")).astype(np.int64))))])


def weather_layer(lat, lon, fields: dict, var: str, cycle, step_h: int, extent: dict, is_sea=None,
                  max_x: int = WEATHER_MAX_X, max_y: int = WEATHER_MAX_Y) -> dict:
    """One step of wind, waves or currents as a grid for a map: magnitude (kn or m) and the direction the flow goes
    to (degrees true), every few grid points so the grid is at most max_x × max_y; NaN (land, ice) → null.
    `lon` is shifted by whole turns to lie in the map's frame (`extent`). With `is_sea(lat, lon)` (the land mask)
    points on land get no direction, so no arrow is drawn over land."""
    if var not in VARIABLES:
        raise ValueError(f"unknown weather variable {var!r}; use one of {', '.join(VARIABLES)}")
    mag, u, v, _label, _cmap = magnitude_and_flow(fields, var)
    lat, lon = np.asarray(lat, float), np.asarray(lon, float)
    mid = 0.5 * (extent["west"] + extent["east"])
    lon = lon - 360.0 * np.round((0.5 * (lon[0] + lon[-1]) - mid) / 360.0)
    sy, sx = max(1, math.ceil(lat.size / max_y)), max(1, math.ceil(lon.size / max_x))
    lat, lon = lat[::sy], lon[::sx]
    mag, u, v = mag[::sy, ::sx], u[::sy, ::sx], v[::sy, ::sx]
    to_deg = np.degrees(np.arctan2(u, v)) % 360.0
    if is_sea is not None:
        to_deg = np.where(is_sea(lat[:, None], lon[None, :]), to_deg, np.nan)

    def grid(a, decimals):
        return [[None if not math.isfinite(x) else round(float(x), decimals) for x in row] for row in a]

    finite = mag[np.isfinite(mag)]
    c = np.datetime64(cycle, "s")
    return {"var": var, "label": LABELS[var], "unit": UNITS[var], "cycle": _iso(c), "step_h": int(step_h),
            "valid_utc": _iso(c + np.timedelta64(int(step_h), "h")), "arrows": "point where the flow goes to",
            "lat": [round(float(x), 3) for x in lat], "lon": [round(float(x), 3) for x in lon],
            "magnitude": grid(mag, 2), "to_deg": grid(to_deg, 0),
            "max": None if finite.size == 0 else round(float(finite.max()), 2)}


def land_png(extent: dict, width_px: int, is_sea) -> bytes:
    """The land over a map's box as a PNG (land a sand colour, sea transparent), `width_px` wide (at most
    LAND_MAX_PX), rows by latitude as the map draws them (equal degrees). `is_sea(lat, lon)` is the product's land
    mask (pipeline.routing.land_mask.is_sea)."""
    w, e, s, n = extent["west"], extent["east"], extent["south"], extent["north"]
    nx = int(min(LAND_MAX_PX, max(8, width_px)))
    ny = int(min(LAND_MAX_PX, max(8, round(nx * (n - s) / max(e - w, 1e-6)))))
    lon = w + (np.arange(nx) + 0.5) * (e - w) / nx
    lat = n - (np.arange(ny) + 0.5) * (n - s) / ny
    land = ~is_sea(lat[:, None], lon[None, :])
    return _png_rgba(np.where(land[..., None], np.array([221, 213, 196, 255], np.uint8), np.uint8(0)).astype(np.uint8))


def _png_rgba(rgba: np.ndarray) -> bytes:
    """A PNG of an (h, w, 4) uint8 image (zlib only: no imaging library in a server that draws one layer)."""
    h, w, _ = rgba.shape
    raw = b"".join(b"\x00" + rgba[i].tobytes() for i in range(h))

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 6, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b""))


LEG_COLUMNS = ["leg", "lat0", "lon0", "lat1", "lon1", "etd_utc", "eta_utc", "dist_nm", "course_deg", "rpm", "stw_kn",
               "sog_kn", "hours", "fuel_t", "wait_h", "wait_fuel_t", "wind_kn", "wind_dir_deg", "hs_m", "wave_dir_deg",
               "current_kn", "beyond_forecast"]
PLAN_COLUMNS = ["run_id", "run_started_at", "trigger", "solver", "status", "reason", "cycle", "start_kind", "start_utc",
                "depart_utc", "eta_utc", "rta_utc", "hours", "fuel_t", "distance_nm", "baseline_fuel_t",
                "baseline_hours", "honest_baseline_rpm", "honest_baseline_fuel_t", "honest_baseline_hours",
                "savings_total_pct", "savings_speed_profile_pct", "savings_route_pct", "model_version",
                "forecast_flag", "n_legs"]


def voyage_view(voyage: dict, route: dict | None, legs: pd.DataFrame, plans: pd.DataFrame, tracks: pd.DataFrame,
                actual: dict | None, run: dict | None) -> dict:
    """The voyage page: its shown plan and legs (with the weather met), every plan made for it (re-plans at sea,
    the constant-speed baselines they were compared with), earlier plans' tracks, and plan against actual."""
    lon_all = legs["lon0"].to_numpy(float) if not legs.empty else np.array([voyage.get("dep_lon"), voyage.get("arr_lon")], float)
    centre = centre_lon_deg(lon_all)
    out = {"voyage": _plain_dict(voyage, drop=("rpm_options",)),
           "route": None, "legs": [], "track": [], "times": [], "plans": records(plans, PLAN_COLUMNS),
           "earlier_tracks": [], "actual": None, "attention": []}
    if route is not None:
        out["route"] = _plain_dict(route)
        out["attention"] = attention_items(route, run)
    pts_lat, pts_lon = [], []
    if not legs.empty:
        lat, lon, t = _waypoints(legs)
        lon = unwrap_lon_deg(lon, centre)
        out["track"] = _pairs(lat, lon)
        out["times"] = [_iso(x) for x in t]
        rows = records(legs, LEG_COLUMNS)
        for row, a, b in zip(rows, lon[:-1], lon[1:]):
            row["lon0"], row["lon1"] = round(float(a), 4), round(float(b), 4)
        out["legs"] = rows
        pts_lat.append(lat)
        pts_lon.append(lon)
    if not tracks.empty:
        for rid, g in tracks.groupby("run_id", sort=False):
            if route is not None and rid == route.get("run_id"):
                continue
            lat = np.r_[g["lat0"].to_numpy(float), g["lat1"].to_numpy(float)[-1:]]
            lon = unwrap_lon_deg(np.r_[g["lon0"].to_numpy(float), g["lon1"].to_numpy(float)[-1:]], centre)
            out["earlier_tracks"].append({"run_id": rid, "track": _pairs(lat, lon)})
            pts_lat.append(lat)
            pts_lon.append(lon)
    if not pts_lat:
        for k in ("dep", "arr"):
            if finite_or_none(voyage.get(f"{k}_lat")) is not None:
                pts_lat.append(np.array([voyage[f"{k}_lat"]], float))
                pts_lon.append(unwrap_lon_deg([voyage[f"{k}_lon"]], centre))
    out["extent"] = extent_of(np.concatenate(pts_lat) if pts_lat else [], np.concatenate(pts_lon) if pts_lon else [],
                              min_span_deg=4.0)
    if actual:
        out["actual"] = _plain_dict(actual)
    return out


def plan_view(plan: dict | None, legs: pd.DataFrame, left: pd.DataFrame, vessels: pd.DataFrame) -> dict:
    """The fleet-plan page: the active plan's Gantt rows (every vessel, idle ones too, each with its legs: ports,
    times, contract, and what the voyage made of each leg became), and the contracts it leaves with the reason."""
    if plan is None:
        return {"plan": None, "vessels": records(vessels), "rows": [], "unassigned": []}
    rows = []
    by_imo = {int(k): g for k, g in legs.groupby("imo")} if not legs.empty else {}
    for v in vessels.to_dict("records"):
        g = by_imo.get(int(v["imo"]))
        rows.append({"imo": int(v["imo"]), "name": v["name"],
                     "legs": [] if g is None else records(g, ["seq", "kind", "contract_code", "from_port", "to_port",
                                                              "dist_nm", "depart_utc", "arrive_utc", "fuel_t", "lift_t",
                                                              "voyage_id", "voyage_status", "voyage_eta_utc",
                                                              "voyage_rta_utc", "voyage_fuel_t", "voyage_reason"])})
    times = [] if legs.empty else [legs["depart_utc"].min(), legs["arrive_utc"].max()]
    return {"plan": _plain_dict(plan),
            "rows": rows, "unassigned": records(left), "start_utc": _iso(times[0]) if times else None,
            "end_utc": _iso(times[1]) if times else None}


def runs_view(runs: pd.DataFrame, cycles: pd.DataFrame, failures: pd.DataFrame) -> dict:
    """The runs page: routing runs (cycle used and its age, outcome, savings against the constant-speed voyage
    arriving at the RTA, fuel-weighted over the voyages compared), the cycles and the ingest files that failed."""
    return {"runs": records(runs), "cycles": records(cycles), "ingest_failures": records(failures)}
