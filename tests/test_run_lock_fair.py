"""The data root's job lock serves waiters in the order they came: an operator's run that waited first is not overtaken
by runs scheduled after it, however eagerly they poll; a waiter that died does not hold up those behind it."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from storage.run_lock import job_lock

WAITER = ("import sys, time\n"
          "from storage.run_lock import job_lock\n"
          "with job_lock(sys.argv[1], sys.argv[2], say=lambda m: print('WAITING', flush=True), poll_s=float(sys.argv[3])):\n"
          "    open(sys.argv[4], 'a').write(sys.argv[2] + '\\n')\n"
          "    time.sleep(0.05)\n")


def _waiter(tmp_path, job: str, poll_s: float) -> subprocess.Popen:
    p = subprocess.Popen([sys.executable, "-c", WAITER, str(tmp_path / "locks"), job, str(poll_s),
                          str(tmp_path / "order.txt")], stdout=subprocess.PIPE, text=True, env=dict(os.environ))
    assert p.stdout.readline().strip() == "WAITING"  # it found the lock taken and queued
    return p


@pytest.mark.slow
def test_waiters_get_the_lock_in_the_order_they_came(tmp_path):
    with job_lock(tmp_path / "locks", "nightly"):
        operator = _waiter(tmp_path, "backfill (operator)", 0.5)  # polls slowly
        dead = _waiter(tmp_path, "ingest killed while waiting", 0.01)
        dead.send_signal(signal.SIGKILL)
        dead.wait(30)
        scheduled = [_waiter(tmp_path, f"ingest {i}", 0.01) for i in range(3)]  # poll fifty times as often
        time.sleep(0.3)  # every waiter has polled a few times
    for p in (operator, *scheduled):
        assert p.wait(60) == 0
    order = (tmp_path / "order.txt").read_text().split("\n")[:-1]
    assert order == ["backfill (operator)", "ingest 0", "ingest 1", "ingest 2"]
    assert list((tmp_path / "locks" / "queue").iterdir()) == []  # every ticket gone, the dead waiter's too
    with job_lock(tmp_path / "locks", "next", wait_s=0):  # and the lock is free
        pass
