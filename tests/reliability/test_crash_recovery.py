"""The ingest process SIGKILLed at many points, then re-run: nothing partial is ever visible and the
re-run gives exactly a clean run's cube and a warehouse that knows every file and the cycle.

Each scenario is a real `ingest-weather` flow run in its own process (forked from one pre-imported
parent, see tests/reliability/ingest_child.py), with its own data root. It is killed at a hook point
during download, decode, the Zarr write or the warehouse writes, or by this process once the raw
store or the cube has reached some size (polled with a deadline, so the point varies run to run).
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from storage import cube
from storage.layout import DataLayout
from tests.reliability.conftest import (REPO, assert_same_cube, child_env, file_urls, visible_cycles_equal_clean,
                                       warehouse_knows_cycle)

DEADLINE_S = 240.0

# scenario -> how the child stops: "POINT:N:kill" (it kills itself) or "POINT:N:pause" (we kill it there)
STOPS = {
    "download-2nd-file": "download:2:pause",
    "decode-4th-file": "decode:4:pause",
    "zarr-creating-the-store": "zarr:8:pause",
    "zarr-mid-region": "zarr:75:kill",  # creating the store takes ~45 writes, the region 64 more
    "before-ingest-log": "log:1:kill",
    "before-cycle-status": "status:1:kill",
    "rewrite-mid-region": "zarr:40:kill",  # a forced re-ingest of a complete cycle
}


def _n_raw(root: Path) -> int:
    return sum(1 for p in (root / "raw").rglob("*") if p.is_file()) if (root / "raw").exists() else 0


def _n_chunks(root: Path) -> int:
    store = DataLayout(root).weather_cube
    return sum(1 for p in store.glob("*/c/**/*") if p.is_file()) if store.exists() else 0


# scenario -> a condition on the data root; we kill the child as soon as it holds
POLLED = {
    "polled-after-2-raw-files": lambda root: _n_raw(root) >= 2,
    "polled-after-first-chunk": lambda root: _n_chunks(root) >= 1,
}
SCENARIOS = [*STOPS, *POLLED]


class Zygote:
    """Drives tests.reliability.ingest_child --zygote: forks every job, reports pids and exit codes."""

    def __init__(self):
        self.proc = subprocess.Popen([sys.executable, "-m", "tests.reliability.ingest_child", "--zygote"], cwd=REPO,
                                     env=child_env(), stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        assert self.proc.stdout.readline().strip() == "READY"
        self.pids: dict[int, int] = {}
        self.exits: dict[int, int] = {}
        self.changed = threading.Condition()

    def start(self, jobs: list[dict]) -> None:
        self.proc.stdin.write(json.dumps(jobs) + "\n")
        self.proc.stdin.flush()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            kind, a, b = line.split()
            with self.changed:
                if kind == "PID":
                    self.pids[int(a)] = int(b)
                else:
                    self.exits[int(a)] = int(b)
                self.changed.notify_all()

    def pid(self, i: int) -> int:
        with self.changed:
            assert self.changed.wait_for(lambda: i in self.pids, timeout=DEADLINE_S)
            return self.pids[i]

    def exited(self, pid: int) -> bool:
        with self.changed:
            return pid in self.exits

    def returncode(self, pid: int) -> int:
        with self.changed:
            assert self.changed.wait_for(lambda: pid in self.exits, timeout=DEADLINE_S), f"child {pid} never ended"
            return self.exits[pid]


def _kill_when(z: Zygote, conditions: dict[int, object]) -> None:
    """Poll every child's condition together; SIGKILL each child as soon as its condition holds."""
    deadline = time.monotonic() + DEADLINE_S
    pending = dict(conditions)
    while pending:
        for pid, condition in list(pending.items()):
            if z.exited(pid):
                del pending[pid]
            elif condition():
                os.kill(pid, signal.SIGKILL)
                del pending[pid]
        assert time.monotonic() < deadline, f"kill conditions never held for children {sorted(pending)}"
        time.sleep(0.002)  # polling interval only; nothing is asserted on time


@pytest.fixture(scope="module")
def crashed(small_mirror, clean_root, tmp_path_factory, prefect_harness):
    """Every scenario run at once, each with its own data root: name -> (root, returncode, child output)."""
    base = tmp_path_factory.mktemp("crashed")
    rish_url, oscar_url = file_urls(small_mirror)
    jobs = []
    for name in SCENARIOS:
        root = base / name / "data"
        (base / name).mkdir()
        args = [str(root), rish_url, oscar_url]
        if name.startswith("rewrite"):
            shutil.copytree(clean_root, root)
            args.append("--force")
        if name in STOPS:
            args += ["--stop", STOPS[name], "--marker", str(base / name / "paused")]
        jobs.append({"argv": args, "out": str(base / name / "out.txt")})
    z = Zygote()
    z.start(jobs)
    try:
        conditions = {}
        for i, name in enumerate(SCENARIOS):
            if name in POLLED:
                conditions[z.pid(i)] = lambda check=POLLED[name], root=base / name / "data": check(root)
            elif STOPS[name].endswith(":pause"):
                conditions[z.pid(i)] = (base / name / "paused").exists
        _kill_when(z, conditions)
        out = {}
        for i, name in enumerate(SCENARIOS):
            rc = z.returncode(z.pid(i))
            out[name] = (base / name / "data", rc, (base / name / "out.txt").read_text())
    finally:
        for pid in z.pids.values():
            if not z.exited(pid):
                os.kill(pid, signal.SIGKILL)
        z.proc.wait(timeout=DEADLINE_S)
    return out


@pytest.mark.parametrize("name", SCENARIOS)
def test_killed_ingest_shows_nothing_partial_and_a_rerun_equals_a_clean_run(crashed, name, ingest, small_mirror, clean_cube):
    root, rc, output = crashed[name]
    assert rc == -signal.SIGKILL, output[-3000:]
    store = DataLayout(root).weather_cube
    visible = visible_cycles_equal_clean(store, clean_cube)  # whatever a reader sees is whole
    if name in ("before-ingest-log", "before-cycle-status"):
        assert visible == 1 and cube.complete_cycles(store)  # the cube was finished before the kill
    elif not name.startswith("polled"):
        assert visible == 0
    report = ingest(root, *file_urls(small_mirror))
    assert report["complete"] and not report["skipped"], report
    assert_same_cube(store, clean_cube)
    warehouse_knows_cycle(root)
    assert not list(root.rglob("*.part")), "a killed download's .part file was left behind"
    if name in ("before-ingest-log", "before-cycle-status"):
        assert ingest(root, *file_urls(small_mirror))["skipped"]  # now the cycle is really done
