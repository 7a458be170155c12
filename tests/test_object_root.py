"""Settings for object storage: where the cube and the exports go, and storage options that are never shown."""

from __future__ import annotations

import pytest

from flows.settings import SettingsError, load_settings


def test_an_object_root_moves_the_cube_and_the_exports_but_not_the_warehouse(tmp_path, monkeypatch):
    monkeypatch.setenv("JITROUTE_DATA", str(tmp_path / "data"))
    monkeypatch.setenv("JITROUTE_OBJECT_ROOT", "s3://fleet-bucket/jitroute/")
    monkeypatch.setenv("JITROUTE_STORAGE_OPTIONS", '{"endpoint_url": "http://127.0.0.1:9", "secret": "s3cr3t-key"}')
    lay = load_settings().layout
    assert lay.weather_cube_url == "s3://fleet-bucket/jitroute/cubes/weather.zarr"
    assert lay.run_exports_url == "s3://fleet-bucket/jitroute/exports"
    assert lay.warehouse == tmp_path / "data" / "warehouse.duckdb" and lay.cube_lock_dir == tmp_path / "data" / "locks"
    assert lay.cube_store.url == lay.weather_cube_url and lay.cube_store.options["secret"] == "s3cr3t-key"
    assert "s3cr3t" not in repr(load_settings()) + repr(lay)


def test_without_an_object_root_everything_stays_under_the_data_root(tmp_path, monkeypatch):
    monkeypatch.setenv("JITROUTE_DATA", str(tmp_path / "data"))
    monkeypatch.delenv("JITROUTE_OBJECT_ROOT", raising=False)
    lay = load_settings().layout
    assert lay.weather_cube_url == str(tmp_path / "data" / "cubes" / "weather.zarr") == str(lay.cube_store.local)
    assert lay.run_exports_url == str(tmp_path / "data" / "exports") and lay.cube_lock_dir is None


@pytest.mark.parametrize("text", ["not json s3cr3t", '["s3cr3t"]'])
def test_unreadable_storage_options_are_named_without_their_value(monkeypatch, text):
    monkeypatch.setenv("JITROUTE_STORAGE_OPTIONS", text)
    with pytest.raises(SettingsError, match="JITROUTE_STORAGE_OPTIONS is not a JSON object") as err:
        load_settings()
    assert "s3cr3t" not in str(err.value)
