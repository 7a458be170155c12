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


@pytest.mark.parametrize("name", ["../V1.rtz", "a/b.rtz", "", "..", "V1\n.rtz"])
def test_a_file_name_that_is_not_plain_is_refused(tmp_path, name):
    with pytest.raises(ExportPathError):
        RunExports(str(tmp_path / "exports")).stage("r1", name, b"x")
    assert not (tmp_path / "exports").exists() or not any((tmp_path / "exports").rglob("*.rtz"))
