"""Export files: single files written in place, and a run's files (RTZ, GeoJSON, PNG) published whole or not at all.

A run's files go under an exports root that is a local folder or an object-store URL (`s3://bucket/prefix/exports`,
through fsspec). While the run routes they are written under `runs/.staging-<run_id>/` (by the routing workers
themselves, each its own voyages' files); once the run's rows are stored they are moved to `runs/<run_id>/` and
then, LAST, `runs/<run_id>/_SUCCESS` is written: a JSON manifest listing every file with its size. On a local disk
the move is one rename of the staging folder; on an object store a move is a copy per object, issued concurrently
(a fleet run shares the copies out among its dask workers: `copy_staged`), so a reader may see a run folder fill
up: readers trust only runs with a manifest, and only the files it lists. A failed or killed run never publishes:
its staging prefix is removed (by the run itself, with any files it had copied; or by the next run when the
process died).

A run's files are named by keys of one to three plain names joined by `/`: the run's own files at the top
(`fleet_map.png`, `weather_waves_<cycle>.png`, the manifest), each voyage's under `voyages/<voyage_id>/`, so no
voyage ID can overwrite a run file or another voyage's file.
"""

from __future__ import annotations

import functools
import json
import re
from datetime import datetime
from dataclasses import dataclass, field
from pathlib import Path

STAGING_PREFIX = ".staging-"
_RUN_ID = re.compile(r"^(\d{8}T\d{6})-[0-9a-f]+$")  # route-fleet's run ids: start time (UTC) and a random tail
MANIFEST = "_SUCCESS"


class ExportPathError(ValueError):
    """An export file name that would land outside its run folder."""


def check_file_name(name: str) -> str:
    """`name` if it is one plain file name (no separator, no control character), else ExportPathError."""
    if (not name or name in (".", "..") or "/" in name or "\\" in name or "\x00" in name
            or any(ord(ch) < 32 for ch in name) or len(name) > 255):
        raise ExportPathError(f"export file name {name!r} is not a plain file name; nothing written")
    return name


def check_key(key: str) -> str:
    """`key` if it is one to three plain file names joined by `/` (a file of the run or of one of its voyages)."""
    parts = key.split("/") if isinstance(key, str) else [key]
    if not 1 <= len(parts) <= 3:
        raise ExportPathError(f"export file name {key!r} is not a plain name in the run folder; nothing written")
    for part in parts:
        check_file_name(part)
    return key


def child_path(folder: Path, name: str) -> Path:
    """`folder/name`, refusing any name that is not one plain file name inside `folder`."""
    folder = Path(folder)
    path = folder / check_file_name(name)
    if path.resolve().parent != folder.resolve():
        raise ExportPathError(f"export file {name!r} would be written outside {folder}; nothing written")
    return path


def write_file(folder: Path, name: str, data: bytes) -> Path:
    """Write `data` to `folder/name` atomically (temporary file, then rename)."""
    folder.mkdir(parents=True, exist_ok=True)
    path = child_path(folder, name)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_bytes(data)
    tmp.replace(path)
    return path


def _is_local(fs) -> bool:
    from fsspec.implementations.local import LocalFileSystem

    return isinstance(fs, LocalFileSystem)


@dataclass(frozen=True)
class RunExports:
    """The runs under one exports root: a local folder or an fsspec URL (`s3://bucket/prefix/exports`)."""

    url: str
    storage_options: dict = field(default_factory=dict, repr=False)  # may hold keys: never shown

    @functools.cached_property
    def _located(self) -> tuple:
        import fsspec

        from storage.cube_location import fs_options

        fs, root = fsspec.core.url_to_fs(self.url, **fs_options(self.url, self.storage_options))
        return fs, root.rstrip("/")

    @property
    def fs(self):
        return self._located[0]

    def _runs(self) -> str:
        return f"{self._located[1]}/runs"

    def _staging(self, run_id: str) -> str:
        return f"{self._runs()}/{STAGING_PREFIX}{check_file_name(run_id)}"

    def _run(self, run_id: str) -> str:
        return f"{self._runs()}/{check_file_name(run_id)}"

    def run_url(self, run_id: str) -> str:
        """Where the run's files are published (a local path when the root is local)."""
        return f"{self.url.rstrip('/')}/runs/{check_file_name(run_id)}"

    def stage(self, run_id: str, name: str, data: bytes) -> str:
        """Write one file of the run (`name`: a key, see `check_key`) under its staging prefix; returns the key."""
        fs, folder = self.fs, self._staging(run_id)
        path = f"{folder}/{check_key(name)}"
        fs.makedirs(path.rsplit("/", 1)[0], exist_ok=True)
        fs.pipe_file(path, data)
        return name

    @property
    def local(self) -> bool:
        """The root is a local folder: publishing is one rename there (elsewhere a copy per file)."""
        return _is_local(self.fs)

    def copy_staged(self, run_id: str, names: list[str]) -> None:
        """Copy these staged files (keys) to `runs/<run_id>/`, in one call (an async filesystem such as s3fs copies
        them concurrently). On an object store a run's copies can be shared out this way (among its dask workers),
        then `publish(copied=True)` only writes the manifest."""
        fs, src, dst = self.fs, self._staging(run_id), self._run(run_id)
        names = [check_key(n) for n in names]
        for folder in sorted({dst} | {f"{dst}/{n.rsplit('/', 1)[0]}" for n in names if "/" in n}):
            fs.makedirs(folder, exist_ok=True)
        if names:
            fs.copy([f"{src}/{n}" for n in names], [f"{dst}/{n}" for n in names])

    def publish(self, run_id: str, only: set[str] | None = None, copied: bool = False,
                sizes: dict[str, int] | None = None) -> dict | None:
        """Move the staged files to `runs/<run_id>/`, then write the manifest last; returns the manifest
        (None when nothing was staged). `only`: the names the run vouches for (e.g. not those a lost worker staged
        before its voyages were given up); others are left out of the manifest. `copied`: on an object store, the
        files are in the run's folder already (`copy_staged`); with `sizes` (name → bytes, as their writers staged
        them) too, the staging is not listed: the manifest lists those files and they are deleted from the staging
        by name (anything else left there, e.g. a lost worker's files, goes with the staging prefix at the next
        run's `discard_stale`). Listing and deleting hundreds of keys by prefix cost the run's host ~0.6 s CPU."""
        fs, src, dst = self.fs, self._staging(run_id), self._run(run_id)
        fs.invalidate_cache(self._runs())  # other processes (the workers) wrote there since this one last listed it
        if copied and sizes is not None and not _is_local(fs):
            return self._publish_copied(run_id, {n: b for n, b in sizes.items() if only is None or n in only})
        if not fs.exists(src):
            return None
        base = fs._strip_protocol(src).rstrip("/") + "/"
        sizes = {fs._strip_protocol(p)[len(base):]: int(info["size"]) for p, info in fs.find(src, detail=True).items()}
        if only is not None:
            sizes = {n: b for n, b in sizes.items() if n in only}
        names = sorted(sizes)
        if _is_local(fs) and not fs.exists(dst):
            fs.mv(src, dst, recursive=True)  # one rename of the folder, however many files it holds
        elif names and not (copied and not _is_local(fs)):
            self.copy_staged(run_id, names)  # deleted in batches by `discard` below
        manifest = {"run_id": run_id, "files": [{"name": n, "bytes": sizes[n]} for n in sorted(sizes)]}
        fs.pipe_file(f"{dst}/{MANIFEST}", json.dumps(manifest, indent=1).encode())
        self._remove(src)
        return manifest

    def _publish_copied(self, run_id: str, sizes: dict[str, int]) -> dict | None:
        if not sizes:
            return None
        fs, src, dst = self.fs, self._staging(run_id), self._run(run_id)
        manifest = {"run_id": run_id, "files": [{"name": n, "bytes": int(sizes[n])} for n in sorted(sizes)]}
        fs.pipe_file(f"{dst}/{MANIFEST}", json.dumps(manifest, indent=1).encode())
        try:
            fs.rm([f"{src}/{check_key(n)}" for n in sorted(sizes)])
        except FileNotFoundError:  # gone already: nothing to delete
            pass
        return manifest

    def manifest(self, run_id: str) -> dict | None:
        """The published run's manifest; None while it is not (or never will be) whole."""
        try:
            return json.loads(self.fs.cat_file(f"{self._run(run_id)}/{MANIFEST}"))
        except FileNotFoundError:
            return None

    def discard(self, run_id: str) -> None:
        """Remove the run's staging prefix, and its run folder when that holds no manifest (files copied there
        before the run failed); nothing there is fine."""
        self._remove(self._staging(run_id))
        if self.manifest(run_id) is None:
            self._remove(self._run(run_id))

    def _remove(self, prefix: str) -> None:
        try:
            self.fs.rm(prefix, recursive=True)
        except FileNotFoundError:
            pass

    def retire_runs(self, keep_days: float) -> list[str]:
        """Retention: delete every published run started more than `keep_days` days before the newest run (the age
        read from the run id, `YYYYmmddTHHMMSS-…`, so one listing and no read per run). Its manifest goes first, so a
        reader never trusts a half-deleted run. Runs named otherwise, staging prefixes and unpublished folders are left
        to `discard_stale`/`discard`. Returns the retired run ids, oldest first."""
        if not keep_days >= 0:  # also NaN
            raise ValueError(f"export retention of {keep_days} days: give a number of days ≥ 0")
        fs, runs = self.fs, self._runs()
        fs.invalidate_cache(runs)
        if keep_days == float("inf") or not fs.exists(runs):
            return []
        started = {}
        for p in fs.ls(runs, detail=False):
            name = p.rstrip("/").rsplit("/", 1)[-1]
            m = _RUN_ID.match(name)
            if m:
                started[name] = datetime.strptime(m.group(1), "%Y%m%dT%H%M%S")
        if not started:
            return []
        newest = max(started.values())
        old = sorted(n for n, t in started.items() if (newest - t).total_seconds() > keep_days * 86400)
        for rid in old:
            try:
                fs.rm(f"{self._run(rid)}/{MANIFEST}")
            except FileNotFoundError:
                pass
            self._remove(self._run(rid))
        return old

    def discard_stale(self, live_run_ids: set[str]) -> list[str]:
        """Remove staging prefixes of runs that are no longer running (killed processes); returns their run ids."""
        fs, runs = self.fs, self._runs()
        if not fs.exists(runs):
            return []
        gone = []
        for p in fs.ls(runs, detail=False):
            name = p.rstrip("/").rsplit("/", 1)[-1]
            rid = name[len(STAGING_PREFIX):] if name.startswith(STAGING_PREFIX) else None
            if rid is not None and rid not in live_run_ids:
                self._remove(self._staging(rid))
                gone.append(rid)
        return gone
