"""The node-line corridor laid along a sea route (corridor.py), and routing on it end to end.

The sea routes are made by hand over the real land mask: round Florida (whose great circle crosses the
peninsula, so the great-circle layout has no route), through the Florida Straits as a strait, and across the
antimeridian. The checks do not take the product's word: distances along the route, land along every leg (the
`global_land_mask` package, every 0.1 NM) and the constant-speed voyage (bisection) are worked out here.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.routing import geodesy as geo
from pipeline.routing.baseline import shortest_route
from pipeline.routing.base_route import base_route_for, with_base_route
from pipeline.routing.corridor import CORRIDOR_SPACING_NM
from pipeline.routing.job import RoutingOptions
from pipeline.routing.sea_route import PassageTransit, SeaRoute
from pipeline.routing.search_space import VoyageGeometryError, build_search_space, reachable
from pipeline.routing.solve import solve
from routing_cases import FAST, constant_speed, field, problem, wavy
from tests import land_reference as globe

# Tampa Bay's offing round the Florida Keys to off Jacksonville: 666 NM where the great circle is 201 NM over land
FLORIDA = [(27.6, -83.2), (25.5, -82.6), (24.3, -82.0), (24.3, -81.0), (25.0, -80.05), (26.5, -79.9), (28.5, -80.2),
           (30.4, -81.1)]
# east of Japan to the Gulf of Alaska's south, across 180°
PACIFIC = [(35.0, 160.0), (41.0, 175.0), (42.0, -175.0), (38.0, -160.0)]


def sea_route(points, passages=()) -> SeaRoute:
    lat = np.array([p[0] for p in points], float)
    lon = np.array([p[1] for p in points], float)
    return SeaRoute(lat, lon, route_length_nm(lat, lon), tuple(passages))


def haversine_nm(lat1, lon1, lat2, lon2):
    p1, p2 = math.radians(lat1), math.radians(lat2)
    a = math.sin((p2 - p1) / 2) ** 2 + math.cos(p1) * math.cos(p2) * math.sin(math.radians(lon2 - lon1) / 2) ** 2
    return 2 * 3440.065 * math.asin(math.sqrt(a))


def route_length_nm(lat, lon):
    return sum(haversine_nm(lat[k], lon[k], lat[k + 1], lon[k + 1]) for k in range(len(lat) - 1))


def distance_to_polyline_nm(lat, lon, points):
    """Least distance (NM) from a point to the polyline, by sampling each segment every 0.05 NM."""
    best = math.inf
    for (a_lat, a_lon), (b_lat, b_lon) in zip(points[:-1], points[1:]):
        n = max(2, int(haversine_nm(a_lat, a_lon, b_lat, b_lon) / 0.05))
        for f in np.linspace(0.0, 1.0, n):
            p_lat, p_lon = geo.gc_interpolate(a_lat, a_lon, b_lat, b_lon, f)
            best = min(best, haversine_nm(lat, lon, p_lat, p_lon))
    return best


def land_on_legs(waypoints, step_nm=0.1):
    """Points on land (global_land_mask) along the great-circle legs through `waypoints`, every `step_nm`."""
    bad = []
    for (a_lat, a_lon), (b_lat, b_lon) in zip(waypoints[:-1], waypoints[1:]):
        n = max(2, int(math.ceil(haversine_nm(a_lat, a_lon, b_lat, b_lon) / step_nm)) + 1)
        for f in np.linspace(0.0, 1.0, n):
            p_lat, p_lon = geo.gc_interpolate(a_lat, a_lon, b_lat, b_lon, f)
            if globe.is_land(p_lat, geo.wrap180(p_lon)):
                bad.append((p_lat, p_lon))
    return bad


@pytest.mark.slow
def test_the_great_circle_layout_has_no_route_round_florida_and_the_corridor_has():
    dep, arr = FLORIDA[0], FLORIDA[-1]
    assert not reachable(build_search_space(dep, arr))  # the issue: the band across the great circle is cut by land
    route = sea_route(FLORIDA)
    space = build_search_space(dep, arr, base_route=route)
    assert reachable(space) and space.sea_route is route and space.base == "gc"
    assert space.base_distance_nm == pytest.approx(route_length_nm(route.lat, route.lon), rel=1e-6)
    L2, P = space.lat.shape
    c = space.centre
    # a line at every waypoint (the route turns at each), at most about 40 NM apart between them
    for wp in FLORIDA[1:-1]:
        assert min(haversine_nm(*wp, space.lat[i, c], space.lon[i, c]) for i in range(L2)) < 1e-6
    gaps = [haversine_nm(space.lat[i, c], space.lon[i, c], space.lat[i + 1, c], space.lon[i + 1, c]) for i in range(L2 - 1)]
    assert max(gaps) <= 1.5 * CORRIDOR_SPACING_NM and space.n_lines >= space.base_distance_nm / (1.5 * CORRIDOR_SPACING_NM)
    # each centre node on the route, nodes spread across it either side
    for i in range(1, L2 - 1):
        assert distance_to_polyline_nm(space.lat[i, c], space.lon[i, c], FLORIDA) < 0.1
        d_line = space.line_d_point_nm[i]
        for j in (c - 1, c + 1):  # the neighbours of the centre node lie across the route, d_line away
            assert haversine_nm(space.lat[i, c], space.lon[i, c], space.lat[i, j], space.lon[i, j]) == pytest.approx(d_line, rel=1e-6)
            off = distance_to_polyline_nm(space.lat[i, j], space.lon[i, j], FLORIDA)  # less at a bend's bisector
            assert 0.5 * d_line <= off <= d_line + 0.05
    # no usable node is on land or within the 2 NM clearance outside the ports' approaches
    from pipeline.routing.land import distance_to_land_nm
    ok = space.node_ok.copy()
    ok[0] = ok[-1] = False
    d = distance_to_land_nm(space.lat[ok], space.lon[ok])
    near_port = np.array([min(haversine_nm(a, b, *FLORIDA[0]), haversine_nm(a, b, *FLORIDA[-1])) <= 10.0
                          for a, b in zip(space.lat[ok], space.lon[ok])])
    assert np.all(d[~near_port] >= 2.0) and not any(globe.is_land(a, b) for a, b in zip(space.lat[ok], space.lon[ok]))
    # a line stops where it meets land: on each side its usable nodes run without a gap from the centre, and
    # nothing between the centre and the farthest of them is land (so no line reaches over Cuba or the Keys)
    stopped = 0
    for i in range(1, L2 - 1):
        for side in (range(c + 1, P), range(c - 1, -1, -1)):
            ok_side = [bool(space.node_ok[i, j]) for j in side]
            n_ok = ok_side.index(False) if False in ok_side else len(ok_side)
            assert not any(ok_side[n_ok:]), (i, ok_side)
            stopped += n_ok < len(ok_side)
            if n_ok:
                far = side[n_ok - 1]
                assert land_on_legs([(space.lat[i, c], space.lon[i, c]), (space.lat[i, far], space.lon[i, far])]) == []
    assert stopped >= 10  # land (the Keys, Cuba, the peninsula) cuts many lines short


def test_a_sea_route_must_run_from_port_to_port():
    route = sea_route(FLORIDA)
    with pytest.raises(VoyageGeometryError, match="NM from the first waypoint"):
        build_search_space((27.0, -83.5), FLORIDA[-1], base_route=route)


@pytest.mark.parametrize("solver", ["bfoa", "dp"])
@pytest.mark.slow
def test_solve_routes_round_florida_clear_of_land_on_time_and_never_worse_than_constant_speed(solver):
    route = sea_route(FLORIDA)
    weather = field(wavy(5), lat=(20.0, 35.0), lon=(270.0, 290.0))
    pr = problem(FLORIDA[0], FLORIDA[-1], 666.0 / 12.0, n_lines=None, n_points=11, base_route=route)
    space = pr.search_space()
    rpm_b, hours_b, fuel_b = constant_speed(pr, space, weather)
    assert hours_b <= pr.t_req_h and rpm_b > min(pr.rpm_options)  # on time at some constant speed, not the slowest
    opts = FAST if solver == "bfoa" else None
    plan = solve(pr, weather, solver=solver, seed=2, options=opts, savings=True)
    assert plan.status == "ok" and plan.legs, plan.reason
    assert plan.hours <= pr.t_req_h + 1e-6
    assert plan.fuel_t <= fuel_b * (1 + 1e-6)
    assert plan.baseline.fuel_t == pytest.approx(fuel_b, rel=1e-6)
    assert plan.baseline.legs[0]["rpm"] == pytest.approx(rpm_b, rel=1e-5)
    # it sails round the Keys, not across the peninsula: as long as the sea route, nowhere near the great circle
    assert plan.distance_nm == pytest.approx(route.dist_nm, rel=0.1)
    assert min(lat for lat, _ in plan.waypoints) < 24.6
    assert land_on_legs(plan.waypoints) == []
    assert plan.min_land_clearance_nm >= 2.0 - 1e-9


def test_a_strait_is_a_gate_of_one_node_on_its_fairway():
    # the Florida Straits between the Keys and Cuba as a strait passage: waypoints 2..4 are its fairway
    strait = PassageTransit("Florida Straits", "strait", 2, 4)
    route = sea_route(FLORIDA, [strait])
    space = build_search_space(FLORIDA[0], FLORIDA[-1], base_route=route)
    assert reachable(space)
    s = np.concatenate(([0.0], np.cumsum([haversine_nm(*a, *b) for a, b in zip(FLORIDA[:-1], FLORIDA[1:])])))
    gates = np.nonzero(space.gate)[0]
    assert len(gates) == 3  # one line at each fairway waypoint ...
    for i, k in zip(gates, (2, 3, 4)):
        assert space.node_ok[i].sum() == 1 and space.node_ok[i, space.centre]
        assert haversine_nm(space.lat[i, space.centre], space.lon[i, space.centre], *FLORIDA[k]) < 1e-6
    # ... and no other line inside the fairway: every line between the gates is a gate
    along = np.array([distance_along(space.lat[i, space.centre], space.lon[i, space.centre], FLORIDA, s)
                      for i in range(space.lat.shape[0])])
    inside = (along > s[2] + 1e-6) & (along < s[4] - 1e-6)
    assert np.all(space.gate[inside])
    # a route through the space passes the gates' nodes
    nodes = shortest_route(space)
    assert all(nodes[i] == space.centre for i in gates)


def distance_along(lat, lon, points, s):
    """Distance along the polyline of its point nearest (lat, lon)."""
    best, at = math.inf, 0.0
    for k, ((a_lat, a_lon), (b_lat, b_lon)) in enumerate(zip(points[:-1], points[1:])):
        for f in np.linspace(0.0, 1.0, 400):
            p_lat, p_lon = geo.gc_interpolate(a_lat, a_lon, b_lat, b_lon, f)
            d = haversine_nm(lat, lon, p_lat, p_lon)
            if d < best:
                best, at = d, s[k] + f * (s[k + 1] - s[k])
    return at


@pytest.mark.slow
def test_a_corridor_across_the_antimeridian():
    route = sea_route(PACIFIC)
    weather = field(wavy(3), lat=(25.0, 55.0), lon=(150.0, 215.0))
    pr = problem(PACIFIC[0], PACIFIC[-1], route.dist_nm / 12.0, n_lines=None, n_points=11, base_route=route)
    space = pr.search_space()
    assert np.all((space.lon >= -180.0) & (space.lon <= 180.0))
    assert (space.lon[space.node_ok] > 170).any() and (space.lon[space.node_ok] < -170).any()
    # neighbouring centre nodes are one line spacing apart, never a trip round the world
    c = space.centre
    gaps = [haversine_nm(space.lat[i, c], space.lon[i, c], space.lat[i + 1, c], space.lon[i + 1, c])
            for i in range(space.lat.shape[0] - 1)]
    assert max(gaps) < 1.5 * CORRIDOR_SPACING_NM
    plan = solve(pr, weather, solver="bfoa", seed=1, options=FAST)
    assert plan.status == "ok", plan.reason
    assert plan.distance_nm == pytest.approx(route.dist_nm, rel=0.05)
    assert plan.fuel_t <= plan.baseline.fuel_t * (1 + 1e-6)
    from pipeline.export.geojson import route_to_geojson
    gj = route_to_geojson(plan.route_row(), plan.legs)
    assert gj["features"][0]["geometry"]["type"] == "MultiLineString"  # cut at ±180, not drawn across the map


def test_the_base_route_is_the_sea_route_where_the_great_circle_crosses_land():
    """Round Florida the great circle crosses the peninsula: bfoa and dp get the global sea route (clear of land,
    round the Keys); the rhumb line never does; an open-ocean voyage keeps the great circle's layout."""
    pr = problem(FLORIDA[0], FLORIDA[-1], 60.0)
    for solver in ("bfoa", "dp"):
        route = base_route_for(pr.dep, pr.arr, RoutingOptions(solver=solver))
        assert route is not None and len(route.lat) > 2 and route.lat.min() < 25.0  # south of the peninsula's tip
        laid = with_base_route(pr, RoutingOptions(solver=solver))
        assert laid.base_route is not None and laid.base_route.dist_nm == pytest.approx(route.dist_nm)
    assert base_route_for(pr.dep, pr.arr, RoutingOptions(solver="rhumb")) is None
    assert with_base_route(pr, RoutingOptions(solver="rhumb")) is pr
    ocean = problem((30.0, -160.0), (33.0, -145.0), 72.0)
    assert base_route_for(ocean.dep, ocean.arr, RoutingOptions(solver="bfoa")) is None


def test_the_rhumb_line_is_not_laid_along_a_sea_route():
    from dataclasses import replace

    from pipeline.routing.problem import RoutingInputError
    pr = problem(FLORIDA[0], FLORIDA[-1], 60.0, base_route=sea_route(FLORIDA))
    with pytest.raises(RoutingInputError, match="sea route"):
        replace(pr, base="rhumb").search_space()


# from the German Bight up the Elbe, through the Kiel Canal (its locks at Brunsbüttel and Holtenau), into Kiel Bay
KIEL = [(54.0, 8.3), (53.95, 8.6), (53.89, 9.14), (54.1, 9.5), (54.3, 9.9), (54.37, 10.14), (54.45, 10.25), (54.6, 10.5)]


def test_a_canal_fairway_over_the_land_mask_is_sailed_as_given():
    canal = PassageTransit("Kiel Canal", "canal", 2, 6, transit_h=8.0, wait_h=1.0)
    route = sea_route(KIEL, [canal])
    dep, arr = KIEL[0], KIEL[-1]
    assert not reachable(build_search_space(dep, arr))  # Jutland lies across the great circle
    space = build_search_space(dep, arr, base_route=route)
    assert reachable(space)
    c = space.centre
    gates = np.nonzero(space.gate)[0]
    assert [tuple(np.round((space.lat[i, c], space.lon[i, c]), 6)) for i in gates] == KIEL[2:7]
    assert all(space.node_ok[i].sum() == 1 for i in gates)
    # the fairway's legs cross what the land mask calls land, and are kept: the mask cannot see a canal
    inland = [i for i in gates[:-1] if land_on_legs([(space.lat[i, c], space.lon[i, c]),
                                                     (space.lat[i + 1, c], space.lon[i + 1, c])], step_nm=0.5)]
    assert inland and all(space.edge_ok[i, c, c] for i in inland)
    weather = field(wavy(2), lat=(50.0, 58.0), lon=(5.0, 15.0))
    pr = problem(dep, arr, 14.0, n_lines=None, n_points=11, base_route=route)  # the canal alone takes 9 h
    plan = solve(pr, weather, solver="bfoa", seed=1, options=FAST)
    assert plan.status == "ok", plan.reason
    # the canal's legs take its transit and waiting hours, whatever the plan's speed (canal_time.py)
    in_canal = [g for g in plan.legs if any(haversine_nm(g["lat0"], g["lon0"], *wp) < 1e-6 for wp in KIEL[2:6])]
    assert len(in_canal) == 4 and sum(g["hours"] for g in in_canal) == pytest.approx(8.0 + 1.0)
    assert "through Kiel Canal (8 h transit + 1 h waiting" in plan.reason
    # the plan sails the fairway, waypoint by waypoint; outside it, it stays at sea
    assert all(min(haversine_nm(*wp, *p) for p in plan.waypoints) < 1e-6 for wp in KIEL[2:7])
    outside = [p for p in plan.waypoints if not any(haversine_nm(*p, *wp) < 1e-6 for wp in KIEL[3:6])]
    assert not any(globe.is_land(*p) for p in outside)
