"""The sea-route bench's exact reference (bench/shortest_sea_path.py) on synthetic land, against the analytic answer."""

from __future__ import annotations

import importlib.util
import math
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from pipeline.routing.sphere import EARTH_RADIUS_NM

_SPEC = importlib.util.spec_from_file_location(
    "shortest_sea_path", Path(__file__).resolve().parents[1] / "bench" / "shortest_sea_path.py")
ssp = importlib.util.module_from_spec(_SPEC)
sys.modules.setdefault("shortest_sea_path", ssp)  # dataclasses look their module up there
_SPEC.loader.exec_module(ssp)


def _island(radius_nm):
    """A round island (a spherical cap) centred at 0 N 0 E: the distance to land."""
    def dist_nm(lat, lon, limit_nm):
        return np.maximum(0.0, ssp.haversine_nm(lat, lon, 0.0, 0.0) - radius_nm)
    return dist_nm


def test_round_an_island_matches_the_tangent_arc_tangent_path():
    # from 60 NM west of a 20 NM island to 60 NM east, 2 NM clear: two tangents to the 22 NM circle and the arc
    # between them (on the sphere: cos D = cos ρ cos t; the tangent point is α from the line, cos α = tan ρ / tan D)
    t0 = time.process_time()
    problem = ssp.Problem(dep=(0.0, -1.0), arr=(0.0, 1.0), clearance_nm=2.0, approach_nm=1.0)
    route = ssp.shortest_route(problem, _island(20.0), (-1.0, 1.0, -1.1, 1.1), 0.02)
    cpu = time.process_time() - t0
    big_d, rho = 60.0 / EARTH_RADIUS_NM, 22.0 / EARTH_RADIUS_NM
    tangent = math.acos(math.cos(big_d) / math.cos(rho))
    alpha = math.acos(math.tan(rho) / math.tan(big_d))
    exact = EARTH_RADIUS_NM * (2.0 * tangent + (math.pi - 2.0 * alpha) * math.sin(rho))
    assert exact == pytest.approx(128.16, abs=0.01)
    assert exact * (1.0 - 1e-4) <= route.dist_nm <= exact * 1.002  # never shorter than possible, 0.2 % at most over
    assert route.grid_nm > route.dist_nm + 1.0  # the raster's zig-zag was pulled out
    # every waypoint keeps the clearance, and the route passes one side of the island
    assert np.all(ssp.haversine_nm(route.lat, route.lon, 0.0, 0.0) >= 22.0 - 0.05)
    assert np.all(route.lat[1:-1] > 0.0) or np.all(route.lat[1:-1] < 0.0)
    assert not route.touches_box
    assert cpu < 2.0


def test_open_water_is_the_great_circle():
    problem = ssp.Problem(dep=(10.0, -30.0), arr=(14.0, -24.0), clearance_nm=2.0, approach_nm=10.0)
    route = ssp.shortest_route(problem, lambda la, lo, lim: np.full(np.shape(la), 25.0), (9.0, 15.0, -31.0, -23.0), 0.1)
    assert route.lat.size == 2
    assert route.dist_nm == pytest.approx(float(ssp.haversine_nm(10.0, -30.0, 14.0, -24.0)), rel=1e-12)


def _wall(lat, lon, limit_nm):
    """A wall of land 1 NM thick along 0° E from 0.5 S to 0.5 N (near the equator a degree is 60 NM both ways)."""
    lat, lon = np.asarray(lat), np.asarray(lon)
    return np.maximum(0.0, 60.0 * np.hypot(lon, np.maximum(0.0, np.abs(lat) - 0.5)) - 0.5)


@pytest.mark.slow
def test_a_one_way_canal_is_sailed_only_its_way_and_a_gate_closes_the_way_round():
    canal = ssp.Fairway("canal", ((0.0, -0.2), (0.0, 0.2)), one_way=True)  # through the wall, eastbound only
    gate = ((0.55, 0.0), (1.5, 0.0))  # closes the way round the wall's northern end
    box = (-1.5, 1.5, -1.0, 1.0)
    east = ssp.shortest_route(ssp.Problem(dep=(0.0, -0.3), arr=(0.0, 0.3), clearance_nm=2.0, approach_nm=1.0,
                                          fairways=(canal,), gates=(gate,)), _wall, box, 0.02)
    assert east.fairways == ["canal"]
    assert east.fairway_runs == [("canal", 1, 2)] and east.lat.size == 4  # port, the canal's two ends, port
    assert east.dist_nm == pytest.approx(36.0, abs=0.1)  # 6 NM to the canal, 24 through, 6 from it
    west = ssp.shortest_route(ssp.Problem(dep=(0.0, 0.3), arr=(0.0, -0.3), clearance_nm=2.0, approach_nm=1.0,
                                          fairways=(canal,), gates=(gate,)), _wall, box, 0.02)
    assert west.fairways == []
    assert west.lat.min() < -0.5  # round the southern end: the northern way crosses the gate
    # two tangents to the 2.5 NM circle round the wall's southern end (30 NM south, the ports 18 NM east and west of
    # the wall) and the arc between them, in the plane (a degree is 60 NM both ways here)
    r, to_end = 2.5, math.hypot(18.0, 30.0)
    arc = 2.0 * math.pi - 2.0 * math.atan2(18.0, 30.0) - 2.0 * math.acos(r / to_end)
    exact = 2.0 * math.sqrt(to_end ** 2 - r ** 2) + r * arc
    assert exact == pytest.approx(75.31, abs=0.01)
    assert exact * (1.0 - 1e-3) <= west.dist_nm <= exact * 1.003


def test_the_bench_judges_a_pair_against_the_exact_route_only_where_searoute_is_more_than_3_percent_above_it():
    import json
    import subprocess

    def row(pair, product, ref):
        return dict(pair=pair, product_nm=product, searoute_nm=ref, diff=product / ref - 1.0)

    rows = [row("searoute detours", 1000.0, 1060.0),  # -5.7 % plain; exact 990: product +1.0 %, searoute +7.1 %
            row("product detours too", 1050.0, 1100.0),  # exact 1000: product +5 % of it
            row("searoute near the exact", 960.0, 1020.0),  # exact 1000: searoute +2 %, judged plainly: -5.9 %
            row("not computed", 1000.0, 1010.0)]
    exact = {"searoute detours": 990.0, "product detours too": 1000.0, "searoute near the exact": 1000.0}
    root = Path(__file__).resolve().parents[1]
    code = ("import json, sys; sys.path.insert(0, 'bench'); from sea_routes import by_the_exact_route; "
            "print(json.dumps({x['pair']: x['rule3'] for x in by_the_exact_route(*json.loads(sys.argv[1]))}))")
    r = subprocess.run([sys.executable, "-c", code, json.dumps([rows, exact])], cwd=root, capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout.strip().splitlines()[-1]) == {
        "searoute detours": "exact within", "product detours too": "exact off", "searoute near the exact": "off",
        "not computed": "within"}
