"""Voyages at sea re-planned from their latest position; stale weather refused; stale plans flagged."""

from __future__ import annotations

import duckdb
import numpy as np
import pandas as pd
import pytest

from pipeline import enroute
from pipeline.routing.geodesy import gc_distance_nm

T = np.datetime64

VOYAGE = {"voyage_id": "V1", "imo": 9140607, "dep_lat": 34.85, "dep_lon": 139.85, "arr_lat": 13.45, "arr_lon": 144.55,
          "depart_utc": T("2020-11-30T04:00"), "rta_utc": T("2020-12-03T16:00"), "status": "planned"}
# a plan of two legs: 10 h to (30, 141), then 20 h to (13.45, 144.55)
LEGS = [{"lat0": 34.85, "lon0": 139.85, "lat1": 30.0, "lon1": 141.0, "etd_utc": T("2020-11-30T04:00"),
         "eta_utc": T("2020-11-30T14:00")},
        {"lat0": 30.0, "lon0": 141.0, "lat1": 13.45, "lon1": 144.55, "etd_utc": T("2020-11-30T14:00"),
         "eta_utc": T("2020-12-01T10:00")}]


def test_position_on_plan_is_where_the_plan_puts_the_ship_then():
    assert enroute.position_on_plan(LEGS, T("2020-11-30T14:00")) == pytest.approx((30.0, 141.0))
    lat, lon = enroute.position_on_plan(LEGS, T("2020-11-30T09:00"))  # half way along the first leg
    d0, d1 = gc_distance_nm(34.85, 139.85, lat, lon), gc_distance_nm(lat, lon, 30.0, 141.0)
    assert d0 == pytest.approx(d1, rel=1e-6) and d0 + d1 == pytest.approx(gc_distance_nm(34.85, 139.85, 30, 141), rel=1e-9)
    assert enroute.position_on_plan(LEGS, T("2020-11-29T00:00")) == (34.85, 139.85)
    assert enroute.position_on_plan(LEGS, T("2020-12-02T00:00")) == (13.45, 144.55)
    assert enroute.position_on_plan([], T("2020-12-02T00:00")) is None


def test_a_fresh_report_is_the_start_an_old_one_is_advanced_along_the_plan():
    rep = enroute.Position(T("2020-11-30T12:00"), 31.0, 140.8)
    fresh = enroute.replan_start(VOYAGE, rep, LEGS, T("2020-12-01T00:00"), 30.0)
    assert (fresh.kind, fresh.lat, fresh.lon, fresh.utc, fresh.advanced_h) == ("noon report", 31.0, 140.8, rep.utc, 0.0)
    old = enroute.replan_start(VOYAGE, rep, LEGS, T("2020-12-01T20:00"), 30.0)  # 32 h old
    assert old.kind == "advanced along plan" and old.utc == T("2020-12-01T20:00") and old.advanced_h == 32.0
    assert (old.lat, old.lon) == (13.45, 144.55) and "32 h old" in old.note and old.position_utc == rep.utc
    alone = enroute.replan_start(VOYAGE, rep, [], T("2020-12-01T20:00"), 30.0)  # nothing to advance it along
    assert (alone.lat, alone.utc, alone.advanced_h) == (31.0, rep.utc, 0.0) and "no current plan" in alone.note
    assert enroute.replan_start(VOYAGE, None, [], T("2020-12-01T20:00"), 30.0) is None


def test_which_voyages_are_planned_from_port_at_sea_or_not_at_all():
    cycle, ref = T("2020-12-01T00:00"), T("2020-12-01T06:00")
    upcoming = {**VOYAGE, "voyage_id": "UP", "imo": 1, "depart_utc": T("2020-12-01T13:00")}
    at_sea = {**VOYAGE, "voyage_id": "SEA", "imo": 2}
    arrived = {**VOYAGE, "voyage_id": "ARR", "imo": 3}
    by_status = {**VOYAGE, "voyage_id": "ST", "imo": 4, "status": "arrived"}
    unknown = {**VOYAGE, "voyage_id": "NONE", "imo": 5}
    later = enroute.Position(T("2020-12-01T12:00"), 20.0, 143.0)  # after ref: not seen yet
    positions = {2: [enroute.Position(T("2020-11-30T12:00"), 31.0, 140.8), later],
                 3: [enroute.Position(T("2020-11-30T20:00"), 13.47, 144.56)]}  # ~1.3 NM from Guam
    got = enroute.select_starts([upcoming, at_sea, arrived, by_status, unknown], positions, {}, cycle_utc=cycle,
                                ref_utc=ref, lookahead_h=120, max_report_age_h=30, arrived_within_nm=5,
                                max_voyage_h=2160)
    kinds = {s.voyage["voyage_id"]: (s.start.kind if s.start else s.why) for s in got}
    assert kinds["UP"] == "port" and kinds["SEA"] == "noon report"
    assert "ARR" not in kinds and "ST" not in kinds
    assert "neither a position report" in kinds["NONE"]
    sea = next(s for s in got if s.voyage["voyage_id"] == "SEA")
    v = enroute.voyage_from(sea.voyage, sea.start)
    assert (v["dep_lat"], v["dep_lon"], v["start_kind"]) == (31.0, 140.8, "noon report")
    assert v["depart_utc"] == pd.Timestamp("2020-11-30T12:00").to_pydatetime() and v["arr_lat"] == 13.45


def _sql(root, q):
    con = duckdb.connect(str(root / "warehouse.duckdb"), read_only=True)
    try:
        return con.execute(q).fetchall()
    finally:
        con.close()


@pytest.fixture(scope="module")
def at_sea_root(tmp_path_factory, demo_mirror):
    """The mirror's 2020-12-01T00 cycle and a 3-vessel fleet whose first voyage is at sea, refitted (plain jobs)."""
    from cli.fleet import _import_fleet
    from tests.conftest import mirror_urls
    from flows.jobs.ingest import ingest_cycle
    from flows.jobs.refit import refit_job
    from pipeline.synthetic.fleet import generate_fleet, write_fleet

    base = tmp_path_factory.mktemp("enroute")
    root = base / "data"
    assert ingest_cycle("2020-12-01T00", data_root=str(root), **mirror_urls(demo_mirror))["complete"]
    write_fleet(generate_fleet("2020-12-01T00", n_vessels=3, days=120, seed=3, at_sea=(0,)), base / "fleet")
    _import_fleet(base / "fleet", root)
    refit_job(data_root=str(root))
    return root


def test_route_fleet_replans_the_ship_at_sea_from_its_noon_report(at_sea_root, monkeypatch):
    from flows.jobs.fleet import route_fleet_job

    monkeypatch.setenv("JITROUTE_DASK_WORKERS", "1")
    s = route_fleet_job(cycle="2020-12-01T00", data_root=str(at_sea_root), solver="gc", exports=False,
                        nominal_utc="2020-12-01T20")
    assert (s["n"], s["n_from_port"], s["n_replanned"]) == (3, 2, 1) and s["cycle_age_h"] == 20.0
    lat, lon = _sql(at_sea_root, "SELECT lat, lon FROM noon_reports WHERE imo = 9140607 "
                                 "AND ts_utc = '2020-12-01 12:00'")[0]
    row = _sql(at_sea_root, "SELECT start_kind, start_lat, start_lon, start_utc, depart_utc, status, stale "
                            "FROM latest_routes WHERE voyage_id = 'V20001'")[0]
    assert row[:3] == ("noon report", lat, lon) and str(row[3]) == "2020-12-01 12:00:00" == str(row[4])
    assert row[5] in ("ok", "late") and row[6] is False
    first = _sql(at_sea_root, "SELECT lat0, lon0 FROM route_legs l JOIN latest_routes r USING (run_id, voyage_id) "
                              "WHERE voyage_id = 'V20001' AND leg = 0")[0]
    assert first == pytest.approx((lat, lon % 360.0 if lon > 180 else lon), abs=1e-6)
    assert _sql(at_sea_root, "SELECT DISTINCT start_kind FROM routes WHERE voyage_id <> 'V20001'") == [("port",)]


def test_a_changed_rta_makes_the_current_plan_stale(at_sea_root):
    from storage import route_store

    with duckdb.connect(str(at_sea_root / "warehouse.duckdb")) as con:
        con.execute("UPDATE voyages SET rta_utc = rta_utc + INTERVAL 6 HOUR WHERE voyage_id = 'V20002'")
    rows = dict((v, (st, why)) for v, st, why in _sql(at_sea_root, "SELECT voyage_id, stale, stale_reason FROM latest_routes"))
    assert rows["V20002"][0] is True and rows["V20002"][1].startswith("RTA changed")
    assert rows["V20003"] == (False, None)
    assert [p["voyage_id"] for p in route_store.stale_plans(at_sea_root / "warehouse.duckdb")] == ["V20002"]


def test_routing_on_a_cycle_too_old_at_the_runs_time_is_refused_and_recorded(at_sea_root):
    from flows.jobs.fleet import StaleWeatherError, route_fleet_job

    with pytest.raises(StaleWeatherError, match=r"cycle 2020-12-01T00 is 48 h old at 2020-12-03T00.*max_cycle_age_h"):
        route_fleet_job(data_root=str(at_sea_root), solver="gc", exports=False, nominal_utc="2020-12-03T00")
    status, age, reason = _sql(at_sea_root, "SELECT status, cycle_age_h, reason FROM route_runs "
                                            "ORDER BY started_at DESC LIMIT 1")[0]
    assert status == "failed" and age == 48.0 and "weather too old" in reason


def test_a_nightly_whose_cycles_are_missing_refuses_the_old_cycle_and_says_which_are_missing(at_sea_root, demo_mirror):
    from tests.conftest import mirror_urls
    from flows.jobs.fleet import StaleWeatherError, nightly_job, nightly_markdown

    published = {}

    class Recorder:  # the plain runner, keeping what the nightly publishes
        prefect = False

        def step(self, fn, *a, name, **kw):
            return fn(*a, **{k: v for k, v in kw.items() if k not in ("retries", "retry_delay_s", "timeout_s")})

        def subflow(self, name, job, **kw):
            return job(run=self, **kw)

        def publish(self, *, key, markdown, table=None, description=""):
            published[key] = markdown

    with pytest.raises(StaleWeatherError, match=r"2020-12-01T00 is 48 h old at 2020-12-03T00"):
        nightly_job(date="2020-12-03", cycles="00", data_root=str(at_sea_root), run=Recorder(), **mirror_urls(demo_mirror))
    text = published["nightly-summary"]
    assert text.startswith("# jitroute nightly 2020-12-03: Failed")
    assert "**Targeted cycles not complete:** 2020-12-03T00" in text and "**Routing refused:** weather too old" in text
    assert _sql(at_sea_root, "SELECT complete FROM cycles WHERE cycle = '2020-12-03 00:00'") == [(False,)]
    assert nightly_markdown  # the same function renders the summary shown by the CLI and Prefect


def test_an_unreachable_rish_listing_records_the_cycle_incomplete_and_files_missing(tmp_path, monkeypatch):
    import flows.jobs.ingest
    from flows.jobs.backfill import backfill_range
    from flows.jobs.ingest import ingest_cycle
    from tests.processes import free_port
    from tests.reliability.ingest_child import fast_load_settings

    monkeypatch.setattr(flows.jobs.ingest, "load_settings", fast_load_settings)  # short retries: nothing will answer

    root = tmp_path / "data"
    url = f"http://127.0.0.1:{free_port()}/rish/"  # nothing listens there
    r = ingest_cycle("2020-12-01T00", data_root=str(root), rish_url=url, oscar_url=url)
    assert r["complete"] is False and "GSM listing unreachable" in r["missing"][0]
    rows = _sql(root, "SELECT source, status FROM ingest_log ORDER BY source")
    assert rows == [("GSM", "missing"), ("GWM", "missing")]
    assert _sql(root, "SELECT complete, missing LIKE '%unreachable%' FROM cycles") == [(False, True)]
    reports = backfill_range("2020-12-01", "2020-12-02", cycles="00", data_root=str(root), rish_url=url, oscar_url=url)
    assert [x["cycle"] for x in reports] == ["2020-12-01T00", "2020-12-02T00"] and not any(x["complete"] for x in reports)


@pytest.mark.parametrize("args, message", [
    (["ingest", "--cycle", "2020-12-01T03"], "is at 03 UTC; GSM/GWM cycles are at 00/06/12/18 UTC"),
    (["backfill", "--start", "1900-01-01", "--end", "2100-12-31"], "outside 2000-01-01"),
    (["backfill", "--start", "2020-01-01", "--end", "2021-06-01"], "at most 366 days"),
    (["backfill", "--start", "2020-12-01", "--end", "2020-12-01", "--cycles", "03"], "GSM/GWM cycles are at"),
])
def test_bad_cycles_and_ranges_are_refused_in_one_line(args, message, tmp_path):
    from tests.processes import jitroute, new_tag, tagged_env

    r = jitroute(*args, "--data", str(tmp_path / "data"), env=tagged_env(new_tag()), timeout_s=120)
    assert r.returncode == 2 and message in r.stderr and r.stderr.count("error:") == 1 and "Traceback" not in r.stderr


def test_an_operators_newer_position_wins_over_the_noon_report():
    report = enroute.Position(T("2020-11-30T12:00"), 31.0, 140.8)
    given = enroute.Position(T("2020-11-30T20:00"), 28.0, 141.5, enroute.START_OPERATOR)
    got = enroute.select_starts([VOYAGE], {VOYAGE["imo"]: [report]}, {}, cycle_utc=T("2020-12-01T00"),
                                ref_utc=T("2020-12-01T00"), lookahead_h=120, max_report_age_h=30, arrived_within_nm=5,
                                max_voyage_h=2160, given={"V1": [given]})
    assert [(s.start.kind, s.start.lat, s.start.utc) for s in got] == [("operator position", 28.0, given.utc)]


def test_jitroute_position_stores_an_operators_position(at_sea_root):
    from tests.processes import jitroute, new_tag, tagged_env

    r = jitroute("position", "V20001", "--at", "2020-12-01T18", "--pos", "24.5,142.0", "--data", str(at_sea_root),
                 env=tagged_env(new_tag()), timeout_s=120)
    assert r.returncode == 0, r.stderr
    assert _sql(at_sea_root, "SELECT voyage_id, ts_utc, lat, lon FROM voyage_positions") == [
        ("V20001", pd.Timestamp("2020-12-01T18:00").to_pydatetime(), 24.5, 142.0)]
    bad = jitroute("position", "NOPE", "--at", "2020-12-01T18", "--pos", "24.5,142.0", "--data", str(at_sea_root),
                   env=tagged_env(new_tag()), timeout_s=120)
    assert bad.returncode == 2 and "voyage NOPE is not in" in bad.stderr


def test_route_voyage_plans_a_ship_at_sea_from_its_latest_position_as_route_fleet_does(at_sea_root):
    """`route --voyage` of the ship at sea, on the cycle (too old now, so at the cycle's time, as an operator's
    route-fleet run): from its newest noon report before then, not from its departure port."""
    import json

    from typer.testing import CliRunner

    from cli.main import app

    (dep_lat, dep_lon, dep), = _sql(at_sea_root, "SELECT dep_lat, dep_lon, depart_utc FROM voyages WHERE voyage_id = 'V20001'")
    lat, lon, ts = _sql(at_sea_root, f"SELECT lat, lon, ts_utc FROM noon_reports WHERE imo = 9140607 AND ts_utc > '{dep}' "
                                     "AND ts_utc <= '2020-12-01 00:00' ORDER BY ts_utc DESC LIMIT 1")[0]
    r = CliRunner().invoke(app, ["route", "--voyage", "V20001", "--cycle", "2020-12-01T00", "--solver", "gc", "--json",
                                 "--data", str(at_sea_root)])
    assert r.exit_code in (0, 3), r.output
    plan = json.loads(r.output[r.output.index("{"):])
    first = plan["legs"][0]
    assert (first["lat0"], first["lon0"] % 360.0) == pytest.approx((lat, lon % 360.0), abs=1e-6)
    assert (first["lat0"], first["lon0"]) != pytest.approx((dep_lat, dep_lon), abs=1e-3)
    assert str(first["etd_utc"])[:16].replace("T", " ") >= str(ts)[:16]


def test_a_plan_voyage_departing_before_the_routable_cycle_is_listed_as_needing_attention(at_sea_root, monkeypatch):
    """Departed before the cycle, no position since, no current plan: nothing to route it from. The run stores it
    as not routed with the reason, so its summary and its page list it, not only a log line."""
    from flows.jobs.fleet import route_fleet_job, run_markdown

    monkeypatch.setenv("JITROUTE_DASK_WORKERS", "1")
    with duckdb.connect(str(at_sea_root / "warehouse.duckdb")) as con:
        con.execute("INSERT INTO voyages (voyage_id, imo, dep_name, dep_lat, dep_lon, arr_name, arr_lat, arr_lon, "
                    "depart_utc, rta_utc, status, plan_id) VALUES ('plan-x-9140671-0', 9140671, 'Busan', 34.95, 129.15, "
                    "'Shanghai', 30.9, 122.75, '2020-11-30 20:00', '2020-12-04 00:00', 'planned', 'plan-x')")
    try:
        s = route_fleet_job(cycle="2020-12-01T00", data_root=str(at_sea_root), solver="gc", exports=False,
                            nominal_utc="2020-12-01T20")
    finally:
        with duckdb.connect(str(at_sea_root / "warehouse.duckdb")) as con:
            con.execute("DELETE FROM voyages WHERE voyage_id = 'plan-x-9140671-0'")
    (p,) = [p for p in s["problems"] if p["voyage_id"] == "plan-x-9140671-0"]
    assert p["status"] == "failed" and "not routed" in p["reason"] and "neither a position report" in p["reason"]
    assert s["n_failed"] >= 1 and s["n"] == s["n_voyages"]
    assert "| plan-x-9140671-0 | failed | not routed" in run_markdown(s)
