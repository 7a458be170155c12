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
    for model in (None, cal.fit_error_model([])):
        j = replace(job, error_model=model)
        same, _ = robust_plan(j, plan, calm, weather_for, [calm])
        assert same is plan and same.reason is None
        assert plan_spread(j, plan, [calm]) == plan_spread(job, plan, [calm])  # the one member's spread


def test_a_calibrated_model_aims_k_sigma_of_the_hours_ahead_early_with_one_member():
    calm = _current(0.0)
    weather_for = lambda problem, space: calm  # noqa: E731
    model = cal.ErrorModel(0.0, cal.PowerLaw(0.04, 1.0), 0.0, cal.PowerLaw(0.01, 0.5), 0.5, cal.PowerLaw(0.3, 0.5),
                           30, "calibrated")
    job = replace(_job(arrival_margin_sigmas=1.65, arrival_margin_max_share=1.0), error_model=model)
    plan, _ = plan_voyage(job, weather_for)
    aimed, _ = robust_plan(job, plan, calm, weather_for, [calm])
    margin = 1.65 * 0.04 * 55.0  # k × σ(55 h ahead) = 3.6 h
    assert aimed.rta_utc == plan.rta_utc
    assert "aims 3.6 h before the RTA (1.65 × σ 2.2 h of the arrival error 55 h ahead; forecast error calibrated " \
        "from 30 verified plans)" in aimed.reason
    assert aimed.hours <= plan.hours - margin + 0.6 and aimed.fuel_t > plan.fuel_t
    late = replace(job, error_model=replace(model, eta_bias_share=0.02))  # + 1.1 h of mean lateness 55 h ahead
    assert "aims 4.7 h before the RTA (its mean lateness 1.1 h + 1.65 × σ 2.2 h" in robust_plan(
        late, plan, calm, weather_for, [calm])[0].reason
    s = plan_spread(job, aimed, [calm])
    claimed = aimed.savings.total_pct
    assert s.savings_p50_pct == pytest.approx(0.5 * claimed)
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
