"""Re-planning never loses a cargo: what a re-plan keeps (voyages of contracts under way, voyages sailed by a
position report, voyages from a voyages file), the vessels it keeps busy, and refusals that protect the record —
end to end through the `jitroute` commands as operators run them, on a generated fleet."""

from __future__ import annotations

import duckdb
import pandas as pd
import pytest
from typer.testing import CliRunner

from pipeline.planning.voyages import replan


def _fleet_root(tmp_path):
    """A data root with a 4-vessel generated fleet (vessels and voyages imported) and its planning files."""
    from flows.jobs.refit import import_fleet_folder
    from pipeline.synthetic.contracts import write_demo_planning
    from pipeline.synthetic.fleet import generate_fleet, write_fleet

    root = tmp_path / "data"
    fl = generate_fleet("2020-12-01T00", n_vessels=4, days=30, seed=3)
    write_fleet(fl, tmp_path / "fleet")
    import_fleet_folder(str(tmp_path / "fleet"), data_root=str(root))
    files = write_demo_planning(fl.vessels, "2020-12-01T00", tmp_path / "plan", n_contracts=6, seed=4,
                                ports=("Busan", "Shanghai", "Qingdao", "Kaohsiung", "Keelung"))
    return root, files


def _cli(*args):
    from cli.main import app

    return CliRunner().invoke(app, [str(a) for a in args])


def _plan(root, files, as_of, first=False):
    extra = ["--availability", files["availability"], "--ports", files["ports"]] if first else []
    r = _cli("plan", "fleet", "--contracts", files["contracts"], *extra, "--as-of", as_of, "--data", root, "--json")
    assert r.exit_code == 0, r.output
    import json

    return json.loads(r.output)


def _q(root, sql, params=()):
    with duckdb.connect(str(root / "warehouse.duckdb"), read_only=True) as con:
        return con.execute(sql, list(params)).fetchdf()


def _voyages(root):
    """Every stored voyage with the plan leg that made it (contract, kind)."""
    return _q(root, "SELECT v.voyage_id, v.imo, v.plan_id, v.dep_name, v.arr_name, v.depart_utc, v.rta_utc, "
                    "l.contract_code, l.kind FROM voyages v LEFT JOIN fleet_plan_legs l USING (voyage_id) "
                    "ORDER BY v.imo, v.depart_utc")


def _assert_every_cargo_once_and_no_vessel_twice(root, codes):
    voy = _voyages(root)
    active = _q(root, "SELECT plan_id FROM fleet_plans WHERE status = 'active'")["plan_id"].tolist()
    assert len(active) == 1
    left = set(_q(root, "SELECT contract_code FROM fleet_plan_unassigned WHERE plan_id = ?", active)["contract_code"])
    laden = voy[voy["kind"] == "laden"]["contract_code"].value_counts()
    for code in codes:  # planned or under way exactly once (one laden voyage), or left by the active plan
        assert laden.get(code, 0) + (code in left) == 1, (code, laden.get(code, 0), code in left)
    for code in set(voy["contract_code"].dropna()):  # every voyage of a contract is of one vessel and one plan
        mine = voy[voy["contract_code"] == code]
        assert mine["imo"].nunique() == 1 and mine["plan_id"].nunique() == 1, mine
    for imo, mine in voy.groupby("imo"):  # no vessel on two voyages at once
        mine = mine.sort_values("depart_utc")
        overlap = mine["depart_utc"].iloc[1:].to_numpy() < mine["rta_utc"].iloc[:-1].to_numpy()
        assert not overlap.any(), mine[["voyage_id", "depart_utc", "rta_utc"]]


@pytest.mark.slow  # end to end through the `jitroute` commands on an imported fleet
def test_plan_sail_a_ballast_leg_re_plan_twice_every_cargo_is_planned_once_and_no_vessel_is_double_booked(tmp_path):
    root, files = _fleet_root(tmp_path)
    first = _plan(root, files, "2020-12-01T00:00Z", first=True)
    codes = [c for c in pd.read_csv(files["contracts"])["code"] if c not in {r["code"] for r in first["contracts_refused"]}]
    _assert_every_cargo_once_and_no_vessel_twice(root, codes)
    voy = _voyages(root)
    # the first ballast leg towards a load port: the vessel sails it, the operator reports a position
    ballast = voy[(voy["kind"] == "ballast") & voy["contract_code"].notna()].sort_values("depart_utc").iloc[0]
    laden_id = voy[(voy["kind"] == "laden") & (voy["contract_code"] == ballast["contract_code"])]["voyage_id"].item()
    at = pd.Timestamp(ballast["depart_utc"]) + pd.Timedelta(hours=3)
    port = _q(root, "SELECT lat, lon FROM ports WHERE port = ?", [ballast["dep_name"]]).iloc[0]
    r = _cli("position", ballast["voyage_id"], "--at", f"{at:%Y-%m-%dT%H:%M}", "--pos",
             f"{port['lat']:.4f},{port['lon']:.4f}", "--data", root)
    assert r.exit_code == 0, r.output
    # re-plan as of before the planned departure (the report says it sailed), then a day after it
    second = _plan(root, files, f"{pd.Timestamp(ballast['depart_utc']) - pd.Timedelta(hours=1):%Y-%m-%dT%H:%M}Z")
    assert ballast["contract_code"] in {r["code"] for r in second["committed"]}
    third = _plan(root, files, f"{pd.Timestamp(ballast['depart_utc']) + pd.Timedelta(days=1):%Y-%m-%dT%H:%M}Z")
    assert ballast["contract_code"] in {r["code"] for r in third["committed"]}
    stored = set(_voyages(root)["voyage_id"])
    assert {ballast["voyage_id"], laden_id} <= stored  # the cargo under way: both its voyages kept
    _assert_every_cargo_once_and_no_vessel_twice(root, codes)
    legs = _q(root, "SELECT contract_code FROM fleet_plan_legs WHERE plan_id IN (?, ?)", [second["plan_id"], third["plan_id"]])
    assert ballast["contract_code"] not in set(legs["contract_code"])  # not planned again by either re-plan
    # the vessel of the cargo under way is given nothing before that cargo's discharge ends
    end = _q(root, "SELECT rta_utc FROM voyages WHERE voyage_id = ?", [laden_id])["rta_utc"].item()
    new = _q(root, "SELECT min(depart_utc) AS t FROM fleet_plan_legs WHERE plan_id = ? AND imo = ?",
             [third["plan_id"], int(ballast["imo"])])["t"].item()
    assert pd.isna(new) or new >= end


@pytest.mark.slow  # end to end through the `jitroute` commands on an imported fleet
def test_a_re_plan_as_of_before_the_active_plan_is_refused_and_deletes_nothing(tmp_path):
    root, files = _fleet_root(tmp_path)
    _plan(root, files, "2020-12-02T00:00Z", first=True)
    before = set(_voyages(root)["voyage_id"])
    for as_of in ("1900-01-01", "2020-12-01T23:00Z"):
        r = _cli("plan", "fleet", "--contracts", files["contracts"], "--as-of", as_of, "--data", root)
        assert r.exit_code != 0 and "cannot go back in time" in r.output and "2020-12-02T00:00Z" in r.output, r.output
    assert set(_voyages(root)["voyage_id"]) == before


@pytest.mark.slow  # end to end through the `jitroute` commands on an imported fleet
def test_the_planner_does_not_book_a_vessel_during_its_voyages_from_the_voyages_file(tmp_path):
    root, files = _fleet_root(tmp_path)
    _plan(root, files, "2020-12-01T00:00Z", first=True)
    voy = _voyages(root)
    from_file = voy[voy["plan_id"].isna()]
    assert len(from_file) >= 2  # the generated fleet's voyages, imported with it
    for imo, mine in voy.groupby("imo"):
        ends = from_file[from_file["imo"] == imo]["rta_utc"]
        planned = mine[mine["plan_id"].notna()]
        if len(ends) and len(planned):
            first = planned.sort_values("depart_utc").iloc[0]
            assert first["depart_utc"] >= ends.max()
            last_file = from_file[from_file["imo"] == imo].sort_values("rta_utc").iloc[-1]
            assert first["dep_name"] == last_file["arr_name"]  # from where that voyage ends


@pytest.mark.slow  # end to end through the `jitroute` commands on an imported fleet
def test_a_noon_report_since_its_departure_makes_a_plan_voyage_sailed_whatever_the_as_of(tmp_path):
    from storage import warehouse

    root, files = _fleet_root(tmp_path)
    _plan(root, files, "2020-12-01T00:00Z", first=True)
    voy = _voyages(root).dropna(subset=["plan_id"]).sort_values("depart_utc")
    leg = voy.iloc[-1]  # the last plan voyage: a re-plan as of just after the first plan keeps nothing else
    at = pd.Timestamp(leg["depart_utc"]) + (pd.Timestamp(leg["rta_utc"]) - pd.Timestamp(leg["depart_utc"])) / 2
    with warehouse.connect(root / "warehouse.duckdb") as con:  # its vessel's noon report half way
        con.execute("INSERT INTO noon_reports (imo, ts_utc, lat, lon) VALUES (?, ?, 30.0, 125.0)",
                    [int(leg["imo"]), at.to_pydatetime()])
    second = _plan(root, files, "2020-12-01T00:01Z")
    assert leg["voyage_id"] in set(_voyages(root)["voyage_id"])
    if pd.notna(leg["contract_code"]):
        assert leg["contract_code"] in {r["code"] for r in second["committed"]}


@pytest.mark.slow  # end to end through the `jitroute` commands on an imported fleet
def test_a_voyages_file_cannot_replace_a_plan_voyage_by_reusing_its_id(tmp_path):
    import shutil

    root, files = _fleet_root(tmp_path)
    _plan(root, files, "2020-12-01T00:00Z", first=True)
    plan_voyage = _voyages(root).dropna(subset=["plan_id"]).iloc[0]
    folder = tmp_path / "again"
    folder.mkdir()
    shutil.copy(tmp_path / "fleet" / "vessels.csv", folder)
    voyages = pd.read_csv(tmp_path / "fleet" / "voyages.csv")
    voyages.loc[0, "voyage_id"] = plan_voyage["voyage_id"]  # a voyage of the file under the plan voyage's ID
    voyages.to_csv(folder / "voyages.csv", index=False)
    r = _cli("fleet", "import", folder, "--data", root)
    assert r.exit_code == 0, r.output
    after = _voyages(root).set_index("voyage_id").loc[plan_voyage["voyage_id"]]
    assert after["plan_id"] == plan_voyage["plan_id"] and after["dep_name"] == plan_voyage["dep_name"]
    why = _q(root, "SELECT reason FROM voyages_rejected WHERE voyage_id = ?", [plan_voyage["voyage_id"]])["reason"]
    assert len(why) == 1 and why[0].startswith(f"voyage_id {plan_voyage['voyage_id']} is a voyage of fleet plan "
                                               f"{plan_voyage['plan_id']}")


@pytest.mark.slow  # end to end through the `jitroute` commands on an imported fleet
def test_latest_routes_drops_the_plans_of_voyages_a_re_plan_replaced(tmp_path):
    from storage import warehouse

    root, files = _fleet_root(tmp_path)
    _plan(root, files, "2020-12-01T00:00Z", first=True)
    routed = list(_voyages(root)["voyage_id"])  # every voyage routed once, "ok"
    with warehouse.connect(root / "warehouse.duckdb") as con:
        con.execute("INSERT INTO route_runs (run_id, started_at, status) VALUES ('r1', now(), 'ok')")
        for vid in routed:
            con.execute("INSERT INTO routes (run_id, voyage_id, status, fuel_t) VALUES ('r1', ?, 'ok', 5.0)", [vid])
        con.execute("INSERT INTO routes (run_id, voyage_id, status, fuel_t) VALUES ('r1', 'ad-hoc', 'ok', 1.0)")
    second = _plan(root, files, "2020-12-03T00:00Z")
    assert second["voyages_replaced"] >= 1
    shown = set(_q(root, "SELECT voyage_id FROM latest_routes")["voyage_id"])
    stored = set(_voyages(root)["voyage_id"])
    assert shown == (set(routed) & stored) | {"ad-hoc"}  # a route of no stored voyage but no plan's either stays


@pytest.mark.slow  # end to end through the `jitroute` commands on an imported fleet
@pytest.mark.parametrize("at, pos, why", [
    ("2020-12-01T12:00", "34.3000,140.3000", "is before its departure 2020-12-01 13:00"),
    ("2021-12-05T00:00", "13.4000,144.5000", "days after its RTA 2020-12-05 01:12"),
    ("2020-12-01T18:00", "35.6800,139.7600", "is on land"),
    ("2020-12-01T18:00", "20.0000,-160.0000", "NM from the departure port at 2020-12-01 13:00"),
])
def test_position_refuses_what_cannot_be_the_voyage_at_sea_and_stores_what_can(tmp_path, at, pos, why):
    root, _ = _fleet_root(tmp_path)
    r = _cli("position", "V20001", "--at", at, "--pos", pos, "--data", root)  # Tokyo Bay → Guam, 12-01 13:00
    assert r.exit_code == 2 and "voyage V20001: position not stored:" in r.output and why in r.output, r.output
    assert len(r.output.strip().splitlines()) == 1
    assert _q(root, "SELECT count(*) AS n FROM voyage_positions")["n"].item() == 0
    ok = _cli("position", "V20001", "--at", "2020-12-01T18:00", "--pos", "34.3,140.3", "--data", root)
    assert ok.exit_code == 0 and "stored" in ok.output, ok.output
    assert _q(root, "SELECT count(*) AS n FROM voyage_positions")["n"].item() == 1


def test_a_position_too_far_from_that_hours_noon_report_is_refused():
    import numpy as np

    from pipeline import enroute

    v = {"depart_utc": np.datetime64("2020-12-01T00:00"), "rta_utc": np.datetime64("2020-12-10T00:00"),
         "dep_lat": 34.85, "dep_lon": 139.85}
    report = enroute.Position(np.datetime64("2020-12-04T12:00"), 30.0, 150.0)
    near = dict(at_sea=True, reports=[report], top_speed_kn=15.0)
    # 4.5 days out the ship may be anywhere within 3,240 NM of port: only the noon report of that hour can tell
    assert enroute.position_problem(v, np.datetime64("2020-12-04T12:30"), 30.2, 150.2, **near) is None
    why = enroute.position_problem(v, np.datetime64("2020-12-04T13:00"), 34.0, 141.0, **near)
    assert why is not None and "from the vessel's noon report at 2020-12-04 12:00" in why and "kn, more than 2" in why
    # a report before the departure is of another voyage: not a reference
    old = dict(near, reports=[enroute.Position(np.datetime64("2020-11-30T23:00"), 0.0, 0.0)])
    assert enroute.position_problem(v, np.datetime64("2020-12-01T00:30"), 34.85, 139.9, **old) is None


# ---------------------------------------------------------------------------------------------- replan, unit


def _row(vid, imo, plan, depart, rta, code=None, kind=None, reported=None, status="planned", arr="B"):
    return {"voyage_id": vid, "imo": imo, "plan_id": plan, "status": status, "depart_utc": pd.Timestamp(depart),
            "rta_utc": pd.Timestamp(rta), "arr_name": arr, "arr_lat": 1.0, "arr_lon": 2.0, "contract_code": code,
            "kind": kind, "port_hours": 12.0, "reported_utc": pd.Timestamp(reported) if reported else pd.NaT}


def test_replan_keeps_every_voyage_of_a_contract_under_way_and_what_a_position_says_has_sailed():
    rows = pd.DataFrame([
        _row("b1", 1, "p", "2020-12-02", "2020-12-03", "K1", "ballast", arr="L"),
        _row("l1", 1, "p", "2020-12-04", "2020-12-06", "K1", "laden", arr="D"),
        _row("b2", 2, "p", "2020-12-05", "2020-12-06", "K2", "ballast", reported="2020-12-05T06"),
        _row("l2", 2, "p", "2020-12-07", "2020-12-08", "K2", "laden", arr="E"),
        _row("l3", 2, "p", "2020-12-10", "2020-12-11", "K3", "laden"),
        _row("f1", 3, None, "2020-12-01", "2020-12-09", arr="Guam"),
        _row("f2", 4, None, "2020-12-01", "2020-12-04", arr=None),
    ])
    out = replan(rows, pd.Timestamp("2020-12-02T12"))
    assert set(out.committed) == {"K1", "K2"} and "position reported 2020-12-05 06:00" in out.committed["K2"]
    assert out.kept_plan_voyages == ["b1", "b2", "l1", "l2"] and out.replaced == ["l3"]
    assert out.busy[1][:2] == (pd.Timestamp("2020-12-06T12"), "D")  # discharge + 12 h in port
    assert out.busy[2][:2] == (pd.Timestamp("2020-12-08T12"), "E")
    assert out.busy[3][:2] == (pd.Timestamp("2020-12-09T12"), "Guam")
    assert out.busy[4] == (pd.Timestamp("2020-12-04T12"), "arrival of f2", 1.0, 2.0)  # a voyage without a port name
    # as of before everything, with no report: nothing of a plan has sailed
    early = replan(rows.assign(reported_utc=pd.NaT), pd.Timestamp("2020-12-01"))
    assert early.committed == {} and early.replaced == ["b1", "b2", "l1", "l2", "l3"]
    # a voyage no longer "planned" (e.g. at sea by the voyages file) has sailed
    at_sea = rows.assign(status=["planned"] * 4 + ["at sea", "planned", "planned"])
    assert "K3" in replan(at_sea, pd.Timestamp("2020-12-01")).committed


@pytest.mark.parametrize("as_of", ["2020-12-07", "2020-12-20"])
def test_replan_frees_a_vessel_whose_voyages_have_ended(as_of):
    rows = pd.DataFrame([_row("l1", 1, "p", "2020-12-04", "2020-12-06", "K1", "laden", arr="D")])
    out = replan(rows, pd.Timestamp(as_of))
    assert out.busy == {} and out.replaced == [] and out.kept_plan_voyages == ["l1"]
