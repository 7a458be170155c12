"""Safe water: the land structure, distance to land, and routes kept clear of small islands, straits and coasts.

Distances are checked against an independent computation on the package's own full-resolution mask
(`global_land_mask`'s grid, read by tests/land_reference.py): great-circle distance from a point to the nearest
land cell taken as a latitude/longitude box. Routes are re-sampled here every 0.05 NM.
"""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from pipeline.routing import land
from pipeline.routing.search_space import build_search_space, reachable
from pipeline.routing import weather_field as wf
from pipeline.routing.voyage import problem_from_voyage
from pipeline.synthetic.fleet import PORTS, ROUTES
from routing_cases import FAST, MODEL, problem, solve
from tests import land_reference as globe

R_NM = 3440.065
MARCUS = (24.286, 153.979)  # Minami-Tori-shima, ~1 NM across, 500 NM from other land
NAURU = (-0.525, 166.918)  # ~3 NM across
CALM = wf.uniform("2020-12-01T00", 400)


def haversine_nm(lat1, lon1, lat2, lon2):
    p1, p2, dl = np.radians(lat1), np.radians(lat2), np.radians(np.asarray(lon2) - lon1)
    a = np.sin((p2 - p1) / 2) ** 2 + np.cos(p1) * np.cos(p2) * np.sin(dl / 2) ** 2
    return 2 * R_NM * np.arcsin(np.sqrt(np.minimum(1.0, a)))


def raw_distance_nm(lat, lon, radius_nm=3.0):
    """Distance to the nearest land cell of the raw mask (cells as boxes, great-circle NM), capped at radius."""
    i0, j0 = int((90.0 - lat) * 120), int(((lon + 180.0) % 360.0) * 120)
    n = int(radius_nm / 0.5) + 2
    m = int(n / math.cos(math.radians(lat))) + 2
    rows, cols = np.arange(i0 - n, i0 + n + 1), np.arange(j0 - m, j0 + m + 1)
    r, c = np.nonzero(~globe.ocean_cells(rows, cols % 43200))
    if not len(r):
        return radius_nm
    top, west = 90.0 - rows[r] / 120.0, -180.0 + cols[c] / 120.0
    lon_u = -180.0 + (lon + 180.0) % 360.0
    d = haversine_nm(lat, lon_u, np.clip(lat, top - 1 / 120.0, top), np.clip(lon_u, west, west + 1 / 120.0))
    return float(min(d.min(), radius_nm))


def slerp(lat0, lon0, lat1, lon1, f):
    a, b = (np.array([math.cos(math.radians(la)) * math.cos(math.radians(lo)),
                      math.cos(math.radians(la)) * math.sin(math.radians(lo)), math.sin(math.radians(la))])
            for la, lo in ((lat0, lon0), (lat1, lon1)))
    w = math.acos(min(1.0, float(a @ b)))
    v = a if w < 1e-12 else (math.sin((1 - f) * w) * a + math.sin(f * w) * b) / math.sin(w)
    return math.degrees(math.asin(v[2])), math.degrees(math.atan2(v[1], v[0]))


def route_samples(waypoints, step_nm=0.05):
    for (la0, lo0), (la1, lo1) in zip(waypoints[:-1], waypoints[1:]):
        n = max(1, int(math.ceil(haversine_nm(la0, lo0, la1, lo1) / step_nm)))
        for k in range(n + 1):
            yield slerp(la0, lo0, la1, lo1, k / n)


def least_raw_clearance_nm(waypoints, ports, approach_nm, radius_nm=3.0):
    """Least raw-mask distance to land along the route at 0.05 NM, outside `approach_nm` of the ports."""
    best = radius_nm
    for la, lo in route_samples(waypoints):
        if min(haversine_nm(la, lo, *p) for p in ports) > approach_nm:
            best = min(best, raw_distance_nm(la, lo, radius_nm))
    return best


def test_is_sea_equals_the_package_mask_everywhere():
    rng = np.random.default_rng(5)
    lat, lon = rng.uniform(-89.9, 89.9, 300_000), rng.uniform(-180.0, 180.0, 300_000)
    assert np.array_equal(land.is_sea(lat, lon), globe.is_ocean(lat, lon))
    # and along coasts, where the mixed tiles' bits do the work
    lat, lon = rng.uniform(30.0, 36.0, 100_000), rng.uniform(129.0, 141.0, 100_000)
    sea = land.is_sea(lat, lon)
    assert 0.2 < sea.mean() < 0.9
    assert np.array_equal(sea, globe.is_ocean(lat, lon))


@pytest.mark.parametrize("island", [MARCUS, NAURU])
def test_distance_to_a_small_island_equals_the_raw_mask(island):
    rng = np.random.default_rng(1)
    lat = island[0] + rng.uniform(-0.1, 0.1, 400)
    lon = island[1] + rng.uniform(-0.1, 0.1, 400)
    got = land.distance_to_land_nm(lat, lon, limit_nm=3.0)
    want = np.array([raw_distance_nm(a, o, 3.0) for a, o in zip(lat, lon)])
    assert (want == 0).any() and ((want > 0) & (want < 3)).sum() > 50  # on it, beside it, and off it
    np.testing.assert_allclose(got[want < 3.0], want[want < 3.0], atol=0.01)
    assert np.all(got[want >= 3.0] >= 3.0 - 0.01)
    # beyond the limit the value is a lower bound, never more than the truth
    far = land.distance_to_land_nm(lat, lon, limit_nm=0.5)
    assert np.all(far <= np.maximum(got, 0.5) + 1e-9) and np.all(far[want >= 0.5] >= 0.5)


@pytest.mark.slow  # a child process
def test_building_the_land_structure_is_small_and_never_loads_the_full_mask():
    code = ("import re, sys\n"
            "from pipeline.routing import land_mask as land\n"
            "g = land.build_land_grid()\n"
            "peak_kb = int(re.search('VmHWM:\\\\s+(\\\\d+)', open('/proc/self/status').read()).group(1))\n"
            "shipped = land.read_saved(land.PACKAGED, land.mask_key(land.mask_path()))\n"
            "same = shipped is not None and all((a == b).all() for a, b in zip(g, shipped))\n"
            "print(g.nbytes, 'global_land_mask.globe' in sys.modules, same, peak_kb // 1024)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    nbytes, loaded, same_as_shipped, peak_mb = int(out[0]), out[1] == "True", out[2] == "True", int(out[3])
    assert nbytes < 20e6 and not loaded
    assert peak_mb < 300, f"building the land structure peaked at {peak_mb} MB"
    assert same_as_shipped, ("the shipped land_grid_v1.npz differs from a build from the installed mask: "
                             "run `python -m pipeline.routing.land_mask` and commit it")


@pytest.mark.slow  # child processes
def test_processes_load_the_shipped_land_structure_without_building_it():
    code = ("import re, sys\n"
            "from pipeline.routing import land, land_mask\n"
            "land_mask.build_land_grid = None  # a build would fail\n"
            "g = land.land_grid()\n"
            "peak_kb = int(re.search('VmHWM:\\\\s+(\\\\d+)', open('/proc/self/status').read()).group(1))\n"
            "print(bool(land.is_sea(24.286, 153.979)), bool(land.is_sea(25.0, 150.0)), peak_kb // 1024)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out[:2] == ["False", "True"]  # Minami-Tori-shima is land, the ocean west of it is not
    assert int(out[2]) < 200, f"loading the land structure peaked at {out[2]} MB"


def test_strait_closes_when_the_clearance_is_more_than_half_its_width():
    # Strait of Gibraltar: its narrowest north–south span of water in the mask is 7–8 NM
    spans = []
    for lon in np.arange(-5.75, -5.40, 0.01):
        lat = np.arange(35.80, 36.12, 1 / 600)
        sea = globe.is_ocean(lat, np.full_like(lat, lon))
        spans.append(sea.sum() * 0.1)
    assert 6.5 < min(spans) < 8.05
    dep, arr = (35.93, -6.1), (36.02, -5.1)  # over 10 NM from the narrows, outside the 5 NM approaches
    kw = dict(n_lines=10, n_points=15, d_point_nm=0.75, approach_nm=5.0)
    assert reachable(build_search_space(dep, arr, clearance_nm=2.0, **kw))
    assert reachable(build_search_space(dep, arr, clearance_nm=3.0, **kw))
    assert not reachable(build_search_space(dep, arr, clearance_nm=4.5, **kw))  # 9 NM > the strait


@pytest.mark.parametrize("island", [MARCUS, NAURU])
@pytest.mark.slow
def test_route_past_a_small_island_keeps_the_clearance(island):
    dep, arr = (island[0] + 0.01, island[1] - 1.5), (island[0] - 0.01, island[1] + 1.5)
    straight = [slerp(*dep, *arr, k / 400) for k in range(401)]
    assert min(raw_distance_nm(a, o) for a, o in straight) < 2.0  # the great circle passes the island closer than 2 NM
    pr = problem(dep, arr, 30, n_lines=8, n_points=11, d_point_nm=1.0)
    space = pr.search_space()
    # also refined on corridors 3× finer across the lines (refine_graph.py): its new nodes and legs keep the clearance
    for solver, split in (("gc", 1), ("dp", 1), ("bfoa", 1), ("dp", 3), ("bfoa", 3)):
        plan = solve(pr, CALM, solver=solver, seed=1, params=FAST, space=space, refine_split=split)
        assert plan.status == "ok", (solver, plan.reason)
        raw = least_raw_clearance_nm(plan.waypoints, [dep, arr], 10.0)
        assert raw >= 2.0 - 0.01, (solver, split, raw)
        assert plan.min_land_clearance_nm == pytest.approx(raw, abs=0.1), solver
        assert plan.route_row()["min_land_clearance_nm"] == plan.min_land_clearance_nm


def test_a_port_close_to_land_is_reached_along_its_approach():
    dep, arr = (MARCUS[0], MARCUS[1] + 0.03), (MARCUS[0] + 0.2, MARCUS[1] + 1.8)
    assert 0.5 < raw_distance_nm(*dep) < 1.5  # the departure lies about 1 NM off the island
    pr = problem(dep, arr, 30, n_lines=6, n_points=11, d_point_nm=1.0)
    plan = solve(pr, CALM, solver="dp", space=pr.search_space())
    assert plan.status == "ok", plan.reason
    assert least_raw_clearance_nm(plan.waypoints, [dep, arr], 10.0) >= 2.0 - 0.01
    close = [(la, lo) for la, lo in route_samples(plan.waypoints, 0.5) if raw_distance_nm(la, lo) < 2.0]
    assert close and max(haversine_nm(la, lo, *dep) for la, lo in close) <= 10.0  # only inside its approach
    no_approach = problem(dep, arr, 30, n_lines=6, n_points=11, d_point_nm=1.0, port_approach_nm=0.0)
    assert solve(no_approach, CALM, solver="dp").status == "infeasible"


@pytest.mark.slow
def test_demo_voyage_off_luzon_keeps_two_miles_from_the_coast():
    dep_name, arr_name = ROUTES[11]  # the demo fleet's twelfth voyage, V20012
    assert (dep_name, arr_name) == ("Manila", "Kaohsiung")
    dep, arr = PORTS[dep_name], PORTS[arr_name]
    straight = [slerp(*dep, *arr, k / 2000) for k in range(2001)]
    assert not all(globe.is_ocean(a, o) for a, o in straight)  # the great circle crosses Luzon
    voyage = {"voyage_id": "V20012", "imo": 9140607, "dep_name": dep_name, "dep_lat": dep[0], "dep_lon": dep[1],
              "arr_name": arr_name, "arr_lat": arr[0], "arr_lon": arr[1], "depart_utc": "2020-12-01T06",
              "rta_utc": "2020-12-03T12", "rpm_options": [70.0, 85.0, 100.0]}
    pr = problem_from_voyage(voyage, MODEL)
    assert pr.land_clearance_nm == 2.0 and pr.port_approach_nm == 10.0
    for solver in ("gc", "dp"):
        plan = solve(pr, CALM, solver=solver)
        assert plan.status in ("ok", "late"), (solver, plan.reason)
        raw = least_raw_clearance_nm(plan.waypoints, [dep, arr], 10.0)
        assert raw >= 2.0 - 0.01, (solver, raw)
        assert plan.min_land_clearance_nm >= 2.0


def test_lines_are_laid_closer_when_the_default_ones_leave_no_route_at_sea():
    # Qingdao → Busan: with a line every ~40 NM no 2 NM-clear leg threads Korea's south-western islands
    from pipeline.routing.search_space import build_search_space, default_n_lines, reachable

    dep, arr = (35.9, 120.65), (34.95, 129.15)
    coarse = build_search_space(dep, arr, n_lines=default_n_lines(420.0))
    assert not reachable(coarse)
    space = build_search_space(dep, arr)
    assert reachable(space) and space.n_lines == 2 * coarse.n_lines
    open_sea = build_search_space((30.0, -160.0), (33.0, -146.0))  # nothing to thread: the default stays
    assert open_sea.n_lines == default_n_lines(open_sea.base_distance_nm)


def test_a_strait_between_two_nodes_of_a_line_gets_more_nodes_along_the_lines():
    """Through Gibraltar (clear corridor ≥ 3.5 NM from land): the default 21 nodes a line leave its corridor between
    two nodes, 41 find it; the plan keeps the 2 NM clearance, checked on the mask independently of the graph."""
    from pipeline.routing.search_space import lay_out_lines

    dep, arr = (35.95, -6.0), (36.0, -5.0)
    assert not reachable(lay_out_lines(dep, arr))  # the default layout: no way through
    space = build_search_space(dep, arr)
    assert reachable(space) and space.lat.shape[1] == 41 and space.n_lines == lay_out_lines(dep, arr).n_lines
    pr = problem(dep, arr, 8.0, n_lines=None, n_points=21)
    plan = solve(pr, CALM, solver="dp", space=space)
    assert plan.status == "ok", plan.reason
    assert plan.min_land_clearance_nm >= 2.0 - 1e-6
    lat, lon = np.array(plan.waypoints).T
    assert lon.min() < -5.7 and lon.max() > -5.3  # it sails through the strait, not round anything
    assert not globe.is_land(lat, lon).any()


STRAITS = {
    # name: (dep, arr, the widest corridor's clearance in the product's mask, NM, to its 0.6 NM grid)
    "gibraltar": ((35.95, -6.0), (36.0, -5.0), None),  # ≥ 3 NM: open at the default 2 NM
    "lombok": ((-8.2, 115.75), (-9.0, 115.8), None),
    "singapore": ((1.25, 104.5), (1.15, 103.55), 1.4),  # among the southern islands: narrower than 2 × 2 NM
    "verde-island": ((14.25, 120.45), (13.6, 121.2), 1.7),  # Manila Bay → Verde Island Passage
}


@pytest.mark.parametrize("name", sorted(STRAITS))
def test_a_strait_routes_when_its_corridor_keeps_the_clearance_and_says_why_not_when_it_does_not(name):
    """Where a corridor keeps `land_clearance_nm` from land the default graph finds a route; where the widest one
    keeps less (the Singapore Strait, the Verde Island Passage: 1.4 and 1.7 NM in the mask), the plan says so,
    names that width and the setting, and a clearance below it routes the voyage, clear of land by it."""
    dep, arr, narrow_nm = STRAITS[name]
    hours = 1.3 * float(haversine_nm(*dep, *arr)) / 10.0
    pr = problem(dep, arr, hours, n_lines=None, n_points=21)
    # the lines across the great circle (given as the space): the global sea route would sail the strait on its
    # passage fairway, at the fairway's own clearance (tests/test_sea_routes.py)
    plan = solve(pr, CALM, solver="bfoa", seed=1, params=FAST, space=pr.search_space())
    if narrow_nm is None:
        assert plan.status == "ok", plan.reason
        assert plan.min_land_clearance_nm >= 2.0 - 1e-6
    else:
        assert plan.status == "infeasible"
        widest = float(plan.reason.split("keeps about ")[1].split(" NM")[0])
        assert abs(widest - narrow_nm) <= 0.2, plan.reason
        assert "routing.land_clearance_nm" in plan.reason
        pr = problem(dep, arr, hours, n_lines=None, n_points=21, land_clearance_nm=1.0)
        plan = solve(pr, CALM, solver="bfoa", seed=1, params=FAST, space=pr.search_space())
        assert plan.status == "ok", plan.reason
        assert plan.min_land_clearance_nm >= 1.0 - 1e-6
    lat, lon = np.array(plan.waypoints).T
    assert not globe.is_land(lat, lon).any()


def test_a_short_voyage_gets_more_nodes_along_its_lines_too():
    """Under 40 NM no closer lines are allowed (they would come within 5 NM of each other), but more nodes along
    the lines are: inside Tokyo Bay, off Yokohama to the Uraga Channel, 21 nodes a line find no way, 41 do."""
    from pipeline.routing.search_space import lay_out_lines

    dep, arr = (35.29, 139.79), (34.9, 139.8)
    assert not reachable(lay_out_lines(dep, arr))
    space = build_search_space(dep, arr)
    assert reachable(space) and space.lat.shape[1] == 41
