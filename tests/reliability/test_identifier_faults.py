"""Hostile voyage IDs and fleet files: an ID never becomes a path outside its run folder, and
`jitroute fleet import` refuses such rows with a reason (kept in `voyages_rejected`) instead of storing them.
Property-based (hypothesis) over arbitrary text, plus the named cases end to end through the CLI and DuckDB."""

from __future__ import annotations

import logging
import re
from pathlib import Path

import duckdb
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from cli.main import app
from pipeline.export.paths import ExportPathError, export_path
from pipeline.fleet_validate import validate_vessels, validate_voyages
from pipeline.synthetic.fleet import generate_fleet, write_fleet
from pipeline.validate_ids import VOYAGE_ID_PATTERN, is_valid_imo, voyage_id_problem

SETTINGS = settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                            HealthCheck.function_scoped_fixture])

HOSTILE = {  # voyage ID -> what the refusal says
    "../../x": "path separator",
    "x..y": "'..'",
    "..": "'..'",
    "a/b/c": "path separator",
    "/etc/passwd": "path separator",
    "C:\\temp\\x": "path separator",
    "V1\nV2": "control characters or a line break",
    "V1\x00.rtz": "control characters or a line break",
    "V\x1b[31mred": "control characters or a line break",
    "V" * 300: "longer than 64 characters (300)",
    " V1": "characters other than",
    ".hidden": "characters other than",
    "-rf": "characters other than",
    "V 1": "characters other than",
    "": "missing voyage_id",
}


@pytest.fixture(autouse=True)
def quiet(monkeypatch):
    monkeypatch.setenv("COLUMNS", "400")
    monkeypatch.setattr(logging, "raiseExceptions", False)


@pytest.mark.parametrize("vid", list(HOSTILE), ids=lambda v: repr(v)[:20])
def test_export_path_refuses_a_hostile_voyage_id_naming_the_voyage(tmp_path, vid):
    run_dir = tmp_path / "exports" / "run1"
    run_dir.mkdir(parents=True)
    with pytest.raises(ExportPathError) as exc:
        export_path(run_dir, vid, ".rtz")
    msg = str(exc.value)
    assert HOSTILE[vid] in msg.split("; a voyage ID must")[0] and "not written" in msg, msg
    assert repr(vid[:80])[1:-1][:20] in msg  # the voyage is named (repr: control characters show, not act)
    assert "\n" not in msg and "\x00" not in msg and "\x1b" not in msg


def test_export_path_keeps_plain_ids_in_the_run_folder_and_refuses_a_symlink_out(tmp_path):
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    assert export_path(run_dir, "V20001", ".rtz") == run_dir.resolve() / "V20001.rtz"
    assert export_path(run_dir, "JP-YOK_2020.12.a", "_plan.png") == run_dir.resolve() / "JP-YOK_2020.12.a_plan.png"
    (run_dir / "V9.rtz").symlink_to(tmp_path / "elsewhere.rtz")  # planted by someone with access to the folder
    with pytest.raises(ExportPathError, match="voyage V9: export file .* would be outside the run folder"):
        export_path(run_dir, "V9", ".rtz")
    with pytest.raises(ExportPathError, match="not a plain file ending"):
        export_path(run_dir, "V9", "/../../x")


@SETTINGS
@given(vid=st.text(min_size=0, max_size=120) | st.from_regex(r"[A-Za-z0-9][A-Za-z0-9._/-]{0,70}", fullmatch=True),
       suffix=st.sampled_from([".rtz", ".geojson", "_plan.png"]))
def test_export_path_is_inside_the_run_folder_or_refused(tmp_path, vid, suffix):
    run_dir = tmp_path / "run"
    run_dir.mkdir(exist_ok=True)
    try:
        p = export_path(run_dir, vid, suffix)
    except ExportPathError as exc:
        assert voyage_id_problem(vid) is not None
        assert "\n" not in str(exc)
        return
    assert p.parent == run_dir.resolve() and p.name == vid + suffix
    assert re.fullmatch(VOYAGE_ID_PATTERN, vid) and ".." not in vid


def _voyage_rows(folder: Path) -> pd.DataFrame:
    return pd.read_csv(folder / "voyages.csv", dtype=str, keep_default_na=False)


@pytest.fixture
def fleet_folder(tmp_path) -> Path:
    folder = tmp_path / "fleet"
    write_fleet(generate_fleet("2020-12-01T00", n_vessels=3, days=20, seed=5), folder)
    (folder / "noon_reports.csv").unlink()
    return folder


def _cli(*args: str) -> tuple[int, str]:
    result = CliRunner().invoke(app, list(args))
    if result.exception and not isinstance(result.exception, SystemExit):
        raise result.exception
    return result.exit_code, re.sub(r"\s+", " ", result.output)


def test_fleet_import_refuses_hostile_voyage_ids_with_the_reason_stored(fleet_folder, tmp_path, prefect_harness):
    good = _voyage_rows(fleet_folder)
    template = good.iloc[0].to_dict()
    hostile = pd.DataFrame([dict(template, voyage_id=vid) for vid in HOSTILE if vid])
    pd.concat([good, hostile], ignore_index=True).to_csv(fleet_folder / "voyages.csv", index=False)
    root = tmp_path / "data"
    before = set(tmp_path.rglob("*"))
    code, out = _cli("fleet", "import", str(fleet_folder), "--data", str(root))
    assert code == 0, out
    n_hostile = len(HOSTILE) - 1
    assert f"3 vessels, 3 voyages imported; 0 vessel rows and {n_hostile} voyage rows refused" in out, out
    con = duckdb.connect(str(root / "warehouse.duckdb"), read_only=True)
    stored = sorted(r[0] for r in con.execute("SELECT voyage_id FROM voyages").fetchall())
    refused = con.execute("SELECT voyage_id, reason, raw, source_file FROM voyages_rejected").fetchall()
    con.close()
    assert stored == sorted(good.voyage_id)
    assert len(refused) == n_hostile
    for vid, reason, raw, source in refused:
        assert HOSTILE[vid] in reason and source == "voyages.csv" and raw.startswith(vid + "|"), (vid, reason)
    new = set(tmp_path.rglob("*")) - before
    assert all(root == p or root in p.parents for p in new), sorted(map(str, new))
    # the same file again: nothing new refused, nothing duplicated
    code, out = _cli("fleet", "import", str(fleet_folder), "--data", str(root))
    con = duckdb.connect(str(root / "warehouse.duckdb"), read_only=True)
    assert con.execute("SELECT count(*) FROM voyages_rejected").fetchone()[0] == n_hostile
    con.close()


def test_fleet_import_checks_imo_check_digits_and_implausible_voyage_lengths(fleet_folder, tmp_path, prefect_harness):
    vessels = pd.read_csv(fleet_folder / "vessels.csv", dtype=str, keep_default_na=False)
    bad_vessels = [dict(vessels.iloc[0].to_dict(), imo="9140608", name="WRONG CHECK"),  # 9140607 is right
                   dict(vessels.iloc[0].to_dict(), imo="9140607.9", name="FRACTION"),
                   dict(vessels.iloc[0].to_dict(), imo="914060", name="SIX DIGITS"),
                   dict(vessels.iloc[0].to_dict(), dwt="inf")]
    pd.concat([vessels, pd.DataFrame(bad_vessels)], ignore_index=True).to_csv(fleet_folder / "vessels.csv", index=False)
    voyages = _voyage_rows(fleet_folder)
    v0 = voyages.iloc[0].to_dict()
    years_late = str(pd.Timestamp(v0["depart_utc"]) + pd.Timedelta(days=3651))
    bad_voyages = [dict(v0, voyage_id="VLONG", rta_utc=years_late),
                   dict(v0, voyage_id="VAMBIG", depart_utc="01/12/2020 13:00"),
                   dict(v0, voyage_id="VGHOST", imo="9999993"),
                   dict(v0, voyage_id="VRPM", rpm_options="[60,inf]")]
    pd.concat([voyages, pd.DataFrame(bad_voyages)], ignore_index=True).to_csv(fleet_folder / "voyages.csv", index=False)
    root = tmp_path / "data"
    code, out = _cli("fleet", "import", str(fleet_folder), "--data", str(root))
    assert code == 0 and "3 vessels, 3 voyages imported; 4 vessel rows and 4 voyage rows refused" in out, out
    con = duckdb.connect(str(root / "warehouse.duckdb"), read_only=True)
    vrej = dict(con.execute("SELECT raw, reason FROM vessels_rejected").fetchall())
    yrej = dict(con.execute("SELECT voyage_id, reason FROM voyages_rejected").fetchall())
    con.close()
    reasons = sorted(vrej.values())
    assert reasons == sorted(["IMO number fails its check digit", "not an integer in imo", "IMO number fails its check digit",
                              "not a finite number in dwt"]), reasons
    assert "implausible voyage length: RTA more than 90 days after departure" in yrej["VLONG"]
    assert yrej["VAMBIG"].startswith("depart_utc: ambiguous timestamp (day/month order unknown")
    assert yrej["VGHOST"] == "unknown vessel" and yrej["VRPM"].startswith("bad rpm_options")
    assert "implausible voyage length" in out and "ambiguous timestamp" in out


# --- fuzzing the imports (pure validation over arbitrary text, then the store) -------------------------------------

cell = st.one_of(st.text(max_size=12), st.sampled_from(["", "nan", "inf", "-inf", "1e400", "9140607", "9140607.9", "0",
                                                        "2020-12-01T12:00Z", "01/11/2018 12:00", "2020-12-01 12:00+09:00",
                                                        "[60,70]", "[]", "-1", "..", "a/b"]))


@SETTINGS
@given(rows=st.lists(st.fixed_dictionaries({c: cell for c in ("voyage_id", "imo", "dep_lat", "dep_lon", "arr_lat", "arr_lon",
                                                               "depart_utc", "rta_utc", "rpm_options", "draft_m")}),
                     max_size=8))
def test_voyage_validation_never_raises_and_every_row_is_accounted_for(rows):
    raw = pd.DataFrame(rows, columns=["voyage_id", "imo", "dep_lat", "dep_lon", "arr_lat", "arr_lon", "depart_utc", "rta_utc",
                                      "rpm_options", "draft_m"]).astype(object)
    good, bad = validate_voyages(raw, {9140607}, "fuzz.csv")
    assert len(good) + len(bad) == len(raw)
    assert bad["reason"].notna().all() if len(bad) else True
    for r in good.itertuples():
        assert voyage_id_problem(r.voyage_id) is None and r.imo == 9140607
        assert pd.notna(r.depart_utc) and pd.notna(r.rta_utc) and (r.rta_utc - r.depart_utc).days <= 90
        assert all(map(lambda x: abs(x) < float("inf"), (r.dep_lat, r.dep_lon, r.arr_lat, r.arr_lon)))


@SETTINGS
@given(rows=st.lists(st.fixed_dictionaries({"imo": cell | st.integers(0, 10**8).map(str), "name": cell, "dwt": cell}),
                     max_size=8))
def test_vessel_validation_never_raises_and_keeps_only_valid_imos(rows):
    raw = pd.DataFrame(rows, columns=["imo", "name", "dwt"]).astype(object)
    good, bad = validate_vessels(raw, "fuzz.csv")
    assert len(good) + len(bad) == len(raw)
    assert all(is_valid_imo(i) for i in good["imo"]) and good["imo"].is_unique
    assert all(abs(x) < float("inf") for x in good["dwt"].dropna())


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(vids=st.lists(st.text(min_size=1, max_size=80), min_size=1, max_size=5))
def test_fuzzed_voyage_ids_through_a_csv_file_and_the_warehouse(tmp_path_factory, vids):
    """Arbitrary IDs written to a real CSV, read back as the import reads it, validated and stored: the good
    ones are stored as they are, the others are refused with their raw text; nothing is lost."""
    from flows.jobs.refit import read_table
    from storage import fleet_store

    folder = tmp_path_factory.mktemp("fuzz")
    row = {"imo": "9140607", "dep_lat": "35.0", "dep_lon": "140.0", "arr_lat": "34.0", "arr_lon": "150.0",
           "depart_utc": "2020-12-01T00:00Z", "rta_utc": "2020-12-03T00:00Z"}
    pd.DataFrame([dict(row, voyage_id=v) for v in vids]).to_csv(folder / "voyages.csv", index=False)
    raw = read_table(folder / "voyages.csv")
    good, bad = validate_voyages(raw, {9140607}, "voyages.csv")
    # a bare carriage return splits a CSV record for readers, so count what the file holds, not what was meant
    # (a trailing "\r" is read as part of the line end: compare with the IDs the file holds, as read)
    assert len(good) + len(bad) == len(raw) and set(good.voyage_id) <= set(raw.voyage_id.dropna())
    db = folder / "warehouse.duckdb"
    fleet_store.import_vessels(db, pd.DataFrame([{"imo": 9140607, "name": "X"}]))
    fleet_store.import_voyages(db, good, bad)
    con = duckdb.connect(str(db), read_only=True)
    stored = {r[0] for r in con.execute("SELECT voyage_id FROM voyages").fetchall()}
    n_refused = con.execute("SELECT count(*) FROM voyages_rejected").fetchone()[0]
    con.close()
    assert stored == set(good.voyage_id) and all(voyage_id_problem(v) is None for v in stored)
    assert n_refused == len(bad.drop_duplicates(subset=["raw", "reason"]))


_NOON_COLS = ["imo", "ts_utc", "rpm", "draft_m", "stw_kn", "sog_kn", "dist_nm", "hours", "fuel_t"]
_noon_cell = st.one_of(st.text(max_size=8), st.sampled_from(["", "inf", "1e400", "9140607", "9140607.9", "80", "10", "12", "24",
                                                             "288", "1.5", "2020-11-01T12:00Z", "2020-11-01 21:00+09:00",
                                                             "01/11/2018 12:00", "2099-01-01T00:00Z"]))


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(noon=st.lists(st.fixed_dictionaries({c: _noon_cell for c in _NOON_COLS}), max_size=6),
       vessels=st.lists(st.fixed_dictionaries({"imo": _noon_cell | st.integers(10**6, 10**7).map(str), "name": st.text(max_size=8),
                                               "dwt": _noon_cell}), max_size=5))
def test_fuzzed_noon_and_vessel_csv_files_through_the_warehouse(tmp_path_factory, noon, vessels):
    """Arbitrary noon-report and vessel rows in real CSV files, read, validated and stored as the imports do:
    every row read is stored, already present or refused with a reason; nothing non-finite, ambiguous or with a
    bad IMO gets in."""
    from flows.jobs.refit import read_table
    from pipeline.performance.validate import validate_noon
    from storage import fleet_store

    folder = tmp_path_factory.mktemp("fuzzcsv")
    db = folder / "warehouse.duckdb"
    pd.DataFrame(vessels, columns=["imo", "name", "dwt"]).to_csv(folder / "vessels.csv", index=False)
    pd.DataFrame(noon, columns=_NOON_COLS).to_csv(folder / "noon.csv", index=False)
    raw_v = read_table(folder / "vessels.csv")
    good_v, bad_v = validate_vessels(raw_v, "vessels.csv")
    assert len(good_v) + len(bad_v) == len(raw_v)
    fleet_store.import_vessels(db, pd.concat([good_v, pd.DataFrame([{"imo": 9140607, "name": "X"}])], ignore_index=True)
                               .drop_duplicates("imo"), bad_v)
    raw_n = read_table(folder / "noon.csv")
    good_n, bad_n = validate_noon(raw_n, fleet_store.known_imos(db), "noon.csv")
    counts = fleet_store.import_noon(db, good_n, bad_n)
    assert counts["inserted"] + counts["already_present"] + counts["rejected"] == len(raw_n)
    con = duckdb.connect(str(db), read_only=True)
    assert all(is_valid_imo(i) for (i,) in con.execute("SELECT imo FROM vessels").fetchall())
    assert con.execute("SELECT count(*) FROM noon_reports WHERE isinf(fuel_t) OR isinf(rpm) OR ts_utc > now()::TIMESTAMP "
                       "OR ts_utc::DATE = '2018-01-11'").fetchone()[0] == 0
    assert con.execute("SELECT count(*) FROM noon_reports").fetchone()[0] == counts["inserted"]
    con.close()
