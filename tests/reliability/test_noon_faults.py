"""Bad noon reports through `jitroute noon import` / `jitroute refit` end to end (real Prefect flows, real
DuckDB): every rejection reason lands in the rejected table, counts add up with nothing lost, a vessel
whose reports are all bad keeps its model, and whole-file problems are refused with a clear message."""

from __future__ import annotations

import logging
import re
import shutil
from pathlib import Path

import duckdb
import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from cli.main import app
from pipeline.synthetic.fleet import generate_fleet, imo_with_check_digit, write_fleet
from storage import fleet_store
from tests.noon_cases import rejection_cases

CUTOFF = pd.Timestamp("2020-10-01")  # reports before it are the stored history; later ones are fresh for tests
NEW_IMO = imo_with_check_digit(914999)


@pytest.fixture(autouse=True)
def wide_console(monkeypatch):
    monkeypatch.setenv("COLUMNS", "400")  # rich tables must not wrap the reasons we look for
    # Prefect's console handler keeps the stream of an earlier CliRunner call (closed since): stay quiet
    monkeypatch.setattr(logging, "raiseExceptions", False)


def _cli(*args: str) -> tuple[int, str]:
    result = CliRunner().invoke(app, list(args))
    if result.exception and not isinstance(result.exception, SystemExit):
        raise result.exception
    return result.exit_code, re.sub(r"\s+", " ", result.output)


@pytest.fixture(scope="module")
def fleet():
    return generate_fleet("2020-12-01T00", n_vessels=3, days=200, seed=11)


@pytest.fixture(scope="module")
def fresh(fleet) -> pd.DataFrame:
    """Good, never imported reports of the two clean vessels (text columns, as read from a CSV)."""
    noon = fleet.noon[fleet.noon.imo.isin(fleet.vessels.imo[1:])].copy()
    noon = noon[pd.to_datetime(noon.ts_utc).dt.tz_localize(None) >= CUTOFF]
    return noon.astype(str).reset_index(drop=True)


@pytest.fixture(scope="module")
def history_root(fleet, tmp_path_factory, prefect_harness) -> Path:
    """A data root with the fleet, its reports before CUTOFF and fitted active models."""
    folder = tmp_path_factory.mktemp("fleet")
    write_fleet(fleet, folder)
    noon = pd.read_csv(folder / "noon_reports.csv", dtype=str)
    noon[pd.to_datetime(noon.ts_utc, errors="coerce").dt.tz_localize(None) < CUTOFF].to_csv(folder / "noon_reports.csv", index=False)
    root = tmp_path_factory.mktemp("history") / "data"
    code, out = _cli("fleet", "import", str(folder), "--data", str(root))
    assert code == 0, out
    code, out = _cli("refit", "--data", str(root))
    assert code == 0 and out.count(" yes ") == 3, out
    return root


@pytest.fixture
def root(history_root, tmp_path) -> Path:
    dst = tmp_path / "data"
    shutil.copytree(history_root, dst)
    return dst


def _q(root: Path, sql: str, params=()) -> list[tuple]:
    con = duckdb.connect(str(root / "warehouse.duckdb"), read_only=True)
    rows = con.execute(sql, list(params)).fetchall()
    con.close()
    return rows


def _counts_line(out: str) -> tuple[int, int, int, int]:
    m = re.search(r"(\d+) rows → (\d+) imported, (\d+) already present, (\d+) rejected", out)
    assert m, out
    return tuple(int(x) for x in m.groups())


def test_every_rejection_reason_through_the_cli(root, fresh, tmp_path):
    base = fresh.iloc[0].to_dict()
    cases = rejection_cases(base, as_text=True)
    # two stored reports sent again: one unchanged (already present), one changed (a conflict)
    cols = [c for c in fleet_store.NOON_COLUMNS if c != "source_file"]
    stored = _q(root, "SELECT * EXCLUDE (source_file) FROM noon_reports WHERE imo = ? ORDER BY ts_utc DESC LIMIT 2", (int(base["imo"]),))
    same, other = ({c: ("" if v is None else pd.Timestamp(v).strftime("%Y-%m-%dT%H:%M:%SZ") if c == "ts_utc" else str(v))
                    for c, v in zip(cols, row)} for row in stored)
    changed = dict(other, stw_kn=str(float(other["stw_kn"]) + 1.0))
    rows = [*cases.values(), base, dict(base), same, changed]
    path = tmp_path / "reasons.csv"
    pd.DataFrame(rows).to_csv(path, index=False)
    n_before = _q(root, "SELECT count(*) FROM noon_reports")[0][0]
    code, out = _cli("noon", "import", str(path), "--data", str(root))
    assert code == 0, out
    n_rows, inserted, present, rejected = _counts_line(out)
    assert (n_rows, inserted, present, rejected) == (len(rows), 1, 1, len(cases) + 2)
    assert inserted + present + rejected == n_rows
    for reason in [*cases, "duplicate timestamp in file", "conflicts with a stored report"]:
        assert reason in out, reason
    got = dict(_q(root, "SELECT reason, count(*) FROM noon_reports_rejected WHERE source_file = ? GROUP BY reason", ("reasons.csv",)))
    assert got == {**{r: 1 for r in cases}, "duplicate timestamp in file": 1,
                   "conflicts with a stored report for the same vessel and time": 1}
    assert _q(root, "SELECT count(*) FROM noon_reports")[0][0] == n_before + 1
    raw = dict(_q(root, "SELECT reason, raw FROM noon_reports_rejected WHERE source_file = ?", ("reasons.csv",)))
    assert "eighty" in raw["not a number in rpm"] and "yesterday noon" in raw["bad timestamp"]  # the row as it came in


def _mixed(fresh: pd.DataFrame, n_good: int, seed: int) -> tuple[pd.DataFrame, int]:
    """n_good fresh good rows and a bad variant of every other fresh row, shuffled; returns (rows, n_bad)."""
    good = fresh.iloc[:n_good]
    bad = []
    for k, (_, r) in enumerate(fresh.iloc[n_good:].iterrows()):
        spoilt = list(rejection_cases(r.to_dict(), as_text=True).values())
        bad.append(spoilt[k % len(spoilt)])
    rows = pd.concat([good, pd.DataFrame(bad)], ignore_index=True).sample(frac=1.0, random_state=seed)
    return rows.reset_index(drop=True), len(bad)


def test_mixed_file_counts_add_up_and_nothing_is_lost(root, fresh, tmp_path):
    rows, n_bad = _mixed(fresh, 40, seed=1)
    path = tmp_path / "mixed.csv"
    rows.to_csv(path, index=False)
    n_before = _q(root, "SELECT count(*) FROM noon_reports")[0][0]
    code, out = _cli("noon", "import", str(path), "--data", str(root))
    assert code == 0, out
    n_rows, inserted, present, rejected = _counts_line(out)
    assert (n_rows, inserted, present, rejected) == (len(rows), 40, 0, n_bad) and inserted + rejected == len(rows)
    stored = _q(root, "SELECT imo, ts_utc FROM noon_reports WHERE source_file = 'mixed.csv'")
    assert len(stored) == 40 and _q(root, "SELECT count(*) FROM noon_reports")[0][0] == n_before + 40
    expect = {(int(r.imo), pd.Timestamp(r.ts_utc).tz_localize(None).to_pydatetime()) for r in fresh.iloc[:40].itertuples()}
    assert set(stored) == expect
    raws = {r[0] for r in _q(root, "SELECT raw FROM noon_reports_rejected WHERE source_file = 'mixed.csv'")}
    lines = [line.replace(",", "|") for line in path.read_text().splitlines()[1:]]
    assert len(raws) == n_bad and raws <= set(lines)  # every bad line is kept, as it came in...
    assert len([line for line in lines if line not in raws]) == 40  # ...and every other line was stored
    # importing the same file again adds nothing anywhere
    code, out = _cli("noon", "import", str(path), "--data", str(root))
    assert _counts_line(out) == (len(rows), 0, 40, n_bad)
    assert _q(root, "SELECT count(*) FROM noon_reports")[0][0] == n_before + 40
    assert _q(root, "SELECT count(*) FROM noon_reports_rejected WHERE source_file = 'mixed.csv'")[0][0] == n_bad


def test_parquet_gives_the_same_result_as_csv(history_root, fresh, tmp_path):
    rows, n_bad = _mixed(fresh, 30, seed=2)
    rows = rows[~rows.isin(["eighty", "yesterday noon"]).any(axis=1)]  # a typed Parquet column cannot hold text
    typed = rows.copy()
    for c in typed.columns:
        typed[c] = pd.to_datetime(typed[c], utc=True) if c == "ts_utc" else pd.to_numeric(typed[c].replace("", np.nan))
    results = {}
    for kind in ("csv", "parquet"):
        root = tmp_path / kind / "data"
        shutil.copytree(history_root, root)
        path = tmp_path / kind / f"reports.{kind}"
        rows.to_csv(path, index=False) if kind == "csv" else typed.to_parquet(path, index=False)
        code, out = _cli("noon", "import", str(path), "--data", str(root))
        assert code == 0, out
        results[kind] = (_counts_line(out),
                         _q(root, "SELECT * EXCLUDE (source_file) FROM noon_reports ORDER BY imo, ts_utc"),
                         _q(root, "SELECT reason, count(*) FROM noon_reports_rejected WHERE source_file LIKE 'reports.%' "
                                  "GROUP BY ALL ORDER BY 1"))
    assert results["csv"][0][1] == 30 and sum(n for _, n in results["csv"][2]) == len(rows) - 30
    assert results["parquet"] == results["csv"]


def test_a_vessel_whose_reports_are_all_bad_keeps_its_model_and_says_why(root, fresh, tmp_path):
    fleet_store.import_vessels(root / "warehouse.duckdb", pd.DataFrame([{"imo": NEW_IMO, "name": "JIT NEW 99", "type": "bulker",
                                                                          "dwt": 80000, "design_speed_kn": 14.0, "mcr_kw": 9000,
                                                                          "rpm_max": 105.0, "design_fuel_tph": 1.4}]))
    models_before = _q(root, "SELECT imo, version, target, active FROM perf_models ORDER BY ALL")
    old_imo = int(fresh.imo.iloc[0])
    bad = []
    for k, (_, r) in enumerate(fresh.iloc[:24].iterrows()):
        spoilt = [v for key, v in rejection_cases(r.to_dict(), as_text=True).items() if key not in ("unknown vessel", "bad timestamp")]
        row = spoilt[k % len(spoilt)]
        bad.append(dict(row, imo=str(NEW_IMO if k % 2 else old_imo)))
    path = tmp_path / "all_bad.csv"
    pd.DataFrame(bad).to_csv(path, index=False)
    code, out = _cli("noon", "import", str(path), "--data", str(root))
    assert code == 0 and _counts_line(out) == (24, 0, 0, 24), out
    code, out = _cli("refit", "--data", str(root))
    assert code == 0, out
    new_row = re.search(rf"│ {NEW_IMO} │ 0 │[^\n]*?no valid noon reports \(all rejected or none imported\): model unchanged", out)
    assert new_row, out
    assert re.search(rf"│ {old_imo} │ \d+ │.*?│ no │", out), out  # the vessel with an active model: not changed
    assert _q(root, "SELECT imo, version, target, active FROM perf_models ORDER BY ALL") == models_before
    assert not _q(root, "SELECT * FROM perf_models WHERE imo = ?", (NEW_IMO,))


BAD_FILES = {  # name -> (bytes, what the error must say besides the file name)
    "empty.csv": (b"", "cannot be read as CSV/Parquet"),
    "no_fuel.csv": (b"imo,ts_utc,rpm,draft_m,stw_kn,hours\n9140601,2020-11-01T12:00:00Z,80,10,12,24\n",
                    "required columns missing: fuel_t"),
    "surplus_first.csv": (b"imo,ts_utc,rpm,draft_m,stw_kn,hours,fuel_t\n9140601,2020-11-01T12:00:00Z,80,10,12,24,30,7,7\n",
                          "line 2 has more fields than the header's 7 columns"),
    "surplus_later.csv": (b"imo,ts_utc,rpm,draft_m,stw_kn,hours,fuel_t\n9140601,2020-11-01T12:00:00Z,80,10,12,24,30\n"
                          b"9140601,2020-11-02T12:00:00Z,80,10,12,24,30,7,7\n", "Expected 7 fields in line 3, saw 9"),
    "latin1.csv": ("imo,ts_utc,rpm,draft_m,stw_kn,hours,fuel_t\n9140601,2020-11-01T12:00:00Z,80,10,12,24,30 t ±é\n"
                   .encode("latin-1"), "cannot be read as CSV/Parquet"),
    "garbage.parquet": (b"PAR1 not really parquet", "cannot be read as CSV/Parquet"),
}


@pytest.mark.parametrize("name", [*BAD_FILES, "missing.csv"])
def test_a_file_that_cannot_be_read_is_refused_whole_with_a_clear_error(root, tmp_path, name):
    path = tmp_path / name
    if name in BAD_FILES:
        path.write_bytes(BAD_FILES[name][0])
    before = _q(root, "SELECT (SELECT count(*) FROM noon_reports), (SELECT count(*) FROM noon_reports_rejected)")
    code, out = _cli("noon", "import", str(path), "--data", str(root))
    assert code == 2 and re.search(rf"error: \S*{name}", out), out
    assert (BAD_FILES[name][1] if name in BAD_FILES else "no such file") in out, out
    assert _q(root, "SELECT (SELECT count(*) FROM noon_reports), (SELECT count(*) FROM noon_reports_rejected)") == before


def test_a_header_only_file_imports_nothing_and_says_so(root, tmp_path):
    path = tmp_path / "header_only.csv"
    path.write_text(",".join(c for c in fleet_store.NOON_COLUMNS if c != "source_file") + "\n")
    code, out = _cli("noon", "import", str(path), "--data", str(root))
    assert code == 0 and _counts_line(out) == (0, 0, 0, 0), out


def _iso(ts: pd.Timestamp, offset_h: int | None) -> str:
    """`ts` (naive UTC) written in another time zone (`+HH:00`), or naive when `offset_h` is None."""
    if offset_h is None:
        return ts.strftime("%Y-%m-%d %H:%M:%S")
    return (ts + pd.Timedelta(hours=offset_h)).strftime("%Y-%m-%dT%H:%M:%S") + f"{offset_h:+03d}:00"


def test_dates_are_iso_8601_per_value_and_implausible_values_are_refused(root, fresh, tmp_path):
    utc = [pd.Timestamp(t).tz_localize(None) for t in fresh.ts_utc.iloc[:6]]
    mixed = [dict(fresh.iloc[k].to_dict(), ts_utc=_iso(utc[k], (9, None, -5, None, 0, 9)[k])) for k in range(6)]
    base = fresh.iloc[10].to_dict()
    imo = str(base["imo"])
    bad = {  # row -> the reason it must be stored with
        "ambiguous": (dict(base, ts_utc="01/11/2018 12:00"), "ambiguous timestamp (day/month order unknown; use ISO 8601, e.g. 2020-12-01T12:00Z)"),
        "dotted": (dict(base, ts_utc="13.11.2018 12:00"), "ambiguous timestamp (day/month order unknown; use ISO 8601, e.g. 2020-12-01T12:00Z)"),
        "future": (dict(base, ts_utc=(pd.Timestamp.now("UTC") + pd.Timedelta(days=30)).strftime("%Y-%m-%dT%H:%MZ")),
                   "timestamp in the future"),
        "inf": (dict(fresh.iloc[11].to_dict(), fuel_t="inf"), "not a finite number in fuel_t"),
        "1e400": (dict(fresh.iloc[12].to_dict(), fuel_t="1e400"), "not a finite number in fuel_t"),
        "fraction": (dict(fresh.iloc[13].to_dict(), imo=imo + ".9"), "not an integer in imo"),
    }
    path = tmp_path / "dates.csv"
    pd.DataFrame([*mixed, *(row for row, _ in bad.values())]).to_csv(path, index=False)
    code, out = _cli("noon", "import", str(path), "--data", str(root))
    assert code == 0 and _counts_line(out) == (12, 6, 0, 6), out
    stored = sorted(r[0] for r in _q(root, "SELECT ts_utc FROM noon_reports WHERE source_file = 'dates.csv'"))
    assert stored == sorted(t.to_pydatetime() for t in utc)  # every offset converted to the same UTC instant
    got = sorted(_q(root, "SELECT reason FROM noon_reports_rejected WHERE source_file = 'dates.csv'"))
    assert got == sorted((r,) for _, r in bad.values())
    assert not _q(root, "SELECT * FROM noon_reports WHERE ts_utc::DATE IN ('2018-01-11', '2018-11-01', '2018-11-13')")
    assert not _q(root, "SELECT * FROM noon_reports WHERE ts_utc > now()::TIMESTAMP OR isinf(fuel_t)")


# --- fuzzing the noon import ------------------------------------------------------------------------------------

from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from pipeline.performance.validate import validate_noon  # noqa: E402

_CELL = st.one_of(st.text(max_size=10), st.sampled_from(["", "nan", "inf", "-inf", "1e400", "9140607", "9140607.9", "0", "24",
                                                         "12.5", "2020-11-01T12:00Z", "2020-11-01 21:00+09:00", "01/11/2018 12:00",
                                                         "2099-01-01T00:00Z", "-3"]))
_COLS = ["imo", "ts_utc", "rpm", "draft_m", "stw_kn", "sog_kn", "dist_nm", "hours", "fuel_t"]


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(rows=st.lists(st.fixed_dictionaries({c: _CELL for c in _COLS}), max_size=6))
def test_noon_validation_of_arbitrary_text_never_raises_and_keeps_only_sound_rows(rows):
    raw = pd.DataFrame(rows, columns=_COLS).astype(object)
    now = pd.Timestamp("2021-01-01")
    good, bad = validate_noon(raw, {9140607}, "fuzz.csv", now=now)
    assert len(good) + len(bad) == len(raw) and (bad["reason"].notna().all() if len(bad) else True)
    for c in ("rpm", "draft_m", "stw_kn", "hours", "fuel_t"):
        assert np.isfinite(good[c].astype(float)).all(), c
    assert (good["imo"] == 9140607).all()
    assert (good["ts_utc"] <= now + pd.Timedelta(hours=1)).all() and good["ts_utc"].notna().all()
