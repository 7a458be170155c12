"""What an operator (or anyone reaching the plan-fleet flow) gives the planner is checked: numbers that would make a
nonsense plan the active one, names that forge lines or run as spreadsheet formulas, dates past what a table holds,
are refused with one line naming the file, row and field; a plan with nothing to sail is stored, not a traceback."""

from __future__ import annotations

import duckdb
import pandas as pd
import pytest

from pipeline.planning.inputs import validate_availability, validate_contracts
from tests.test_planning import _raw

AVAIL = dict(imo="9074729", from_utc="2020-12-01", from_port="Busan", until_utc="", until_port="", ports="",
             cargo_types="grain;coal", daily_cost="9000", laden_draft_m="", ballast_draft_m="", laden_speed_kn="")
CONTRACT = dict(code="K1", cargo_type="grain", min_t="40000", max_t="45000", load_port="Busan", discharge_port="Qingdao",
                early_utc="2020-12-05T00:00Z", late_utc="2020-12-08T00:00Z", penalty="")


def test_availability_rows_with_nan_costs_inverted_drafts_or_unsafe_names_are_refused():
    rows = [AVAIL,
            {**AVAIL, "daily_cost": "nan"},
            {**AVAIL, "daily_cost": "NaN"},
            {**AVAIL, "daily_cost": "1e308"},
            {**AVAIL, "laden_draft_m": "2", "ballast_draft_m": "20"},
            {**AVAIL, "laden_draft_m": "5"},  # below the default ballast draft (7 m)
            {**AVAIL, "cargo_types": "grain;=HYPERLINK(\"http://evil\")"},
            {**AVAIL, "ports": "Busan;Qin\x1b[2Jgdao"},
            {**AVAIL, "laden_speed_kn": "400"},
            {**AVAIL, "laden_draft_m": "12", "ballast_draft_m": "8"}]
    good, bad = validate_availability(_raw(rows), known_imos={9074729}, ports={"Busan", "Qingdao"}, source="a.csv")
    assert len(good) == 1 and good["daily_cost"].iloc[0] == 9000  # the first; the last repeats its imo
    reasons = list(bad["reason"])
    assert reasons == [
        "not a number in daily_cost (NaN; leave the cell empty for the default)",
        "not a number in daily_cost (NaN; leave the cell empty for the default)",
        "daily_cost above 1e+12",
        "laden_draft_m below ballast_draft_m (empty: 11.5 and 7 m): a loaded ship floats deeper",
        "laden_draft_m below ballast_draft_m (empty: 11.5 and 7 m): a loaded ship floats deeper",
        "starts with =, +, - or @ (a spreadsheet would run it as a formula) in cargo_types",
        "control characters or a line break in ports",
        "laden_speed_kn above 40",
        "duplicate imo in file"], reasons
    assert set(bad["source_file"]) == {"a.csv"}


def test_contract_rows_with_absurd_penalties_dates_or_unsafe_names_are_refused():
    rows = [CONTRACT,
            {**CONTRACT, "code": "K2", "penalty": "1e308"},
            {**CONTRACT, "code": "K3", "penalty": "nan"},
            {**CONTRACT, "code": "K4", "penalty": "-5"},
            {**CONTRACT, "code": "K5", "late_utc": "2263-01-01T00:00Z"},
            {**CONTRACT, "code": "K6", "early_utc": "2030-12-05T00:00Z", "late_utc": "2030-12-08T00:00Z"},
            {**CONTRACT, "code": "K7", "cargo_type": "@SUM(A1:A9)"},
            {**CONTRACT, "code": "K8", "load_port": "Busan\r\nINFO forged line"},
            {**CONTRACT, "code": "K9", "max_t": "1e9"}]
    good, bad = validate_contracts(_raw(rows), as_of=pd.Timestamp("2020-12-01"), ports={"Busan", "Qingdao"},
                                   source="contracts.csv")
    assert list(good["code"]) == ["K1"]
    why = dict(zip(bad["code"], bad["reason"]))
    assert why == {
        "K2": "penalty above 1e+12",
        "K3": "not a number in penalty (NaN; leave the cell empty for the default)",
        "K4": "negative penalty",
        "K5": "late_utc: timestamp out of range (give one between 1677-09-22 and 2262-04-11)",
        "K6": "window opens more than 732 days after the planning time 2020-12-01 00:00:00 (check its year)",
        "K7": "starts with =, +, - or @ (a spreadsheet would run it as a formula) in cargo_type",
        "K8": "control characters or a line break in load_port",
        "K9": "max_t above 1e+06"}, why


@pytest.fixture(scope="module")
def fleet_root(tmp_path_factory):
    """A data root with a 4-vessel demo fleet and its planning files (nothing planned yet)."""
    from flows.jobs.refit import import_fleet_folder
    from pipeline.synthetic.contracts import write_demo_planning
    from pipeline.synthetic.fleet import generate_fleet, write_fleet

    base = tmp_path_factory.mktemp("plan-inputs")
    fl = generate_fleet("2020-12-01T00", n_vessels=4, days=30, seed=3)
    write_fleet(fl, base / "fleet")
    import_fleet_folder(str(base / "fleet"), data_root=str(base / "data"))
    files = write_demo_planning(fl.vessels, "2020-12-01T00", base / "plan", n_contracts=6, seed=4,
                                ports=("Busan", "Shanghai", "Qingdao", "Kaohsiung", "Keelung"))
    return base / "data", files


def _plans(root) -> int:
    with duckdb.connect(str(root / "warehouse.duckdb"), read_only=True) as con:
        return con.execute("SELECT count(*) FROM fleet_plans").fetchone()[0]


@pytest.mark.parametrize("option, value, says", [("--fuel-price", "-600", "--fuel-price -600: give a number ≥ 0"),
                                                 ("--fuel-price", "nan", "--fuel-price nan: give a number ≥ 0"),
                                                 ("--penalty", "-1", "--penalty -1: give a number ≥ 0"),
                                                 ("--penalty", "1e308", "and at most 1e+12"),
                                                 ("--time-limit", "inf", "--time-limit inf: give a number above 0"),
                                                 ("--effort", "0", "--effort 0: give a number above 0"),
                                                 ("--effort", "1e9", "--effort 1e+09: give a number above 0 and at most 300"),
                                                 ("--as-of", "9999-01-01T00:00Z", "timestamp out of range")])
@pytest.mark.slow
def test_plan_fleet_refuses_its_own_absurd_numbers_before_storing_anything(fleet_root, monkeypatch, option, value, says):
    from typer.testing import CliRunner

    from cli.main import app

    monkeypatch.delenv("PREFECT_API_URL", raising=False)
    monkeypatch.setenv("COLUMNS", "400")
    root, files = fleet_root
    before = _plans(root)
    res = CliRunner().invoke(app, ["plan", "fleet", "--contracts", files["contracts"], "--availability",
                                   files["availability"], "--ports", files["ports"], "--data", str(root), option, value])
    assert res.exit_code == 2 and says in res.output and "Traceback" not in res.output, res.output
    assert _plans(root) == before


@pytest.mark.slow  # the planning job end to end on an imported demo fleet
def test_a_plan_with_no_legs_is_stored_with_every_contract_left(fleet_root, tmp_path):
    from flows.jobs.planning import plan_fleet_job

    root, files = fleet_root
    free = pd.read_csv(files["contracts"]).assign(penalty=0)  # leaving a contract costs nothing: nothing is sailed
    free.to_csv(tmp_path / "free.csv", index=False)
    s = plan_fleet_job(str(tmp_path / "free.csv"), files["availability"], files["ports"], "2020-12-01T00:00Z",
                       data_root=str(root), picture=False)
    assert s["voyages_added"] == 0 and s["n_assigned"] == 0 and s["total_cost"] == 0
    assert s["n_unassigned"] == s["n_contracts"] == len(free) - 1  # K007's window has zero length: refused
    with duckdb.connect(str(root / "warehouse.duckdb"), read_only=True) as con:
        assert con.execute("SELECT status FROM fleet_plans WHERE plan_id = ?", [s["plan_id"]]).fetchone() == ("active",)
        assert con.execute("SELECT count(*) FROM fleet_plan_legs WHERE plan_id = ?", [s["plan_id"]]).fetchone() == (0,)
        assert con.execute("SELECT count(*) FROM fleet_plan_unassigned WHERE plan_id = ?",
                           [s["plan_id"]]).fetchone() == (s["n_contracts"],)


@pytest.mark.slow  # the planning job end to end on an imported demo fleet
def test_a_book_larger_than_the_planner_builds_in_bounded_memory_is_refused_before_building(fleet_root, tmp_path,
                                                                                            monkeypatch):
    from typer.testing import CliRunner

    from cli.main import app

    monkeypatch.delenv("PREFECT_API_URL", raising=False)
    monkeypatch.setenv("COLUMNS", "400")
    root, files = fleet_root
    one = pd.read_csv(files["contracts"]).iloc[0]
    early = pd.Timestamp("2020-12-05") + pd.to_timedelta(range(10_000), unit="min")
    book = pd.DataFrame([one] * 10_000).assign(code=[f"B{i:05d}" for i in range(10_000)], early_utc=early.strftime("%Y-%m-%dT%H:%M"),
                                               late_utc=(early + pd.Timedelta(days=3)).strftime("%Y-%m-%dT%H:%M"))
    book.to_csv(tmp_path / "book.csv", index=False)
    before = _plans(root)
    res = CliRunner().invoke(app, ["plan", "fleet", "--contracts", str(tmp_path / "book.csv"), "--availability",
                                   files["availability"], "--ports", files["ports"], "--as-of", "2020-12-01T00:00Z",
                                   "--time-limit", "30", "--data", str(root)])
    assert res.exit_code == 2 and "10000 open contracts for 4 vessels: the planner takes at most 2000" in res.output, \
        res.output
    assert "shorter horizon" in res.output and _plans(root) == before
