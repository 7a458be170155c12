"""One scheduled job at a time per data root: the nightly, an ingest and a backfill never overlap.

An exclusive `flock` on `<data root>/locks/jobs.lock`; the file names the holder (job, host, PID,
since) so a waiting job can say what it waits for. The kernel releases the lock when the holder
dies, so a killed run never blocks the next one. Re-entrant within a process (the nightly holds it
while it runs its ingests).

Waiters are served first come, first served: each takes a ticket (a file in `locks/queue/`, named by the time it
arrived and held under its own `flock` while it waits) and takes the lock only when no live ticket older than its own
is left, so an operator's backfill that waited first is not overtaken by the ingests scheduled after it. A ticket
whose waiter died is unlocked by the kernel and removed by the next waiter that finds it.
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
    ticket = None
    try:
        deadline = None if wait_s is None else time.monotonic() + wait_s
        said = False
        queue = lock_dir / "queue"
        while True:
            if not _older_tickets_alive(queue, ticket[0].name if ticket else None):
                try:
                    fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
                    break
                except BlockingIOError:
                    pass
            if ticket is None:  # the lock is taken or others wait: queue behind those who came before
                ticket = _take_ticket(queue)
            if not said:
                say(f"waiting for {_holder_text(path)} to finish (lock {path})")
                said = True
            if deadline is not None and time.monotonic() >= deadline:
                raise TimeoutError(f"data root is busy: {_holder_text(path)} holds {path}") from None
            time.sleep(poll_s)
        _drop_ticket(ticket)
        ticket = None
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
        _drop_ticket(ticket)
        fh.close()


def _take_ticket(queue: Path) -> tuple[Path, object]:
    """A ticket in `queue` named by this arrival's time, locked by this process before it is visible (made under a
    temporary name, locked, then renamed), so a waiter never takes a live ticket for a dead one."""
    queue.mkdir(parents=True, exist_ok=True)
    name = f"{time.time_ns():020d}-{os.getpid()}-{threading.get_ident()}"
    tmp = queue / f".{name}.new"
    th = open(tmp, "w")
    fcntl.flock(th, fcntl.LOCK_EX)
    os.rename(tmp, queue / f"{name}.ticket")
    return queue / f"{name}.ticket", th


def _drop_ticket(ticket) -> None:
    if ticket is None:
        return
    path, th = ticket
    try:
        path.unlink()
    except FileNotFoundError:
        pass
    th.close()


def _older_tickets_alive(queue: Path, mine: str | None) -> bool:
    """Is a waiter that arrived before ticket `mine` (None: any waiter) still waiting? Tickets of dead waiters (their
    flock free) are removed."""
    for other in sorted(queue.glob("*.ticket")):
        if mine is not None and other.name >= mine:
            return False
        try:
            oh = open(other, "r")
        except FileNotFoundError:
            continue  # it took the lock (or gave up) meanwhile
        with oh:
            try:
                fcntl.flock(oh, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                return True
            try:  # its waiter died: nobody holds its ticket
                other.unlink()
            except FileNotFoundError:
                pass
    return False
