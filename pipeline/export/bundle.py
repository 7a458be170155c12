"""A plan's export files as bytes: RTZ (schema-validated), GeoJSON, route map and convergence PNGs.

Each export stands alone: one that fails is reported by name and the others are still made. The
caller decides where the bytes go (a run's staging folder, a `--rtz` path), so workers need no shared
file system and nothing is written for a voyage whose rows never reached the warehouse. The PNGs are drawn by
`draw` (pipeline/export/drawing.py: here by default, or by a child process, so a worker never loads matplotlib)
from plain inputs made here.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from dataclasses import dataclass, field

from pipeline.export import geojson, rtz
from pipeline.export.drawing import Draw, draw_here
from pipeline.routing import weather_field as wf
from pipeline.routing.plan import Plan

KINDS = ("rtz", "geojson", "png", "convergence")
SUFFIX = {"rtz": ".rtz", "geojson": ".geojson", "png": ".png", "convergence": ".convergence.png"}


@dataclass
class ExportBundle:
    voyage_id: str
    files: dict[str, bytes] = field(default_factory=dict)  # kind → bytes (file `<voyage_id><SUFFIX[kind]>`)
    errors: dict[str, str] = field(default_factory=dict)  # kind → what went wrong


def named_route(plan: Plan, vessel: dict, voyage: dict) -> dict:
    """The route row with the names exports show (vessel, departure and arrival ports)."""
    return dict(plan.route_row(), vessel_name=vessel.get("name"), dep_name=voyage.get("dep_name"),
                arr_name=voyage.get("arr_name"))


def rtz_bytes(plan: Plan, vessel: dict, voyage: dict) -> bytes:
    doc = rtz.route_to_rtz(named_route(plan, vessel, voyage), plan.legs)
    rtz.validate_rtz(doc)
    return doc


def geojson_bytes(plan: Plan, vessel: dict, voyage: dict) -> bytes:
    return json.dumps(geojson.route_to_geojson(named_route(plan, vessel, voyage), plan.legs), indent=1).encode()


def route_map_bytes(plan: Plan, vessel: dict, voyage: dict, weather: wf.WeatherField, draw: Draw = draw_here) -> bytes:
    """The route and its baseline over the wind/wave field met at mid-voyage (the field's snapshot is cut here: only
    it, not the voyage's weather, goes to `draw`)."""
    lats = [p[0] for p in plan.waypoints]
    lons = [p[1] for p in plan.waypoints]
    mid = plan.legs[len(plan.legs) // 2]["etd_utc"]
    snap = wf.snapshot(weather, mid, (min(lats), max(lats)), (min(lons), max(lons)))
    base_legs = plan.baseline.legs if plan.baseline is not None else None
    return draw("route_map", named_route(plan, vessel, voyage), plan.legs, base_legs,
                snap if snap["hs_m"] is not None else None)


def convergence_bytes(plan: Plan, draw: Draw = draw_here) -> bytes:
    return draw("convergence", plan.history, f"{plan.voyage_id}: BFOA best cost per cycle")


def export_plan(plan: Plan, weather: wf.WeatherField, vessel: dict, voyage: dict,
                kinds: Iterable[str] = KINDS, draw: Draw = draw_here) -> ExportBundle:
    """Every asked-for export of a plan with legs; a failing export is recorded in `errors`, never raised. `draw`
    draws the PNGs (pipeline/export/drawing.py)."""
    out = ExportBundle(str(plan.voyage_id))
    if not plan.legs:
        return out
    makers = {
        "rtz": lambda: rtz_bytes(plan, vessel, voyage),
        "geojson": lambda: geojson_bytes(plan, vessel, voyage),
        "png": lambda: route_map_bytes(plan, vessel, voyage, weather, draw),
        "convergence": lambda: convergence_bytes(plan, draw),
    }
    for kind in kinds:
        if kind == "convergence" and plan.history is None:
            continue
        try:
            out.files[kind] = makers[kind]()
        except Exception as exc:  # exports are secondary: keep the plan, say which export failed and why
            out.errors[kind] = f"{type(exc).__name__}: {exc}"
    return out
