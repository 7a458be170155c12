"""Noon-report validation and import, least-squares fits, activation rule, fuzzy model."""

import io
import json
import shutil
from pathlib import Path

import duckdb
import numpy as np
import pandas as pd
import pytest

from pipeline.performance import features, fit, fuzzy, huber, mlp
from pipeline.performance.refit import REPORT_COLUMNS, Gate, fitted_from_rows, refit_fleet, refit_vessel, storage_actions
from pipeline.performance.validate import NoonFileError, validate_noon
from pipeline.synthetic.fleet import generate_fleet, is_valid_imo
from storage import fleet_store
from tests.noon_cases import rejection_cases


@pytest.fixture(scope="module")
def fleet():
    return generate_fleet("2020-12-01T00", n_vessels=4, days=365, seed=3)


def _as_text(df):
    return pd.read_csv(io.StringIO(df.to_csv(index=False)), dtype=str, keep_default_na=False, na_values=[""])


@pytest.fixture(scope="module")
def fleet_checked(fleet):
    """`fleet`'s noon reports as a CSV file gives them, validated: (good, rejected), made once; tests take copies."""
    return validate_noon(_as_text(fleet.noon), set(fleet.vessels.imo))


def test_demo_fleet_has_valid_imos_and_voyages(fleet):
    assert all(is_valid_imo(i) for i in fleet.vessels.imo)
    assert not is_valid_imo(9140608)
    assert (fleet.voyages.rta_utc > fleet.voyages.depart_utc).all()


def test_physical_coefficients_are_recovered(fleet, fleet_checked):
    good = fleet_checked[0].copy()
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


def test_direction_fold_and_joint_design_equal_their_plain_definitions():
    """fold_rel_deg skips the float mod for the usual range but gives |((rel + 180) mod 360) − 180| exactly;
    design_matrices gives what design_matrix gives per target, bit for bit."""
    rng = np.random.default_rng(2)
    rel = np.concatenate([rng.uniform(-2000, 2000, 20000), rng.integers(-720, 721, 2000).astype(float),
                          [0.0, -0.0, 180.0, -180.0, 540.0, 360.0, 720.0, -360.0, 1e300, np.nan, np.inf],
                          np.nextafter([180.0, -180.0, 540.0, 900.0], np.inf), np.nextafter([180.0, -180.0, 540.0], -np.inf)])
    got = np.array([features.fold_rel_deg(r) for r in rel])
    np.testing.assert_array_equal(got, [abs(((r + 180.0) % 360.0) - 180.0) for r in rel.tolist()])  # Python's float mod
    n = 500
    cols = [rng.uniform(40, 110, n), rng.uniform(5, 15, n), rng.uniform(-1, 2, n), rng.uniform(0, 40, n),
            rng.uniform(-360, 720, n), rng.uniform(0, 8, n), rng.uniform(-360, 720, n), rng.uniform(0, 30, n)]
    for form in (features.FORM_THESIS, features.FORM_PHYSICAL):
        Xs, Xf = features.design_matrices(form, *cols)
        np.testing.assert_array_equal(Xs, features.design_matrix(form, "speed", *cols))
        np.testing.assert_array_equal(Xf, features.design_matrix(form, "fuel", *cols))

def test_constant_regressor_is_dropped_only_beside_an_intercept():
    n = 40
    rng = np.random.default_rng(1)
    rpm = rng.uniform(60, 100, n)
    zeros = np.zeros(n)
    X = features.design_matrix(features.FORM_THESIS, "speed", rpm, np.full(n, 10.0), zeros, zeros, zeros, zeros, zeros, zeros)
    res = fit.fit_target("thesis", "speed", X, 0.15 * rpm + 2.0)
    # no intercept in the thesis form: the constant draft is its only constant term and stays; all-zero columns go
    assert set(res.dropped) == {"trim_m", "wind_dir_rel_deg", "wind_kn", "wave_dir_rel_deg", "wave_m"}
    np.testing.assert_allclose(res.coef[:3], [0.2, 0.0, 0.15], atol=1e-9)
    X = features.design_matrix(features.FORM_PHYSICAL, "speed", rpm, np.full(n, 10.0), np.full(n, 0.5), zeros, zeros, zeros,
                               zeros, np.full(n, 3.0))
    res = fit.fit_target("physical", "speed", X, 0.15 * rpm + 2.0)
    # beside the intercept "1" a constant draft, trim or fouling cannot be told apart from it: dropped and said
    assert {"draft_m", "trim_m", "months_dd"} <= set(res.dropped) and "1" not in res.dropped
    assert res.rmse < 1e-8


GAS_NIRVANA = Path(__file__).parent / "fixtures" / "gas_nirvana_fig3_15.csv"


def gas_nirvana() -> pd.DataFrame:
    """The thesis's 22 hourly records of MV Gas Nirvana (figure 3.15), oldest first, as noon-report columns."""
    df = pd.read_csv(GAS_NIRVANA, comment="#").sort_values("ts_utc").reset_index(drop=True)
    return df.assign(imo=9140607, hours=1.0, months_since_drydock=0.0)


@pytest.mark.slow
def test_thesis_form_reproduces_the_published_gas_nirvana_fit():
    """Ordinary least squares, no intercept, on [draft, trim, rpm, wind direction, wind speed]: the thesis's
    speed coefficients, R² and RMSE. Trim is 2 on every row: it is kept (the only constant term); the wave
    columns are all zero (0/0 in the table): β = 0."""
    inp = fit.inputs_from_reports(gas_nirvana())
    X = fit.design("thesis", "speed", inp)
    assert X.shape == (22, 7) and (X[:, 1] == 2.0).all()
    res = fit.fit_target("thesis", "speed", X, inp["stw_kn"])
    assert not res.robust
    np.testing.assert_allclose(res.coef[:5], [1.80521, 12.63045, -0.13117, -0.02029, -0.09710], atol=1e-4)
    assert res.dropped == ["wave_dir_rel_deg", "wave_m"] and (res.coef[5:] == 0).all()
    assert res.r2 == pytest.approx(0.8854, abs=1e-4) and res.rmse == pytest.approx(0.580, abs=1e-3)
    # the refit path takes the form's default (no Huber re-weighting for the thesis form), and its gate
    # refuses this model: 18 training rows for 5 coefficients, and fuel is not explained (R² 0.14 in-sample)
    assert fit.robust_default("thesis") is False and fit.robust_default("physical") is True
    fuel = fit.fit_target("thesis", "fuel", fit.design("thesis", "fuel", inp), inp["fuel_tph"])
    assert fuel.r2 == pytest.approx(0.1357, abs=1e-3)
    rows, s = refit_vessel(9140607, gas_nirvana(), None, 1, form="thesis")
    assert not s["changed"] and [r["status"] for r in rows] == ["rejected", "rejected"]
    assert "under-determined: 18 training rows" in s["reason"]
    rows, s = refit_vessel(9140607, gas_nirvana(), None, 1, form="thesis", gate=Gate(min_rows_per_coef=3))
    assert not s["changed"] and "fuel R² " in s["why"]


def test_every_rejection_reason(fleet):
    base = fleet.noon[fleet.noon.imo == fleet.vessels.imo[1]].head(3).iloc[0].to_dict()
    cases = rejection_cases(base)
    rows = [cases[k] for k in cases] + [base, dict(base)]
    good, bad = validate_noon(_as_text(pd.DataFrame(rows)), set(fleet.vessels.imo))
    assert list(bad.reason) == list(cases) + ["duplicate timestamp in file"]
    assert len(good) == 1


def test_file_without_required_columns_is_refused():
    with pytest.raises(NoonFileError, match="reports.csv.*fuel_t"):
        validate_noon(pd.DataFrame({"imo": ["1"], "ts_utc": ["2020-01-01"]}), source="reports.csv")


@pytest.mark.slow
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



@pytest.mark.slow  # a whole generated fleet imported three ways (at once, month by month, in reverse)
def test_refit_read_matches_the_ordered_table_read(fleet, tmp_path):
    """`load_for_refit` (Arrow, ordered in numpy) gives the rows `load_reports` gives (ORDER BY imo, ts),
    and the same active models and next versions, for the whole fleet and for some vessels, whether
    the rows came in one import, in monthly imports in time order, or in imports out of order."""
    good, bad = validate_noon(_as_text(fleet.noon), set(fleet.vessels.imo))
    good.loc[good.index[:3], "wind_kn"] = np.nan  # NULLs read as NaN
    imo = int(fleet.vessels.imo[1])
    rows, _ = refit_vessel(imo, good[good.imo == imo].sort_values("ts_utc"), None, 1)
    cols = ("imo", "ts_utc", "rpm", "wind_kn", "fuel_t")
    months = [g for _, g in good.groupby(pd.to_datetime(good["ts_utc"]).dt.to_period("M"))]
    for imports in ([good], months, months[::-1]):
        db = tmp_path / f"w{len(list(tmp_path.iterdir()))}.duckdb"
        fleet_store.import_vessels(db, fleet.vessels)
        for part in imports:
            fleet_store.import_noon(db, part.sample(frac=1.0, random_state=0), bad.head(0))
        assert fleet_store.save_fits(db, rows) == fleet_store.active_models(db)  # what it returns is what it stored
        for imos in (None, [int(fleet.vessels.imo[2]), imo]):
            arrays, active, versions, _ = fleet_store.load_for_refit(db, imos, cols)
            df = fleet_store.load_reports(db, imos, columns=cols)
            assert list(arrays) == list(cols) and len(df) == len(arrays["imo"]) > 0
            for c in cols:
                np.testing.assert_array_equal(arrays[c], df[c].to_numpy(), err_msg=c)
            assert active == fleet_store.active_models(db) and imo in active
            assert versions == fleet_store.next_versions(db) == {imo: 2}

@pytest.mark.slow
def test_refit_read_of_a_table_larger_than_a_row_group_matches_the_ordered_table_read(fleet, fleet_checked, tmp_path):
    """Past one DuckDB row group (122,880 rows) the refit read still gives every row once, in vessel and time order:
    a year of four vessels repeated 90 times, 400 days apart (131,400 rows), imported newest first."""
    good, bad = (part.copy() for part in fleet_checked)
    ts = pd.to_datetime(good["ts_utc"])
    years = [good.assign(ts_utc=(ts + pd.Timedelta(days=400 * k)).dt.strftime("%Y-%m-%dT%H:%M:%S")) for k in range(90)]
    db = tmp_path / "w.duckdb"
    fleet_store.import_vessels(db, fleet.vessels)
    fleet_store.import_noon(db, pd.concat(years[::-1], ignore_index=True), bad.head(0))
    arrays, *_ = fleet_store.load_for_refit(db, None, REPORT_COLUMNS)
    df = fleet_store.load_reports(db, None, columns=REPORT_COLUMNS)
    assert len(df) == len(arrays["imo"]) == 90 * len(good) > 122_880
    for c in REPORT_COLUMNS:
        np.testing.assert_array_equal(arrays[c], df[c].to_numpy(), err_msg=c)


def test_stored_data_hashes_do_not_change_with_how_the_reports_are_held(fleet, fleet_checked):
    """A model's data_hash (its rows, form and fit settings) is what a refit with nothing new compares with the stored
    models: it must stay the value stored before (pinned), whether the reports come as a DataFrame or as the read-only
    arrays the warehouse read shares with Arrow; else every vessel would get a new model version after an upgrade."""
    good = fleet_checked[0].copy()
    imo = int(fleet.vessels.imo[0])
    rows_df = good[good.imo == imo].sort_values("ts_utc")
    arrays = {c: rows_df[c].to_numpy(dtype="datetime64[us]" if c == "ts_utc" else float) for c in REPORT_COLUMNS if c != "imo"}
    for a in arrays.values():
        a.flags.writeable = False
    for form, pinned in (("physical", "112ce623a4ed32ce03eedf02bc060995405eac69"),
                         ("thesis", "112ce623a4ed32ce03eedf02bc06099596d7d340")):
        for reports in (rows_df, arrays):
            rows, _ = refit_vessel(imo, reports, None, 1, form=form)
            assert {r["data_hash"] for r in rows} == {pinned}, form


def test_coefficients_json_equals_json_dumps_for_every_kind_of_result():
    """The stored coefficients' text, made from a template per regressor list, is `json.dumps` of the coefficients,
    for several lists of regressors in one batch and for results with a non-finite value (NaN, inf)."""
    from pipeline.performance.refit import _coefficients_json_of

    rng = np.random.default_rng(5)
    results = []
    for i in range(12):
        form, target = (("physical", "speed"), ("physical", "fuel"), ("thesis", "speed"))[i % 3]
        names = (features.SPEED_REGRESSORS if target == "speed" else features.FUEL_REGRESSORS)[features.FORM_IDS[form]]
        coef = rng.normal(size=len(names)) * 10.0 ** rng.integers(-8, 8, size=len(names))
        if i in (4, 7):
            coef[1] = (np.nan, np.inf)[i == 7]
        results.append(fit.FitResult(form, target, names, coef, 100, 0.9, 0.1, 0.1))
    assert _coefficients_json_of(results) == [json.dumps(r.coefficients()) for r in results]


def test_underdetermined_model_is_refused():
    fl = generate_fleet("2020-12-01T00", n_vessels=1, days=120, seed=5)
    good, _ = validate_noon(_as_text(fl.noon), set(fl.vessels.imo))
    imo = int(fl.vessels.imo[0])
    rows, s = refit_vessel(imo, good.head(20), None, 1)
    assert not s["changed"] and "under-determined" in s["reason"] and not any(r["active"] for r in rows)


def test_a_ship_with_one_to_three_reports_is_refused_and_the_fleet_is_still_fitted(fleet_checked, fleet):
    """A fit through two or three rows leaves residuals of exactly 0, which the Huber weights divided by (the
    robust physical form): the whole fleet's refit raised ZeroDivisionError. One row (held out, none to train on)
    was refused as needing "≥ 0" rows."""
    good = fleet_checked[0]
    new_ship, old_ship = int(fleet.vessels.imo[0]), int(fleet.vessels.imo[1])
    for n in (1, 2, 3):
        few = good[good.imo == new_ship].sort_values("ts_utc").head(n)
        reports = pd.concat([few, good[good.imo == old_ship]]).reset_index(drop=True)
        rows, summaries = refit_fleet(reports, {}, {})
        by_imo = {s["imo"]: s for s in summaries}
        assert "under-determined" in by_imo[new_ship]["reason"], by_imo[new_ship]
        assert "(need ≥ 0)" not in by_imo[new_ship]["reason"]
        assert by_imo[old_ship]["changed"] and any(r["imo"] == old_ship and r["active"] for r in rows)


def _store_refit(db, form="best", gate=Gate()):
    """What the refit-performance flow does, without Prefect: read, refit, store."""
    reports, active, versions, fitted = fleet_store.load_for_refit(db, None, REPORT_COLUMNS)
    rows, summaries = refit_fleet(reports, active, versions, form=form, gate=gate, fitted=fitted_from_rows(fitted))
    reactivate, flags = storage_actions(summaries)
    fleet_store.save_fits(db, rows, reactivate=reactivate, flags=flags)
    return summaries


def _models(db):
    with duckdb.connect(str(db), read_only=True) as con:
        return con.execute("SELECT imo, version, form, status, active, flag FROM perf_models WHERE target = 'speed' "
                           "ORDER BY imo, version").fetchall()


@pytest.fixture(scope="module")
def history_made(tmp_path_factory):
    """The folder of `history`'s warehouse, generated, validated and imported once per module; its later reports."""
    fl = generate_fleet("2020-12-01T00", n_vessels=2, days=365, seed=21)
    folder = tmp_path_factory.mktemp("history")
    db = folder / "w.duckdb"
    fleet_store.import_vessels(db, fl.vessels)
    good, _ = validate_noon(_as_text(fl.noon), set(fl.vessels.imo))
    good = good.sort_values(["imo", "ts_utc"])
    day = good.groupby("imo").cumcount()
    fleet_store.import_noon(db, good[day < 250], good.head(0))
    return folder, good[day >= 250], [int(i) for i in fl.vessels.imo]


@pytest.fixture()
def history(history_made, tmp_path):
    """A warehouse with two vessels' first 250 days of a year of reports (each test its own copy of the folder
    `history_made` made, snapshot included, with new file times), and the other 115 days by vessel."""
    folder, later, imos = history_made
    shutil.copytree(folder, tmp_path / "history", copy_function=shutil.copyfile)
    return tmp_path / "history" / "w.duckdb", later.copy(), list(imos)


@pytest.mark.slow
def test_versions_nothing_new_new_batch_worse_form_and_switching_back(history):
    db, later, imos = history
    first = _store_refit(db)
    assert [(m[1], m[2], m[3]) for m in _models(db)] == [(1, "physical", "active")] * 2  # every form tried, physical won
    assert all("thesis speed" in s["reason"] and "first model" in s["why"] for s in first)
    # nothing new: nothing stored, whatever the form asked for
    again = _store_refit(db)
    assert _models(db) == [(i, 1, "physical", "active", True, None) for i in imos]
    assert all(not s["changed"] and s["why"] == "same as the active model" for s in again)
    # the thesis form learns weather gains on these ships: the sanity gate refuses it, naming the check and the point
    insane = _store_refit(db, "thesis", gate=Gate(max_speed_rmse_share=1.0, max_fuel_rmse_share=1.0))
    assert all(not s["changed"] and s["why"].startswith("physical sanity (") and " at rpm " in s["why"] for s in insane)
    assert [(m[1], m[2], m[3]) for m in _models(db)] == [(1, "physical", "active"), (2, "thesis", "rejected")] * 2
    with duckdb.connect(str(db)) as con:
        con.execute("DELETE FROM perf_models WHERE version = 2")
    # a worse form is compared with the active model on the same held-out rows, and stored rejected
    # (with a gate it passes on its own)
    worse = _store_refit(db, "thesis", gate=Gate(max_speed_rmse_share=1.0, max_fuel_rmse_share=1.0, sanity=False))
    assert [(m[1], m[2], m[3]) for m in _models(db)] == [(1, "physical", "active"), (2, "thesis", "rejected")] * 2
    assert all(not s["changed"] and s["why"].startswith("worse than the active model on the 50 held-out rows") for s in worse)
    # switching back and forth with nothing new stores nothing
    n_before = len(_models(db))
    _store_refit(db, "physical")
    _store_refit(db, "thesis")
    assert len(_models(db)) == n_before
    # a new batch of good reports: a new version, fitted on all rows, replaces the old one
    fleet_store.import_noon(db, later[later.groupby("imo").cumcount() < 40], later.head(0))
    new = _store_refit(db)
    assert [(m[1], m[2], m[3]) for m in _models(db) if m[0] == imos[0]] == [
        (1, "physical", "superseded"), (2, "thesis", "rejected"), (3, "physical", "active")]
    assert all(s["changed"] and "not worse on held-out rows than the active v1 (physical)" in s["reason"] for s in new)
    assert all(s["n"] == 290 and s["n_holdout"] == 40 for s in new)  # judged on the 40 reports newer than v1
    with duckdb.connect(str(db), read_only=True) as con:
        n_rows, data_to = con.execute("SELECT n_rows, data_to_utc FROM perf_models WHERE active AND imo = ? AND target = 'speed'",
                                      [imos[0]]).fetchone()
    assert n_rows == 290 and data_to == later[later.imo == imos[0]].ts_utc.iloc[39]  # refitted on all rows


def test_switching_forms_compares_and_reactivates_instead_of_storing_a_copy(history):
    db, _, imos = history
    _store_refit(db, "physical")
    # a gate that lets anything through activates the thesis form over the physical one ...
    loose = Gate(min_r2=-1e9, max_speed_rmse_share=1e9, max_fuel_rmse_share=1e9, not_worse=1e9, sanity=False)
    _store_refit(db, "thesis", gate=loose)
    assert [(m[1], m[2], m[3]) for m in _models(db) if m[0] == imos[0]] == [(1, "physical", "superseded"), (2, "thesis", "active")]
    # ... and switching back compares the physical fit with it on the same rows: better, so v1 is active again
    back = _store_refit(db, "physical")
    assert [(m[1], m[2], m[3]) for m in _models(db) if m[0] == imos[0]] == [(1, "physical", "active"), (2, "thesis", "superseded")]
    assert all(s["changed"] and s["reactivate"] == 1 and "re-activates v1" in s["reason"] for s in back)
    assert all("not worse on held-out rows than the active v2 (thesis)" in s["reason"] for s in back)


def test_a_broken_speed_log_batch_is_flagged_and_refused(history):
    db, later, imos = history
    _store_refit(db)
    batch = later[later.groupby("imo").cumcount() < 30].copy()
    broken = batch.imo == imos[1]
    batch.loc[broken, "stw_kn"] = (batch.loc[broken, "stw_kn"] * 0.6).round(3)  # the log under-reads by 40 %
    fleet_store.import_noon(db, batch, batch.head(0))
    out = {s["imo"]: s for s in _store_refit(db)}
    assert out[imos[0]]["changed"] and not out[imos[1]]["changed"]
    assert "speed residuals stepped by -" in out[imos[1]]["flag"] and "speed log" in out[imos[1]]["why"]
    models = _models(db)
    assert [(m[1], m[3]) for m in models if m[0] == imos[1]] == [(1, "active"), (2, "rejected")]
    with duckdb.connect(str(db), read_only=True) as con:
        flags = dict(con.execute("SELECT imo, flag FROM model_quality WHERE target = 'speed'").fetchall())
    assert flags[imos[0]] is None and "contradict the active model" in flags[imos[1]]


def _reference_fit(X, y, robust, k_folds=fit.K_FOLDS):
    """The documented fit, written plainly: drop constant regressors (but the intercept), scale to unit
    RMS, Huber IRLS by weighted lstsq until the step is ≤ ROBUST_RTOL of the largest coefficient (at most
    ROBUST_ITERATIONS solves; re-weighting only before a solve), k-fold CV (row p in fold p mod k) refitted from the
    rows with the weights of the last solve."""
    ok = np.isfinite(X).all(axis=1) & np.isfinite(y)
    X, y = X[ok], y[ok]
    keep = (X.max(axis=0) - X.min(axis=0) > 1e-12) | ((X == 1.0).all(axis=0))
    scale = np.sqrt((X[:, keep] ** 2).mean(axis=0))
    Z = X[:, keep] / scale
    w, beta = np.ones(len(y)), np.zeros(keep.sum())
    for it in range(fit.ROBUST_ITERATIONS if robust else 1):
        prev = beta
        sw = np.sqrt(w)
        beta = np.linalg.lstsq(Z * sw[:, None], y * sw, rcond=None)[0]
        if it and np.abs(beta - prev).max() <= fit.ROBUST_RTOL * max(np.abs(beta).max(), 1e-12):
            break
        if robust and it < fit.ROBUST_ITERATIONS - 1:  # new weights only for a solve that follows
            r = y - Z @ beta
            s = 1.4826 * np.median(np.abs(r - np.median(r))) or 1e-9
            w = np.minimum(1.0, fit.HUBER_K * s / np.abs(r))
    r = y - Z @ beta
    fold = np.arange(len(y)) % k_folds
    cv_sq = 0.0
    for f in range(k_folds):
        tr, te = fold != f, fold == f
        sw = np.sqrt(w[tr])
        b = np.linalg.lstsq(Z[tr] * sw[:, None], y[tr] * sw, rcond=None)[0]
        cv_sq += ((y[te] - Z[te] @ b) ** 2).sum()
    coef = np.zeros(X.shape[1])
    coef[keep] = beta / scale
    return coef, np.sqrt((r ** 2).mean()), np.sqrt(cv_sq / len(y))


def test_huber_median_equals_numpy_median_whatever_the_guess():
    """The medians behind the Huber scale select among values near a guess when it brackets the middle,
    else among all (also with many equal values): always exactly np.median."""
    rng = np.random.default_rng(5)
    for trial in range(400):
        m = int(rng.integers(1, 400))
        a = rng.standard_t(2, size=m)
        if trial % 3 == 0:
            a[: m // 2] = 0.25  # ties at the middle
        if trial % 4 == 0:
            a = np.round(a, 1)
        true = np.median(a)
        for guess, width in ((np.nan, np.nan), (true, 0.05), (true + 0.3, 0.1), (0.0, 10.0), (5.0, 0.01)):
            assert huber.median_near(a, m, guess, width, np.empty((3, m))) == true, (trial, m, guess, width)

def test_batched_robust_fit_equals_each_vessel_fitted_alone(fleet_checked):
    """A fleet fit gives every vessel what a fit of that vessel alone gives, and that is the plain
    IRLS + CV written out above: each vessel stops re-weighting when its own coefficients settle,
    whatever the other vessels in the batch do."""
    good = fleet_checked[0].copy()
    good = good.sort_values(["imo", "ts_utc"])
    parts = [g for _, g in good.groupby("imo")]
    parts[1] = parts[1].head(150).copy()
    parts[1]["trim_m"] = 0.5  # a constant regressor: dropped for this vessel only
    parts[2] = parts[2].copy()
    parts[2].loc[parts[2].index[::9], "stw_kn"] *= 0.5  # outliers: Huber weights differ from 1
    parts[2].loc[parts[2].index[5], "rpm"] = np.nan  # a row the fit must leave out
    reports = pd.concat(parts)
    inp = fit.inputs_from_reports(reports)
    sizes = [len(p) for p in parts]
    bounds = np.r_[0, np.cumsum(sizes)]
    for target, y in (("speed", inp["stw_kn"]), ("fuel", inp["fuel_tph"])):
        X = fit.design("physical", target, inp)
        batched = fit.fit_targets("physical", target, X, y, bounds, robust=True)
        for g, res in enumerate(batched):
            s = slice(bounds[g], bounds[g + 1])
            alone = fit.fit_target("physical", target, X[s], y[s], robust=True)
            np.testing.assert_allclose(res.coef, alone.coef, rtol=1e-12, atol=1e-15)
            assert (res.rmse, res.cv_rmse, res.dropped) == (alone.rmse, alone.cv_rmse, alone.dropped)
            # a fouling or weather term that came out as a gain is left out: the reference fits without it
            Xr = X[s].copy()
            Xr[:, [res.names.index(d) for d in res.dropped if d in features.NON_NEGATIVE | features.NON_POSITIVE_SPEED]] = 0.0
            coef, rmse, cv = _reference_fit(Xr, y[s], robust=True)
            np.testing.assert_allclose(res.coef, coef, rtol=1e-8, atol=1e-12 * np.abs(coef).max())
            assert res.rmse == pytest.approx(rmse, rel=1e-9) and res.cv_rmse == pytest.approx(cv, rel=1e-8)
    assert fit.fit_targets("physical", "speed", fit.design("physical", "speed", inp), inp["stw_kn"], bounds,
                           robust=True)[1].dropped == ["trim_m"]
    assert batched[2].n == sizes[2] - 1

@pytest.mark.parametrize("inputs,expected", [((8, 4, 1), 1.75), ((8, 5, 3), 1.75), ((10, 2, 3), 1.75), ((6, 3, 4), 1.43),
                                             ((10, 5, 7), 2.57), ((5, 2, 2), 0.934)])
def test_fuzzy_model_reproduces_published_outputs(inputs, expected):
    assert fuzzy.fuel_tph(*inputs) == pytest.approx(expected, abs=0.01)


def test_fuzzy_fires_the_published_rules():
    assert fuzzy.fired_rules(8, 4, 1) == [23, 26]
    assert fuzzy.fired_rules(10, 5, 7) == [17, 18]


@pytest.mark.parametrize("form", ["mlp/fuzzy", "fuzzy", "Physical", ""])
def test_refit_refuses_a_form_that_does_not_exist_in_one_line(form, tmp_path, monkeypatch):
    from typer.testing import CliRunner

    from cli.main import app

    monkeypatch.setenv("COLUMNS", "400")
    res = CliRunner().invoke(app, ["refit", "--form", form, "--data", str(tmp_path / "d")])
    assert res.exit_code == 2, res.output
    assert res.output.strip().count("\n") == 0 and "unknown model form" in res.output and "thesis" in res.output
    assert not (tmp_path / "d").exists()  # refused before anything was created


def test_refit_fits_the_physical_form_unless_told_otherwise():
    """One default everywhere a refit starts (pipeline, job, Prefect flow, command line); `best` is opt-in."""
    import inspect

    import typer

    from cli.main import app
    from flows.jobs.refit import refit_job
    from flows.refit import refit_performance
    from pipeline.performance.refit import DEFAULT_FORM

    assert DEFAULT_FORM == "physical"
    for fn in (refit_fleet, refit_vessel, refit_job, refit_performance.fn):
        assert inspect.signature(fn).parameters["form"].default == DEFAULT_FORM, fn.__name__
    cmd = typer.main.get_command(app).commands["refit"]
    option = next(p for p in cmd.params if p.name == "form")
    assert option.default == DEFAULT_FORM and "best (opt-in" in option.help


def test_calm_water_speed_and_fuel_do_not_depend_on_heading():
    """No wind and no waves: every form gives one speed and one fuel rate whatever the (meaningless)
    relative direction, including the −180° routing gets from atan2(−0, −0); and a leg sailed north
    takes as long as the same leg sailed south."""
    from pipeline.performance.model import PerformanceModel, reference_model
    from pipeline.routing.engine import leg as lk
    from pipeline.routing import weather_field as wf

    gn = gas_nirvana()
    inp = fit.inputs_from_reports(gn)
    X = fit.designs("thesis", inp)
    thesis = PerformanceModel("thesis", fit.fit_target("thesis", "speed", X["speed"], inp["stw_kn"]).coef,
                              fit.fit_target("thesis", "fuel", X["fuel"], inp["fuel_tph"]).coef)
    rel = np.array([-180.0, -90.0, -0.0, 0.0, 45.0, 90.0, 180.0, 270.0, 359.0])
    for m in (thesis, reference_model()):
        for rpm in (100.0, 120.0):
            stw = m.stw_kn(rpm, 6.0, 2.0, 0.0, rel, 0.0, rel)
            fuel = m.fuel_tph(rpm, 6.0, 2.0, 0.0, rel, 0.0, rel)
            assert np.ptp(stw) == 0.0 and np.ptp(fuel) == 0.0 and stw[0] > 5.0, (m.form, stw)
    calm = wf.uniform(np.datetime64("2020-12-01T00"), 240.0)
    for m in (thesis, reference_model()):
        ves = lk.vessel(m, draft_m=6.0, trim_m=2.0, rpm_options=(120.0,))
        north = lk.sail_leg(0.0, 150.0, 3.0, 150.0, 0.0, 120.0, ves, calm)
        south = lk.sail_leg(3.0, 150.0, 0.0, 150.0, 0.0, 120.0, ves, calm)
        assert north[lk.CODE] == south[lk.CODE] == lk.OK
        assert north[lk.H] == pytest.approx(south[lk.H], rel=1e-12) and north[lk.FUEL] == pytest.approx(south[lk.FUEL], rel=1e-12)


def test_physical_weather_loss_is_largest_head_on_always_a_loss_and_bounded(fleet, fleet_checked):
    """A fitted physical model: at 30 kn wind and 4 m seas the speed loss falls from head to beam to
    following and is never a gain; it never takes more than half the calm speed; fuel never drops
    below the calm-water rate at the same rpm (50 kn following wind and 8 m seas included)."""
    from pipeline.performance.model import PerformanceModel

    good = fleet_checked[0].copy()
    imo = int(fleet.vessels.imo[0])
    rows, _ = refit_vessel(imo, good[good.imo == imo].sort_values("ts_utc"), None, 1)
    coef = {r["target"]: np.array(list(json.loads(r["coefficients"]).values())) for r in rows}
    m = PerformanceModel("physical", coef["speed"], coef["fuel"])
    assert (coef["speed"][4:6] > 0).all() and (coef["fuel"][4:6] > 0).all()
    rel = np.arange(0.0, 360.0, 5.0)
    calm = m.stw_kn(85.0, 9.0, 0.5)
    stw = m.stw_kn(85.0, 9.0, 0.5, 30.0, rel, 4.0, rel)
    loss = calm - stw
    head, beam, following = loss[rel == 0][0], loss[rel == 90][0], loss[rel == 180][0]
    assert head > beam > following > 0
    assert (loss > 0).all() and (np.diff(loss[rel <= 180]) < 0).all()  # falls all the way from head to following
    np.testing.assert_allclose(loss[rel > 180], loss[(rel > 0) & (rel < 180)][::-1], rtol=1e-12)  # port = starboard
    # bounded: a hurricane head-on takes at most half the calm-water speed
    assert m.stw_kn(85.0, 9.0, 0.5, 120.0, 0.0, 15.0, 0.0) == pytest.approx(0.5 * calm, rel=1e-12)
    fuel_calm = m.fuel_tph(85.0, 9.0, 0.5)
    for wind, hs in ((50.0, 8.0), (30.0, 4.0), (5.0, 0.5)):
        fuel = m.fuel_tph(85.0, 9.0, 0.5, wind, rel, hs, rel)
        assert (fuel >= fuel_calm).all() and fuel[rel == 180][0] < fuel[rel == 90][0] < fuel[rel == 0][0]
    # the direction shape on its own: 1 head-on, 0.45 beam, 0.14 following
    np.testing.assert_allclose([features.direction_weight(a) for a in (0.0, 90.0, 180.0, -90.0, 270.0)],
                               [1.0, 0.45, 0.14, 0.45, 0.45], atol=1e-12)


def test_physical_fit_never_learns_a_weather_gain():
    """Reports in which following wind makes the ship faster (and burn less): the fit leaves the wind term
    out rather than give it the wrong sign, so the model never predicts a gain, and routing's kernels
    give what the vectorised model gives."""
    from pipeline.performance.model import PerformanceModel

    rng = np.random.default_rng(4)
    n = 300
    rpm, draft, trim = rng.uniform(60, 100, n), rng.uniform(6, 12, n), rng.normal(0.5, 0.4, n)
    wind, wrel = rng.uniform(0, 40, n), rng.uniform(0, 180, n)
    hs, srel = rng.uniform(0, 5, n), rng.uniform(0, 180, n)
    stw = 0.15 * rpm + 0.001 * wind**2 * (1 - np.cos(np.radians(wrel))) - 0.08 * hs**2 + rng.normal(0, 0.1, n)  # wind helps
    fuel = 1.4 * (rpm / 100) ** 3 - 0.0002 * wind**2 + rng.normal(0, 0.01, n)
    cols = (rpm, draft, trim, wind, wrel, hs, srel, np.zeros(n))
    sp = fit.fit_target("physical", "speed", features.design_matrix(1, "speed", *cols), stw)
    fu = fit.fit_target("physical", "fuel", features.design_matrix(1, "fuel", *cols), fuel)
    assert "wind_loss" in sp.dropped and sp.coef[4] == 0.0 and sp.coef[5] > 0.05  # the wave loss is still learnt
    assert "wind_load" in fu.dropped and fu.coef[4] == 0.0
    m = PerformanceModel("physical", sp.coef, fu.coef)
    rel = np.arange(0.0, 181.0, 15.0)
    assert (m.stw_kn(80.0, 9.0, 0.5, 40.0, rel, 3.0, rel) < m.stw_kn(80.0, 9.0, 0.5)).all()
    for a in rel:
        assert features.stw_kn_nb(1, m.speed_coef, 80.0, 9.0, 0.5, 40.0, a, 3.0, a, 0.0) == m.stw_kn(80.0, 9.0, 0.5, 40.0, a, 3.0, a)
        assert features.fuel_tph_nb(1, m.fuel_coef, 80.0, 9.0, 0.5, 40.0, a, 3.0, a, 0.0) == m.fuel_tph(80.0, 9.0, 0.5, 40.0, a, 3.0, a)


def test_storage_returns_plain_rows_and_the_pipeline_builds_models(fleet, fleet_checked, tmp_path):
    """storage imports nothing from pipeline; a stored active model comes back as plain values and
    `model_from_stored` builds the model routing uses (None for coefficients of an older form definition)."""
    import ast

    from pipeline.performance.model import model_from_stored
    from pipeline.performance.validate import raw_text

    root = Path(__file__).resolve().parents[1] / "storage"
    for path in root.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else [node.module or ""] if isinstance(node, ast.ImportFrom) else []
            assert not any(n.split(".")[0] == "pipeline" for n in names), f"{path.name} imports {names}"
    sample = _as_text(fleet.noon.head(5))
    assert fleet_store._raw_text(sample).tolist() == raw_text(sample).tolist()  # one format for the raw column

    db = tmp_path / "w.duckdb"
    fleet_store.import_vessels(db, fleet.vessels)
    good = fleet_checked[0].copy()
    imo = int(fleet.vessels.imo[1])
    rows, s = refit_vessel(imo, good[good.imo == imo].sort_values("ts_utc"), None, 1, form="physical")
    fleet_store.save_fits(db, rows)
    stored = fleet_store.active_model(db, imo)
    assert isinstance(stored, dict) and stored["form"] == "physical" and isinstance(stored["speed"], dict)
    m = model_from_stored(stored, imo)
    assert (m.imo, m.version, m.form) == (imo, 1, "physical")
    np.testing.assert_array_equal(m.speed_coef, list(json.loads(rows[0]["coefficients"]).values()))
    assert m.months_dd == pytest.approx(good[good.imo == imo].months_since_drydock.max())
    old = dict(stored, speed={k.replace("wind_loss", "wind_kn2_cos"): v for k, v in stored["speed"].items()})
    assert model_from_stored(old, imo) is None and model_from_stored(None) is None
    assert fleet_store.active_model(db, 1234567) is None


def _nonlinear_reports(n=400, seed=8):
    """Time-ordered inputs and targets with a speed curve no least-squares form here has (a saturating rpm law)."""
    rng = np.random.default_rng(seed)
    rpm, draft, trim = rng.uniform(50, 110, n), rng.uniform(6, 12, n), rng.normal(0.5, 0.5, n)
    wind, wrel, hs, srel = rng.gamma(3, 5, n), rng.uniform(0, 180, n), rng.gamma(2, 0.8, n), rng.uniform(0, 180, n)
    X = features.mlp_inputs(rpm, draft, trim, wind, wrel, hs, srel)
    speed = 16 * np.tanh(rpm / 70) - 0.1 * draft - 0.0012 * X[:, 3] ** 2 - 0.15 * X[:, 4] ** 2
    fuel = 1.6 * (rpm / 100) ** 3 * (1 + 0.02 * draft) + 0.0004 * X[:, 3] ** 2
    Y = np.column_stack([speed + rng.normal(0, 0.15, n), fuel * rng.normal(1, 0.02, n)])
    return (rpm, draft, trim, wind, wrel, hs, srel), X, Y, np.column_stack([speed, fuel])


def test_mlp_is_seeded_stops_early_on_the_newest_rows_and_learns_what_it_is_shown():
    _, X, Y, truth = _nonlinear_reports()
    fit_rows = slice(0, 300)
    p1, info = mlp.train(X[fit_rows], Y[fit_rows], seed=3)
    p2, _ = mlp.train(X[fit_rows], Y[fit_rows], seed=3)
    p3, _ = mlp.train(X[fit_rows], Y[fit_rows], seed=4)
    assert p1.shape == (mlp.N_PARAMS,) == (279,) and np.array_equal(p1, p2) and not np.array_equal(p1, p3)
    assert (info["n_train"], info["n_val"]) == (240, 60) and info["best_epoch"] < info["epochs"] <= mlp.MAX_EPOCHS
    # the validation rows are the newest: spoiling them changes where training stops, not what it learns from
    spoiled = Y[fit_rows].copy()
    spoiled[240:] += 3.0
    p4, info4 = mlp.train(X[fit_rows], spoiled, seed=3)
    np.testing.assert_array_equal(p4[: 2 * mlp.N_IN], p1[: 2 * mlp.N_IN])  # input scaling from the older rows only
    assert info4["best_epoch"] != info["best_epoch"]
    # on rows it never saw, speed within the noise and fuel within 2 % (the monotone shape costs a little speed
    # accuracy here, 0.147 kn against 0.092 unconstrained, and gains fuel accuracy, 1.2 % against 2.4 %)
    pred = mlp.forward(p1, X[300:])
    assert np.sqrt(np.mean((pred[:, 0] - truth[300:, 0]) ** 2)) < 0.15
    assert np.mean(np.abs(pred[:, 1] / truth[300:, 1] - 1)) < 0.02
    # routing's compiled forward pass is the same network
    for i in range(300, 310):
        for out in (0, 1):
            assert mlp.forward_nb(p1, *X[i], out) == pytest.approx(pred[i - 300, out], rel=1e-12)


def _nonlinear_report_frame(n=360):
    """Noon reports of vessel 9140607, one a day from 2020-01-01, built from `_nonlinear_reports`."""
    cols, _, Y, _ = _nonlinear_reports(n=n)
    reports = pd.DataFrame({"imo": 9140607, "ts_utc": pd.date_range("2020-01-01", periods=n, freq="D"), "rpm": cols[0],
                            "draft_m": cols[1], "trim_m": cols[2], "wind_kn": cols[3], "wind_dir_rel_deg": cols[4], "wave_m": cols[5],
                            "wave_dir_rel_deg": cols[6], "months_since_drydock": 0.0, "stw_kn": Y[:, 0], "fuel_t": Y[:, 1] * 24,
                            "hours": 24.0})
    return reports


def test_mlp_form_refits_routes_and_has_no_heading_in_calm_water():
    from pipeline.performance.model import PerformanceModel

    reports = _nonlinear_report_frame()
    # "best" keeps the physical form: the (monotone) network is not better on the held-out rows here
    rows, s = refit_vessel(9140607, reports, None, 1, form="best")
    assert s["changed"] and s["form"] == "physical" and "mlp speed" in s["reason"] and "thesis speed" in s["reason"]
    rows, s = refit_vessel(9140607, reports, None, 1, form="mlp")
    assert s["changed"] and s["form"] == "mlp" and s["gate"] == "default"
    # monotone by construction, the network is about as good as the physical form here (0.297 against 0.316 kn;
    # unconstrained it scored 0.199 but learnt speed gains in heavy head seas, which the gate refuses)
    assert s["speed_holdout_rmse"] < 0.30 and [r["form"] for r in rows] == ["mlp", "mlp"]
    coef = np.array(list(json.loads(rows[0]["coefficients"]).values()))
    assert np.array_equal(coef, list(json.loads(rows[1]["coefficients"]).values()))  # one network, two outputs
    m = PerformanceModel("mlp", coef, coef)
    np.testing.assert_allclose(m.stw_kn(80.0, 9.0, 0.5, 20.0, 30.0, 2.0, 40.0),
                               mlp.forward(coef, features.mlp_inputs(80.0, 9.0, 0.5, 20.0, 30.0, 2.0, 40.0))[0, 0], rtol=1e-12)
    rel = np.array([-180.0, -0.0, 0.0, 90.0, 180.0, 270.0])
    assert np.ptp(m.stw_kn(90.0, 9.0, 0.5, 0.0, rel, 0.0, rel)) == 0.0 and np.ptp(m.fuel_tph(90.0, 9.0, 0.5, 0.0, rel, 0.0, rel)) == 0.0
    with pytest.raises(ValueError, match="no design matrix"):
        features.design_matrix(features.FORM_MLP, "speed", *(np.zeros(2) for _ in range(8)))


def test_fuzzy_model_from_the_command_line(monkeypatch):
    from typer.testing import CliRunner

    from cli.main import app

    monkeypatch.setenv("COLUMNS", "200")
    res = CliRunner().invoke(app, ["model", "fuzzy", "10", "5", "7"])
    assert res.exit_code == 0 and res.output.strip() == f"fuel {fuzzy.fuel_tph(10, 5, 7):.3f} t/h (rules fired: 17, 18)"
    assert abs(float(res.output.split()[1]) - 2.57) < 0.01  # the published output
    res = CliRunner().invoke(app, ["model", "fuzzy", "12", "5", "7"])
    assert res.exit_code == 2 and "SPEED 12 is outside the model's range 5–11" in res.output


@pytest.mark.parametrize("imo,seed", [(9140607, 1), (9140619, 2)])
def test_forms_scored_against_a_truth_outside_all_of_them(imo, seed):
    """Quadratic losses with their own head/beam/following shape, 5 % noise, 2 % outliers; the 55 days after
    the fitted year are never part of the fit. The form `--form best` chooses is within 10 % of the noise floor on
    speed and within 5 % fuel MAPE; the thesis form is told apart as worse."""
    from pipeline.performance.benchmark import score_forms
    from pipeline.synthetic import truth

    df, true = truth.reports(truth.TrueVessel(imo), "2020-12-01", 420, seed)
    fitted, later, true_later = df.iloc[:365], df.iloc[365:], true.iloc[365:]
    _, chosen = refit_vessel(imo, fitted, None, 1, form="best")  # every form, chosen with a margin
    assert chosen["changed"]
    scores = score_forms(fitted, later, true_later).set_index("form")
    print(f"\n{scores.round(3).to_string()}\nchosen: {chosen['form']}")
    assert scores.loc[chosen["form"], "speed_vs_floor"] <= 1.10 and scores.loc[chosen["form"], "fuel_mape_pct"] <= 5.0
    assert scores.loc["thesis", "fuel_mape_pct"] > 3 * scores.loc[chosen["form"], "fuel_mape_pct"]
    assert 0.6 < scores.loc["thesis", "noise_floor_kn"] < 0.9  # 5 % of ~15 kn, plus the outliers


GAS_NIRVANA_VESSEL = pd.DataFrame([{"imo": 9140607, "name": "GAS NIRVANA", "type": "lpg", "dwt": 3500.0, "design_speed_kn": 16.0,
                                    "mcr_kw": 3000.0, "rpm_max": 125.0, "design_fuel_tph": 1.8}])


@pytest.mark.slow  # end to end through the `jitroute` command on a warehouse
def test_bunker_logs_import_with_validation_from_the_command_line(tmp_path, monkeypatch):
    import logging

    from typer.testing import CliRunner

    from cli.main import app

    monkeypatch.setenv("COLUMNS", "300")
    monkeypatch.setattr(logging, "raiseExceptions", False)  # Prefect's console handler outlives CliRunner's stream
    data = tmp_path / "data"
    data.mkdir()
    fleet_store.import_vessels(data / "warehouse.duckdb", GAS_NIRVANA_VESSEL)
    good = pd.read_csv(Path(__file__).parent / "fixtures" / "gas_nirvana_bunker_logs.csv", comment="#", dtype=str)
    bad = pd.DataFrame([
        dict(good.iloc[0], bill_no="b1", received_t="-5"),
        dict(good.iloc[0], bill_no="b2", received_t="150000"),
        dict(good.iloc[0], bill_no="b3", date_utc="31/31/2020"),
        dict(good.iloc[0], bill_no="b4", imo="9999999"),
        dict(good.iloc[0], bill_no="b5", fuel_type=""),
        dict(good.iloc[0], bill_no="b6", received_t="lots"),
        dict(good.iloc[1]),
    ])
    path = tmp_path / "bunkers.csv"
    pd.concat([good, bad]).to_csv(path, index=False)
    res = CliRunner().invoke(app, ["bunker", "import", str(path), "--data", str(data)])
    assert res.exit_code == 0, res.output
    assert "14 rows → 7 imported, 0 already present, 7 rejected" in res.output
    for reason in ("negative received_t", "received looks like kg", "date_utc: ambiguous timestamp",
                   "IMO number fails its check digit", "missing fuel_type", "not a number in received_t",
                   "duplicate bill and fuel in file"):
        assert f"1 × {reason}" in res.output
    with duckdb.connect(str(data / "warehouse.duckdb"), read_only=True) as con:
        rows = con.execute("SELECT fuel_type, sum(received_t) FROM bunker_logs GROUP BY 1 ORDER BY 1").fetchall()
    assert rows == [("DO", 150.0), ("LFO", 490.0)]
    # importing again adds nothing; a changed quantity for a stored note is refused, not overwritten
    res = CliRunner().invoke(app, ["bunker", "import", str(path), "--data", str(data)])
    assert "0 imported, 7 already present" in res.output
    good.loc[0, "received_t"] = "55"
    good.to_csv(path, index=False)
    res = CliRunner().invoke(app, ["bunker", "import", str(path), "--data", str(data)])
    assert "conflicts with the stored row: 9140607 bnk20201201 DO" in res.output


def test_voyage_performance_sets_plan_beside_actual(tmp_path):
    from storage import warehouse

    db = tmp_path / "w.duckdb"
    fleet_store.import_vessels(db, GAS_NIRVANA_VESSEL)
    voyage = dict(imo=9140607, dep_lat=20.8, dep_lon=106.8, arr_lat=10.7, arr_lon=106.8, draft_m=6.0, trim_m=2.0,
                  rpm_options="[110, 120]", max_hs_m=6.0, max_wind_kn=50.0)
    fleet_store.import_voyages(db, pd.DataFrame([
        dict(voyage, voyage_id="voy20200001", dep_name="Hai Phong", arr_name="Sai Gon", depart_utc="2020-12-06T00:00Z",
             rta_utc="2020-12-10T12:00Z"),
        dict(voyage, voyage_id="voy20200002", dep_name="Sai Gon", arr_name="Hai Phong", depart_utc="2020-12-15T00:00Z",
             rta_utc="2020-12-19T12:00Z")]))
    days = pd.date_range("2020-12-06T12:00", "2020-12-10T12:00", freq="D").append(
        pd.date_range("2020-12-15T12:00", "2020-12-19T12:00", freq="D"))  # at sea; none in port (rpm 0 is no report)
    noon = pd.DataFrame({"imo": "9140607", "ts_utc": days.strftime("%Y-%m-%dT%H:%M:%SZ"), "rpm": "120", "draft_m": "6",
                         "stw_kn": "12", "sog_kn": "12", "dist_nm": "288", "hours": "24", "fuel_t": "20"})
    fleet_store.import_noon(db, *validate_noon(noon, {9140607}))
    with warehouse.connect(db) as con:
        con.execute("INSERT INTO route_runs (run_id, started_at, status) VALUES ('r1', '2020-12-05', 'ok')")
        con.execute("INSERT INTO routes (run_id, voyage_id, imo, status, depart_utc, eta_utc, rta_utc, fuel_t, model_version) "
                    "VALUES ('r1', 'voy20200001', 9140607, 'ok', '2020-12-06', '2020-12-10 06:00', '2020-12-10 12:00', 95.0, 3)")
    with duckdb.connect(str(db), read_only=True) as con:
        vp = con.execute("SELECT * FROM voyage_performance ORDER BY voyage_id").fetchdf().set_index("voyage_id")
    v1 = vp.loc["voy20200001"]
    assert v1.n_reports == 5 and v1.actual_fuel_t == 100.0 and v1.planned_fuel_t == 95.0 and v1.model_version == 3
    assert v1.fuel_error_pct == pytest.approx(-5.0) and v1.arrival_error_h == pytest.approx(6.0) and v1.late_h == 0.0
    v2 = vp.loc["voy20200002"]  # sailed, never planned: actuals without a plan
    assert v2.n_reports == 5 and v2.actual_fuel_t == 100.0 and pd.isna(v2.planned_fuel_t) and pd.isna(v2.fuel_error_pct)


@pytest.mark.slow
def test_bunker_import_is_as_strict_as_noon_import_and_keeps_every_refused_row(tmp_path, monkeypatch):
    """The attacks on the old import: a date-only first row no longer decides the format of the others; day/month
    dates are refused, not guessed; inf, a date in 2031, IMO 9140607.9 and 17,000 t for a 3,500 dwt ship are refused;
    every refused row is in bunker_logs_rejected with its reason and raw text."""
    import logging

    from typer.testing import CliRunner

    from cli.main import app

    monkeypatch.setenv("COLUMNS", "300")
    monkeypatch.delenv("PREFECT_API_URL", raising=False)
    monkeypatch.setattr(logging, "raiseExceptions", False)
    data = tmp_path / "data"
    data.mkdir()
    fleet_store.import_vessels(data / "warehouse.duckdb", GAS_NIRVANA_VESSEL)
    row = dict(imo="9140607", port="Hai Phong", supplier="PV Oil", fuel_type="DO", received_t="50", rob_t="0")
    rows = pd.DataFrame([
        dict(row, bill_no="g1", date_utc="2020-12-06"),  # date only, first: fine, and says nothing about the others
        dict(row, bill_no="g2", date_utc="2020-12-07T08:30:00Z"),
        dict(row, bill_no="g3", date_utc="2020-12-08T08:30:00+07:00"),
        dict(row, bill_no="g4", date_utc="2020-12-09 10:00"),
        dict(row, bill_no="a1", date_utc="01/02/2025"),
        dict(row, bill_no="a2", date_utc="13/02/2025"),
        dict(row, bill_no="f1", date_utc="2020-12-10", rob_t="inf"),
        dict(row, bill_no="f2", date_utc="2031-01-01"),
        dict(row, bill_no="f3", date_utc="2020-12-10", imo="9140607.9"),
        dict(row, bill_no="f4", date_utc="2020-12-10", received_t="17000"),
        dict(row, bill_no="f5", date_utc="2020-12-10", port="Hai Phong\n\x1b[31mfake"),
    ])
    path = tmp_path / "bunkers.csv"
    rows.to_csv(path, index=False)
    res = CliRunner().invoke(app, ["bunker", "import", str(path), "--data", str(data)])
    assert res.exit_code == 0, res.output
    assert "11 rows → 4 imported, 0 already present, 7 rejected" in res.output
    assert "bunker_logs_rejected" in res.output
    with duckdb.connect(str(data / "warehouse.duckdb"), read_only=True) as con:
        stored = con.execute("SELECT bill_no, date_utc FROM bunker_logs ORDER BY bill_no").fetchall()
        refused = dict(con.execute("SELECT bill_no, reason FROM bunker_logs_rejected").fetchall())
        raw = dict(con.execute("SELECT bill_no, raw FROM bunker_logs_rejected").fetchall())
    assert [b for b, _ in stored] == ["g1", "g2", "g3", "g4"]
    assert [str(d) for _, d in stored] == ["2020-12-06 00:00:00", "2020-12-07 08:30:00", "2020-12-08 01:30:00",
                                           "2020-12-09 10:00:00"]
    assert refused["a1"].startswith("date_utc: ambiguous timestamp") and refused["a2"].startswith("date_utc: ambiguous")
    assert refused["f1"] == "not a finite number in rob_t"
    assert refused["f2"] == "date in the future"
    assert refused["f3"] == "not an integer in imo"
    assert refused["f4"] == "received more than the vessel's deadweight (3500 t)"
    assert refused["f5"] == "control characters or a line break in port"
    assert "01/02/2025" in raw["a1"] and "9140607.9" in raw["f3"] and "17000" in raw["f4"]
    assert len(stored) + len(refused) == len(rows)  # nothing lost
    # a re-import stores no refused row twice
    CliRunner().invoke(app, ["bunker", "import", str(path), "--data", str(data)])
    with duckdb.connect(str(data / "warehouse.duckdb"), read_only=True) as con:
        assert con.execute("SELECT count(*) FROM bunker_logs_rejected").fetchone()[0] == 7


def _hai_phong_to_sai_gon(db) -> None:
    """GAS NIRVANA and its voyage voy20200001, Hai Phong 2020-12-06 00:00 to Sai Gon, RTA 2020-12-10 12:00."""
    fleet_store.import_vessels(db, GAS_NIRVANA_VESSEL)
    fleet_store.import_voyages(db, pd.DataFrame([dict(
        voyage_id="voy20200001", imo=9140607, dep_name="Hai Phong", arr_name="Sai Gon", dep_lat=20.8, dep_lon=106.8,
        arr_lat=10.7, arr_lon=106.8, depart_utc="2020-12-06T00:00Z", rta_utc="2020-12-10T12:00Z", draft_m=6.0, trim_m=2.0,
        rpm_options="[110, 120]", max_hs_m=6.0, max_wind_kn=50.0)]))


def test_plan_against_actual_ends_a_late_voyage_at_its_arrival_not_at_rta_plus_3_days(tmp_path):
    """A voyage arriving four days late is measured to its arrival report (within 10 NM of the destination), and a
    shifting-to-berth report after arrival is not sea time."""
    from storage import warehouse

    db = tmp_path / "w.duckdb"
    _hai_phong_to_sai_gon(db)
    days = pd.date_range("2020-12-06T12:00", "2020-12-14T12:00", freq="D")  # 9 reports, the last at the destination
    lat = np.linspace(19.6, 10.72, len(days))
    sea = pd.DataFrame({"imo": "9140607", "ts_utc": days.strftime("%Y-%m-%dT%H:%M:%SZ"), "lat": lat.round(3).astype(str),
                        "lon": "106.8", "rpm": "120", "draft_m": "6", "stw_kn": "5", "sog_kn": "5", "dist_nm": "120",
                        "hours": "24", "fuel_t": "20"})
    berth = pd.DataFrame([{"imo": "9140607", "ts_utc": "2020-12-15T10:00:00Z", "lat": "10.77", "lon": "106.74", "rpm": "40",
                           "draft_m": "6", "stw_kn": "0.2", "sog_kn": "0.2", "dist_nm": "5", "hours": "22", "fuel_t": "1.5"}])
    good, bad = validate_noon(pd.concat([sea, berth], ignore_index=True), {9140607})
    assert len(good) == 10 and len(bad) == 0
    fleet_store.import_noon(db, good, bad)
    with warehouse.connect(db) as con:
        con.execute("INSERT INTO route_runs (run_id, started_at, status) VALUES ('r1', '2020-12-05', 'ok')")
        con.execute("INSERT INTO routes (run_id, voyage_id, imo, status, depart_utc, eta_utc, rta_utc, fuel_t, model_version) "
                    "VALUES ('r1', 'voy20200001', 9140607, 'ok', '2020-12-06', '2020-12-10 06:00', '2020-12-10 12:00', 95.0, 3)")
    with duckdb.connect(str(db), read_only=True) as con:
        v = con.execute("SELECT * FROM voyage_performance").fetchdf().iloc[0]
    assert v.n_reports == 9 and v.actual_fuel_t == 180.0 and v.actual_hours == 216.0  # the berth report left out
    assert str(v.actual_arrival_utc) == "2020-12-14 12:00:00"
    assert v.fuel_error_pct == pytest.approx(100 * (95 - 180) / 180)  # -47.2 %, not cut at RTA + 3 days
    assert v.arrival_error_h == pytest.approx(4 * 24 + 6) and v.late_h == pytest.approx(96.0)


@pytest.mark.slow
def test_plan_against_actual_compares_a_replan_from_its_start_and_a_ship_at_sea_has_no_arrival(tmp_path):
    """A voyage re-planned at sea at 12-08 06:00 (plan: 50 t to go) is compared from there: the 12-08 noon report
    counts for its 6 h after the start (5 of 20 t), the later ones whole. While the ship is at sea its last report is
    no arrival: no errors (the old view put 50 t against the whole voyage's fuel); once it reports at the destination
    the errors are those of the re-plan's part."""
    from storage import warehouse

    db = tmp_path / "w.duckdb"
    _hai_phong_to_sai_gon(db)

    def reports(days, lats):
        return pd.DataFrame({"imo": "9140607", "ts_utc": days.strftime("%Y-%m-%dT%H:%M:%SZ"), "lat": lats, "lon": "106.8",
                             "rpm": "120", "draft_m": "6", "stw_kn": "5", "sog_kn": "5", "dist_nm": "120",
                             "hours": "24", "fuel_t": "20"})
    at_sea = reports(pd.date_range("2020-12-06T12:00", "2020-12-09T12:00", freq="D"), ["18.75", "16.75", "14.75", "12.75"])
    good, bad = validate_noon(at_sea, {9140607})
    assert len(good) == 4 and len(bad) == 0
    fleet_store.import_noon(db, good, bad)
    with warehouse.connect(db) as con:
        con.execute("INSERT INTO route_runs (run_id, started_at, status) VALUES ('r1', '2020-12-05', 'ok'), "
                    "('r2', '2020-12-08 06:00', 'ok')")
        con.execute("INSERT INTO routes (run_id, voyage_id, imo, status, depart_utc, eta_utc, rta_utc, fuel_t, start_kind, "
                    "start_utc) VALUES ('r1', 'voy20200001', 9140607, 'ok', '2020-12-06', '2020-12-10 06:00', "
                    "'2020-12-10 12:00', 95.0, 'port', '2020-12-06'), ('r2', 'voy20200001', 9140607, 'ok', '2020-12-08 06:00', "
                    "'2020-12-10 06:00', '2020-12-10 12:00', 50.0, 'noon report', '2020-12-08 06:00')")

    def row():
        with duckdb.connect(str(db), read_only=True) as con:
            return con.execute("SELECT * FROM voyage_performance").fetchdf().iloc[0]
    v = row()
    assert v.run_id == "r2" and v.plan_start_kind == "noon report" and str(v.compared_from_utc) == "2020-12-08 06:00:00"
    assert v.n_reports == 2 and v.actual_fuel_t == pytest.approx(25.0) and v.actual_hours == pytest.approx(30.0)
    assert not v.arrived and str(v.last_report_utc) == "2020-12-09 12:00:00"
    assert pd.isna(v.actual_arrival_utc) and pd.isna(v.fuel_error_pct) and pd.isna(v.arrival_error_h) and pd.isna(v.late_h)
    good, bad = validate_noon(reports(pd.DatetimeIndex(["2020-12-10T12:00"]), ["10.75"]), {9140607})
    assert len(good) == 1 and len(bad) == 0
    fleet_store.import_noon(db, good, bad)
    v = row()
    assert v.arrived and str(v.actual_arrival_utc) == "2020-12-10 12:00:00" and v.n_reports == 3
    assert v.actual_fuel_t == pytest.approx(45.0) and v.fuel_error_pct == pytest.approx(100 * (50 - 45) / 45)
    assert v.arrival_error_h == pytest.approx(6.0) and v.late_h == pytest.approx(0.0)


@pytest.mark.slow
def test_a_noon_file_imported_in_chunks_stores_what_a_whole_file_import_stores(fleet, tmp_path, monkeypatch):
    """Read, validated and stored 500 rows at a time (in one transaction): the same rows, rejected rows and reasons as
    one chunk, including a (vessel, time) repeated in another chunk of the file (a duplicate, not a second report)."""
    import flows.jobs.refit as refit_job

    noon = _as_text(fleet.noon)
    repeat = noon.iloc[[10]].copy()
    repeat["fuel_t"] = "99"  # the same vessel and time 2,000 rows later, with other values
    path = tmp_path / "noon.csv"
    pd.concat([noon.iloc[:2000], repeat, noon.iloc[2000:]], ignore_index=True).to_csv(path, index=False)
    results = {}
    for rows in (10**9, 500):
        monkeypatch.setattr(refit_job, "NOON_CHUNK_ROWS", rows)
        monkeypatch.setattr(refit_job.read_table_chunks, "__defaults__", (rows,))
        root = tmp_path / f"data{rows}"
        root.mkdir()
        fleet_store.import_vessels(root / "warehouse.duckdb", fleet.vessels)
        counts = refit_job.import_noon_file(str(path), data_root=str(root))
        with duckdb.connect(str(root / "warehouse.duckdb"), read_only=True) as con:
            stored = con.execute("SELECT * FROM noon_reports ORDER BY imo, ts_utc").fetchdf()
            rejected = con.execute("SELECT reason, count(*) FROM noon_reports_rejected GROUP BY 1 ORDER BY 1").fetchall()
        results[rows] = counts, stored, rejected
    (whole, stored_whole, rej_whole), (chunked, stored_chunked, rej_chunked) = results[10**9], results[500]
    assert chunked == whole and chunked["reasons"].get("duplicate timestamp in file", 0) >= 1
    assert chunked["rows"] == len(noon) + 1 == chunked["inserted"] + chunked["rejected"]  # nothing lost
    pd.testing.assert_frame_equal(stored_chunked, stored_whole)
    assert rej_chunked == rej_whole
