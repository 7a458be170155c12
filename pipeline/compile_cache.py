"""Where numba keeps the compiled kernels: one folder per digest of the pipeline's sources.

numba's own cache (`cache=True`) checks only the source file of the kernel it loads: a kernel that calls a
kernel in another file, or compiles in another file's constant, keeps running the old callee after that file is
edited. jitroute therefore points numba at `<cache root>/jitroute-<digest>`, the digest being a hash of the
content of every pipeline/**/*.py (and the numba and Python versions): any edit to the pipeline gives a new,
empty folder, so a cached kernel can never be older than the source tree. Folders of other digests are removed
once they have not been used for a while (the current one and the two last used are kept).

The cache root is, in this order: $JITROUTE_NUMBA_CACHE; $NUMBA_CACHE_DIR (taken as the root: a
`jitroute-<digest>` folder is made inside it); the pipeline's own `__pycache__/numba` when the checkout is
writable; else the user's cache folder ($XDG_CACHE_HOME or ~/.cache)/jitroute/numba, so a read-only install works.

`configure()` runs when `pipeline` is imported, before any kernel is decorated (numba reads its cache folder
when a `cache=True` kernel is defined); it sets NUMBA_CACHE_DIR, which child processes (dask workers) inherit.
Standard library only: this runs on every import of the pipeline.
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import platform
import shutil
import sys
import time
from pathlib import Path

PIPELINE = Path(__file__).resolve().parent
PREFIX = "jitroute-"
KEEP = 3  # digest folders kept: the current one and the two used last
IDLE_S = 600.0  # a folder used in the last 10 minutes is never removed (another process may be running that code)
USED = "last-used"  # file touched in a digest folder whenever a process configures it


def sources_digest(pipeline: Path = PIPELINE) -> str:
    """Hash of the content of every pipeline source file (path and bytes) and of the numba and Python versions."""
    h = hashlib.sha256()
    h.update(f"python {platform.python_version()} numba {_numba_version()}\n".encode())
    for p in sorted(pipeline.rglob("*.py")):
        h.update(f"{p.relative_to(pipeline).as_posix()}\n".encode())
        h.update(p.read_bytes())
    return h.hexdigest()[:16]


def _numba_version() -> str:
    """numba's version without importing it (or scanning the installed distributions, ~0.1 s)."""
    spec = importlib.util.find_spec("numba")
    if spec is None or not spec.origin:
        return "none"
    try:
        return (Path(spec.origin).parent / "_version.py").read_text()
    except OSError:
        return spec.origin


def _writable(folder: Path) -> bool:
    while not folder.exists():
        folder = folder.parent
    return os.access(folder, os.W_OK)


def cache_root(environ=os.environ) -> Path:
    """The folder that holds the per-digest folders (see the module's docstring for the order)."""
    if environ.get("JITROUTE_NUMBA_CACHE"):
        return Path(environ["JITROUTE_NUMBA_CACHE"])
    numba_dir = environ.get("NUMBA_CACHE_DIR")
    if numba_dir:
        p = Path(numba_dir)
        return p.parent if p.name.startswith(PREFIX) else p  # set by a parent process: its root is ours
    in_tree = PIPELINE / "__pycache__" / "numba"
    if _writable(in_tree):
        return in_tree
    return Path(environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "jitroute" / "numba"


def cache_dir(environ=os.environ) -> Path:
    """numba's cache folder for the pipeline sources as they are now."""
    return cache_root(environ) / f"{PREFIX}{sources_digest()}"


def prune(root: Path, current: Path, keep: int = KEEP, idle_s: float = IDLE_S) -> list[Path]:
    """Remove the digest folders under `root` other than the `keep` used last (`current` counts as used now) and
    those used in the last `idle_s` seconds; returns what was removed."""
    now = time.time()

    def last_used(p: Path) -> float:
        if p == current:
            return float("inf")
        try:
            return (p / USED).stat().st_mtime
        except OSError:
            try:
                return p.stat().st_mtime
            except OSError:
                return 0.0

    try:
        folders = [p for p in root.iterdir() if p.is_dir() and p.name.startswith(PREFIX)]
    except OSError:
        return []
    folders.sort(key=last_used, reverse=True)
    removed = []
    for p in folders[keep:]:
        if now - last_used(p) > idle_s:
            shutil.rmtree(p, ignore_errors=True)
            removed.append(p)
    return removed


def configure() -> Path:
    """Point numba's cache at this source tree's digest folder (creating it, marking it used, removing stale ones)."""
    folder = cache_dir()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        (folder / USED).touch()
        prune(folder.parent, folder)
    except OSError:
        pass  # numba falls back to compiling without a cache when the folder cannot be written
    os.environ["NUMBA_CACHE_DIR"] = str(folder)
    if "numba" in sys.modules:  # imported before the pipeline: numba reads config.CACHE_DIR when a kernel is defined
        sys.modules["numba"].config.CACHE_DIR = str(folder)
    return folder
