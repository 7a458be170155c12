"""Raw downloaded files under the data root, and quarantine for corrupt ones.

Layout: raw/<source>/<YYYYMMDD>/<file name>; quarantine/<source>/<file name>.<timestamp>.
File names are plain names checked by the listing code; `path_for` checks again so nothing
is ever written outside the raw store.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np


def path_for(raw_dir: Path, source: str, cycle, file_name: str) -> Path:
    if not file_name or file_name == "." or "/" in file_name or "\\" in file_name or ".." in file_name or "\x00" in file_name:
        raise ValueError(f"refusing to store {file_name!r}: not a plain file name")
    day = np.datetime_as_string(np.datetime64(cycle, "D")).replace("-", "")
    folder = (Path(raw_dir) / source.lower() / day).resolve()
    p = (folder / file_name).resolve()
    if p.parent != folder:
        raise ValueError(f"refusing to store {file_name!r} outside {folder}")
    return p


def quarantine(quarantine_dir: Path, source: str, path: Path) -> Path:
    """Move a corrupt file aside (kept for inspection, never decoded again)."""
    dest = Path(quarantine_dir) / source.lower() / f"{Path(path).name}.{int(time.time())}"
    dest.parent.mkdir(parents=True, exist_ok=True)
    os.replace(path, dest)
    return dest
