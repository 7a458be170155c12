"""No saving from weather nobody forecast: past a cycle's last valid time every route meets the same neutral weather,
and each saving is split into the part the forecast covers and the part it does not.

Expected values come from the model's formulas and from fields built here; the neutral weather is checked against a
uniform field sailed inside its valid times.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.performance.features import DIR_A, DIR_B, DIR_C
from pipeline.routing.engine import leg as lk
from pipeline.routing import weather_field as wf
from pipeline.routing.savings import savings_split
from pipeline.routing.solve import solve
from routing_cases import MODEL, problem

T0 = np.datetime64("2020-12-01T00")


def _vessel():
    return lk.vessel(MODEL, draft_m=10.0, trim_m=0.0, max_step_h=0.5, rpm_options=(70.0, 85.0, 100.0))


def _field(hours, step_h, fn, lat=(-20.0, 60.0), lon=(150.0, 250.0), res=1.0):
    """Valid times 0, step_h, … hours after T0; fn(LA, LO, h) → {var: array}, unset variables 0."""
    la, lo = np.arange(lat[0], lat[1] + 1e-9, res), np.arange(lon[0], lon[1] + 1e-9, res)
    LA, LO = np.meshgrid(la, lo, indexing="ij")
    hrs = np.arange(0.0, hours + 1e-9, step_h)
    kw = {k: np.zeros((hrs.size,) + LA.shape) for k in ("u10", "v10", "swh", "mwd_deg", "uo", "vo")}
    for n, h in enumerate(hrs):
        for k, v in fn(LA, LO, h).items():
            kw[k][n] = np.broadcast_to(v, LA.shape)
    return wf.from_arrays(la, lo, T0 + (hrs * 3600).astype("timedelta64[s]"), **kw)


def _block(LA, LO, lat0, lon0, hs=7.0, wind_ms=22.0, from_deg=90.0):
    """A storm: Hs and wind of the given strength from `from_deg` (an easterly: head-on to the eastbound voyages
    here) on a 6° × 8° block of cells (outside it calm)."""
    inside = (LA >= lat0) & (LA < lat0 + 6.0) & (LO >= lon0) & (LO < lon0 + 8.0)
    u, v = -wind_ms * math.sin(math.radians(from_deg)), -wind_ms * math.cos(math.radians(from_deg))
    return dict(swh=np.where(inside, hs, 0.0), u10=np.where(inside, u, 0.0), v10=np.where(inside, v, 0.0),
                mwd_deg=np.full(LA.shape, from_deg))


def test_the_beyond_angle_is_where_the_direction_weight_takes_its_mean_over_headings():
    theta = np.radians(np.linspace(0.0, 360.0, 360000, endpoint=False))
    c = np.cos(theta)
    mean_w = np.mean(DIR_A + DIR_B * c + DIR_C * c * c)
    cb = math.cos(math.radians(lk.BEYOND_REL_DEG))
    assert DIR_A + DIR_B * cb + DIR_C * cb * cb == pytest.approx(mean_w, abs=1e-6)
    assert 80.0 < lk.BEYOND_REL_DEG < 85.0


def test_neutral_weather_is_the_fields_mean_wind_speed_and_hs():
    # a third of the cells at each valid time carry 9 m/s and Hs 3 m, the rest calm; NaN (land) left out
    def fn(LA, LO, h):
        on = (np.round(LO) % 3 == 0)
        return dict(u10=np.where(on, 9.0, 0.0), swh=np.where(on, 3.0, 0.0))
    f = _field(24, 12, fn, lat=(0.0, 4.0), lon=(180.0, 188.0))
    share = np.mean(np.round(np.arange(180.0, 188.1, 1.0)) % 3 == 0)
    assert f.neutral_beyond == pytest.approx((9.0 * share, 3.0 * share))
    holes = f.cells.copy()
    holes[0, 0, :, wf.SWH] = np.nan
    f2 = wf.WeatherField(holes, f.times_h, f.grid, f.t_ref)
    assert f2.neutral_beyond[1] == pytest.approx(np.nanmean(holes[..., wf.SWH]))
    assert f2.kernel.beyond_hs_m == f2.neutral_beyond[1]


def test_a_leg_past_the_last_step_sails_in_the_neutral_weather_not_the_frozen_storm():
    # a storm sits on the leg in the last step (48 h); the leg is sailed from 60 h: it must meet the field's mean
    # wind speed and Hs at BEYOND_REL_DEG off the bow, exactly as a uniform field with that weather would give it
    f = _field(48, 12, lambda LA, LO, h: _block(LA, LO, -3.0, 178.0) if h == 48 else {})
    w_ms, hs_m = f.neutral_beyond
    assert 0.0 < hs_m < 1.0  # the storm's cells are a small share of the field
    leg = (0.0, 180.0, 0.0, 183.0)  # along the equator, course 090 throughout
    past = lk.sail_leg(*leg, 60.0, 85.0, _vessel(), f)
    frm = (90.0 + lk.BEYOND_REL_DEG) % 360.0  # the direction the weather comes from at that angle off the bow
    u, v = -w_ms * math.sin(math.radians(frm)), -w_ms * math.cos(math.radians(frm))
    same = wf.uniform(T0, 500, wind_ms=(u, v), swh_m=hs_m, wave_from_deg=frm)
    inside = lk.sail_leg(*leg, 60.0, 85.0, _vessel(), same)
    assert past[lk.CODE] == lk.OK and past[lk.BEYOND] == 1.0 and inside[lk.BEYOND] == 0.0
    assert past[lk.H] == pytest.approx(inside[lk.H], rel=1e-6)
    assert past[lk.FUEL] == pytest.approx(inside[lk.FUEL], rel=1e-6)
    assert past[lk.FUEL_BEYOND] == pytest.approx(past[lk.FUEL], rel=1e-12)
    assert past[lk.CUR_KN] == 0.0
    # the frozen storm would have cost hours: the same leg inside the last step is much slower
    stormy = lk.sail_leg(*leg, 48.0 - 1e-9, 85.0, _vessel(), _field(100, 52, lambda LA, LO, h: _block(LA, LO, -3.0, 178.0)))
    assert stormy[lk.H] > past[lk.H] * 1.1
    # a leg starting 2 h before the last step: only the fuel after 48 h is beyond
    cross = lk.sail_leg(*leg, 46.0, 85.0, _vessel(), f)
    assert 0.0 < cross[lk.FUEL_BEYOND] < cross[lk.FUEL]
    rate = cross[lk.FUEL] / cross[lk.H]  # the rate is the same throughout in this field away from the storm
    assert cross[lk.FUEL_BEYOND] == pytest.approx(rate * (46.0 + cross[lk.H] - 48.0), rel=0.1)


def _voyage_fields(storm_lat0, storm_lon0):
    """Valid times 0..60 h every 12 h, calm but for a storm block at (storm_lat0, storm_lon0) in the last step."""
    return _field(60, 12, lambda LA, LO, h: _block(LA, LO, storm_lat0, storm_lon0) if h == 60 else {},
                  lat=(10.0, 50.0), lon=(170.0, 240.0), res=0.5)


@pytest.mark.slow
def test_a_storm_in_the_last_step_where_the_ship_is_only_later_changes_no_plan():
    """The ship reaches the storm's area (about 120 h out) long after the last step (60 h). With the last step frozen
    the planner would route round the storm; now the plan is the plan on a field whose storm lies elsewhere (the
    same cells shifted off the corridor, so both fields have the same means)."""
    pr = problem((30.0, -175.0), (35.0, -130.0), 200.0, rpm_options=(70, 85, 100))
    storm = _voyage_fields(31.0, 212.0)  # on the great circle near 148 W, reached ~110-140 h out
    away = _voyage_fields(12.0, 172.0)  # the same block far south-west of the corridor
    assert storm.neutral_beyond == pytest.approx(away.neutral_beyond, rel=1e-9)
    a = solve(pr, storm, solver="dp", savings=True, continuous=False)
    b = solve(pr, away, solver="dp", savings=True, continuous=False)
    assert a.status == b.status == "ok"
    assert a.waypoints == b.waypoints
    assert [leg["rpm"] for leg in a.legs] == [leg["rpm"] for leg in b.legs]
    assert a.fuel_t == pytest.approx(b.fuel_t, rel=1e-9)
    assert a.savings.total_pct == pytest.approx(b.savings.total_pct, abs=1e-9)
    # the same storm inside the forecast (every valid time to 300 h) does move the plan: the test can fail
    inside = _field(300, 60, lambda LA, LO, h: _block(LA, LO, 31.0, 212.0), lat=(10.0, 50.0), lon=(170.0, 240.0),
                    res=0.5)
    c = solve(pr, inside, solver="dp", savings=True, continuous=False)
    assert c.fuel_t > a.fuel_t * 1.01 or c.waypoints != a.waypoints


def test_the_saving_past_the_last_step_is_reported_apart_and_the_split_adds_up():
    """A voyage of ~200 h on a 60 h forecast: most of it lies past the last step. The split's parts add up to the
    total; in neutral weather the beyond part is what the speed profile and the route gain there, and a voyage
    inside the forecast has nothing beyond."""
    pr = problem((30.0, -175.0), (35.0, -130.0), 200.0, rpm_options=(70, 85, 100))
    fld = _field(60, 12, lambda LA, LO, h: _block(LA, LO, 29.0, 180.0, hs=5.0), lat=(10.0, 50.0),
                 lon=(170.0, 240.0), res=0.5)
    plan = solve(pr, fld, solver="dp", savings=True)
    s = plan.savings
    assert plan.hours_beyond_forecast > 120.0 and "beyond horizon" in plan.forecast_flag
    assert s.forecast_pct + s.beyond_forecast_pct == pytest.approx(s.total_pct, abs=1e-9)
    assert 0.0 < s.plan_fuel_beyond_t < plan.fuel_t and 0.0 < s.baseline_fuel_beyond_t < s.baseline_fuel_t
    assert plan.fuel_beyond_forecast_t == pytest.approx(sum(leg["fuel_beyond_forecast_t"] for leg in plan.legs))
    # the legs' beyond fuel is the fuel of the hours past 60 h
    for leg in plan.legs:
        if leg["hours_beyond_forecast"] == 0.0:
            assert leg["fuel_beyond_forecast_t"] == 0.0
        elif leg["hours_beyond_forecast"] >= leg["hours"] - 1e-9:
            assert leg["fuel_beyond_forecast_t"] == pytest.approx(leg["fuel_t"], rel=1e-9)
    row = plan.route_row()
    assert row["savings_forecast_pct"] == pytest.approx(s.forecast_pct)
    assert row["savings_beyond_forecast_pct"] == pytest.approx(s.beyond_forecast_pct)
    again = savings_split(pr, fld, plan)
    assert again.forecast_pct == pytest.approx(s.forecast_pct, abs=1e-6)
    # a short voyage inside the forecast: no fuel, and no saving, past it
    short = problem((30.0, -175.0), (31.0, -168.0), 40.0, rpm_options=(70, 85, 100))
    p2 = solve(short, fld, solver="dp", savings=True)
    assert p2.forecast_flag is None
    assert p2.savings.beyond_forecast_pct == 0.0 and p2.savings.forecast_pct == pytest.approx(p2.savings.total_pct)


def test_fleet_savings_reports_what_the_forecast_backs_apart_from_what_lies_past_it(tmp_path):
    """Two voyages: V1 claims 10 t saved, 8 of them past the forecast's last step; V2 (inside the forecast) 5 t.
    fleet_savings keeps the total (15 t of 500) but says 7 t of it are backed by the forecast and 8 t are not."""
    import duckdb

    from flows.jobs.fleet import run_markdown
    from schemas.tables.routes import ROUTES
    from storage import route_store

    def row(v, fuel, base, fuel_beyond, base_beyond, flag):
        total = 100 * (base - fuel) / base
        beyond = 100 * (base_beyond - fuel_beyond) / base
        return ROUTES.empty_row(
            voyage_id=v, imo=9140607, solver="dp", objective="jit", status="ok", fuel_t=fuel, baseline_fuel_t=base,
            depart_utc="2020-12-01T06:00Z", cycle="2020-12-01T00Z", n_legs=2, n_legs_beyond_forecast=1 if flag else 0,
            forecast_flag=flag, hours_beyond_forecast=100.0 if flag else 0.0, honest_baseline_fuel_t=base,
            profile_fuel_t=base, savings_total_pct=total, savings_speed_profile_pct=0.0, savings_route_pct=total,
            fuel_beyond_forecast_t=fuel_beyond, honest_baseline_fuel_beyond_forecast_t=base_beyond,
            savings_forecast_pct=total - beyond, savings_beyond_forecast_pct=beyond)

    db = tmp_path / "w.duckdb"
    route_store.begin_run(db, "r1", cycle="2020-12-01T00", solver="dp", trigger="manual", n_voyages=3)
    rows = [row("V1", 190.0, 200.0, 92.0, 100.0, "beyond horizon"), row("V2", 295.0, 300.0, 0.0, 0.0, None),
            dict(row("V3", 100.0, 100.0, 0.0, 0.0, None), fuel_beyond_forecast_t=None,  # made before the split
                 honest_baseline_fuel_beyond_forecast_t=None, savings_forecast_pct=None, savings_beyond_forecast_pct=None)]
    route_store.write_run_results(db, tmp_path / "exports", "r1", rows, [])
    with duckdb.connect(str(db), read_only=True) as con:
        got = con.execute("SELECT n_compared, n_split, n_beyond_horizon, savings_total_pct, savings_forecast_pct, "
                          "savings_beyond_forecast_pct, fuel_beyond_forecast_t FROM fleet_savings").fetchone()
        comments = dict(con.execute("SELECT column_name, comment FROM duckdb_columns() WHERE table_name = 'routes' "
                                    "AND column_name LIKE '%forecast%'").fetchall())
    assert got[:3] == (3, 2, 1)
    assert got[3] == pytest.approx(100 * 15 / 600)
    assert got[4] == pytest.approx(100 * 7 / 500) and got[5] == pytest.approx(100 * 8 / 500)
    assert got[6] == pytest.approx(92.0)
    assert "backs" in comments["savings_forecast_pct"] and "assumption" in comments["savings_beyond_forecast_pct"]
    md = run_markdown(route_store.run_summary(db, "r1"))
    assert "1.4 % is saved within the forecast's valid times and 1.6 % past them (1 voyage sails" in md


def test_the_ensemble_sails_the_plan_and_its_baseline_through_every_member():
    """Members: the forecast planned on, and one with a 1 m/s current against the voyage (the same everywhere). In
    the first the plan is on time and burns what it planned; in the second it is late (same rpm, slower over ground)
    and so is its baseline; the fuel percentiles lie between the two members' fuel."""
    from pipeline.routing.ensemble import describe, sail_plan, spread

    pr = problem((30.0, -175.0), (31.0, -160.0), 80.0, rpm_options=(70, 85, 100))
    calm = wf.uniform(T0, 400)
    plan = solve(pr, calm, solver="dp", savings=True)
    assert plan.status == "ok" and plan.baseline is not None
    ves = pr.kernel_vessel()
    h, f = sail_plan(plan.legs, plan.depart_utc, calm, ves)
    assert h == pytest.approx(plan.hours, abs=1e-6) and f == pytest.approx(plan.fuel_t, rel=1e-9)
    against = wf.uniform(T0, 400, current_ms=(-1.0, 0.0))  # the voyage heads east
    h2, f2 = sail_plan(plan.legs, plan.depart_utc, against, ves)
    assert h2 > plan.hours + 5.0 and f2 > f
    s = spread(plan, [calm, against], ves)
    assert s.n_members == 2 and s.p_on_time == pytest.approx(0.5) and s.baseline_p_on_time == pytest.approx(0.5)
    assert f < s.fuel_p10_t < s.fuel_p50_t < s.fuel_p90_t < f2
    assert s.fuel_p50_t == pytest.approx((f + f2) / 2)
    b_calm = sail_plan(plan.baseline.legs, plan.depart_utc, calm, ves)[1]
    assert s.savings_p10_pct <= 100 * (b_calm - f) / b_calm + 1e-9 or s.savings_p90_pct >= 100 * (b_calm - f) / b_calm - 1e-9
    assert "across 2 forecasts: on time 50 %" in describe(s)
    assert spread(plan, [], ves) is None
