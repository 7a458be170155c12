"""One scheduled job at a time per data root: the nightly, an ingest and a backfill never overlap.

An exclusive `flock` on `<data root>/locks/jobs.lock`; the file names the holder (job, host, PID,
since) so a waiting job can say what it waits for. The kernel releases the lock when the holder
dies, so a killed run never blocks the next one. Re-entrant within a process (the nightly holds it
while it runs its ingests).
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import socket
import threading
import time
from collections.abc import Callable, Iterator
from datetime import datetime, timezone
from pathlib import Path

_held: dict[str, int] = {}
_guard = threading.Lock()


def _holder_text(path: Path) -> str:
    try:
        return path.read_text().strip() or "another job"
    except OSError:
        return "another job"


@contextlib.contextmanager
def job_lock(lock_dir: Path, job: str, *, say: Callable[[str], None] = lambda _m: None,
             poll_s: float = 0.5, wait_s: float | None = None) -> Iterator[None]:
    """Hold the data root's job lock while the block runs; `say` gets one "waiting for …" line if it is taken.

    `wait_s` None waits for ever (a scheduled job simply runs after the one before it); otherwise a
    TimeoutError naming the holder is raised after that long.
    """
    lock_dir = Path(lock_dir)
    lock_dir.mkdir(parents=True, exist_ok=True)
    path = lock_dir / "jobs.lock"
    key = str(path.resolve())
    with _guard:
        if _held.get(key):
            _held[key] += 1
            reentered = True
        else:
            reentered = False
    if reentered:
        try:
            yield
        finally:
            with _guard:
                _held[key] -= 1
        return
    fh = open(path, "a+")
    try:
        deadline = None if wait_s is None else time.monotonic() + wait_s
        said = False
        while True:
            try:
                fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if not said:
                    say(f"waiting for {_holder_text(path)} to finish (lock {path})")
                    said = True
                if deadline is not None and time.monotonic() >= deadline:
                    raise TimeoutError(f"data root is busy: {_holder_text(path)} holds {path}") from None
                time.sleep(poll_s)
        since = datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
        fh.seek(0)
        fh.truncate()
        fh.write(f"{job} (host {socket.gethostname()}, pid {os.getpid()}, since {since})\n")
        fh.flush()
        with _guard:
            _held[key] = 1
        try:
            yield
        finally:
            with _guard:
                _held.pop(key, None)
            fh.seek(0)
            fh.truncate()
            fh.flush()
            fcntl.flock(fh, fcntl.LOCK_UN)
    finally:
        fh.close()
