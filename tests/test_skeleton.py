from pathlib import Path

import numpy as np

from flows.settings import load_settings
from pipeline.performance.model import PerformanceModel, reference_model
from storage import warehouse


def test_settings_env_and_overrides(monkeypatch, tmp_path):
    monkeypatch.setenv("JITROUTE_DATA", str(tmp_path / "d"))
    monkeypatch.setenv("JITROUTE_RISH_URL", "file:///mirror/")
    s = load_settings(**{"grid.res_deg": 0.25})
    assert s.data_root == tmp_path / "d"
    assert s.sources.rish_url == "file:///mirror/"
    assert s.grid.res_deg == 0.25
    assert s.layout.weather_cube == tmp_path / "d" / "cubes" / "weather.zarr"


def test_reference_model_speed_and_fuel():
    m = reference_model(design_speed_kn=14.0, rpm_max=100.0, design_fuel_tph=1.5)
    assert np.isclose(m.stw_kn(100.0, 10.0, 0.0), 14.0)
    assert np.isclose(m.fuel_tph(100.0, 10.0, 0.0), 1.5)
    # head seas cost 1.5 kn, following seas 0.14 of that
    assert np.isclose(m.stw_kn(100.0, 10.0, 0.0, hs_m=4.0, wave_rel_deg=0.0), 12.5)
    assert np.isclose(m.stw_kn(100.0, 10.0, 0.0, hs_m=4.0, wave_rel_deg=180.0), 14.0 - 0.14 * 1.5)
    back = PerformanceModel.from_json(m.to_json())
    assert np.allclose(back.speed_coef, m.speed_coef)


def test_warehouse_migrates_and_snapshots(tmp_path: Path, migrated_from_scratch):
    db = tmp_path / "w.duckdb"
    with warehouse.connect(db) as con:
        names = {r[0] for r in con.execute("SELECT name FROM schema_migrations").fetchall()}
    assert (tmp_path / "w.snapshot.duckdb").exists()
    with warehouse.connect(db, write=False) as con:
        assert {r[0] for r in con.execute("SELECT name FROM schema_migrations").fetchall()} == names


def test_the_scipy_range_of_pyproject_is_one_whose_highs_the_planner_can_import():
    """The planner imports scipy's private HiGHS bindings (`scipy.optimize._highspy._core`, from scipy 1.15): the
    range pyproject allows must not admit a scipy without them."""
    import tomllib

    import scipy
    from packaging.requirements import Requirement

    project = tomllib.loads((Path(__file__).parents[1] / "pyproject.toml").read_text())["project"]
    (spec,) = [Requirement(r).specifier for r in project["dependencies"] if Requirement(r).name == "scipy"]
    assert not spec.contains("1.13.1") and not spec.contains("1.14.1")  # no _highspy._core there
    assert spec.contains(scipy.__version__)  # the one this venv runs the tests with
    from pipeline.planning import master_lp

    assert hasattr(master_lp.highs, "_Highs")
