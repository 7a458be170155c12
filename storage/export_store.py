"""A run's export files (RTZ, GeoJSON, PNG): written to a staging folder, published whole or not at all.

`exports/runs/.staging-<run_id>/` fills while the run routes; after the warehouse commit it is
renamed to `exports/runs/<run_id>/` in one step. A failed or killed run never leaves files for
voyages whose rows did not reach the warehouse: its staging folder is removed (by the run itself,
or by the next run when the process died).
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

STAGING_PREFIX = ".staging-"


class ExportPathError(ValueError):
    """An export file name that would land outside its run folder."""


def runs_dir(exports: Path) -> Path:
    return Path(exports) / "runs"


def run_dir(exports: Path, run_id: str) -> Path:
    return runs_dir(exports) / run_id


def staging_dir(exports: Path, run_id: str) -> Path:
    return runs_dir(exports) / f"{STAGING_PREFIX}{run_id}"


def child_path(folder: Path, name: str) -> Path:
    """`folder/name`, refusing any name that is not one plain file name inside `folder`."""
    folder = Path(folder)
    if (not name or name in (".", "..") or "/" in name or "\\" in name or "\x00" in name
            or any(ord(ch) < 32 for ch in name) or len(name) > 255):
        raise ExportPathError(f"export file name {name!r} is not a plain file name; nothing written")
    path = folder / name
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


def publish(exports: Path, run_id: str) -> Path | None:
    """Move the run's staging folder into place; returns the published folder (None when nothing was staged)."""
    src, dst = staging_dir(exports, run_id), run_dir(exports, run_id)
    if not src.exists():
        return None
    os.replace(src, dst)
    return dst


def discard(exports: Path, run_id: str) -> None:
    shutil.rmtree(staging_dir(exports, run_id), ignore_errors=True)


def discard_stale(exports: Path, live_run_ids: set[str]) -> list[str]:
    """Remove staging folders of runs that are no longer running (killed processes); returns their run ids."""
    gone = []
    root = runs_dir(exports)
    if not root.exists():
        return gone
    for p in root.glob(f"{STAGING_PREFIX}*"):
        rid = p.name[len(STAGING_PREFIX):]
        if rid not in live_run_ids:
            shutil.rmtree(p, ignore_errors=True)
            gone.append(rid)
    return gone
