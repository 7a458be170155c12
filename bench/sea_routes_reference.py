"""The exact shortest sea route for the sea-route bench's pairs, independent of the product's sea graph.

For a pair of bench/sea_routes.py: the shortest route over the product's own land mask (pipeline/routing/land.py's
distance to land) under the product's rule (2 NM clearance, at sea only within 10 NM of either port) with the same
passages as the product applies them (passages.py: fairways sailed vertex by vertex, the traffic separation schemes'
lanes one way, no leg across a gate or a side of an area to avoid, the avoided passages' fairways closed but their
gates kept), found on a fine raster and string-pulled (bench/shortest_sea_path.py). The raster covers the bounding
box of the product's route and searoute's line (when searoute is installed) plus `MARGIN_DEG`, at 0.05° or coarser
so that it holds at most `MAX_CELLS` cells; when the path runs along the box's edge the margin doubles (up to twice).

    .venv/bin/python bench/sea_routes_reference.py                 # the pairs of REFERENCE_PAIRS, writes the JSON
    .venv/bin/python bench/sea_routes_reference.py "Manila - Guam"  # some pairs only (merged into the JSON)

Prints per pair the product, searoute (as the bench's reference) and the exact route, and whether the product is
within ±3 % of the exact route while searoute is not; writes bench/sea_routes_reference.json (the bench reads it,
sea_routes.py --recompute-reference runs this). CPU seconds per pair: about 1–60 s (the raster's size).
"""

from __future__ import annotations

import os

os.environ["NUMBA_NUM_THREADS"] = "1"  # before numba is imported anywhere

import datetime  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from shortest_sea_path import Fairway, Problem, haversine_nm, shortest_route  # noqa: E402

from sea_route_pairs import CLEARANCE_NM, PAIRS, PORTS, key  # noqa: E402

from pipeline.routing.clearance import DEFAULT_APPROACH_NM  # noqa: E402
from pipeline.routing.global_routes import FAIRWAY_END_APPROACH_NM, JOIN_NM  # noqa: E402
from pipeline.routing.land import distance_to_land_nm  # noqa: E402
from pipeline.routing.passages import PASSAGES, area_gates  # noqa: E402

RECORDED = Path(__file__).with_name("sea_routes_reference.json")
RES_DEG = 0.05
MAX_CELLS = 600_000
MARGIN_DEG = 1.0
# the pairs off by more than 3 % of searoute (plain, 2026-12-05) and five within, over passages of every kind
REFERENCE_PAIRS = (
    "Colon - Balboa", "Antwerp - Gothenburg", "Miami - Vancouver", "Hamburg - Gdansk (avoid kiel)",
    "Port Klang - Hong Kong", "Melbourne - Auckland", "Manila - Guam", "Singapore - Manila", "Hong Kong - Qingdao",
    "Guam - Manila", "Auckland - Honolulu", "Valparaiso - Sydney", "Rio de Janeiro - Lagos",
    "Buenos Aires - Cape Town", "Dakar - New York",
    "Rotterdam - Gdansk (avoid kiel)", "Sydney - Port Hedland", "Port Hedland - Qingdao", "Busan - Tokyo Bay",
    "Qingdao - Tokyo Bay", "Kaohsiung - Ningbo",
    # within ±3 %
    "Singapore - Shanghai", "Piraeus - Constanta", "Naples - Piraeus", "Davao - Hong Kong", "Lisbon - Rotterdam",
)


def _unwrapped(lon: np.ndarray, ref: float) -> np.ndarray:
    """Longitudes made continuous along a line, starting near `ref`."""
    out = np.empty(len(lon))
    prev = ref
    for k, x in enumerate(lon):
        prev = prev + (x - prev + 180.0) % 360.0 - 180.0
        out[k] = prev
    return out


def _along(lat: np.ndarray, lon: np.ndarray, step_nm: float = 20.0) -> tuple[np.ndarray, np.ndarray]:
    """Points every `step_nm` along the great-circle legs of a line: a leg's great circle bulges poleward of its
    ends, and the box must hold it."""
    from pipeline.routing.sphere import gc_points

    out_lat, out_lon = [lat[:1]], [lon[:1]]
    for k in range(lat.size - 1):
        n = int(haversine_nm(lat[k], lon[k], lat[k + 1], lon[k + 1]) / step_nm) + 2
        la, lo = gc_points(lat[k], lon[k], lat[k + 1], lon[k + 1], np.linspace(0.0, 1.0, n)[1:])
        out_lat.append(la)
        out_lon.append(lo)
    return np.concatenate(out_lat), np.concatenate(out_lon)


def problem_for(dep, arr, avoid, clearance_nm: float, approach_nm: float = DEFAULT_APPROACH_NM) -> Problem:
    """The product's rule and passages for a voyage, as shortest_sea_path states them."""
    fairways = tuple(Fairway(p.name, tuple(p.fairway), p.one_way) for p in PASSAGES if p.name not in set(avoid))
    gates = tuple(g for p in PASSAGES for g in p.gates) + area_gates()  # the areas to avoid: their sides
    return Problem(dep=tuple(dep), arr=tuple(arr), clearance_nm=clearance_nm, approach_nm=approach_nm,
                   fairways=fairways, gates=gates, fairway_end_approach_nm=FAIRWAY_END_APPROACH_NM, join_nm=JOIN_NM)


def exact_route(dep, arr, avoid, lines, clearance_nm: float):
    """(Route, box, res_deg): the shortest route of `problem_for` over the raster round `lines` (lists of (lat, lon)
    arrays: the routes whose box it covers)."""
    lines = [_along(np.asarray(la, np.float64), np.asarray(lo, np.float64)) for la, lo in lines]
    lat = np.concatenate([la for la, _ in lines])
    lon = np.concatenate([_unwrapped(lo, dep[1]) for _, lo in lines])
    problem = problem_for((dep[0], dep[1]), (arr[0], dep[1] + (arr[1] - dep[1] + 180.0) % 360.0 - 180.0), avoid,
                          clearance_nm)
    margin = MARGIN_DEG
    for _ in range(3):
        box = (max(lat.min() - margin, -80.0), min(lat.max() + margin, 84.0), lon.min() - margin, lon.max() + margin)
        area = (box[1] - box[0]) * (box[3] - box[2])
        res = max(RES_DEG, math.ceil(math.sqrt(area / MAX_CELLS) * 100.0) / 100.0)
        route = shortest_route(problem, lambda la, lo, lim: distance_to_land_nm(la, lo, limit_nm=lim), box, res)
        if not route.touches_box:
            break
        margin *= 2.0
    return route, box, res


def product_clearance_nm(route) -> float:
    """The exact route's least distance to land outside its fairways and approaches, by the product's own check
    (global_routes.least_clearance_outside_passages_nm, every 0.1 NM): an independent check that the raster's rule
    is the product's (at least the clearance, less the 0.05 NM between samples)."""
    from pipeline.routing.global_routes import least_clearance_outside_passages_nm
    from pipeline.routing.passages import passage
    from pipeline.routing.sea_route import PassageTransit, SeaRoute

    transits = tuple(PassageTransit(name, passage(name).kind, a, b) for name, a, b in route.fairway_runs)
    lon = (route.lon + 180.0) % 360.0 - 180.0
    return least_clearance_outside_passages_nm(SeaRoute(route.lat, lon, route.dist_nm, transits))


def compute(keys, clearance_nm: float) -> dict[str, dict]:
    """The exact route's figures for the bench pairs named by `keys` (sea_routes.key); prints a line per pair."""
    from pipeline.routing.global_routes import sea_route

    try:
        import searoute as sr
    except ImportError:
        sr = None
    out = {}
    for a, b, avoid in PAIRS:
        k = key(a, b, avoid)
        if k not in keys:
            continue
        t = time.process_time()
        r = sea_route(PORTS[a], PORTS[b], avoid=set(avoid), clearance_nm=clearance_nm)
        lines = [(r.lat, r.lon)]
        if sr is not None:
            (la, lo), (lb, lob) = PORTS[a], PORTS[b]
            f = sr.searoute([lo, la], [lob, lb], units="naut",
                            restrictions=["northwest"] + [x for x in avoid if x in ("suez", "panama")])
            x, y = np.array(f["geometry"]["coordinates"]).T
            lines.append((y, x))
        route, box, res = exact_route(PORTS[a], PORTS[b], avoid, lines, clearance_nm)
        cpu = time.process_time() - t
        clear = product_clearance_nm(route)
        out[k] = dict(nm=round(route.dist_nm, 1), product_check_clearance_nm=round(clear, 2), grid_nm=round(route.grid_nm, 1), res_deg=res,
                      box=[round(v, 3) for v in box], waypoints=int(route.lat.size), fairways=route.fairways,
                      touches_box=bool(route.touches_box), cpu_s=round(cpu, 1))
        print(f"  {k:44s} exact {route.dist_nm:8,.1f} NM (raster {res:g}°, {route.lat.size} waypoints, "
              f"{'+'.join(route.fairways) or '-'}; the product's check: {clear:.2f} NM from land; product "
              f"{r.dist_nm:,.1f}; {cpu:.1f} s CPU)", flush=True)
    return out


def record(keys, clearance_nm: float) -> dict:
    """Compute `keys` and merge them into bench/sea_routes_reference.json, written after each pair; returns the
    whole record."""
    rec = json.loads(RECORDED.read_text()) if RECORDED.exists() else {}
    pairs = rec.get("pairs", {})
    for k in keys:
        pairs.update(compute([k], clearance_nm))
        rec = dict(what="the shortest route under the product's rule and passages on a fine raster, string-pulled "
                        "(bench/sea_routes_reference.py)", clearance_nm=clearance_nm, approach_nm=DEFAULT_APPROACH_NM,
                   computed=datetime.date.today().isoformat(), pairs=dict(sorted(pairs.items())))
        RECORDED.write_text(json.dumps(rec, indent=1, ensure_ascii=False) + "\n")
    return rec


def main() -> int:
    keys = sys.argv[1:] or list(REFERENCE_PAIRS)
    known = {key(a, b, avoid) for a, b, avoid in PAIRS}
    unknown = [k for k in keys if k not in known]
    if unknown:
        print(f"not a pair of the bench: {', '.join(repr(k) for k in unknown)}; the pairs are named as "
              f"bench/sea_routes.py prints them, e.g. {sorted(known)[:3]}", file=sys.stderr)
        return 2
    record(keys, CLEARANCE_NM)
    return 0


if __name__ == "__main__":
    sys.exit(main())
