"""Which process owns a `running` routing run, and settling the runs whose process died.

Its own module, with nothing of the warehouse in it, because every writer connection calls `reap_dead_runs`
(storage/warehouse.py) while the routing runs' store (storage/route_store.py) builds on the warehouse."""

from __future__ import annotations

import socket
from datetime import datetime, timezone
from pathlib import Path


def process_started(pid: int) -> str | None:
    """The start time of process `pid` (clock ticks after boot, from /proc), None when it does not exist."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return stat.rsplit(")", 1)[1].split()[19]  # field 22 (starttime); the name in (…) may hold spaces


def process_alive(pid: int | None, started: str | None) -> bool:
    """Process `pid` exists and is the one that started at `started` (not a later process given the same PID)."""
    if not pid:
        return False
    now = process_started(int(pid))
    return now is not None and (started is None or now == started)


def reap_dead_runs(con) -> list[str]:
    """Mark this host's `running` runs whose process is gone as failed ("process died"); returns their ids.

    Called by every writer connection (storage.warehouse.connect), so a SIGKILLed run is settled by the
    next command that opens the warehouse. Runs of other hosts are left to their own host.
    """
    try:
        rows = con.execute("SELECT run_id, pid, pid_started FROM route_runs WHERE status = 'running' AND host = ?",
                           [socket.gethostname()]).fetchall()
    except Exception:  # a warehouse older than the owner columns (before its migration)
        return []
    dead = [(rid, pid) for rid, pid, started in rows if not process_alive(pid, started)]
    now_utc = datetime.now(timezone.utc).replace(tzinfo=None)
    for rid, pid in dead:
        con.execute("UPDATE route_runs SET status = 'failed', finished_at = ?, reason = ? WHERE run_id = ?",
                    [now_utc, f"process died (host {socket.gethostname()}, pid {pid} no longer runs)", rid])
    return [rid for rid, _pid in dead]
