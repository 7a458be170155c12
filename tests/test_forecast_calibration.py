"""The forecast-error model calibrated from verified plans (pipeline/routing/calibration.py) and what it sizes: the
arrival margin by the hours ahead (job.robust_plan) and the plan's spread around the saving it can expect.

Errors are drawn here from a stated law (σ = a·h^b, a bias, a skill), so the fit must give back what was put in.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from pipeline.routing import calibration as cal
from pipeline.routing.job import plan_spread, plan_voyage, robust_plan
from test_robust_decisions import _current, _job


def _rows(n=1000, a=0.08, b=1.0, bias=0.02, fuel_sd=0.01, skill=0.4, sav_sd=0.5, seed=3):
    """plan_verification rows whose errors follow the stated law, claimed passages of 10..300 h."""
    rng = np.random.default_rng(seed)
    t0 = np.datetime64("2024-01-01T00:00", "s")
    rows = []
    for _ in range(n):
        h = rng.uniform(10.0, 300.0)
        e = bias * h + a * h ** b * rng.standard_normal()
        claim = rng.uniform(-1.0, 4.0)
        eta = t0 + np.timedelta64(int(round(h * 3600)), "s")
        rows.append({"coverage": "verified", "hours_total": h + e, "claimed_eta_utc": eta,
                     "realised_eta_utc": eta + np.timedelta64(int(round(e * 3600)), "s"), "claimed_fuel_t": 500.0,
                     "realised_fuel_t": 500.0 * (1.0 + fuel_sd * rng.standard_normal()), "claimed_savings_pct": claim,
                     "realised_savings_pct": skill * claim + sav_sd * rng.standard_normal()})
    return rows


def test_the_fit_gives_back_the_law_the_errors_were_drawn_from():
    m = cal.fit_error_model(cal.verification_errors(_rows()))
    assert m.source == "calibrated" and m.n_plans == 1000
    assert m.eta_bias_share == pytest.approx(0.02, abs=0.006)
    assert m.eta_sd_h.b == pytest.approx(1.0, abs=0.15)
    assert m.eta_sd_h.at(100.0) == pytest.approx(8.0, rel=0.15)  # 0.08 × 100 h
    assert m.fuel_sd_share.at(100.0) == pytest.approx(0.01, rel=0.2)
    assert m.skill == pytest.approx(0.4, abs=0.05)
    assert m.saving_sd_pts.at(100.0) == pytest.approx(0.5, rel=0.2)
    # a spread growing as the square root of the lead is told apart from one growing linearly
    sq = cal.fit_error_model(cal.verification_errors(_rows(a=0.8, b=0.5, bias=0.0)))
    assert sq.eta_sd_h.b == pytest.approx(0.5, abs=0.15) and abs(sq.eta_bias_share) < 0.01


def test_too_few_verified_plans_give_the_stated_default_and_say_so():
    rows = _rows(n=cal.MIN_PLANS - 1)
    m = cal.fit_error_model(cal.verification_errors(rows))
    assert m.source == "default" and m.n_plans == cal.MIN_PLANS - 1
    assert m.eta_sd_h == cal.DEFAULT.eta_sd_h and m.skill == cal.DEFAULT.skill
    assert "default" in m.note() and f"only {cal.MIN_PLANS - 1} verified plans" in m.note()
    assert "calibrated from 1000 verified plans" in cal.fit_error_model(cal.verification_errors(_rows())).note()


def test_only_wholly_verified_rows_with_a_claim_and_a_realisation_count():
    rows = _rows(n=5)
    rows[1]["coverage"] = "partly verified"
    rows[2]["realised_eta_utc"] = None
    rows[3]["claimed_fuel_t"] = float("nan")
    errs = cal.verification_errors(rows)
    assert len(errs) == 2
    r = rows[0]
    e = float((r["realised_eta_utc"] - r["claimed_eta_utc"]) / np.timedelta64(1, "s")) / 3600.0
    assert errs[0].eta_error_h == pytest.approx(e) and errs[0].hours_ahead == pytest.approx(r["hours_total"] - e)


def test_the_margin_shrinks_as_the_voyage_nears_its_end_and_is_capped():
    m = cal.ErrorModel(0.01, cal.PowerLaw(0.1, 1.0), 0.0, cal.PowerLaw(0.01, 0.5), 0.5, cal.PowerLaw(0.2, 0.5), 20,
                       "calibrated")
    assert cal.arrival_margin_h(m, 200.0, 1.65, max_share=1.0) == pytest.approx(0.01 * 200 + 1.65 * 0.1 * 200)
    assert cal.arrival_margin_h(m, 24.0, 1.65, max_share=1.0) == pytest.approx(0.01 * 24 + 1.65 * 0.1 * 24)
    assert cal.arrival_margin_h(m, 200.0, 1.65, max_share=0.05) == pytest.approx(10.0)
    assert cal.arrival_margin_h(m, 200.0, 0.0) == 0.0
    # sized by the error after the last re-plan: at most horizon_h hours ahead, the cap still on the hours ahead
    assert cal.arrival_margin_h(m, 200.0, 1.65, max_share=1.0, horizon_h=24.0) == pytest.approx(0.01 * 24 + 1.65 * 0.1 * 24)
    assert cal.arrival_margin_h(m, 12.0, 1.65, max_share=1.0, horizon_h=24.0) == pytest.approx(0.01 * 12 + 1.65 * 0.1 * 12)
    assert cal.arrival_margin_h(m, 200.0, 1.65, max_share=0.01, horizon_h=24.0) == pytest.approx(2.0)
    assert cal.margin_error_h(200.0, None) == 200.0 and cal.margin_error_h(200.0, 24.0) == 24.0
    # ... and what of the whole passage's error (35 h here) the ship's speed reserve cannot make up, when more
    whole, last = 0.01 * 200 + 1.65 * 0.1 * 200, 0.01 * 24 + 1.65 * 0.1 * 24
    assert cal.arrival_margin_h(m, 200.0, 1.65, 1.0, horizon_h=24.0, reserve_h=10.0) == pytest.approx(whole - 10.0)
    assert cal.arrival_margin_h(m, 200.0, 1.65, 1.0, horizon_h=24.0, reserve_h=40.0) == pytest.approx(last)
    assert cal.arrival_margin_h(m, 200.0, 1.65, 1.0, horizon_h=24.0, reserve_h=0.0) == pytest.approx(whole)
    assert cal.arrival_margin_h(m, 200.0, 1.65, 1.0, reserve_h=40.0) == pytest.approx(whole)  # no horizon: all of it


def test_the_default_model_needs_two_members_a_calibrated_one_none():
    calibrated = cal.fit_error_model(cal.verification_errors(_rows()))
    default = cal.fit_error_model([])
    assert cal.in_effect(default, 1) is None and cal.in_effect(default, 2) is default
    assert cal.in_effect(calibrated, 0) is calibrated and cal.in_effect(None, 4) is None


def test_p_on_time_and_the_expected_saving():
    m = cal.ErrorModel(0.0, cal.PowerLaw(0.05, 1.0), 0.0, cal.PowerLaw(0.01, 0.0), 0.5, cal.PowerLaw(0.4, 0.0), 20,
                       "calibrated")
    # 100 h planned, σ 5 h: on time by the RTA itself half the time, 1.65 σ early 95 %
    assert cal.p_on_time(m, 100.0, 100.0) == pytest.approx(0.5)
    assert cal.p_on_time(m, 100.0 - 1.65 * 5.0 * 0.95, 100.0) == pytest.approx(0.95, abs=0.01)
    lo, mid, hi = cal.expected_saving_pct(m, 3.0, 100.0)
    assert mid == pytest.approx(1.5) and hi - mid == pytest.approx(cal.Z90 * 0.4) and mid - lo == pytest.approx(hi - mid)


def test_with_one_member_and_no_history_the_plan_is_the_solvers():
    calm = _current(0.0)
    weather_for = lambda problem, space: calm  # noqa: E731
    job = _job(arrival_margin_sigmas=1.65, arrival_margin_max_share=1.0)
    plan, _ = plan_voyage(job, weather_for)
    solvers_reason = plan.reason  # the solver's own (dp: the space it certifies)
    for model in (None, cal.fit_error_model([])):
        j = replace(job, error_model=model)
        same, _ = robust_plan(j, plan, calm, weather_for, [calm])
        assert same is plan and same.reason == solvers_reason  # nothing added
        assert plan_spread(j, plan, [calm]) == plan_spread(job, plan, [calm])  # the one member's spread


def _calm_voyage_with_a_calibrated_model():
    """(calm weather, its weather_for, a calibrated model with σ_eta = 0.04 · h, the job aiming 1.65 σ early with it,
    the solver's plan for the RTA)."""
    calm = _current(0.0)
    weather_for = lambda problem, space: calm  # noqa: E731
    model = cal.ErrorModel(0.0, cal.PowerLaw(0.04, 1.0), 0.0, cal.PowerLaw(0.01, 0.5), 0.5, cal.PowerLaw(0.3, 0.5),
                           30, "calibrated")
    job = replace(_job(arrival_margin_sigmas=1.65, arrival_margin_max_share=1.0), error_model=model)
    plan, _ = plan_voyage(job, weather_for)
    return calm, weather_for, model, job, plan


@pytest.mark.slow
def test_a_calibrated_model_aims_k_sigma_of_the_hours_ahead_early_with_one_member():
    calm, weather_for, model, job, plan = _calm_voyage_with_a_calibrated_model()
    aimed, _ = robust_plan(job, plan, calm, weather_for, [calm])
    margin = 1.65 * 0.04 * 55.0  # k × σ(55 h ahead) = 3.6 h
    assert aimed.rta_utc == plan.rta_utc
    assert "aims 3.6 h before the RTA (1.65 × σ 2.2 h of the arrival error 55 h ahead; forecast error calibrated " \
        "from 30 verified plans)" in aimed.reason
    assert aimed.hours <= plan.hours - margin + 0.6 and aimed.fuel_t > plan.fuel_t
    last = replace(job, options=replace(job.options, arrival_margin_horizon_h=12.0))  # the error after a last re-plan
    last_reason = robust_plan(last, plan, calm, weather_for, [calm])[0].reason
    assert "aims 0.8 h before the RTA (1.65 × σ 0.5 h of the arrival error 12 h ahead" in last_reason
    assert "its speed reserve of" in last_reason  # in calm water at full speed it could gain hours: not needed here
    late = replace(job, error_model=replace(model, eta_bias_share=0.02))  # + 1.1 h of mean lateness 55 h ahead
    assert "aims 4.7 h before the RTA (its mean lateness 1.1 h + 1.65 × σ 2.2 h" in robust_plan(
        late, plan, calm, weather_for, [calm])[0].reason
    s = plan_spread(job, aimed, [calm])
    claimed, margin_cost = aimed.savings.total_pct, aimed.savings.margin_cost_pct
    assert s.savings_p50_pct == pytest.approx(0.5 * (claimed + margin_cost) - margin_cost)
    assert s.p_on_time > 0.9  # aimed 1.65 σ early: on time about 95 % of the time
    assert s.fuel_p10_t < aimed.fuel_t < s.fuel_p90_t
    assert "expected to realise a saving of" in aimed.reason
    assert math.isfinite(s.baseline_p_on_time)


def test_route_fleet_fits_the_model_on_the_warehouses_verified_plans(tmp_path):
    from datetime import datetime

    from flows.jobs.fleet import error_model
    from schemas.tables.routes import PLAN_VERIFICATION
    from storage import route_store, verification_store

    db = tmp_path / "warehouse.duckdb"
    route_store.begin_run(db, "R1", cycle=np.datetime64("2024-01-01T00"), solver="bfoa", trigger="manual", n_voyages=12)
    assert error_model(db).source == "default" and error_model(db).n_plans == 0  # no history yet
    drawn = _rows(n=12)
    rows = [PLAN_VERIFICATION.empty_row(run_id="R1", voyage_id=f"V{i}", plan_kind="port", verified_at=datetime(2024, 1, 9),
                                        **{k: (v.item() if isinstance(v, np.datetime64) else v) for k, v in r.items()})
            for i, r in enumerate(drawn)]
    rows[0]["coverage"] = "partly verified"  # its realised figures are partly a forecast: not counted
    verification_store.write_verifications(db, rows)
    m = error_model(db)
    assert m.source == "calibrated" and m.n_plans == 11
    same = cal.fit_error_model(cal.verification_errors(drawn[1:]))  # the same fit as on the rows themselves
    for name in ("eta_bias_share", "fuel_bias_share", "skill"):
        assert getattr(m, name) == pytest.approx(getattr(same, name), rel=1e-9)
    assert m.eta_sd_h.at(100.0) == pytest.approx(same.eta_sd_h.at(100.0), rel=1e-9)


@pytest.mark.slow
def test_a_plan_aiming_early_claims_against_the_baseline_arriving_at_the_rta_and_shows_the_margins_cost():
    calm, weather_for, model, job, plan = _calm_voyage_with_a_calibrated_model()
    margin_s = int(round(cal.arrival_margin_h(model, 55.0, 1.65, 1.0) * 3600.0))  # 3.6 h
    early_job = replace(job, voyage={**job.voyage, "rta_utc": job.voyage["rta_utc"] - np.timedelta64(margin_s, "s")})
    early, _ = plan_voyage(early_job, weather_for)  # what the margin aims at, planned by hand
    aimed, _ = robust_plan(job, plan, calm, weather_for, [calm])
    s, at_rta = aimed.savings, plan.savings
    # against the constant speed arriving at the RTA itself, the voyage the master sails (and verification re-sails)
    assert aimed.baseline is plan.baseline and s.baseline_fuel_t == at_rta.baseline_fuel_t
    assert s.total_pct == pytest.approx(100.0 * (at_rta.baseline_fuel_t - aimed.fuel_t) / at_rta.baseline_fuel_t)
    # the margin's cost: the constant speed arriving 3.6 h early burns that much more than the one arriving at the RTA
    f_early = early.savings.baseline_fuel_t
    assert f_early > at_rta.baseline_fuel_t
    assert s.margin_cost_pct == pytest.approx(100.0 * (f_early - at_rta.baseline_fuel_t) / at_rta.baseline_fuel_t)
    assert s.speed_profile_pct + s.route_pct - s.margin_cost_pct == pytest.approx(s.total_pct)
    assert s.forecast_pct + s.beyond_forecast_pct == pytest.approx(s.total_pct)
    # in calm water a plan can gain nothing on the constant speed: aiming early is a loss of about the margin's cost
    assert s.total_pct < -0.5 * s.margin_cost_pct < 0.0
    assert "after the margin's cost of" in aimed.reason
    row = aimed.route_row("R1")
    assert row["margin_cost_pct"] == pytest.approx(s.margin_cost_pct) and row["savings_total_pct"] == s.total_pct
    assert plan.route_row("R1")["margin_cost_pct"] == 0.0  # a plan for the RTA costs no margin


def test_the_expected_saving_discounts_the_forecasts_gain_but_not_the_margins_cost():
    m = cal.ErrorModel(0.0, cal.PowerLaw(0.05, 1.0), 0.0, cal.PowerLaw(0.01, 0.0), 0.5, cal.PowerLaw(0.4, 0.0), 20,
                       "calibrated")
    # gains 3 % on the early constant speed, whose 2 % more than at the RTA is paid for sure: claim 1 %
    lo, mid, hi = cal.expected_saving_pct(m, 1.0, 100.0, margin_cost_pct=2.0)
    assert mid == pytest.approx(0.5 * 3.0 - 2.0) and hi - mid == pytest.approx(cal.Z90 * 0.4)


def test_route_severity_is_the_hours_weighted_mean_hs_inside_the_forecast():
    legs = [{"hours": 10.0, "hs_m": 1.0, "beyond_forecast": False}, {"hours": 30.0, "hs_m": 5.0, "beyond_forecast": False},
            {"hours": 50.0, "hs_m": 9.0, "beyond_forecast": True}]  # past the last step: neutral weather, left out
    assert cal.route_hs_mean_m(legs) == pytest.approx((10 * 1.0 + 30 * 5.0) / 40.0)
    assert math.isnan(cal.route_hs_mean_m(legs[2:])) and math.isnan(cal.route_hs_mean_m([]))


def _stormy_and_calm_rows(n=600, seed=5):
    """Half the plans on calm routes (Hs 1–2 m: σ 0.02·h, no bias), half through storms (Hs 3–5 m: σ 0.08·h, late by
    3 % of the hours ahead)."""
    calm = _rows(n=n // 2, a=0.02, bias=0.0, seed=seed)
    stormy = _rows(n=n // 2, a=0.08, bias=0.03, seed=seed + 1)
    rng = np.random.default_rng(seed)
    for r in calm:
        r["route_hs_mean_m"] = rng.uniform(1.0, 2.0)
    for r in stormy:
        r["route_hs_mean_m"] = rng.uniform(3.0, 5.0)
    return calm + stormy


def test_the_model_splits_by_the_forecasts_severity_when_the_errors_differ_with_it():
    m = cal.fit_error_model(cal.verification_errors(_stormy_and_calm_rows()))
    assert 2.0 <= m.severity_split_m <= 3.0  # between the calm routes' Hs and the stormy ones'
    calm, stormy = m.given(1.5), m.given(4.0)
    assert calm.n_plans == 300 and stormy.n_plans == 300
    assert calm.eta_sd_h.at(100.0) == pytest.approx(2.0, rel=0.2) and abs(calm.eta_bias_share) < 0.005
    assert stormy.eta_sd_h.at(100.0) == pytest.approx(8.0, rel=0.2)
    assert stormy.eta_bias_share == pytest.approx(0.03, abs=0.008)
    # the margin: small on a calm route, large through storms; the whole model's without a severity
    assert cal.arrival_margin_h(calm, 200.0, 1.65, 1.0) < 0.4 * cal.arrival_margin_h(stormy, 200.0, 1.65, 1.0)
    assert m.given(float("nan")) is m and calm.given(4.0) is calm
    assert "whose route's mean Hs in the forecast was below" in calm.note() and "as this plan's 1.5 m" in calm.note()
    # the split explains the errors better than the hours alone
    whole = replace(m, calm=None, stormy=None)
    errs = cal.verification_errors(_stormy_and_calm_rows())
    assert cal.eta_neg_log_likelihood(m, errs) < cal.eta_neg_log_likelihood(whole, errs) - cal.SPLIT_EXTRA_PARAMS


def test_no_split_where_the_severity_tells_nothing_or_is_unknown():
    rows = _rows(n=600)
    rng = np.random.default_rng(9)
    for r in rows:
        r["route_hs_mean_m"] = rng.uniform(1.0, 5.0)  # drawn apart from the errors
    m = cal.fit_error_model(cal.verification_errors(rows))
    assert m.calm is None and m.given(4.0) is m
    assert cal.fit_error_model(cal.verification_errors(_rows(n=600))).calm is None  # no severity at all


def test_the_warehouse_gives_each_verified_plan_its_routes_severity_and_stores_the_margins_cost(tmp_path):
    import duckdb

    from schemas.tables.routes import PLAN_VERIFICATION, ROUTE_LEGS, ROUTES
    from storage import route_store, verification_store

    db, run = tmp_path / "warehouse.duckdb", "R1"
    route_store.begin_run(db, run, cycle=np.datetime64("2024-01-01T00"), solver="bfoa", trigger="manual", n_voyages=2)
    routes = [ROUTES.empty_row(run_id=run, voyage_id=v, imo=9000001, status="ok", fuel_t=100.0, n_legs=2,
                               margin_cost_pct=m) for v, m in (("A", 1.25), ("B", None))]
    legs = [ROUTE_LEGS.empty_row(run_id=run, voyage_id="A", leg=i, hours=h, hs_m=hs, beyond_forecast=b)
            for i, (h, hs, b) in enumerate([(10.0, 1.0, False), (30.0, 5.0, False), (50.0, 9.0, True)])]
    route_store.write_run_results(db, tmp_path / "exports", run, routes, legs)
    rows = [PLAN_VERIFICATION.empty_row(run_id=run, voyage_id=v, plan_kind="port", coverage="verified",
                                        verified_at=np.datetime64("2024-01-09T00").item()) for v in "AB"]
    verification_store.write_verifications(db, rows)
    got = verification_store.verifications(db).set_index("voyage_id")["route_hs_mean_m"]
    assert got["A"] == pytest.approx(cal.route_hs_mean_m([{"hours": 10.0, "hs_m": 1.0}, {"hours": 30.0, "hs_m": 5.0}]))
    assert math.isnan(got["B"])  # no legs stored: unknown, the hours-only model
    with duckdb.connect(str(db), read_only=True) as con:
        stored = dict(con.execute("SELECT voyage_id, margin_cost_pct FROM latest_routes").fetchall())
    assert stored == {"A": 1.25, "B": None}


def test_a_margin_the_ship_cannot_make_gives_the_earliest_arrival_it_can_not_a_plan_for_the_rta():
    calm = _current(0.0)
    weather_for = lambda problem, space: calm  # noqa: E731
    model = cal.ErrorModel(0.0, cal.PowerLaw(0.165, 1.0), 0.0, cal.PowerLaw(0.01, 0.5), 0.5, cal.PowerLaw(0.3, 0.5),
                           30, "calibrated")  # 1.65 × 0.165 × 55 h = 15 h: aims at 40 h, the ship needs 44 h at full speed
    job = replace(_job(arrival_margin_sigmas=1.65, arrival_margin_max_share=1.0), error_model=model)
    plan, _ = plan_voyage(job, weather_for)
    aimed, _ = robust_plan(job, plan, calm, weather_for, [calm])
    assert aimed.status == "ok" and aimed.rta_utc == plan.rta_utc
    assert 40.0 < aimed.hours < plan.hours - 5.0  # as early as it can, hours before the plan for the RTA
    assert "aims 15.0 h before the RTA" in aimed.reason and "can arrive only" in aimed.reason
    assert aimed.savings.margin_cost_pct > 0.0 and aimed.baseline is plan.baseline
