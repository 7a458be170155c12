"""The console's data (pipeline/export/console_data.py) on hand-made cases, and its server's guards (token, binding).
The pages in a browser: tests/test_console_browser.py."""

from __future__ import annotations

import struct
import zlib
from datetime import datetime

import numpy as np
import pandas as pd
import pytest

from pipeline.export import console_data as cd

# starlette asks for httpx2 in its test client; httpx (installed) still serves it
pytestmark = pytest.mark.filterwarnings("ignore:Using `httpx` with `starlette.testclient`")


def _legs(points, start="2020-12-01T00:00", hours=(10.0,)):
    """Legs between consecutive (lat, lon) points, each `hours` long (cycled), back to back."""
    t = pd.Timestamp(start)
    rows = []
    for i, ((a, b), (c, d)) in enumerate(zip(points[:-1], points[1:])):
        h = hours[i % len(hours)]
        rows.append({"voyage_id": "V1", "leg": i, "lat0": a, "lon0": b, "lat1": c, "lon1": d, "etd_utc": t,
                     "eta_utc": t + pd.Timedelta(hours=h)})
        t += pd.Timedelta(hours=h)
    return pd.DataFrame(rows)


def test_the_position_on_a_plan_is_interpolated_in_time_along_the_leg_sailed():
    lat, lon, t = cd._waypoints(_legs([(0, 0), (0, 10), (10, 10)], hours=(10.0, 20.0)))
    assert cd.position_on_plan(lat, lon, t, datetime(2020, 12, 1, 4)) == pytest.approx((0.0, 4.0, 1))
    assert cd.position_on_plan(lat, lon, t, datetime(2020, 12, 1, 20)) == pytest.approx((5.0, 10.0, 2))
    assert cd.position_on_plan(lat, lon, t, datetime(2020, 11, 30)) == (0.0, 0.0, 0)  # not sailed: at the start
    assert cd.position_on_plan(lat, lon, t, datetime(2020, 12, 3)) == (10.0, 10.0, 3)  # arrived


def test_a_fleet_across_the_date_line_is_one_piece_centred_on_it():
    assert abs(cd.centre_lon_deg([170.0, -170.0])) == pytest.approx(180.0)
    assert cd.centre_lon_deg([10.0, 30.0]) == pytest.approx(20.0)
    routes = pd.DataFrame([{"voyage_id": "V1", "imo": 1, "vessel_name": "A", "status": "ok",
                            "depart_utc": pd.Timestamp("2020-12-01"), "voyage_depart_utc": pd.Timestamp("2020-12-01"),
                            "eta_utc": pd.Timestamp("2020-12-02T06:00"), "rta_utc": pd.Timestamp("2020-12-02T06:00"),
                            "dep_lat": 0.0, "dep_lon": 175.0}])
    legs = _legs([(0, 175.0), (0, -175.0), (5, -170.0)], hours=(15.0, 15.0))
    view = cd.fleet_view(routes, legs, pd.DataFrame(), datetime(2020, 12, 1, 6), "as asked", None)
    v = view["voyages"][0]
    # 6 h into a 15 h leg of 10° eastwards across 180°: 179°E, drawn continuous (no jump of 350°)
    assert v["position"]["lon"] == pytest.approx(179.0) and v["position"]["phase"] == "at sea"
    lons = [p[1] for p in v["ahead"]]
    assert lons == pytest.approx([179.0, 185.0, 190.0])
    assert v["behind"] == [[0.0, 175.0], [0.0, 179.0]]
    box = view["extent"]
    assert box["west"] < 175.0 and box["east"] > 190.0 and box["east"] - box["west"] < 30


def test_one_ship_marker_per_vessel_at_its_current_voyage():
    def voyage(vid, imo, phase, etd):
        return {"voyage_id": vid, "imo": imo, "etd_utc": etd, "position": {"phase": phase}}

    vs = [voyage("A1", 1, "arrived", "2020-11-20T00:00:00Z"), voyage("A2", 1, "at sea", "2020-11-29T00:00:00Z"),
          voyage("A3", 1, "not sailed", "2020-12-05T00:00:00Z"),
          voyage("B1", 2, "not sailed", "2020-12-09T00:00:00Z"), voyage("B2", 2, "not sailed", "2020-12-03T00:00:00Z"),
          voyage("C1", 3, "arrived", "2020-11-01T00:00:00Z"), voyage("C2", 3, "arrived", "2020-11-10T00:00:00Z")]
    cd.mark_current_voyages(vs)
    assert [v["voyage_id"] for v in vs if v["current"]] == ["A2", "B2", "C2"]


def test_attention_says_how_late_and_why_a_voyage_has_no_plan():
    late = {"status": "late", "eta_utc": datetime(2020, 12, 3, 11, 36), "rta_utc": datetime(2020, 12, 3, 0, 48)}
    assert cd.attention_items(late, None) == ["late: ETA 10.8 h after the RTA"]
    failed = {"status": "failed", "reason": float("nan")}
    assert cd.attention_items(failed, None) == ["no plan (failed): no reason recorded"]
    ok = {"status": "ok", "eta_utc": datetime(2020, 12, 3), "rta_utc": datetime(2020, 12, 3), "stale": pd.NA,
          "forecast_flag": "beyond horizon", "hours_beyond_forecast": 8.04, "run_id": "r1"}
    assert cd.attention_items(ok, {"run_id": "r1", "cycle_age_h": 48.0}) == [
        "beyond horizon: 8.0 h sailed past the forecast's last step", "planned on a cycle 48 h old"]


def test_positions_are_shown_at_the_newest_run_when_the_data_is_old():
    run = {"nominal_utc": pd.Timestamp("2020-12-01T06:00"), "started_at": pd.Timestamp("2026-12-05T07:00")}
    now = datetime(2026, 12, 5, 8)
    assert cd.as_of_time(now, run)[0] == datetime(2020, 12, 1, 6)
    fresh = {"nominal_utc": pd.Timestamp("2026-12-05T02:30")}
    assert cd.as_of_time(now, fresh) == (now, "now")
    assert cd.as_of_time(now, run, datetime(2020, 12, 2)) == (datetime(2020, 12, 2), "as asked")


def test_weather_arrows_point_where_the_flow_goes_and_none_over_land():
    lat, lon = np.array([10.0, 0.0]), np.array([100.0, 110.0, 120.0])
    shape = (2, 3)
    fields = {"u10": np.full(shape, 0.0), "v10": np.full(shape, -10.0),  # wind from the north: blows to the south
              "swh": np.full(shape, 2.0), "mwd": np.full(shape, 270.0),  # waves from the west: run to the east
              "uo": np.full(shape, 0.5), "vo": np.full(shape, 0.5)}  # current setting to the north-east
    box = {"west": -260.0, "east": -235.0, "south": -5.0, "north": 15.0}  # the same place, a turn to the west
    wind = cd.weather_layer(lat, lon, fields, "wind", "2020-12-01T00", 6, box)
    assert wind["to_deg"][0] == [180.0, 180.0, 180.0] and wind["unit"] == "kn"
    assert wind["magnitude"][0][0] == pytest.approx(10.0 * 3600 / 1852, abs=0.01)
    assert wind["lon"] == [-260.0, -250.0, -240.0] and wind["valid_utc"] == "2020-12-01T06:00:00Z"
    assert cd.weather_layer(lat, lon, fields, "waves", "2020-12-01T00", 6, box)["to_deg"][1] == [90.0, 90.0, 90.0]
    assert cd.weather_layer(lat, lon, fields, "currents", "2020-12-01T00", 6, box)["to_deg"][0][0] == 45.0
    fields["swh"][0, 1] = np.nan
    assert cd.weather_layer(lat, lon, fields, "waves", "2020-12-01T00", 6, box)["magnitude"][0][1] is None
    land_in_middle = lambda la, lo: np.broadcast_to(np.abs(lo - (-250.0)) > 1.0, np.broadcast_shapes(la.shape, lo.shape))  # noqa: E731
    masked = cd.weather_layer(lat, lon, fields, "wind", "2020-12-01T00", 6, box, is_sea=land_in_middle)
    assert masked["to_deg"][0] == [180.0, None, 180.0] and masked["magnitude"][0][1] is not None
    with pytest.raises(ValueError, match="unknown weather variable"):
        cd.weather_layer(lat, lon, fields, "rain", "2020-12-01T00", 6, box)


def _png_pixels(png: bytes) -> np.ndarray:
    """(h, w, 4) of a PNG the console writes (8-bit RGBA, filter 0 on every row)."""
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    w, h = struct.unpack(">II", png[16:24])
    pos, data = 8, b""
    while pos < len(png):
        n, kind = struct.unpack(">I", png[pos:pos + 4])[0], png[pos + 4:pos + 8]
        if kind == b"IDAT":
            data += png[pos + 8:pos + 8 + n]
        pos += 12 + n
    raw = np.frombuffer(zlib.decompress(data), np.uint8).reshape(h, 1 + 4 * w)
    assert (raw[:, 0] == 0).all()
    return raw[:, 1:].reshape(h, w, 4)


def test_the_land_picture_has_land_where_the_mask_has_it():
    from pipeline.routing.land_mask import is_sea

    box = {"west": 120.0, "east": 150.0, "south": 25.0, "north": 45.0}  # Japan, Korea, open Pacific
    px = _png_pixels(cd.land_png(box, 300, is_sea))
    assert px.shape == (200, 300, 4)

    def alpha_at(lat, lon):
        return px[int((box["north"] - lat) / 20 * 200), int((lon - box["west"]) / 30 * 300), 3]

    assert alpha_at(36.0, 139.0) == 255  # Honshu, inland
    assert alpha_at(30.0, 145.0) == 0  # open sea
    land_share = (px[..., 3] > 0).mean()
    mask_share = (~is_sea(np.linspace(44.95, 25.05, 200)[:, None], np.linspace(120.05, 149.95, 300)[None, :])).mean()
    assert land_share == pytest.approx(mask_share, abs=0.01)


@pytest.mark.parametrize("host, loopback", [("127.0.0.1", True), ("localhost", True), ("::1", True), ("127.0.1.1", True),
                                            ("0.0.0.0", False), ("192.168.1.5", False), ("myhost", False)])
def test_only_loopback_counts_as_this_machine(host, loopback):
    from cli.web_console import is_loopback

    assert is_loopback(host) is loopback


def test_binding_beyond_loopback_needs_a_token(tmp_path):
    from typer.testing import CliRunner

    from cli.main import app

    (tmp_path / "data").mkdir()
    res = CliRunner().invoke(app, ["console", "--data", str(tmp_path / "data"), "--host", "0.0.0.0"])
    assert res.exit_code == 2 and "--token" in res.output
    res = CliRunner().invoke(app, ["console", "--data", str(tmp_path / "data"), "--host", "0.0.0.0", "--token", "short"])
    assert res.exit_code == 2 and "too short" in res.output


def test_with_a_token_every_request_must_carry_it(tmp_path):
    from starlette.testclient import TestClient

    from cli.console_app.app import TOKEN_COOKIE, create_app
    from storage.layout import DataLayout

    token = "a-long-enough-secret"
    client = TestClient(create_app(DataLayout(tmp_path / "data"), token=token), base_url="http://127.0.0.1")
    refused = client.get("/api/runs")
    assert refused.status_code == 401 and "token" in refused.text
    assert client.get("/api/runs", headers={"Authorization": "Bearer wrong-secret-123"}).status_code == 401
    # the right token: the request passes (and finds no warehouse in this empty data root, saying what to do)
    answer = client.get("/api/runs", headers={"Authorization": f"Bearer {token}"})
    assert answer.status_code == 503 and "jitroute demo" in answer.json()["error"]
    page = client.get(f"/fleet?token={token}")
    assert page.status_code == 200 and TOKEN_COOKIE in page.headers["set-cookie"]
    assert client.get("/api/runs").status_code == 503  # the cookie carries it from now on
    assert "default-src 'self'" in page.headers["content-security-policy"]


def test_an_empty_data_root_says_what_to_run(tmp_path):
    from starlette.testclient import TestClient

    from cli.console_app.app import create_app
    from storage.layout import DataLayout

    client = TestClient(create_app(DataLayout(tmp_path / "data")), base_url="http://127.0.0.1")
    for url in ("/api/fleet", "/api/plan", "/api/runs", "/api/voyage/V1"):
        r = client.get(url)
        assert r.status_code == 503 and "run `jitroute demo`" in r.json()["error"], url
    assert client.get("/api/weather?west=1&east=0&south=0&north=1&cycle=2020-12-01T00").status_code == 400
    assert client.get("/static/console.js").status_code == 200
    assert client.get("/fleet").text.count("/static/") == 2  # one script, one style: nothing from elsewhere
    assert "http" not in client.get("/fleet").text.replace("http-equiv", "")
