"""A plan's export files as bytes: RTZ (schema-validated), GeoJSON and the route map PNG (the operator's set), and the
BFOA convergence plot (a developer's diagnostic, made only when asked: `kinds` with DEBUG_KINDS).

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

OPERATOR_KINDS = ("rtz", "geojson", "png")  # what a run exports for every voyage
DEBUG_KINDS = ("convergence",)  # added by the `debug_plots` setting (JITROUTE_DEBUG_PLOTS=1) or asked for by name
KINDS = OPERATOR_KINDS + DEBUG_KINDS
SUFFIX = {"rtz": ".rtz", "geojson": ".geojson", "png": ".png", "convergence": ".convergence.png"}


@dataclass
class ExportBundle:
    voyage_id: str
    files: dict[str, bytes] = field(default_factory=dict)  # kind → bytes (file `<voyage_id><SUFFIX[kind]>`)
    errors: dict[str, str] = field(default_factory=dict)  # kind → what went wrong


def kinds_of_run(debug_plots: bool) -> tuple[str, ...]:
    """The exports a fleet run makes of each voyage: the operator's set, and the diagnostics with `debug_plots`."""
    return KINDS if debug_plots else OPERATOR_KINDS


def named_route(plan: Plan, vessel: dict, voyage: dict, run_id: str | None = None) -> dict:
    """The route row of the run `run_id` with the names exports show (vessel, departure and arrival ports) and where
    the plan starts (`start_kind`: port, or the noon report / position a plan re-made at sea starts from)."""
    return dict(plan.route_row(run_id), vessel_name=vessel.get("name"), dep_name=voyage.get("dep_name"),
                arr_name=voyage.get("arr_name"), start_kind=voyage.get("start_kind"))


def rtz_bytes(plan: Plan, vessel: dict, voyage: dict, run_id: str | None = None) -> bytes:
    doc = rtz.route_to_rtz(named_route(plan, vessel, voyage, run_id), plan.legs)
    rtz.validate_rtz(doc)
    return doc


def geojson_bytes(plan: Plan, vessel: dict, voyage: dict, run_id: str | None = None) -> bytes:
    """The GeoJSON; its route feature carries `run_id`, so a file copied out of its run folder still names its run."""
    return json.dumps(geojson.route_to_geojson(named_route(plan, vessel, voyage, run_id), plan.legs), indent=1).encode()


def route_map_bytes(plan: Plan, vessel: dict, voyage: dict, weather: wf.WeatherField, draw: Draw = draw_here,
                    run_id: str | None = None) -> bytes:
    """The route and its baseline over the wind/wave field met at mid-voyage (the field's snapshot is cut here: only
    it, not the voyage's weather, goes to `draw`); the field carries its valid time (`valid_utc`, ISO UTC), which
    the map's title names."""
    from pipeline.export.voyage import iso_utc

    lats = [p[0] for p in plan.waypoints]
    lons = [p[1] for p in plan.waypoints]
    mid = plan.legs[len(plan.legs) // 2]["etd_utc"]
    snap = wf.snapshot(weather, mid, (min(lats), max(lats)), (min(lons), max(lons)))
    base_legs = plan.baseline.legs if plan.baseline is not None else None
    note = f"the forecast step nearest the ship at mid-voyage, {iso_utc(mid)}"
    field = dict(snap, valid_utc=iso_utc(snap["valid_utc"]), valid_note=note) if snap["hs_m"] is not None else None
    return draw("route_map", named_route(plan, vessel, voyage, run_id), plan.legs, base_legs, field)


def convergence_bytes(plan: Plan, draw: Draw = draw_here) -> bytes:
    return draw("convergence", plan.history, f"{plan.voyage_id}: BFOA best cost per cycle")


def export_plan(plan: Plan, weather: wf.WeatherField, vessel: dict, voyage: dict,
                kinds: Iterable[str] = OPERATOR_KINDS, draw: Draw = draw_here,
                run_id: str | None = None) -> ExportBundle:
    """Every asked-for export of a plan with legs (default: the operator's set, no convergence plot); a failing
    export is recorded in `errors`, never raised. `draw` draws the PNGs (pipeline/export/drawing.py); `run_id` is the
    run the plan belongs to, written into the files."""
    out = ExportBundle(str(plan.voyage_id))
    if not plan.legs:
        return out
    makers = {
        "rtz": lambda: rtz_bytes(plan, vessel, voyage, run_id),
        "geojson": lambda: geojson_bytes(plan, vessel, voyage, run_id),
        "png": lambda: route_map_bytes(plan, vessel, voyage, weather, draw, run_id),
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
