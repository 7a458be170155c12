"""Route exports: RTZ against the IEC 61174 schemas, GeoJSON, and PNG maps/plots."""

import json
from datetime import datetime, timedelta

import numpy as np
import pandas as pd
import pytest
from lxml import etree

from pipeline.export import plots
from pipeline.export.geojson import route_to_geojson
from pipeline.export.rtz import JITROUTE_NS, route_to_rtz, rtz_file_name, validate_rtz
from pipeline.routing.geodesy import gc_bearing_deg, gc_distance_nm

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
RTZ_NS = {"1.0": "http://www.cirm.org/RTZ/1/0", "1.1": "http://www.cirm.org/RTZ/1/1",
          "1.2": "http://www.cirm.org/RTZ/1/2"}
# North Pacific, eastbound across the dateline between waypoints 2 and 3
POINTS = [(40.0, 176.0), (40.6, 178.3), (41.0, 179.5), (41.3, -179.6), (41.8, -177.2)]
DEPART = datetime(2021, 1, 10, 6, 0, 0)


def make_legs(points=POINTS, depart=DEPART, sog_kn=(12.4, 12.9, 11.7, 13.2), rpm=(71.26, 74.8, 68.49, 77.51)):
    legs, t = [], depart
    for i, ((la0, lo0), (la1, lo1)) in enumerate(zip(points[:-1], points[1:])):
        dist = gc_distance_nm(la0, lo0, la1, lo1)
        hours = dist / sog_kn[i]
        eta = t + timedelta(hours=hours)  # not whole seconds on purpose
        legs.append(dict(leg=i, lat0=la0, lon0=lo0, lat1=la1, lon1=lo1, course_deg=gc_bearing_deg(la0, lo0, la1, lo1),
                         dist_nm=dist, rpm=rpm[i], stw_kn=sog_kn[i] - 0.3, sog_kn=sog_kn[i], hours=hours,
                         fuel_t=0.9 * hours, etd_utc=t, eta_utc=pd.Timestamp(eta), wind_kn=18.0 + i,
                         wind_dir_deg=350.0 + 5 * i, hs_m=2.5 + 0.1 * i, wave_dir_deg=300.0,
                         current_kn=np.nan if i == 1 else 0.4, beyond_forecast=i == 3))
        t = eta
    return legs


@pytest.fixture
def voyage():
    legs = make_legs()
    route = dict(voyage_id="V0007", imo=9074729, vessel_name="Pacific Trader", solver="bfoa", status="ok",
                 reason=None, depart_utc=DEPART, eta_utc=legs[-1]["eta_utc"],
                 rta_utc=pd.Timestamp("2021-01-11T12:00:00"), hours=sum(x["hours"] for x in legs),
                 fuel_t=sum(x["fuel_t"] for x in legs), baseline_fuel_t=np.float64(30.0), savings_pct=np.nan,
                 distance_nm=sum(x["dist_nm"] for x in legs), dep_name="Yokohama", arr_name="Dutch Harbor")
    return route, legs


def _parse(xml: bytes, version="1.1"):
    ns = {"r": RTZ_NS[version], "jr": JITROUTE_NS}
    return etree.fromstring(xml), ns


# --- RTZ --------------------------------------------------------------------------------------

@pytest.mark.parametrize("version", ["1.0", "1.1", "1.2"])
def test_rtz_validates_against_its_schema(voyage, version):
    xml = route_to_rtz(*voyage, version=version)
    validate_rtz(xml, version=version)
    doc, ns = _parse(xml, version)
    assert doc.get("version") == version
    info = doc.find("r:routeInfo", ns)
    assert info.get("routeName") == "V0007_Yokohama-Dutch_Harbor"
    assert rtz_file_name(voyage[0]) == info.get("routeName") + ".rtz"
    assert info.get("vesselIMO") == "9074729" and info.get("vesselName") == "Pacific Trader"


def test_rtz_waypoints_are_the_leg_endpoints(voyage):
    route, legs = voyage
    doc, ns = _parse(route_to_rtz(route, legs))
    wps = doc.findall("r:waypoints/r:waypoint", ns)
    assert len(wps) == len(legs) + 1
    got = [(float(w.find("r:position", ns).get("lat")), float(w.find("r:position", ns).get("lon"))) for w in wps]
    np.testing.assert_allclose(got, POINTS, atol=5e-7)
    assert all(len(w.find("r:position", ns).get("lon").split(".")[1]) >= 6 for w in wps)
    assert [w.get("name") for w in wps][::len(wps) - 1] == ["Yokohama", "Dutch Harbor"]
    # a leg's data sits on the waypoint it leads to; the first waypoint has none
    assert wps[0].find("r:leg", ns) is None
    assert {w.find("r:leg", ns).get("geometryType") for w in wps[1:]} == {"Orthodrome"}


def test_rtz_schedule_has_the_legs_times_speeds_and_rpm(voyage):
    route, legs = voyage
    doc, ns = _parse(route_to_rtz(route, legs))
    ids = [w.get("id") for w in doc.findall("r:waypoints/r:waypoint", ns)]
    els = doc.findall("r:schedules/r:schedule/r:calculated/r:scheduleElement", ns)
    assert [e.get("waypointId") for e in els] == ids
    assert els[0].get("eta") is None and els[0].get("etd") == "2021-01-10T06:00:00Z"
    for k, el in enumerate(els[1:], start=1):
        leg = legs[k - 1]
        eta = pd.Timestamp(el.get("eta").rstrip("Z"))
        assert el.get("eta").endswith("Z")
        assert abs((eta - leg["eta_utc"]).total_seconds()) <= 0.5
        if k < len(legs):
            assert el.get("etd") == el.get("eta")  # no stay at intermediate waypoints
        assert float(el.get("speed")) == pytest.approx(leg["sog_kn"], abs=0.005)
        assert int(el.get("rpm")) == round(leg["rpm"])
        ext = el.find("r:extensions/r:extension/jr:leg", ns)
        assert float(ext.get("rpm")) == pytest.approx(leg["rpm"], abs=0.005)
        assert ext.get("beyondForecast") == ("true" if leg["beyond_forecast"] else "false")
    assert els[2].get("currentSpeed") is None  # NaN met is left out, not written as "nan"
    assert els[3].get("windDirection") == "0.0"  # 360° folds to 0


@pytest.mark.parametrize("version", ["1.0", "1.1", "1.2"])
def test_rtz_legs_carry_their_planned_speed(voyage, version):
    route, legs = voyage
    route = dict(route, savings_total_pct=3.4567, savings_speed_profile_pct=-0.88, savings_route_pct=4.3367,
                 min_engine_hold_h=12.0, limits_fuel_t=0.1396)
    xml = route_to_rtz(route, legs, version=version)
    validate_rtz(xml, version=version)
    doc, ns = _parse(xml, version)
    wps = doc.findall("r:waypoints/r:waypoint", ns)
    for wp, leg in zip(wps[1:], legs):  # the leg leading to each waypoint after the first
        el = wp.find("r:leg", ns)
        assert float(el.get("speedMin")) == float(el.get("speedMax")) == pytest.approx(leg["sog_kn"], abs=0.005)
    ext = doc.find(".//jr:voyage", ns)
    assert ext.get("savingsTotalPct") == "3.46" and ext.get("savingsRoutePct") == "4.34"
    assert ext.get("minEngineHoldH") == "12.00" and ext.get("limitsFuelT") == "0.140"


def test_rtz_1_0_wind_is_in_metres_per_second(voyage):
    doc, ns = _parse(route_to_rtz(*voyage, version="1.0"), "1.0")
    el = doc.findall("r:schedules/r:schedule/r:calculated/r:sheduleElement", ns)[1]
    assert float(el.get("windSpeed")) == pytest.approx(18.0 / 1.943844, abs=0.05)


def test_broken_rtz_fails_validation_naming_the_problem(voyage):
    doc, ns = _parse(route_to_rtz(*voyage))
    doc.remove(doc.find("r:waypoints", ns))
    with pytest.raises(ValueError, match=r"V0007_Yokohama.*line \d+: .*waypoints"):
        validate_rtz(etree.tostring(doc))

    doc, ns = _parse(route_to_rtz(*voyage))
    doc.find("r:waypoints/r:waypoint/r:position", ns).set("lon", "180.000000")
    with pytest.raises(ValueError, match=r"attribute 'lon': \[facet 'maxExclusive'\]"):
        validate_rtz(etree.tostring(doc))

    doc, ns = _parse(route_to_rtz(*voyage))
    doc.findall("r:waypoints/r:waypoint", ns)[2].set("id", "1")
    with pytest.raises(ValueError, match="unique, repeated: 1"):
        validate_rtz(etree.tostring(doc))

    with pytest.raises(ValueError, match="not well-formed"):
        validate_rtz(b"<route version='1.1'>")


def test_rtz_schema_folder_comes_from_the_environment(voyage, tmp_path, monkeypatch):
    monkeypatch.setenv("JITROUTE_RTZ_SCHEMAS", str(tmp_path))
    with pytest.raises(FileNotFoundError, match="JITROUTE_RTZ_SCHEMAS"):
        validate_rtz(route_to_rtz(*voyage))


def test_a_point_at_the_antimeridian_is_written_as_minus_180(voyage):
    route, legs = voyage
    legs[-1]["lon1"] = 179.99999996
    xml = route_to_rtz(route, legs)
    validate_rtz(xml)
    doc, ns = _parse(xml)
    assert doc.findall("r:waypoints/r:waypoint/r:position", ns)[-1].get("lon") == "-180.000000"


def test_voyage_without_legs_is_refused_naming_it(voyage):
    route = dict(voyage[0], status="infeasible", reason="arrival on land")
    for export in (route_to_rtz, route_to_geojson):
        with pytest.raises(ValueError, match="V0007.*no legs.*arrival on land"):
            export(route, [])


# --- GeoJSON ----------------------------------------------------------------------------------

def test_geojson_is_json_safe_and_cut_at_the_antimeridian(voyage):
    route, legs = voyage
    gj = route_to_geojson(route, legs)
    back = json.loads(json.dumps(gj, allow_nan=False))
    assert back == gj
    line, *points = back["features"]
    assert line["geometry"]["type"] == "MultiLineString"  # RFC 7946 §3.1.9: cut, not drawn across the map
    west, east = line["geometry"]["coordinates"]
    assert [len(west), len(east)] == [4, len(legs) + 1 - 3 + 1]
    assert west[-1][0] == 180.0 and east[0][0] == -180.0 and west[-1][1] == east[0][1]  # the parts meet at ±180
    # the crossing latitude lies on the leg from 179.5 °E to 179.6 °W (−179.6), a fifth of the way (0.5 of 0.9°)
    (x2, y2), (x3, y3) = west[-2], east[1]
    assert (x2, x3) == (179.5, -179.6) and west[-1][1] == pytest.approx(y2 + (y3 - y2) * 0.5 / 0.9, abs=1e-6)
    coords = np.array(west[:-1] + east[1:])
    np.testing.assert_allclose(coords[:, 0], [p[1] for p in POINTS], atol=1e-9)
    np.testing.assert_allclose(coords[:, 1], [p[0] for p in POINTS])
    assert all(-180.0 <= x <= 180.0 for part in (west, east) for x, _y in part)
    lats = [p[0] for p in POINTS]
    assert back["bbox"] == line["bbox"] == [min(p[1] for p in POINTS if p[1] > 0), min(lats),
                                            max(p[1] for p in POINTS if p[1] < 0), max(lats)]
    assert back["bbox"][0] > back["bbox"][2]  # §5.2: a box across the antimeridian has west > east
    props = line["properties"]
    assert props["savings_pct"] is None and props["reason"] is None
    assert props["depart_utc"] == "2021-01-10T06:00:00Z" and props["baseline_fuel_t"] == 30.0

    assert [p["properties"]["index"] for p in points] == list(range(len(legs) + 1))
    assert [p["geometry"]["coordinates"][0] for p in points] == [p[1] for p in POINTS]
    p0, p1, _p2, p3, last = (p["properties"] for p in points)
    assert p0["eta_utc"] is None and p0["etd_utc"] == "2021-01-10T06:00:00Z" and p0["rpm"] == 71.26
    assert p1["eta_utc"] == pd.Timestamp(legs[0]["eta_utc"]).round("s").strftime("%Y-%m-%dT%H:%M:%SZ")
    assert p1["current_kn"] is None and p1["sog_kn"] == 12.9  # leg 1 starts at waypoint 1
    assert p3["lon_deg"] == -179.6 and p3["beyond_forecast"] is True
    assert last["rpm"] is None and last["name"] == "Dutch Harbor"


def test_geojson_of_a_route_that_stays_on_one_side_is_one_line_with_a_plain_bbox():
    from pipeline.export.geojson import bbox_of, split_at_antimeridian

    lat, lon = np.array([35.0, 30.0, 20.0]), np.array([139.8, 141.0, 144.6])
    assert split_at_antimeridian(lat, lon) == [[[139.8, 35.0], [141.0, 30.0], [144.6, 20.0]]]
    assert bbox_of(lat, lon) == [139.8, 20.0, 144.6, 35.0]
    west_bound = split_at_antimeridian(np.array([50.0, 51.0]), np.array([-179.0, -181.0]))  # 179 °W → 179 °E
    assert west_bound == [[[-179.0, 50.0], [-180.0, 50.5]], [[180.0, 50.5], [179.0, 51.0]]]


# --- PNG --------------------------------------------------------------------------------------

def _field():
    lat = np.arange(50.0, 30.0 - 0.1, -0.5)  # north to south, as JMA writes it
    lon = np.arange(0.0, 360.0, 0.5)  # 0..360 east, as the cube holds it
    la, lo = np.meshgrid(lat, lon, indexing="ij")
    hs = 1.0 + 3.0 * np.exp(-((la - 42.0) ** 2 + (((lo - 180.0 + 180) % 360 - 180) / 2) ** 2) / 20.0)
    return dict(lat=lat, lon=lon, hs_m=hs, u_ms=np.full_like(hs, 8.0), v_ms=np.full_like(hs, -3.0))


def _is_png(path):
    data = path.read_bytes()
    return data[:8] == PNG_MAGIC and len(data) > 10_000


def test_route_map_draws_the_dateline_route_in_one_piece(voyage, tmp_path):
    route, legs = voyage
    baseline = make_legs(points=[POINTS[0], POINTS[-1]], sog_kn=(12.5,), rpm=(72.0,))
    fig = plots.route_map_figure(route, legs, baseline, field=_field())
    ax = fig.axes[0]
    x0, x1 = ax.get_xlim()
    assert x0 < 180.0 < x1 and x1 - x0 < 20.0  # not stretched across the world
    (plan,) = [ln for ln in ax.get_lines() if ln.get_label() == "plan"]
    assert np.abs(np.diff(plan.get_xdata())).max() < 1.0
    assert "V0007" in ax.get_title() and "saving n/a" in ax.get_title()
    assert [a.get_ylabel() for a in fig.axes[1:]] == ["significant wave height Hs [m]"]
    assert {type(c).__name__ for c in ax.collections} == {"QuadContourSet", "Barbs"}  # Hs, wind; no land here

    out = plots.route_map_png(tmp_path / "maps" / "V0007.png", route, legs, baseline, field=_field())
    assert out == tmp_path / "maps" / "V0007.png" and _is_png(out)


def _drawn_boxes(fig):
    """Figure box and the drawn boxes (tick labels and title included) of every axes and legend."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    renderer = FigureCanvasAgg(fig).get_renderer()
    fig.draw(renderer)
    return fig.bbox, [a.get_tightbbox(renderer) for a in fig.axes], [lg.get_window_extent(renderer) for lg in fig.legends]


@pytest.mark.parametrize("points", [None, [(20.0, 140.0), (52.0, 141.0)], [(35.0, 140.0), (36.0, 240.0)]])
def test_route_map_layout_keeps_map_colourbar_title_and_legend_apart_and_inside(voyage, points):
    # the map's layout is computed, not left to a layout engine: for the dateline voyage, a north-south one and a
    # very wide one, everything drawn stays on the figure and nothing covers anything else
    route, legs = voyage
    if points is not None:
        legs = make_legs(points=points, sog_kn=(12.0,), rpm=(70.0,))
    fig = plots.route_map_figure(route, legs, None, field=_field())
    page, (map_box, bar_box), legends = _drawn_boxes(fig)
    for box in (map_box, bar_box, *legends):
        assert page.x0 - 1 <= box.x0 and box.x1 <= page.x1 + 1 and page.y0 - 1 <= box.y0 and box.y1 <= page.y1 + 1
    assert not map_box.overlaps(bar_box) and not any(map_box.overlaps(lg) for lg in legends)
    assert fig.axes[0].get_aspect() == pytest.approx(1.0 / np.cos(np.radians(np.mean(fig.axes[0].get_ylim()))))


def test_route_map_of_a_voyage_without_legs_still_draws(voyage, tmp_path):
    route = dict(voyage[0], status="infeasible", reason="no way through the ice limit")
    out = plots.route_map_png(tmp_path / "none.png", route, [], field=_field())
    assert _is_png(out)


def test_convergence_plot_shows_history_and_dp_optimum(tmp_path):
    hist = [105.0, 101.0, 102.5, 99.0, 99.0, 98.2]
    fig = plots.convergence_figure({"bfoa": np.array(hist), "dp_cost": 97.5})
    ax = fig.axes[0]
    labels = [ln.get_label() for ln in ax.get_lines()]
    assert labels == ["best in cycle", "best so far", "DP optimum 97.5"]
    np.testing.assert_allclose(ax.get_lines()[1].get_ydata(), [105.0, 101.0, 101.0, 99.0, 99.0, 98.2])
    assert "+0.72 % vs DP" in ax.get_title()
    assert _is_png(plots.convergence_png(tmp_path / "conv.png", hist, title="V0007 bfoa"))
    assert plots.convergence_png(tmp_path / "empty.png", []).read_bytes()[:8] == PNG_MAGIC


def test_fleet_map_colours_voyages_by_status(voyage, tmp_path):
    route, legs = voyage
    west = make_legs(points=[(35.0, 141.0), (38.0, 150.0), (42.0, 160.0)], sog_kn=(12.0, 12.0), rpm=(70.0, 70.0))
    fleet = [(route, legs), (dict(route, voyage_id="V0008", status="late"), west),
             (dict(route, voyage_id="V0009", status="infeasible"), [])]
    fig = plots.fleet_map_figure(fleet)
    ax = fig.axes[0]
    colours = {ln.get_color() for ln in ax.get_lines() if len(ln.get_xdata()) > 2}
    assert colours == {plots.STATUS_COLOURS["ok"], plots.STATUS_COLOURS["late"]}
    assert {t.get_text().split(" ETA ")[0] for t in ax.texts} >= {"V0007", "V0008", "no route: V0009 (infeasible)"}
    x0, x1 = ax.get_xlim()
    assert x0 < 141.0 and x1 > 183.0  # both voyages in one frame, the dateline one not wrapped to −180
    assert _is_png(plots.fleet_map_png(tmp_path / "fleet.png", fleet, title="run 2021-01-10"))


# --- what an operator reads on the pictures ----------------------------------------------------------------------

def test_route_map_names_the_weather_s_valid_time_and_the_units_of_colour_and_barbs(voyage):
    route, legs = voyage
    field = dict(_field(), valid_utc="2021-01-10T18:00:00Z", valid_note="the forecast step nearest mid-voyage")
    title = plots.route_map_figure(route, legs, None, field=field).axes[0].get_title()
    assert "weather valid 2021-01-10T18:00:00Z (the forecast step nearest mid-voyage)" in title
    assert "Hs [m]" in title and "wind barbs [kn]" in title and "comes FROM" in title
    assert "ETD 2021-01-10T06:00:00Z" in title and "LATE" not in title  # on time


def test_a_late_plan_s_map_says_by_how_many_hours(voyage):
    route, legs = voyage
    eta = legs[-1]["eta_utc"]
    late = dict(route, status="late", rta_utc=eta - pd.Timedelta(hours=7, minutes=30))
    fig = plots.route_map_figure(late, legs)
    assert "LATE by 7.5 h" in fig.axes[0].get_title()
    assert any("7.5 h after the RTA" in t.get_text() for t in fig.axes[0].texts)
    assert plots.late_hours(route) is None  # arrives before its RTA


def test_time_marks_sit_on_whole_utc_hours_where_the_plan_puts_the_ship(voyage):
    route, legs = voyage
    marks = plots.time_marks(legs)
    t0, t1 = legs[0]["etd_utc"], legs[-1]["eta_utc"].to_pydatetime()
    step = plots.time_mark_step_h((t1 - t0).total_seconds() / 3600.0)
    assert 3 <= len(marks) <= 10 and all(t.minute == 0 and t.hour % step == 0 and t0 < t < t1 for t, _la, _lo in marks)
    # the ship at a mark is on the leg sailed then, in proportion to the leg's time
    t, lat, lon = marks[0]
    leg = next(x for x in legs if x["etd_utc"] <= t <= x["eta_utc"])
    frac = (t - leg["etd_utc"]) / (leg["eta_utc"].to_pydatetime() - leg["etd_utc"])
    from pipeline.routing.sphere import gc_points
    want = gc_points(leg["lat0"], leg["lon0"], leg["lat1"], leg["lon1"], frac)
    assert (lat, lon) == pytest.approx((float(want[0]), float(want[1])))
    ax = plots.route_map_figure(route, legs).axes[0]
    assert sorted(t.get_text() for t in ax.texts if t.get_text().endswith("Z")) == sorted(plots.dtg(m[0]) for m in marks)


def test_position_at_is_in_port_before_departure_on_the_track_at_sea_and_at_the_arrival_after():
    legs = make_legs(points=[(30.0, 140.0), (30.0, 142.0), (30.0, 144.0)], sog_kn=(10.0, 10.0), rpm=(70.0, 70.0))
    mid = legs[0]["etd_utc"] + (legs[0]["eta_utc"].to_pydatetime() - legs[0]["etd_utc"]) / 2
    assert plots.position_at(legs, DEPART - timedelta(hours=1)) == (30.0, 140.0, "in port")
    assert plots.position_at(legs, DEPART, starts_at_sea=True)[2] == "at sea"
    lat, lon, where = plots.position_at(legs, mid)
    assert where == "at sea" and lon == pytest.approx(141.0, abs=1e-6) and lat > 30.0  # a great circle bows poleward
    assert plots.position_at(legs, legs[-1]["eta_utc"] + pd.Timedelta(hours=1)) == (30.0, 144.0, "arrived")


def test_route_map_draws_no_wind_barb_on_land(voyage):
    from pipeline.routing.land_mask import is_sea

    route, _ = voyage
    legs = make_legs(points=[(33.0, 136.0), (34.0, 141.0)], sog_kn=(12.0,), rpm=(70.0,))  # along Japan's south coast
    lat, lon = np.arange(45.0, 25.0, -0.5), np.arange(125.0, 150.0, 0.5)
    u = np.full((lat.size, lon.size), 10.0)
    field = dict(lat=lat, lon=lon, hs_m=np.full_like(u, 2.0), u_ms=u, v_ms=u)
    (barbs,) = [c for c in plots.route_map_figure(route, legs, None, field).axes[0].collections
                if type(c).__name__ == "Barbs"]
    xy = barbs.get_offsets()
    assert len(xy) > 20 and is_sea(xy[:, 1], xy[:, 0]).all()
    assert not is_sea(np.array([35.0, 36.0]), np.array([138.0, 139.0])).any()  # Honshu is on this map, without barbs


def test_fleet_map_marks_each_ship_now_shortens_plan_ids_and_keeps_labels_apart(voyage):
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    route, legs = voyage
    plan_vid = "plan-20201201T0000-446a6a-9140956-1"
    west = make_legs(points=[(35.0, 141.0), (38.0, 150.0), (42.0, 160.0)], sog_kn=(12.0, 12.0), rpm=(70.0, 70.0))
    near = make_legs(points=[(35.2, 141.1), (38.1, 150.2), (42.1, 160.1)], sog_kn=(12.0, 12.0), rpm=(70.0, 70.0))
    now = DEPART + timedelta(hours=6)
    fleet = [(dict(route, start_kind="noon report"), legs), (dict(route, voyage_id="V0008", status="late"), west),
             (dict(route, voyage_id=plan_vid, start_kind="port"), near),
             (dict(route, voyage_id="V0010"), make_legs(depart=DEPART + timedelta(days=1)))]
    fig = plots.fleet_map_figure(fleet, "run r1", now_utc=now)
    ax = fig.axes[0]
    texts = [t for t in ax.texts if t.get_text().split(" ETA ")[0] in ("V0007", "V0008", "9140956/1", "V0010")]
    assert sorted(t.get_text() for t in texts) == sorted(
        f"{name} ETA {plots.dtg(lg[-1]['eta_utc'].to_pydatetime())}"
        for name, (_r, lg) in zip(("V0007", "V0008", "9140956/1", "V0010"), fleet))
    assert "fleet plan plan-20201201T0000-446a6a" in ax.get_title() and "2021-01-10T12:00:00Z" in ax.get_title()
    renderer = FigureCanvasAgg(fig).get_renderer()
    boxes = [t.get_window_extent(renderer) for t in texts]
    assert not any(a.overlaps(b) for i, a in enumerate(boxes) for b in boxes[i + 1:])
    ships = {ln.get_marker(): ln for ln in ax.get_lines() if ln.get_linestyle() == "None" and ln.get_marker() in "^s"}
    at_sea = ships["^"]
    want = [plots.position_at(lg, now)[:2] for _r, lg in fleet[:3]]
    got = sorted(zip(np.asarray(at_sea.get_ydata()), np.asarray(at_sea.get_xdata()) % 360.0))
    np.testing.assert_allclose(got, sorted((la, lo % 360.0) for la, lo in want))
    (in_port,) = [ln for ln in ax.get_lines() if ln.get_marker() == "s" and ln.get_linestyle() == "None"]
    assert (in_port.get_xdata()[0] % 360.0, in_port.get_ydata()[0]) == pytest.approx((176.0, 40.0))  # V0010 sails tomorrow
    assert plots.short_voyage_label("a-very-long-voyage-identifier-2020") == "a-very…er-2020"


def test_the_convergence_plot_is_left_out_of_a_run_unless_debug_plots_is_set(monkeypatch):
    from flows.settings import SettingsError, load_settings
    from pipeline.export.bundle import OPERATOR_KINDS, kinds_of_run

    monkeypatch.delenv("JITROUTE_DEBUG_PLOTS", raising=False)
    assert load_settings().debug_plots is False and kinds_of_run(False) == OPERATOR_KINDS == ("rtz", "geojson", "png")
    monkeypatch.setenv("JITROUTE_DEBUG_PLOTS", "1")
    assert load_settings().debug_plots is True and "convergence" in kinds_of_run(True)
    monkeypatch.setenv("JITROUTE_DEBUG_PLOTS", "maybe")
    with pytest.raises(SettingsError, match="JITROUTE_DEBUG_PLOTS='maybe' is not 1 or 0"):
        load_settings()


def test_a_large_fleet_s_map_labels_only_the_voyages_not_ok():
    n = plots.MAX_FLEET_LABELS + 1
    fleet = [(dict(voyage_id=f"V{k:04d}", status="late" if k in (3, 40) else "ok"),
              make_legs(points=[(20.0 + 0.2 * k, 130.0), (20.0 + 0.2 * k, 131.0)], sog_kn=(12.0,), rpm=(70.0,)))
             for k in range(n)]
    ax = plots.fleet_map_figure(fleet, "run r2").axes[0]
    assert sorted(t.get_text().split(" ETA ")[0] for t in ax.texts) == ["V0003", "V0040"]
    assert f"labels on 2 voyages not ok only, of {n}" in ax.get_title()
