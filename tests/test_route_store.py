import duckdb
import pandas as pd
import pytest

from storage import route_store


def _route(voyage_id, status, fuel, base):
    return {"voyage_id": voyage_id, "imo": 9140607, "solver": "bfoa", "objective": "jit", "status": status,
            "reason": None if status == "ok" else "no feasible route", "depart_utc": "2020-12-01T06:00Z",
            "eta_utc": "2020-12-03T06:00Z", "rta_utc": "2020-12-03T06:00Z", "hours": 48.0, "fuel_t": fuel,
            "baseline_fuel_t": base, "savings_pct": None, "distance_nm": 700.0, "cycle": "2020-12-01T00Z",
            "seed": 1, "runtime_s": 0.5, "n_legs": 2, "beyond_forecast": False}


def _leg(voyage_id, leg):
    return {"voyage_id": voyage_id, "leg": leg, "lat0": 35.0, "lon0": 140.0, "lat1": 34.0, "lon1": 141.0,
            "course_deg": 140.0, "dist_nm": 70.0, "rpm": 80.0, "stw_kn": 12.0, "sog_kn": 12.5, "hours": 5.6,
            "fuel_t": 4.0, "etd_utc": "2020-12-01T06:00Z", "eta_utc": "2020-12-01T11:36Z", "wind_kn": 15.0,
            "wind_dir_deg": 270.0, "hs_m": 2.0, "wave_dir_deg": 260.0, "current_kn": 0.5, "beyond_forecast": False}


def test_run_results_written_once_in_a_transaction(tmp_path):
    db = tmp_path / "w.duckdb"
    route_store.begin_run(db, "r1", cycle="2020-12-01T00", solver="bfoa", trigger="manual", n_voyages=2)
    rows = [_route("V1", "ok", 90.0, 100.0), _route("V2", "infeasible", None, None)]
    n_ok, n_failed = route_store.write_run_results(db, tmp_path / "exports", "r1", rows, [_leg("V1", 0), _leg("V1", 1)])
    assert (n_ok, n_failed) == (1, 1)
    s = route_store.run_summary(db, "r1")
    assert s["status"] == "partial" and s["n"] == 2 and s["n_failed"] == 1
    assert s["savings_pct"] == pytest.approx(10.0)
    assert [p["voyage_id"] for p in s["problems"]] == ["V2"]
    legs = pd.read_parquet(tmp_path / "exports" / "routes" / "run_id=r1" / "route_legs.parquet")
    assert list(legs["leg"]) == [0, 1]
    # the primary key refuses a second copy of the same run's rows, and nothing of it lands
    with pytest.raises(duckdb.ConstraintException):
        route_store.write_run_results(db, tmp_path / "exports", "r1", rows[:1], [])
    con = duckdb.connect(str(tmp_path / "w.snapshot.duckdb"), read_only=True)
    assert con.execute("SELECT count(*) FROM routes").fetchone()[0] == 2
    assert con.execute("SELECT eta_utc FROM route_legs WHERE leg = 1").fetchone()[0].hour == 11


def test_a_plan_past_the_forecast_horizon_is_stored_flagged_and_needs_attention(tmp_path):
    db = tmp_path / "w.duckdb"
    route_store.begin_run(db, "r2", cycle="2020-12-01T00", solver="bfoa", trigger="manual", n_voyages=2)
    past = dict(_route("V3", "ok", 90.0, 100.0), forecast_flag="beyond horizon", hours_beyond_forecast=14.5,
                hours_before_cycle=0.0, beyond_forecast=3)
    route_store.write_run_results(db, tmp_path / "exports", "r2", [dict(_route("V1", "ok", 90.0, 100.0), beyond_forecast=0), past], [])
    with duckdb.connect(str(db), read_only=True) as con:
        flags = con.execute("SELECT voyage_id, forecast_flag, hours_beyond_forecast FROM routes ORDER BY 1").fetchall()
    assert flags == [("V1", None, None), ("V3", "beyond horizon", 14.5)]
    problems = route_store.run_summary(db, "r2")["problems"]
    assert [(p["voyage_id"], p["status"]) for p in problems] == [("V3", "ok, beyond horizon")]
