"""A run's exports: staged, moved into place, the manifest written last; stale staging of dead runs removed."""

from __future__ import annotations

import json

import pytest

from storage.export_store import MANIFEST, ExportPathError, RunExports


def test_publish_moves_the_staged_files_and_writes_the_manifest_listing_them(tmp_path):
    runs = RunExports(str(tmp_path / "exports"))
    runs.stage("r1", "V1.rtz", b"<rtz/>")
    runs.stage("r1", "fleet_map.png", b"\x89PNG....")
    assert runs.manifest("r1") is None  # staged only: nothing a reader may trust
    manifest = runs.publish("r1")
    out = tmp_path / "exports" / "runs" / "r1"
    assert manifest == {"run_id": "r1", "files": [{"name": "V1.rtz", "bytes": 6}, {"name": "fleet_map.png", "bytes": 8}]}
    assert json.loads((out / MANIFEST).read_text()) == manifest == runs.manifest("r1")
    assert (out / "V1.rtz").read_bytes() == b"<rtz/>"
    assert sorted(p.name for p in (tmp_path / "exports" / "runs").iterdir()) == ["r1"]  # staging gone
    assert runs.run_url("r1") == f"{tmp_path / 'exports'}/runs/r1"
    assert runs.publish("r2") is None  # nothing staged, nothing published


def test_stale_staging_of_dead_runs_is_removed_and_a_live_runs_kept(tmp_path):
    runs = RunExports(str(tmp_path / "exports"))
    for rid in ("dead", "live"):
        runs.stage(rid, "V1.rtz", b"x")
    assert runs.discard_stale({"live"}) == ["dead"]
    assert sorted(p.name for p in (tmp_path / "exports" / "runs").iterdir()) == [".staging-live"]


@pytest.mark.parametrize("name", ["../V1.rtz", "a/../../b.rtz", "", "..", "V1\n.rtz", "voyages/V1/x/y.rtz", "/abs.rtz",
                                  "voyages//V1.rtz"])
def test_a_file_name_that_is_not_plain_is_refused(tmp_path, name):
    with pytest.raises(ExportPathError):
        RunExports(str(tmp_path / "exports")).stage("r1", name, b"x")
    assert not (tmp_path / "exports").exists() or not any((tmp_path / "exports").rglob("*.rtz"))


def test_voyage_ids_named_like_run_files_or_like_each_other_s_files_overwrite_nothing(tmp_path):
    """Voyage IDs that pass the ID rule but spell a run file (`fleet_map`, `weather_waves_<cycle>`) or another voyage's
    file (`V20001.convergence` + `.png` = `V20001` + `.convergence.png`): every staged file is published apart."""
    from pipeline.export.bundle import SUFFIX
    from pipeline.export.paths import voyage_export_key

    runs = RunExports(str(tmp_path / "exports"))
    staged = {"fleet_map.png": b"run map", "weather_waves_2020-12-01T12.png": b"run waves"}
    for vid in ("fleet_map", "weather_waves_2020-12-01T12", "V20001", "V20001.convergence"):
        for kind, suffix in SUFFIX.items():
            staged[voyage_export_key(vid, suffix)] = f"{vid} {kind}".encode()
    for key, data in staged.items():
        runs.stage("r1", key, data)
    manifest = runs.publish("r1")
    out = tmp_path / "exports" / "runs" / "r1"
    assert len(manifest["files"]) == len(staged) == 2 + 4 * len(SUFFIX)  # nothing lost to a collision
    for key, data in staged.items():
        assert (out / key).read_bytes() == data, key
    assert (out / "fleet_map.png").read_bytes() == b"run map"
    assert (out / "voyages" / "V20001" / "V20001.convergence.png").read_bytes() == b"V20001 convergence"
    assert (out / "voyages" / "V20001.convergence" / "V20001.convergence.png").read_bytes() == b"V20001.convergence png"
