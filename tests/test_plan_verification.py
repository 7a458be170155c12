"""Verification: a plan and its baseline re-sailed in the analysed weather of later cycles (issue 41, item 4)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.routing.engine import leg as lk
from pipeline.routing import weather_field as wf
from pipeline.routing.ensemble import sail_plan
from pipeline.routing.geodesy import gc_distance_nm
from pipeline.routing.verification import (NOT_VERIFIED, PARTLY, VERIFIED, VerificationError, constant_rpm_legs,
                                           verification_weather, verify)
from tests.routing_cases import MODEL

VESSEL = lk.vessel(MODEL, rpm_options=(70.0, 85.0, 100.0))  # STW = 0.14·rpm kn, fuel = 1.5·(rpm/100)³ t/h in calm water
LAT = np.arange(10.0, 50.01, 1.0)
LON = np.arange(180.0, 250.01, 1.0)


def cycle(init: str, *, wind_ms=(0.0, 0.0), hs_m=0.0, wave_from_deg=0.0, last_step_h=132, lat=LAT) -> wf.WeatherField:
    """A cycle of uniform weather at every step 0..last_step_h every 6 h, as the cube gives it (times from the cycle)."""
    c = np.datetime64(init, "s")
    steps = np.arange(0, last_step_h + 1, 6)
    shape = (steps.size, lat.size, LON.size)
    return wf.from_arrays(lat, LON, c + (steps * 3600).astype("timedelta64[s]"), u10=np.full(shape, wind_ms[0]),
                          v10=np.full(shape, wind_ms[1]), swh=np.full(shape, hs_m), mwd_deg=np.full(shape, wave_from_deg),
                          uo=np.zeros(shape), vo=np.zeros(shape), cycle=c, t_ref=c)


def test_a_plan_verified_with_a_later_stormier_cycle_burns_what_that_weather_costs():
    a = cycle("2020-12-01T00")  # the plan's forecast: calm
    b = cycle("2020-12-01T12", wind_ms=(-15.0, 0.0), hs_m=3.0, wave_from_deg=90.0)  # what came: head wind and sea
    legs = constant_rpm_legs([30.0, 30.0, 30.0], [200.0, 205.0, 210.0], 85.0)
    depart = np.datetime64("2020-12-01T12")
    dist_nm = sum(gc_distance_nm(g["lat0"], g["lon0"], g["lat1"], g["lon1"]) for g in legs)
    claimed_h, claimed_t = sail_plan(legs, depart, a, VESSEL)
    # the claim, by hand: calm water at 85 rpm
    assert claimed_h == pytest.approx(dist_nm / (0.14 * 85.0), rel=1e-3)
    assert claimed_t == pytest.approx(1.5 * 0.85 ** 3 * dist_nm / (0.14 * 85.0), rel=1e-3)

    vw = verification_weather([b, a])  # any order
    assert [str(c) for c in vw.cycles] == ["2020-12-01T00:00:00", "2020-12-01T12:00:00"]
    v = verify(legs, None, depart, vw, VESSEL)
    # independently: the same legs in one uniform field of B's weather (no merging of cycles involved)
    truth_h, truth_t = sail_plan(legs, depart, wf.uniform("2020-11-30T00", 400.0, wind_ms=(-15.0, 0.0), swh_m=3.0,
                                                             wave_from_deg=90.0), VESSEL)
    assert v.plan_fuel_t == pytest.approx(truth_t, rel=1e-6) and v.plan_hours == pytest.approx(truth_h, rel=1e-6)
    assert v.plan_fuel_t - claimed_t == pytest.approx(truth_t - claimed_t, rel=1e-6)
    assert v.plan_fuel_t > claimed_t * 1.02 and v.plan_hours > claimed_h  # the head sea costs fuel and time
    # B's analysis covers 12..18 h: six hours of a passage of about two days, so partly verified
    assert v.hours_analysed == pytest.approx(6.0, abs=1e-6)
    assert v.hours_total == pytest.approx(truth_h, rel=1e-6) and v.coverage == PARTLY
    assert math.isnan(v.realised_savings_pct)  # no baseline given


def test_a_plan_analysed_over_half_its_hours_is_partly_verified_and_whole_once_later_cycles_come():
    rpm = 100.0  # 14 kn in calm water
    legs = constant_rpm_legs([20.0, 24.0, 28.4], [200.0, 200.0, 200.0], rpm)
    dist_nm = sum(gc_distance_nm(g["lat0"], g["lon0"], g["lat1"], g["lon1"]) for g in legs)
    hours = dist_nm / 14.0
    assert 35.0 < hours < 37.0
    depart = np.datetime64("2020-12-01T00")
    cycles = [cycle("2020-12-01T00"), cycle("2020-12-01T12")]  # analysis to 18 h: half the passage
    v = verify(legs, None, depart, verification_weather(cycles), VESSEL)
    assert v.hours_total == pytest.approx(hours, rel=1e-4)
    assert v.hours_analysed == pytest.approx(18.0, abs=1e-6) and v.coverage == PARTLY
    cycles += [cycle("2020-12-02T00"), cycle("2020-12-02T12")]  # analysis to 42 h: the whole passage
    v = verify(legs, None, depart, verification_weather(cycles), VESSEL)
    assert v.hours_analysed == pytest.approx(v.hours_total, abs=1e-3) and v.coverage == VERIFIED  # to the second
    # a plan departing after the newest analysis has none
    later = verify(legs, None, np.datetime64("2020-12-03T00"), verification_weather(cycles), VESSEL)
    assert later.hours_analysed == 0.0 and later.coverage == NOT_VERIFIED


def test_the_realised_saving_compares_plan_and_baseline_in_the_same_weather():
    # north-east wind and sea: a plan slowing down (85 rpm) vs a baseline at 100 rpm over the same track
    came = cycle("2020-12-01T00", wind_ms=(-8.0, -8.0), hs_m=2.5, wave_from_deg=45.0)
    lats, lons = [30.0, 31.0, 32.0], [200.0, 202.0, 204.0]
    plan, base = constant_rpm_legs(lats, lons, [85.0, 100.0]), constant_rpm_legs(lats, lons, 100.0)
    depart = np.datetime64("2020-12-01T00")
    v = verify(plan, base, depart, verification_weather([came]), VESSEL, claimed_savings_pct=5.0)
    ph, pf = sail_plan(plan, depart, came, VESSEL)
    bh, bf = sail_plan(base, depart, came, VESSEL)
    assert (v.plan_fuel_t, v.baseline_fuel_t) == (pytest.approx(pf), pytest.approx(bf))
    assert v.realised_savings_pct == pytest.approx(100 * (bf - pf) / bf) and v.claimed_savings_pct == 5.0
    assert v.baseline_eta_utc == depart + np.timedelta64(int(round(bh * 3600)), "s")


def test_weather_limits_do_not_stop_the_ship_that_sails_on():
    storm = cycle("2020-12-01T00", wind_ms=(0.0, 20.0), hs_m=6.0, wave_from_deg=180.0)
    legs = constant_rpm_legs([30.0, 30.0], [200.0, 203.0], 100.0)
    limited = VESSEL._replace(max_hs_m=4.0)
    assert not math.isfinite(sail_plan(legs, "2020-12-01T00", storm, limited)[0])  # a plan could not be made here
    v = verify(legs, None, "2020-12-01T00", verification_weather([storm]), limited)
    assert v is not None and v.plan_fuel_t > 0  # but the ship that met it still arrives, at a cost


def test_cycles_on_different_grids_are_refused_naming_them():
    with pytest.raises(VerificationError, match="another grid"):
        verification_weather([cycle("2020-12-01T00"), cycle("2020-12-01T12", lat=np.arange(10.0, 40.01, 1.0))])


# --- the warehouse: plan_verification and the realised columns of fleet_savings -------------------------------------

def _route(run_id, vid, fuel_t, base_t, p10, p90, p_on_time, margin_cost_pct=None):
    from schemas.tables.routes import ROUTES

    return ROUTES.empty_row(run_id=run_id, voyage_id=vid, imo=9000001, status="ok", fuel_t=fuel_t,
                            margin_cost_pct=margin_cost_pct,
                            honest_baseline_fuel_t=base_t, savings_total_pct=100 * (1 - fuel_t / base_t),
                            profile_fuel_t=base_t, n_legs=2, savings_p10_pct=p10, savings_p50_pct=(p10 + p90) / 2,
                            savings_p90_pct=p90, p_on_time=p_on_time, ensemble_members=4,
                            depart_utc=np.datetime64("2020-12-01T00").item(), rta_utc=np.datetime64("2020-12-03T00").item())


def _verified(run_id, vid, coverage, hours_analysed, fuel_t, base_t, late_h=0.0):
    from datetime import datetime

    from schemas.tables.routes import PLAN_VERIFICATION

    return PLAN_VERIFICATION.empty_row(run_id=run_id, voyage_id=vid, plan_kind="port", coverage=coverage,
                                       hours_analysed=hours_analysed, hours_total=40.0, realised_fuel_t=fuel_t,
                                       realised_baseline_fuel_t=base_t, realised_late_h=late_h,
                                       cycles_used="2020-12-01T00, 2020-12-01T12", verified_at=datetime(2020, 12, 3))


@pytest.mark.slow
def test_fleet_savings_adds_up_the_realised_saving_and_the_spread_like_with_like(tmp_path):
    import duckdb

    from storage import route_store, verification_store

    db, run = tmp_path / "warehouse.duckdb", "R1"
    route_store.begin_run(db, run, cycle=np.datetime64("2020-12-01T00"), solver="bfoa", trigger="manual", n_voyages=4)
    routes = [_route(run, "A", 90.0, 100.0, 2.0, 12.0, 1.0, 1.5), _route(run, "B", 190.0, 200.0, -1.0, 9.0, 0.5),
              _route(run, "C", 45.0, 50.0, 0.0, 20.0, 0.75, 0.4), _route(run, "D", 10.0, 10.0, 0.0, 0.0, 1.0, 0.0)]
    route_store.write_run_results(db, tmp_path / "exports", run, routes, [])
    rows = [_verified(run, "A", "verified", 40.0, 95.0, 101.0),  # realised: 95 vs 101
            _verified(run, "B", "partly verified", 20.0, 205.0, 203.0, late_h=2.0),  # realised: worse than the baseline
            _verified(run, "C", "verified", 40.0, 50.0, None)]  # no baseline stored: not compared
    assert verification_store.write_verifications(db, rows) == 3
    assert verification_store.write_verifications(db, rows[:1]) == 1  # a plan verified again replaces its row
    with duckdb.connect(str(db), read_only=True) as con:
        f = con.execute("SELECT * FROM fleet_savings").fetchdf().iloc[0]
        assert con.execute("SELECT count(*) FROM plan_verification").fetchone()[0] == 3
    assert (f.n_voyages, f.n_verified, f.n_verified_whole, f.n_verified_compared, f.n_realised_on_time) == (4, 3, 2, 2, 2)
    assert f.realised_fuel_t == pytest.approx(95 + 205) and f.realised_baseline_fuel_t == pytest.approx(101 + 203)
    assert f.realised_savings_pct == pytest.approx(100 * (1 - 300 / 304))  # −(−1.3 %): fuel-weighted, A and B
    assert f.verified_claimed_savings_pct == pytest.approx(100 * (1 - 280 / 300))  # the same two plans' claim
    assert f.savings_total_pct == pytest.approx(100 * (1 - 335 / 360))  # the run's claim over all four, unchanged
    assert f.verified_hours_analysed == pytest.approx(100.0) and f.verified_hours_total == pytest.approx(120.0)
    # the spread, weighted by the baseline's fuel as the saving itself is
    assert f.savings_p10_pct == pytest.approx((2 * 100 - 1 * 200 + 0 * 50 + 0 * 10) / 360)
    assert f.savings_p90_pct == pytest.approx((12 * 100 + 9 * 200 + 20 * 50 + 0 * 10) / 360)
    assert f.p_on_time == pytest.approx((1 + 0.5 + 0.75 + 1) / 4) and f.n_ensemble == 4
    # what the arrival margins cost, weighted the same way (B stored without the column: no margin)
    assert f.margin_cost_pct == pytest.approx((1.5 * 100 + 0.4 * 50) / 360)
    summary = route_store.run_summary(db, run)
    assert summary["n_verified"] == 3 and summary["realised_savings_pct"] == pytest.approx(f.realised_savings_pct)


# --- the nightly, end to end on a generated mirror with two cycles --------------------------------------------------

class Recorder:
    """The plain runner, keeping what the nightly publishes."""

    prefect = False

    def __init__(self):
        self.published = {}

    def step(self, fn, *a, name, **kw):
        return fn(*a, **{k: v for k, v in kw.items() if k not in ("retries", "retry_delay_s", "timeout_s")})

    def subflow(self, name, job, **kw):
        return job(run=self, **kw)

    def publish(self, *, key, markdown, table=None, description=""):
        self.published[key] = markdown


@pytest.fixture(scope="module")
def two_cycle_root(tmp_path_factory):
    """A mirror with the 00 and 12 UTC cycles of 2020-12-01 (leads to 12 h, to stay small) and a 3-vessel fleet whose
    first voyage is at sea, refitted; nothing routed yet."""
    from cli.fleet import _import_fleet
    from flows.jobs.refit import refit_job
    from pipeline.synthetic.fleet import generate_fleet, write_fleet
    from pipeline.synthetic.mirror import write_mirror

    base = tmp_path_factory.mktemp("verify")
    mirror = write_mirror(base / "mirror", "2020-12-01", "2020-12-01", cycles=(0, 12), seed=0, max_lead_h=12)
    write_fleet(generate_fleet("2020-12-01T00", n_vessels=3, days=120, seed=3, at_sea=(0,)), base / "fleet")
    root = base / "data"
    root.mkdir()
    _import_fleet(base / "fleet", root)
    refit_job(data_root=str(root))
    return root, mirror


@pytest.mark.slow  # the nightly run twice end to end (ingest, route the fleet, verify), then `jitroute verify`
def test_the_nightly_verifies_the_plans_of_the_cycle_before_in_the_analysed_weather(two_cycle_root, monkeypatch):
    import duckdb

    import flows.jobs.fleet as fleet
    import flows.jobs.ingest as ingest
    import flows.jobs.verify as verify_job
    from flows.settings import load_settings
    from tests.conftest import mirror_urls

    def settings(**overrides):  # the mirror's short leads; the constant-speed solver, to stay quick
        return load_settings(**overrides).with_overrides(**{"sources.gsm_max_lead_h": 12, "routing.solver": "gc"})
    for module in (fleet, ingest, verify_job):
        monkeypatch.setattr(module, "load_settings", settings)
    monkeypatch.setenv("JITROUTE_DASK_WORKERS", "1")
    root, mirror = two_cycle_root
    first = fleet.nightly_job(date="2020-12-01", cycles="00", data_root=str(root), run=Recorder(), **mirror_urls(mirror))
    run1 = first["routing"]["run_id"]
    rec = Recorder()
    second = fleet.nightly_job(date="2020-12-01", cycles="12", data_root=str(root), run=rec, **mirror_urls(mirror))
    assert second["cycle_used"] == "2020-12-01T12"
    with duckdb.connect(str(root / "warehouse.duckdb"), read_only=True) as con:
        rows = con.execute("SELECT p.*, r.depart_utc FROM plan_verification p JOIN routes r USING (run_id, voyage_id) "
                           "WHERE run_id = ?", [run1]).fetchdf()
        f = con.execute("SELECT * FROM fleet_savings WHERE run_id = ?", [run1]).fetchdf().iloc[0]
    assert len(rows) >= 1 and second["verification"]["n_verified"] >= len(rows)
    # the analysis runs from 00 to 18 UTC (each cycle's leads to 6 h); the voyages last days: partly verified
    for r in rows.to_dict("records"):
        assert r["cycles_used"] == "2020-12-01T00, 2020-12-01T12" and r["coverage"] == "partly verified"
        assert str(r["analysed_until_utc"]) == "2020-12-01 18:00:00"
        start = max(r["depart_utc"], r["analysed_until_utc"].replace(hour=0))
        assert 0 < r["hours_analysed"] <= (r["analysed_until_utc"] - start).total_seconds() / 3600 + 1e-6
        assert r["hours_analysed"] < r["hours_total"]
        # a gc plan is the constant-speed voyage itself: sailed against itself it realises exactly no saving
        assert r["realised_savings_pct"] == pytest.approx(0.0, abs=1e-9)
        assert r["realised_baseline_fuel_t"] == pytest.approx(r["realised_fuel_t"])
    assert f.n_verified == len(rows) and f.n_verified_whole == 0
    text = rec.published["nightly-summary"]
    assert "## Verification" in text and "Verified " in text and "partly" in text and "claimed saving" in text

    # by hand: `jitroute verify --run` re-sails a run's plans again once their rows are gone
    from typer.testing import CliRunner

    from cli.main import app

    with duckdb.connect(str(root / "warehouse.duckdb")) as con:
        con.execute("DELETE FROM plan_verification WHERE run_id = ?", [run1])
    monkeypatch.setenv("COLUMNS", "250")
    res = CliRunner().invoke(app, ["verify", "--run", run1, "--data", str(root)])
    assert res.exit_code == 0, res.output
    assert f"Verified {len(rows)} plan" in res.output and "partly" in res.output
    assert all(vid in res.output for vid in rows.voyage_id)
    with duckdb.connect(str(root / "warehouse.duckdb"), read_only=True) as con:
        again = con.execute("SELECT voyage_id, hours_analysed, realised_fuel_t FROM plan_verification WHERE run_id = ? "
                            "ORDER BY voyage_id", [run1]).fetchall()
    assert again == [(r.voyage_id, pytest.approx(r.hours_analysed), pytest.approx(r.realised_fuel_t))
                     for r in rows.sort_values("voyage_id").itertuples()]


def test_the_voyage_map_states_the_plans_spread_and_geojson_keeps_the_baseline_track():
    import json

    from pipeline.export.geojson import route_to_geojson
    from pipeline.export.plots import route_map_figure
    from pipeline.export.voyage import spread_text

    legs = [dict(g, etd_utc=np.datetime64("2020-12-01T00").item(), eta_utc=np.datetime64("2020-12-01T20").item(),
                 fuel_t=10.0, hours=20.0, dist_nm=260.0) for g in constant_rpm_legs([30.0, 31.0], [200.0, 205.0], 90.0)]
    route = {"voyage_id": "V1", "status": "ok", "solver": "bfoa", "fuel_t": 10.0, "ensemble_members": 4,
             "p_on_time": 0.75, "savings_p10_pct": -0.42, "savings_p90_pct": 2.1,
             "baseline_lat_deg": np.array([30.0, 31.0]), "baseline_lon_deg": np.array([200.0, 205.0]),
             "baseline_leg_rpm": np.array([90.0])}
    said = "across 4 forecasts: on time 75 %, saving P10–P90 -0.4 to 2.1 %"
    assert spread_text(route) == said
    assert spread_text({**route, "p_on_time": None}) is None and spread_text({}) is None
    title = route_map_figure(route, legs).axes[0].get_title()
    assert f"uncertainty {said}" in title
    assert "uncertainty" not in route_map_figure({**route, "ensemble_members": None}, legs).axes[0].get_title()
    props = json.loads(json.dumps(route_to_geojson(route, legs), allow_nan=False))["features"][0]["properties"]
    assert props["baseline_lat_deg"] == [30.0, 31.0] and props["baseline_leg_rpm"] == [90.0]


def test_each_older_cycle_gives_its_short_leads_from_the_one_just_before_the_departure():
    from flows.jobs.verify import _cycle_windows
    from pipeline.routing.problem import WeatherWindow

    cycles = [np.datetime64(c, "s") for c in ("2020-12-02T12", "2020-12-02T00", "2020-12-01T12", "2020-12-01T00")]
    window = WeatherWindow(np.datetime64("2020-12-01T19", "s"), np.datetime64("2020-12-03T00", "s"), (30.0, 40.0),
                           (200.0, 210.0))
    got = {str(c)[:13]: (str(w.from_utc)[:13], str(w.to_utc)[:13]) for c, w in _cycle_windows(cycles, window, 6.0)}
    # the newest whole; 01T12's 12..18 h (the analysis just before a 19 h departure, to interpolate from); 01T00 not
    assert got == {"2020-12-02T12": ("2020-12-01T19", "2020-12-03T00"), "2020-12-02T00": ("2020-12-02T00", "2020-12-02T06"),
                   "2020-12-01T12": ("2020-12-01T12", "2020-12-01T18")}


def test_route_fleet_s_run_table_gives_the_spread_and_the_realised_saving_beside_the_claim():
    from rich.console import Console

    from cli.fleet import run_table

    def shown(summary):
        console = Console(width=150, record=True)
        console.print(run_table(summary))
        return console.export_text()

    text = shown({"p_on_time": 0.75, "savings_p10_pct": -0.42, "savings_p90_pct": 2.1, "n_verified": 3,
                  "n_verified_whole": 1, "verified_claimed_savings_pct": 1.24, "realised_savings_pct": 0.31})
    assert "75 %" in text and "-0.4 % – 2.1 %" in text and "3 (1)" in text and "1.2 % / 0.3 %" in text
    assert "claimed / realised" not in shown({"n_verified": 0})  # nothing verified: no realised row


def test_runs_in_the_old_parquet_layout_move_with_the_baseline_track_columns_empty(tmp_path):
    import pandas as pd
    import pyarrow.parquet as pq

    from schemas.tables.routes import ROUTE_BASELINE_TRACK_ADDED, ROUTES
    from storage import route_store

    old = tmp_path / "routes" / "run_id=R0"
    old.mkdir(parents=True)
    row = {k: v for k, v in _route("R0", "A", 9.0, 10.0, 0.0, 1.0, 1.0).items() if k not in ROUTE_BASELINE_TRACK_ADDED}
    pd.DataFrame([row]).drop(columns=["run_id"]).to_parquet(old / "routes.parquet")  # written before the columns
    assert route_store.migrate_old_parquet_layout(tmp_path) == ["R0"]
    moved = pq.read_table(route_store.parquet_dir(tmp_path, "routes") / "run_id=R0" / "part-0.parquet")
    assert moved.schema.field("baseline_lat_deg").type == ROUTES.arrow_schema().field("baseline_lat_deg").type
    assert moved.column("baseline_lat_deg").to_pylist() == [None] and moved.column("fuel_t").to_pylist() == [9.0]
