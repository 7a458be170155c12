"""Noon-report validation and import, least-squares fits, activation rule, fuzzy model."""

import io
import json

import duckdb
import numpy as np
import pandas as pd
import pytest

from pipeline.performance import features, fit, fuzzy
from pipeline.performance.refit import refit_vessel
from pipeline.performance.validate import NoonFileError, validate_noon
from pipeline.synthetic.fleet import generate_fleet, is_valid_imo
from storage import fleet_store


@pytest.fixture(scope="module")
def fleet():
    return generate_fleet("2020-12-01T00", n_vessels=4, days=365, seed=3)


def _as_text(df):
    return pd.read_csv(io.StringIO(df.to_csv(index=False)), dtype=str, keep_default_na=False, na_values=[""])


def test_demo_fleet_has_valid_imos_and_voyages(fleet):
    assert all(is_valid_imo(i) for i in fleet.vessels.imo)
    assert not is_valid_imo(9140608)
    assert (fleet.voyages.rta_utc > fleet.voyages.depart_utc).all()


def test_physical_coefficients_are_recovered(fleet):
    good, _ = validate_noon(_as_text(fleet.noon), set(fleet.vessels.imo))
    imo = int(fleet.vessels.imo[1])
    rows, summary = refit_vessel(imo, good[good.imo == imo].sort_values("ts_utc"), None, 1)
    truth = fleet.true_models[imo]
    speed = np.array(list(json.loads(rows[0]["coefficients"]).values()))
    fuel = np.array(list(json.loads(rows[1]["coefficients"]).values()))
    assert speed[1] == pytest.approx(truth.speed_coef[1], rel=0.03)  # kn per rpm
    assert speed[5] == pytest.approx(truth.speed_coef[5], rel=0.15)  # head-sea loss
    assert fuel[1] == pytest.approx(truth.fuel_coef[1], rel=0.05)  # rpm³ term
    assert summary["speed_r2"] > 0.98 and summary["fuel_r2"] > 0.98
    assert summary["speed_rmse"] == pytest.approx(0.15, abs=0.03)  # the noise we put in
    assert summary["speed_cv_rmse"] >= summary["speed_rmse"]


def test_thesis_form_matches_numpy_lstsq_on_a_hand_made_table():
    rng = np.random.default_rng(0)
    n = 12
    D, T, rpm = rng.uniform(8, 12, n), rng.uniform(-1, 1, n), rng.uniform(60, 100, n)
    wd, ws, vd, vh = rng.uniform(0, 180, n), rng.uniform(0, 30, n), rng.uniform(0, 180, n), rng.uniform(0, 5, n)
    y = 0.3 * D + 0.2 * T + 0.12 * rpm - 0.004 * wd - 0.03 * ws + 0.002 * vd - 0.4 * vh + rng.normal(0, 0.05, n)
    X = features.design_matrix(features.FORM_THESIS, "speed", rpm, D, T, ws, wd, vh, vd, np.zeros(n))
    np.testing.assert_allclose(X[:, 0], D)  # column order a1·D, a2·T, a3·rpm, a4·WindDir, a5·WindSpd, a6·WaveDir, a7·WaveHt
    np.testing.assert_allclose(X[:, 3], wd)
    res = fit.fit_target("thesis", "speed", X, y)
    np.testing.assert_allclose(res.coef, np.linalg.lstsq(X, y, rcond=None)[0], rtol=1e-6)


def test_constant_regressor_is_dropped_and_said():
    n = 40
    rng = np.random.default_rng(1)
    rpm = rng.uniform(60, 100, n)
    X = features.design_matrix(features.FORM_THESIS, "speed", rpm, np.full(n, 10.0), np.zeros(n), np.zeros(n), np.zeros(n),
                               np.zeros(n), np.zeros(n), np.zeros(n))
    res = fit.fit_target("thesis", "speed", X, 0.15 * rpm)
    # draft is constant here, so it cannot be told apart from the intercept: dropped too
    assert set(res.dropped) == {"draft_m", "trim_m", "wind_dir_rel_deg", "wind_kn", "wave_dir_rel_deg", "wave_m"}
    assert res.rmse < 1e-8


def test_every_rejection_reason(fleet):
    base = fleet.noon[fleet.noon.imo == fleet.vessels.imo[1]].head(3).iloc[0].to_dict()
    def row(**kw):
        r = dict(base); r.update(kw); return r
    cases = {
        "missing stw_kn": row(stw_kn=None),
        "not a number in rpm": row(rpm="eighty"),
        "bad timestamp": row(ts_utc="yesterday noon"),
        "unknown vessel": row(imo=9999999),
        "hours <= 0": row(hours=0),
        "negative fuel_t": row(fuel_t=-1),
        "out of range draft_m": row(draft_m=40),
        "speed beyond physics": row(stw_kn=50, sog_kn=50, dist_nm=50 * base["hours"]),
        "fuel looks like kg": row(fuel_t=base["fuel_t"] * 1000),
        "speed looks like m/s": row(sog_kn=base["sog_kn"] / 1.943844),
        "sog inconsistent with distance": row(dist_nm=base["dist_nm"] * 1.5),
    }
    rows = [cases[k] for k in cases] + [base, dict(base)]
    good, bad = validate_noon(_as_text(pd.DataFrame(rows)), set(fleet.vessels.imo))
    assert list(bad.reason) == list(cases) + ["duplicate timestamp in file"]
    assert len(good) == 1


def test_file_without_required_columns_is_refused():
    with pytest.raises(NoonFileError, match="reports.csv.*fuel_t"):
        validate_noon(pd.DataFrame({"imo": ["1"], "ts_utc": ["2020-01-01"]}), source="reports.csv")


def test_import_is_idempotent_and_conflicts_are_rejected(fleet, tmp_path):
    db = tmp_path / "w.duckdb"
    fleet_store.import_vessels(db, fleet.vessels)
    good, bad = validate_noon(_as_text(fleet.noon), fleet_store.known_imos(db))
    first = fleet_store.import_noon(db, good, bad)
    again = fleet_store.import_noon(db, *validate_noon(_as_text(fleet.noon), fleet_store.known_imos(db)))
    assert first["inserted"] == len(good) and again["inserted"] == 0 and again["already_present"] == len(good)
    con = duckdb.connect(str(db), read_only=True)
    n_rej = con.execute("SELECT count(*) FROM noon_reports_rejected").fetchone()[0]
    con.close()
    assert n_rej == len(bad) > 0  # re-import added no rejected rows either
    changed = good.head(1).copy()
    changed["stw_kn"] += 1.0
    c = fleet_store.import_noon(db, changed, bad.head(0))
    assert c["conflicts"] == 1 and c["inserted"] == 0


def test_worse_or_underdetermined_models_are_not_activated(fleet):
    good, _ = validate_noon(_as_text(fleet.noon), set(fleet.vessels.imo))
    imo = int(fleet.vessels.imo[2])
    g = good[good.imo == imo].sort_values("ts_utc")
    rows, s = refit_vessel(imo, g.head(20), None, 1)
    assert not s["changed"] and "under-determined" in s["reason"] and not rows[0]["active"]
    rows, s = refit_vessel(imo, g, None, 1)
    assert s["changed"]
    active = {"form": "physical", "version": 1, "speed": json.loads(rows[0]["coefficients"]), "fuel": json.loads(rows[1]["coefficients"])}
    spoiled = g.copy()
    spoiled.loc[spoiled.index[:250], "stw_kn"] = spoiled["stw_kn"].iloc[:250] * 0.6  # a corrupted history
    rows2, s2 = refit_vessel(imo, spoiled, active, 2, robust=False)
    assert not s2["changed"] and "worse on held-out" in s2["reason"]
    _, s3 = refit_vessel(imo, g, active, 2)
    assert not s3["changed"] and s3["reason"] == "same as the active model"


@pytest.mark.parametrize("inputs,expected", [((8, 4, 1), 1.75), ((8, 5, 3), 1.75), ((10, 2, 3), 1.75), ((6, 3, 4), 1.43),
                                             ((10, 5, 7), 2.57), ((5, 2, 2), 0.934)])
def test_fuzzy_model_reproduces_published_outputs(inputs, expected):
    assert fuzzy.fuel_tph(*inputs) == pytest.approx(expected, abs=0.01)


def test_fuzzy_fires_the_published_rules():
    assert fuzzy.fired_rules(8, 4, 1) == [23, 26]
    assert fuzzy.fired_rules(10, 5, 7) == [17, 18]
