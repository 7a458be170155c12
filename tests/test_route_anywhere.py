"""Voyages through Suez, Panama and Malacca route end to end, through the CLI and the nightly, and a voyage told to
avoid Suez rounds the Cape (the global sea-route layer as each voyage's base route, the corridor laid along it)."""

from __future__ import annotations

import json

import duckdb
import pandas as pd
import pytest
from typer.testing import CliRunner

from tests.conftest import fleet_data_root, mirror_urls

pytestmark = pytest.mark.slow

# pilot stations at sea (lat, lon); the RTA leaves the ship about 11 kn over the sea route's length
SHANGHAI, ROTTERDAM = (31.0, 122.7), (52.0, 3.7)
NEW_YORK, LOS_ANGELES = (40.45, -73.8), (33.65, -118.3)
SINGAPORE, COLOMBO = (1.15, 103.75), (6.95, 79.8)
DEPART = pd.Timestamp("2020-12-01T13:00")
TRADES = {  # name → (from, to, RTA, the box (lat0, lat1, lon0, lon1) one of the plan's legs must start in)
    "suez": (SHANGHAI, ROTTERDAM, DEPART + pd.Timedelta(hours=940), (29.8, 31.4, 32.2, 32.7)),
    "panama": (NEW_YORK, LOS_ANGELES, DEPART + pd.Timedelta(hours=450), (8.8, 9.5, -80.0, -79.4)),
    "malacca": (SINGAPORE, COLOMBO, DEPART + pd.Timedelta(hours=150), (2.0, 5.5, 98.5, 101.5)),
}


def _legs_start_in(legs, box) -> bool:
    lat0, lat1, lon0, lon1 = box
    return any(lat0 <= g["lat0"] <= lat1 and lon0 <= g["lon0"] <= lon1 for g in legs)


@pytest.fixture(scope="module")
def root(tmp_path_factory, demo_mirror):
    return fleet_data_root(tmp_path_factory.mktemp("anywhere"), demo_mirror, n_vessels=2, days=120, seed=5, refit=True)


def _imo(root) -> int:
    with duckdb.connect(str(root / "warehouse.duckdb"), read_only=True) as con:
        return int(con.execute("SELECT imo FROM vessels ORDER BY imo LIMIT 1").fetchone()[0])


def _route(root, dep, arr, rta, *extra):
    from cli.main import app

    args = ["route", "--from", f"{dep[0]},{dep[1]}", "--to", f"{arr[0]},{arr[1]}", "--depart", f"{DEPART:%Y-%m-%dT%H}",
            "--rta", f"{rta:%Y-%m-%dT%H}", "--imo", str(_imo(root)), "--data", str(root), "--json", "--ensemble", "0",
            *extra]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 0, res.output[-3000:]
    return json.loads(res.output[res.output.index("{"):])


@pytest.mark.parametrize("trade", sorted(TRADES))
def test_the_cli_routes_through_the_canal_or_strait(root, trade):
    dep, arr, rta, box = TRADES[trade]
    plan = _route(root, dep, arr, rta)
    assert plan["status"] == "ok", plan["reason"]
    assert _legs_start_in(plan["legs"], box), f"the {trade} plan does not pass through {box}"
    assert plan["fuel_t"] <= plan["baseline_fuel_t"] + 1e-9  # never worse than constant speed on the same route


def test_avoiding_suez_rounds_the_cape(root):
    """Shanghai–Rotterdam: without Suez the shortest way is through Panama; without both, round the Cape."""
    dep, arr, _, suez = TRADES["suez"]
    rta = DEPART + pd.Timedelta(hours=1150)
    plan = _route(root, dep, arr, rta, "--avoid", "suez", "--avoid", "panama")
    assert plan["status"] == "ok", plan["reason"]
    assert not _legs_start_in(plan["legs"], suez)
    assert min(g["lat0"] for g in plan["legs"]) < -34.0, "round the Cape of Good Hope"
    assert plan["distance_nm"] > 13_000  # Shanghai–Rotterdam by the Cape is about 13,900 NM (Suez about 10,500)


def test_an_unknown_passage_is_refused_by_name(root):
    from cli.main import app

    res = CliRunner().invoke(app, ["route", "--from", "31.0,122.7", "--to", "52.0,3.7", "--depart", "2020-12-01T13",
                                   "--rta", "2021-01-08T12", "--imo", str(_imo(root)), "--data", str(root),
                                   "--avoid", "atlantis"])
    assert res.exit_code != 0 and "atlantis" in res.output and "suez" in res.output


def test_the_nightly_routes_voyages_through_suez_panama_and_malacca(root, demo_mirror, prefect_harness):
    from flows.fleet import nightly
    from storage import fleet_store

    imo = _imo(root)
    rows = [{"voyage_id": f"VX-{t}", "imo": imo, "dep_name": f"{t} from", "dep_lat": dep[0], "dep_lon": dep[1],
             "arr_name": f"{t} to", "arr_lat": arr[0], "arr_lon": arr[1], "depart_utc": DEPART, "rta_utc": rta, "rpm_options": None}
            for t, (dep, arr, rta, _) in TRADES.items()]
    fleet_store.import_voyages(root / "warehouse.duckdb", pd.DataFrame(rows))
    out = nightly(date="2020-12-01", data_root=str(root), cycles="00", **mirror_urls(demo_mirror))
    run_id = out["routing"]["run_id"]
    with duckdb.connect(str(root / "warehouse.duckdb"), read_only=True) as con:
        routes = con.execute("SELECT voyage_id, status, reason, distance_nm FROM routes WHERE run_id = ? "
                             "AND voyage_id LIKE 'VX-%'", [run_id]).fetchdf().set_index("voyage_id")
        legs = con.execute("SELECT voyage_id, lat0, lon0 FROM route_legs WHERE run_id = ? AND voyage_id LIKE 'VX-%'",
                           [run_id]).fetchdf()
    assert set(routes.index) == {f"VX-{t}" for t in TRADES}
    for t, (_, _, _, box) in TRADES.items():
        assert routes.loc[f"VX-{t}", "status"] == "ok", routes.loc[f"VX-{t}", "reason"]
        mine = legs[legs.voyage_id == f"VX-{t}"].to_dict("records")
        assert _legs_start_in(mine, box), f"VX-{t} does not pass through {box}"
