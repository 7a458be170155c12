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


@pytest.mark.parametrize("where", ["local", "s3"])
def test_publish_lists_only_the_files_the_run_vouches_for(tmp_path, request, where):
    if where == "s3":
        env = request.getfixturevalue("s3_endpoint")
        runs = RunExports("s3://jitroute/root/exports", {"endpoint_url": env["AWS_ENDPOINT_URL"],
                                                         "key": env["AWS_ACCESS_KEY_ID"], "secret": env["AWS_SECRET_ACCESS_KEY"]})
    else:
        runs = RunExports(str(tmp_path / "exports"))
    names = [f"V{k}.rtz" for k in range(12)]
    for n in names:
        runs.stage("r1", n, n.encode())
    runs.stage("r1", "LOST.rtz", b"staged by a worker whose voyages were given up")
    manifest = runs.publish("r1", only=set(names))
    assert [f["name"] for f in manifest["files"]] == sorted(names) and runs.manifest("r1") == manifest
    assert all(runs.fs.cat_file(f"{runs.run_url('r1')}/{n}") == n.encode() for n in names)
    assert not runs.fs.exists(runs._staging("r1"))  # staging gone


def test_copies_shared_out_before_the_publish_and_a_failed_run_s_copies_removed(request):
    """On an object store the workers copy shares of the staged files into the run folder; the publish then only
    writes the manifest (no file copied twice, none missing). A run that fails after its copies removes them."""
    env = request.getfixturevalue("s3_endpoint")
    runs = RunExports("s3://jitroute/shares/exports", {"endpoint_url": env["AWS_ENDPOINT_URL"],
                                                       "key": env["AWS_ACCESS_KEY_ID"], "secret": env["AWS_SECRET_ACCESS_KEY"]})
    assert not runs.local
    names = [f"voyages/V{k}/V{k}.rtz" for k in range(7)] + ["fleet_map.png"]
    for rid in ("r1", "r2"):
        for n in names:
            runs.stage(rid, n, n.encode())
        for share in (names[0::2], names[1::2]):
            runs.copy_staged(rid, share)
    copies = []
    runs.fs.copy = lambda *a, **k: copies.append(a)  # the publish must not copy again
    manifest = runs.publish("r1", only=set(names), copied=True)
    del runs.fs.copy
    assert copies == [] and [f["name"] for f in manifest["files"]] == sorted(names)
    assert all(runs.fs.cat_file(f"{runs.run_url('r1')}/{n}") == n.encode() for n in names)
    assert not runs.fs.exists(runs._staging("r1"))
    runs.discard("r2")  # failed after its copies: neither its staging nor its unpublished folder stays
    # files staged by other processes after this one listed the runs (as a run's host does first) are published
    import s3fs

    assert runs.discard_stale({"r3"}) == []
    elsewhere = s3fs.S3FileSystem(skip_instance_cache=True, endpoint_url=env["AWS_ENDPOINT_URL"],
                                  key=env["AWS_ACCESS_KEY_ID"], secret=env["AWS_SECRET_ACCESS_KEY"])
    elsewhere.pipe_file(f"{runs._staging('r3')}/V1.rtz", b"<rtz/>")
    assert runs.publish("r3", only={"V1.rtz"})["files"] == [{"name": "V1.rtz", "bytes": 6}]
    assert not runs.fs.exists(runs._staging("r2")) and not runs.fs.exists(runs.run_url("r2"))
    assert runs.manifest("r1") == manifest  # a published run is never discarded
    runs.discard("r1")
    assert runs.manifest("r1") == manifest


def test_a_publish_of_copied_files_with_their_sizes_lists_nothing_and_empties_the_staging(request):
    """The run's host knows what its workers staged (name → bytes) and that they copied it: the manifest is made from
    that, the staged files are deleted by name, and no prefix is listed (hundreds of keys cost the host CPU)."""
    env = request.getfixturevalue("s3_endpoint")
    runs = RunExports("s3://jitroute/sized/exports", {"endpoint_url": env["AWS_ENDPOINT_URL"],
                                                      "key": env["AWS_ACCESS_KEY_ID"], "secret": env["AWS_SECRET_ACCESS_KEY"]})
    sizes = {f"voyages/V{k}/V{k}.rtz": 10 + k for k in range(5)} | {"fleet_map.png": 3}
    for n, b in sizes.items():
        runs.stage("r1", n, b"x" * b)
    runs.stage("r1", "LOST.rtz", b"staged by a worker whose voyages were given up")
    runs.copy_staged("r1", sorted(sizes))
    listed = []
    find, ls = runs.fs.find, runs.fs.ls
    runs.fs.find = lambda *a, **k: listed.append(a) or find(*a, **k)
    runs.fs.ls = lambda *a, **k: listed.append(a) or ls(*a, **k)
    manifest = runs.publish("r1", only=set(sizes) - {"fleet_map.png"}, copied=True, sizes=sizes)
    runs.fs.find, runs.fs.ls = find, ls
    assert listed == []
    assert manifest == runs.manifest("r1") == {"run_id": "r1", "files": [
        {"name": n, "bytes": sizes[n]} for n in sorted(sizes) if n != "fleet_map.png"]}
    assert all(runs.fs.cat_file(f"{runs.run_url('r1')}/{n}") == b"x" * sizes[n] for n in sizes)
    left = [p.rsplit(".staging-r1/", 1)[1] for p in runs.fs.find(runs._staging("r1"))]
    assert left == ["LOST.rtz", "fleet_map.png"]  # only what the run did not vouch for stays in the staging …
    assert runs.discard_stale(set()) == ["r1"] and not runs.fs.exists(runs._staging("r1"))  # … until the next run
    assert runs.publish("r2", copied=True, sizes={}) is None  # nothing staged, nothing published


def test_a_worker_stages_its_voyages_exports_and_returns_only_their_entries(tmp_path):
    import numpy as np

    from flows.jobs.route_worker import route_one
    from pipeline.performance.model import reference_model
    from pipeline.routing.job import RouteJob, RoutingOptions

    voyage = {"voyage_id": "VSTAGE", "imo": 1, "dep_lat": 34.0, "dep_lon": 141.0, "arr_lat": 30.0, "arr_lon": 147.0,
              "depart_utc": np.datetime64("2020-12-01T02"), "rta_utc": np.datetime64("2020-12-02T18"),
              "rpm_options": [70, 85, 100]}
    job = RouteJob(voyage=voyage, vessel={"rpm_max": 100}, model=reference_model(14.0, 100.0, 1.5).to_json(),
                   run_id="r1", cycle="2020-12-01T00:00:00", exports=True, options=RoutingOptions(n_lines=6, n_points=7))
    res = route_one(job, None, exports_to=(str(tmp_path / "exports"), {}))
    staging = tmp_path / "exports" / "runs" / ".staging-r1"
    files = [p for p in staging.rglob("*") if p.is_file()]
    assert res["exports"] == {} and res["export_errors"] == {} and res["route"]["status"] == "ok"
    assert sorted(res["staged"], key=lambda f: f["name"]) == sorted(
        ({"name": p.relative_to(staging).as_posix(), "bytes": p.stat().st_size} for p in files), key=lambda f: f["name"])
    assert {p.suffix for p in files} >= {".rtz", ".geojson", ".png"}
    assert {p.parent.relative_to(staging).as_posix() for p in files} == {"voyages/VSTAGE"}


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


@pytest.mark.parametrize("where", ["local", "s3"])
def test_runs_older_than_the_retention_are_deleted_whole_and_newer_ones_and_stagings_kept(tmp_path, request, where):
    if where == "s3":
        env = request.getfixturevalue("s3_endpoint")
        runs = RunExports("s3://jitroute/retention/exports", {"endpoint_url": env["AWS_ENDPOINT_URL"],
                                                              "key": env["AWS_ACCESS_KEY_ID"],
                                                              "secret": env["AWS_SECRET_ACCESS_KEY"]})
    else:
        runs = RunExports(str(tmp_path / "exports"))
    ids = ["20201201T023000-aaaaaa", "20201203T023000-bbbbbb", "20201205T023000-cccccc"]
    for rid in ids:
        for n in ("fleet_map.png", "voyages/V1/V1.rtz"):
            runs.stage(rid, n, rid.encode())
        assert runs.publish(rid) is not None
    runs.stage("20201101T000000-dddddd", "V9.rtz", b"a run still routing")  # staged long ago: not a published run
    assert runs.retire_runs(float("inf")) == [] and runs.retire_runs(4.0) == []  # the oldest is exactly 4 days older
    assert runs.retire_runs(2.5) == ids[:1]
    assert runs.manifest(ids[0]) is None and not runs.fs.exists(runs.run_url(ids[0]))
    assert all(runs.manifest(rid) is not None for rid in ids[1:])
    assert runs.fs.cat_file(f"{runs.run_url(ids[1])}/voyages/V1/V1.rtz") == ids[1].encode()
    assert runs.fs.exists(runs._staging("20201101T000000-dddddd"))
    assert runs.retire_runs(0) == ids[1:2] and runs.manifest(ids[2]) is not None  # the newest run always stays
    with pytest.raises(ValueError, match="give a number of days ≥ 0"):
        runs.retire_runs(float("nan"))


def test_the_export_retention_comes_from_the_environment(monkeypatch):
    from flows.settings import SettingsError, load_settings

    monkeypatch.setenv("JITROUTE_EXPORT_RETENTION_DAYS", "30")
    assert load_settings().export_retention_days == 30.0
    monkeypatch.setenv("JITROUTE_EXPORT_RETENTION_DAYS", "-1")
    with pytest.raises(SettingsError, match="JITROUTE_EXPORT_RETENTION_DAYS"):
        load_settings()
    monkeypatch.delenv("JITROUTE_EXPORT_RETENTION_DAYS")
    assert load_settings().export_retention_days is None
