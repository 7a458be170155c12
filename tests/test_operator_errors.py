"""Operators' mistakes end in one clear line and an exit code a monitoring cron sees, never in a traceback, a green
check of nothing, or a file that is not what its name says."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from cli.main import app
from storage import cube
from tests.test_cube_window import CYCLE, CYCLE2, cycle_ds


@pytest.fixture
def runner(monkeypatch):
    monkeypatch.setenv("COLUMNS", "400")
    monkeypatch.delenv("JITROUTE_CUBE_RETENTION_DAYS", raising=False)
    monkeypatch.delenv("PREFECT_API_URL", raising=False)
    return CliRunner()


@pytest.mark.parametrize("command", [["cube", "check"], ["cube", "repair"], ["warehouse", "check"],
                                     ["cube", "retire", "--keep-days", "2"]])
def test_a_check_of_a_mistyped_data_root_fails(runner, tmp_path, command):
    for wrong in (tmp_path / "dta", tmp_path):  # absent, or a folder that is no data root
        res = runner.invoke(app, [*command, "--data", str(wrong)])
        assert res.exit_code == 2 and f"no data root at {wrong}" in res.output, res.output
        assert "Traceback" not in res.output and not (tmp_path / "dta").exists()


def test_a_check_of_a_data_root_without_a_cube_still_says_so(runner, tmp_path):
    (tmp_path / "data" / "raw").mkdir(parents=True)
    res = runner.invoke(app, ["cube", "check", "--data", str(tmp_path / "data")])
    assert res.exit_code == 0 and "no weather cube at" in res.output, res.output


@pytest.mark.slow
def test_cube_retire_keeps_everything_for_an_infinite_retention_and_refuses_nan(runner, tmp_path):
    store = tmp_path / "data" / "cubes" / "weather.zarr"
    for c in (CYCLE, CYCLE2):
        cube.write_cycle(store, cycle_ds(c), complete=True)
    for days in ("inf", "1e300"):
        res = runner.invoke(app, ["cube", "retire", "--keep-days", days, "--data", str(tmp_path / "data")])
        assert res.exit_code == 0 and "retired 0 cycle(s)" in res.output, res.output
    assert cube.complete_cycles(store) == [CYCLE, CYCLE2]
    res = runner.invoke(app, ["cube", "retire", "--keep-days", "nan", "--data", str(tmp_path / "data")])
    assert res.exit_code == 2 and "greater than or equal to 0" in res.output, res.output
    with pytest.raises(cube.CubeError, match="give a number of days ≥ 0"):  # the setting's way in
        cube.retire_cycles(store, float("nan"))
    assert cube.complete_cycles(store) == [CYCLE, CYCLE2]
    res = runner.invoke(app, ["cube", "retire", "--keep-days", "0.1", "--data", str(tmp_path / "data")])
    assert res.exit_code == 0 and "retired 1 cycle(s)" in res.output  # the 00 UTC cycle, 6 h before the newest


@pytest.mark.parametrize("args, suffix", [(["--animate", "--out", "x.png"], ".gif"), (["--out", "x.gif"], ".png"),
                                          (["--animate", "--out", "x"], ".gif")])
def test_weather_map_refuses_a_file_name_that_is_not_what_it_writes(runner, tmp_path, args, suffix):
    out = tmp_path / args[-1]
    args = [*args[:-1], str(out)]
    res = runner.invoke(app, ["weather", "map", "--var", "wind", *args, "--data", str(tmp_path / "data")])
    assert res.exit_code == 2 and f"give a file name ending in {suffix}" in res.output, res.output
    assert not out.exists()


@pytest.mark.slow
def test_model_predict_json_is_strict_json_when_the_model_overflows(runner, tmp_path):
    from tests.test_model_sanity import _gas_nirvana_warehouse

    data, csv = _gas_nirvana_warehouse(tmp_path)
    assert runner.invoke(app, ["noon", "import", str(csv), "--data", str(data)]).exit_code == 0
    assert runner.invoke(app, ["refit", "--form", "thesis", "--data", str(data)]).exit_code == 0
    res = runner.invoke(app, ["model", "predict", "--imo", "9140607", "--version", "1", "--rpm", "120", "--draft-m",
                              "1e308", "--json", "--data", str(data)])
    assert res.exit_code == 0, res.output
    out = json.loads(res.output, parse_constant=lambda c: pytest.fail(f"{c} is not JSON"))
    assert out["stw_kn"] is None and "far outside" in out["not_finite"]["stw_kn"]
    assert out["draft_m"] == 1e308 and out["rpm"] == 120
    res = runner.invoke(app, ["model", "predict", "--imo", "9140607", "--version", "1", "--rpm", "120", "--draft-m",
                              "6", "--json", "--data", str(data)])
    out = json.loads(res.output)
    assert out["not_finite"] == {} and out["stw_kn"] == pytest.approx(1.80521 * 6 + 12.63045 * 2 - 0.13117 * 120, abs=0.02)


@pytest.fixture(scope="module")
def fleet_root(tmp_path_factory):
    from flows.jobs.refit import import_fleet_folder
    from pipeline.synthetic.fleet import generate_fleet, write_fleet

    base = tmp_path_factory.mktemp("fleet")
    fl = generate_fleet("2020-12-01T00", n_vessels=2, days=30, seed=3)
    write_fleet(fl, base / "fleet")
    import_fleet_folder(str(base / "fleet"), data_root=str(base / "data"))
    return base / "data", fl


@pytest.mark.parametrize("note, says", [("ok\nINFO forged line", "control characters or a line break"),
                                        ("\x1b[2Jcleared", "control characters or a line break"),
                                        ("=HYPERLINK(\"http://x\")", "starts with =, +, - or @ (a spreadsheet"),
                                        ("@SUM(A1)", "starts with =, +, - or @ (a spreadsheet")])
@pytest.mark.slow
def test_position_notes_and_exclusion_reasons_that_forge_lines_or_run_as_formulas_are_refused(runner, fleet_root,
                                                                                              note, says):
    import duckdb

    root, fl = fleet_root
    voyage = fl.voyages["voyage_id"].iloc[0]
    imo = str(fl.voyages["imo"].iloc[0])
    res = runner.invoke(app, ["position", voyage, "--at", "2020-12-02T00", "--pos", "20,140", "--note", note,
                              "--data", str(root)])
    assert res.exit_code == 2 and f"--note: {says}" in res.output, res.output
    res = runner.invoke(app, ["noon", "exclude", "--imo", imo, "--from", "2020-11-01", "--to", "2020-11-02",
                              "--reason", note, "--data", str(root)])
    assert res.exit_code == 2 and f"--reason: {says}" in res.output, res.output
    with duckdb.connect(str(root / "warehouse.duckdb"), read_only=True) as con:
        tables = {r[0] for r in con.execute("SELECT table_name FROM information_schema.tables").fetchall()}
        for table in ("voyage_positions", "noon_exclusions"):
            if table in tables:
                assert con.execute(f"SELECT count(*) FROM {table}").fetchone()[0] == 0
