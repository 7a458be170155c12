"""`jitroute sea-route`: the shortest sea route between two positions over the whole ocean, with its passages."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from cli.console import console


def _position(text: str) -> tuple[float, float]:
    try:
        lat, lon = (float(x) for x in text.split(","))
    except ValueError:
        raise typer.BadParameter(f"{text!r} is not LAT,LON in degrees (e.g. 31.0,122.7)") from None
    return lat, lon


def sea_route_cmd(
        dep: str = typer.Argument(..., help="departure LAT,LON in degrees, at sea (the pilot station)"),
        arr: str = typer.Argument(..., help="arrival LAT,LON in degrees, at sea"),
        avoid: list[str] = typer.Option([], "--avoid", help="a passage to avoid (repeat for more): suez, panama, kiel, "
                                        "corinth, gibraltar, dover, singapore, …; see docs/sea-routes.md"),
        clearance_nm: float = typer.Option(2.0, "--clearance-nm", help="keep this far from land, NM"),
        approach_nm: float = typer.Option(10.0, "--approach-nm", help="within this of either port, only be at sea, NM"),
        waypoints: bool = typer.Option(False, "--waypoints", help="print every waypoint"),
        geojson: Path | None = typer.Option(None, "--geojson", help="write the route as a GeoJSON LineString here"),
) -> None:
    """The shortest sea route from DEP to ARR clear of land: its length, the passages it sails through (canals
    with their transit and waiting hours) and, on request, its waypoints."""
    from pipeline.routing.geodesy import gc_distance_nm
    from pipeline.routing.global_routes import sea_route

    a, b = _position(dep), _position(arr)
    r = sea_route(a, b, avoid=set(avoid), clearance_nm=clearance_nm, approach_nm=approach_nm)
    gc = float(gc_distance_nm(*a, *b))
    console.print(f"{r.dist_nm:,.1f} NM ({100 * (r.dist_nm / gc - 1):+.1f} % over the great circle {gc:,.1f} NM), "
                  f"{r.lat.size} waypoints", highlight=False)
    for p in r.passages:
        extra = f", transit {p.transit_h:g} h + waiting {p.wait_h:g} h" if p.transit_h is not None else ""
        console.print(f"  {p.kind} {p.name}: waypoints {p.start_index}–{p.end_index}{extra}", highlight=False)
    if waypoints:
        for k, (la, lo) in enumerate(zip(r.lat, r.lon)):
            console.print(f"  {k:4d} {la:9.4f} {lo:10.4f}", highlight=False)
    if geojson is not None:
        feature = {"type": "Feature", "properties": {"dist_nm": r.dist_nm, "passages": [p.name for p in r.passages]},
                   "geometry": {"type": "LineString", "coordinates": [[float(lo), float(la)] for la, lo in zip(r.lat, r.lon)]}}
        geojson.write_text(json.dumps(feature))
        console.print(f"wrote {geojson}", highlight=False)


def register(app: typer.Typer) -> None:
    app.command("sea-route")(sea_route_cmd)
