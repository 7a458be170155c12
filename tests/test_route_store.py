import duckdb
import pandas as pd
import polars as pl
import pyarrow as pa
import pyarrow.dataset as ds
import pyarrow.parquet as pq
import pytest

from schemas.tables.routes import ROUTE_LEGS, ROUTES
from storage import route_store


def _route(voyage_id, status, fuel, base):
    return ROUTES.empty_row(**{"voyage_id": voyage_id, "imo": 9140607, "solver": "bfoa", "objective": "jit", "status": status,
            "reason": None if status == "ok" else "no feasible route", "depart_utc": "2020-12-01T06:00Z",
            "eta_utc": "2020-12-03T06:00Z", "rta_utc": "2020-12-03T06:00Z", "hours": 48.0, "fuel_t": fuel,
            "baseline_fuel_t": base, "savings_pct": None, "distance_nm": 700.0, "cycle": "2020-12-01T00Z",
            "seed": 1, "runtime_s": 0.5, "n_legs": 2, "n_legs_beyond_forecast": 0})


def _leg(voyage_id, leg):
    return ROUTE_LEGS.empty_row(**{"voyage_id": voyage_id, "leg": leg, "lat0": 35.0, "lon0": 140.0, "lat1": 34.0, "lon1": 141.0,
            "course_deg": 140.0, "dist_nm": 70.0, "rpm": 80.0, "stw_kn": 12.0, "sog_kn": 12.5, "hours": 5.6,
            "fuel_t": 4.0, "etd_utc": "2020-12-01T06:00Z", "eta_utc": "2020-12-01T11:36Z", "wind_kn": 15.0,
            "wind_dir_deg": 270.0, "hs_m": 2.0, "wave_dir_deg": 260.0, "current_kn": 0.5, "beyond_forecast": False,
                                   "hours_beyond_forecast": 0.0, "hours_before_cycle": 0.0, "hours_without_wind": 0.0})


def test_run_results_written_once_in_a_transaction(tmp_path):
    db = tmp_path / "w.duckdb"
    route_store.begin_run(db, "r1", cycle="2020-12-01T00", solver="bfoa", trigger="manual", n_voyages=2)
    rows = [_route("V1", "ok", 90.0, 100.0), _route("V2", "infeasible", None, None)]
    n_ok, n_failed = route_store.write_run_results(db, tmp_path / "exports", "r1", rows, [_leg("V1", 0), _leg("V1", 1)])
    assert (n_ok, n_failed) == (1, 1)
    s = route_store.run_summary(db, "r1")
    assert s["status"] == "partial" and s["n"] == 2 and s["n_failed"] == 1
    assert s["savings_vs_discrete_pct"] == pytest.approx(10.0)
    assert s["savings_total_pct"] is None and s["n_compared"] == 0  # no honest baseline on these rows
    assert [p["voyage_id"] for p in s["problems"]] == ["V2"]
    legs = pd.read_parquet(route_store.parquet_dir(tmp_path / "exports", "route_legs") / "run_id=r1" / "part-0.parquet")
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
                hours_before_cycle=0.0, n_legs_beyond_forecast=3)
    route_store.write_run_results(db, tmp_path / "exports", "r2", [dict(_route("V1", "ok", 90.0, 100.0), n_legs_beyond_forecast=0), past], [])
    with duckdb.connect(str(db), read_only=True) as con:
        flags = con.execute("SELECT voyage_id, forecast_flag, hours_beyond_forecast FROM routes ORDER BY 1").fetchall()
    assert flags == [("V1", None, None), ("V3", "beyond horizon", 14.5)]
    problems = route_store.run_summary(db, "r2")["problems"]
    assert [(p["voyage_id"], p["status"]) for p in problems] == [("V3", "ok, beyond horizon")]


def _two_runs(tmp_path):
    """Two runs written (3 routes, 5 legs), the exports folder."""
    db, exports = tmp_path / "w.duckdb", tmp_path / "exports"
    for run_id, voyages in (("r1", ["V1", "V2"]), ("r2", ["V1"])):
        route_store.begin_run(db, run_id, cycle="2020-12-01T00", solver="bfoa", trigger="manual", n_voyages=len(voyages))
        rows = [_route(v, "ok", 90.0, 100.0) for v in voyages[:1]] + [
            ROUTES.empty_row(voyage_id=v, imo=9140607, status="failed", reason="no cube", n_legs=0, n_legs_beyond_forecast=0)
            for v in voyages[1:]]
        legs = [dict(_leg("V1", i), beyond_forecast=i == 2) for i in range(3 if run_id == "r1" else 2)]
        route_store.write_run_results(db, exports, run_id, rows, legs)
    return exports


@pytest.mark.parametrize("table, n_rows, time_col", [("routes", 3, "eta_utc"), ("route_legs", 5, "etd_utc")])
@pytest.mark.slow
def test_each_parquet_folder_reads_as_one_table_in_pyarrow_polars_and_duckdb(tmp_path, table, n_rows, time_col):
    folder = route_store.parquet_dir(_two_runs(tmp_path), table)
    assert sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*")  if p.is_file()) == [
        "run_id=r1/part-0.parquet", "run_id=r2/part-0.parquet"]  # no temp file left behind

    t = ds.dataset(folder, partitioning="hive").to_table()
    assert t.num_rows == n_rows and sorted(set(t["run_id"].to_pylist())) == ["r1", "r2"]
    assert t.schema.field(time_col).type == pa.timestamp("us", tz="UTC")

    df = pl.scan_parquet(folder / "**/*.parquet", hive_partitioning=True).collect()
    assert df.height == n_rows and sorted(df["run_id"].unique().to_list()) == ["r1", "r2"]
    assert df.schema[time_col] == pl.Datetime("us", "UTC")

    with duckdb.connect() as con:
        n, n_runs, typ = con.execute(
            f"SELECT count(*), count(DISTINCT run_id), any_value(typeof({time_col})) "
            "FROM read_parquet(?, hive_partitioning = true)", [str(folder / "**/*.parquet")]).fetchone()
    assert (n, n_runs, typ) == (n_rows, 2, "TIMESTAMP WITH TIME ZONE")


def test_a_column_name_has_one_type_in_both_parquet_tables(tmp_path):
    exports = _two_runs(tmp_path)
    routes, legs = (pq.read_schema(route_store.parquet_dir(exports, t) / "run_id=r1" / "part-0.parquet")
                    for t in ("routes", "route_legs"))
    shared = set(routes.names) & set(legs.names)
    assert {"voyage_id", "hours", "fuel_t", "eta_utc"} <= shared and "beyond_forecast" not in routes.names
    assert {n: routes.field(n).type for n in shared} == {n: legs.field(n).type for n in shared}
    assert routes.field("n_legs_beyond_forecast").type == pa.int32() and legs.field("beyond_forecast").type == pa.bool_()
    legs_r1 = pq.read_table(route_store.parquet_dir(exports, "route_legs") / "run_id=r1" / "part-0.parquet")
    assert legs_r1["beyond_forecast"].to_pylist() == [False, False, True]
    assert str(legs_r1["etd_utc"][0]) == "2020-12-01 06:00:00+00:00"


@pytest.mark.slow
def test_runs_in_the_old_parquet_layout_move_to_the_per_table_folders_on_the_next_write(tmp_path):
    exports = tmp_path / "exports"
    old = exports / "routes" / "run_id=r0"
    old.mkdir(parents=True)
    route = dict(_route("V1", "ok", 90.0, 100.0), beyond_forecast=2)
    del route["n_legs_beyond_forecast"]
    pd.DataFrame([route]).assign(eta_utc=pd.Timestamp("2020-12-03T06:00")).to_parquet(old / "routes.parquet")
    pd.DataFrame([_leg("V1", 0)]).assign(etd_utc=pd.Timestamp("2020-12-01T06:00")).to_parquet(old / "route_legs.parquet")
    _two_runs(tmp_path)
    assert not old.exists()
    routes = ds.dataset(route_store.parquet_dir(exports, "routes"), partitioning="hive").to_table().to_pandas()
    r0 = routes[routes["run_id"] == "r0"].iloc[0]
    assert len(routes) == 4 and r0["n_legs_beyond_forecast"] == 2
    assert r0["eta_utc"] == pd.Timestamp("2020-12-03T06:00Z")  # the old naive time read as UTC
    legs = ds.dataset(route_store.parquet_dir(exports, "route_legs"), partitioning="hive").to_table()
    assert legs.num_rows == 6 and legs.schema.field("etd_utc").type == pa.timestamp("us", tz="UTC")


def test_run_savings_are_fuel_weighted_over_the_honest_baseline_and_make_the_headline(tmp_path):
    from flows.jobs.fleet import run_markdown

    db = tmp_path / "w.duckdb"
    route_store.begin_run(db, "r3", cycle="2020-12-01T00", solver="bfoa", trigger="manual", n_voyages=3)

    def honest(row, base, profile, limits):
        fuel = row["fuel_t"]
        return dict(row, honest_baseline_rpm=75.4, honest_baseline_fuel_t=base, honest_baseline_hours=48.0,
                    profile_fuel_t=profile, savings_total_pct=100 * (base - fuel) / base,
                    savings_speed_profile_pct=100 * (base - profile) / base, savings_route_pct=100 * (profile - fuel) / base,
                    min_engine_hold_h=12.0, engine_change_cost_t=0.05, n_engine_changes=2,
                    unlimited_fuel_t=fuel - limits, limits_fuel_t=limits)

    rows = [honest(_route("V1", "ok", 90.0, 120.0), 100.0, 98.0, 0.5),  # 10 % saved on a small voyage
            honest(_route("V2", "ok", 380.0, 450.0), 400.0, 390.0, 1.25),  # 5 % on a large one
            _route("V3", "infeasible", None, None)]
    route_store.write_run_results(db, tmp_path / "exports", "r3", rows, [])
    with duckdb.connect(str(db), read_only=True) as con:
        cols = {r[0] for r in con.execute("DESCRIBE routes").fetchall()}
        view = con.execute("SELECT savings_total_pct, savings_speed_profile_pct, savings_route_pct, limits_fuel_t, "
                           "savings_vs_discrete_pct FROM fleet_savings WHERE run_id = 'r3'").fetchone()
    assert {"honest_baseline_rpm", "honest_baseline_fuel_t", "honest_baseline_hours", "savings_total_pct",
            "savings_speed_profile_pct", "savings_route_pct", "unlimited_fuel_t", "limits_fuel_t",
            "n_engine_changes", "min_engine_hold_h"} <= cols
    # sums over the fleet, not the mean of the voyages' percentages (which would be 7.5 %)
    assert view[0] == pytest.approx(100 * (1 - 470 / 500))
    assert view[1] == pytest.approx(100 * (1 - 488 / 500)) and view[2] == pytest.approx(100 * 18 / 500)
    assert view[3] == pytest.approx(1.75) and view[4] == pytest.approx(100 * (1 - 470 / 570))
    s = route_store.run_summary(db, "r3")
    assert s["savings_total_pct"] == pytest.approx(view[0]) and s["n_compared"] == 2
    md = run_markdown(s)
    headline = md.splitlines()[2]
    assert headline.startswith("Savings 6.0 % against sailing the base route at the one constant speed")
    assert "speed profile 2.4 %, route 3.6 %" in headline and "limits cost 1.75 t" in headline
    assert "17.5" not in headline  # the discrete-rpm figure is no headline


def test_the_next_writer_fails_this_hosts_runs_whose_process_is_gone_and_leaves_other_hosts_runs(tmp_path):
    """A run killed without a word stays `running` until the next writer connection (warehouse.connect) sees its
    process gone (the PID's start time differs: the PID now names another process) and marks it failed."""
    from storage import warehouse

    db = tmp_path / "w.duckdb"
    assert route_store.begin_run(db, "alive", cycle=None, solver="gc", trigger="manual", n_voyages=1) == {"alive"}
    route_store.begin_run(db, "killed", cycle=None, solver="gc", trigger="manual", n_voyages=1)
    route_store.begin_run(db, "elsewhere", cycle=None, solver="gc", trigger="manual", n_voyages=1)
    with warehouse.connect(db, checked=False) as con:
        con.execute("UPDATE route_runs SET pid_started = 'not-this-start' WHERE run_id = 'killed'")
        con.execute("UPDATE route_runs SET host = 'another-host', pid_started = 'x' WHERE run_id = 'elsewhere'")
    assert route_store.begin_run(db, "next", cycle=None, solver="gc", trigger="manual", n_voyages=1) == {
        "alive", "elsewhere", "next"}
    with warehouse.connect(db, write=False) as con:
        status = dict(con.execute("SELECT run_id, status || ' ' || coalesce(reason, '') FROM route_runs").fetchall())
    assert status["killed"].startswith("failed process died (host ") and "no longer runs" in status["killed"]
    assert status["alive"] == status["elsewhere"] == status["next"] == "running "
