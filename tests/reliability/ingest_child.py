"""The real `ingest-weather` flow in a child process, optionally stopped at a hook point.

    python -m tests.reliability.ingest_child ROOT RISH_URL OSCAR_URL [--stop POINT:N:HOW] [--force]
                                             [--fsize-limit BYTES] [--timeout S]
    python -m tests.reliability.ingest_child --zygote     (see `zygote`)

POINT (the N-th time it is reached, counting from 1):
  download  a file's body is fully written to its `.part` file, not yet renamed
  decode    a raw file has been decoded
  zarr      a file of the cube store is about to be written (metadata, chunk or cycle state)
  state     the cycle's final state (complete/incomplete) is about to be set
  log       the cube is written; the ingest log is about to be written
  status    the ingest log is written; the cycle status is about to be written
HOW: `kill` — the process SIGKILLs itself there; `pause` — it writes "PAUSED <POINT>" to stdout (or
to the `--marker` file) and blocks until the parent kills it. `--fsize-limit` runs under RLIMIT_FSIZE
(SIGXFSZ ignored, so writes past the limit fail with EFBIG like a full disk); `--timeout` sets the
HTTP timeout. The report is printed as JSON on the last line.
"""

from __future__ import annotations

import dataclasses

import json
import os
import resource
import signal
import sys
import threading
from pathlib import Path

FAST_OVERRIDES = {
    "sources.gsm_max_lead_h": 12,
    "sources.gsm_long_lead_h": 0,  # the mirrors here have no leads past 12 h: no empty slots for them in the cube
    "sources.http_timeout_s": 2.0,
    "sources.http_retries": 1,
    "sources.http_backoff_s": 0.01,
}


def fast_load_settings(**overrides):
    """`flows.settings.load_settings` with the suite's overrides on top (short retries, 0–12 h leads)."""
    from flows.settings import load_settings

    return load_settings(**overrides).with_overrides(**FAST_OVERRIDES)


def load_settings_with(**extra):
    """A `load_settings` replacement: the suite's overrides plus `extra` (keys like "sources.http_timeout_s")."""

    def load(**overrides):
        return fast_load_settings(**overrides).with_overrides(**extra)

    return load


def _stop(point: str, how: str, marker: Path | None) -> None:
    if how == "kill":
        os.kill(os.getpid(), signal.SIGKILL)
    if marker is not None:
        marker.write_text(f"PAUSED {point}\n")
    else:
        print(f"PAUSED {point}", flush=True)
    while True:  # the parent kills us while we wait here
        signal.pause()


def _counted(stop, n: int, fn, before: bool, count: dict | None = None):
    count = {"n": 0} if count is None else count  # a shared dict counts calls of several functions together
    lock = count.setdefault("lock", threading.Lock())  # downloads and decodes run in worker threads

    def wrapper(*args, **kwargs):
        with lock:
            count["n"] += 1
            k = count["n"]  # this call's number, whatever other threads do meanwhile
        if before and k == n:
            stop()
        out = fn(*args, **kwargs)
        if not before and k == n:
            stop()
        return out

    return wrapper


def install_stop(point: str, n: int, how: str, marker: Path | None = None) -> None:
    import zarr.storage._local as zarr_local

    import flows.jobs.ingest as flow
    from pipeline.sources import fetch
    from storage import cube, ingest_log

    def stop():
        _stop(point, how, marker)

    if point == "download":
        fetch._download = _counted(stop, n, fetch._download, before=False)
    elif point == "decode":
        shared = {"n": 0}
        counted = {name: dataclasses.replace(src, decode=_counted(stop, n, src.decode, before=False, count=shared))
                   for name, src in flow.BY_NAME.items()}
        flow.BY_NAME.clear()
        flow.BY_NAME.update(counted)  # the ingest decodes each file through its source's entry
    elif point == "zarr":
        zarr_local._put = _counted(stop, n, zarr_local._put, before=True)
    elif point == "state":
        real = cube._set_state

        def set_state(path, index, state):
            if state != cube.STATE_HIDDEN:
                stop()
            real(path, index, state)

        cube._set_state = set_state
    elif point == "log":
        ingest_log.record_files = _counted(stop, n, ingest_log.record_files, before=True)
    elif point == "status":
        ingest_log.set_cycle_status = _counted(stop, n, ingest_log.set_cycle_status, before=True)
    else:
        raise SystemExit(f"unknown stop point {point!r}")


def _opt(rest: list[str], name: str) -> str | None:
    return rest[rest.index(name) + 1] if name in rest else None


def main(argv: list[str]) -> int:
    root, rish_url, oscar_url, *rest = argv
    if _opt(rest, "--fsize-limit"):
        limit = int(_opt(rest, "--fsize-limit"))
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    import flows.ingest as flow
    import flows.jobs.ingest as job

    extra = {"sources.http_timeout_s": float(_opt(rest, "--timeout"))} if _opt(rest, "--timeout") else {}
    job.load_settings = load_settings_with(**extra)
    if _opt(rest, "--stop"):
        point, n, how = _opt(rest, "--stop").split(":")
        marker = _opt(rest, "--marker")
        install_stop(point, int(n), how, Path(marker) if marker else None)
    report = flow.ingest_weather("2020-12-01T00", data_root=root, rish_url=rish_url, oscar_url=oscar_url,
                                 force="--force" in rest)
    print(json.dumps(report), flush=True)
    return 0


def zygote() -> int:
    """Import everything once, then fork one child per job so each starts in milliseconds.

    Reads one JSON line: a list of {"argv": [...], "out": path}; every child runs `main(argv)` with
    stdout+stderr to `out`. Prints "PID <index> <pid>" per child, then "EXIT <pid> <returncode>" as
    each ends (returncode -9 when SIGKILLed), then exits.
    """
    import flows.ingest  # noqa: F401  (the expensive imports, shared by every fork)
    import zarr.storage._local  # noqa: F401

    print("READY", flush=True)
    jobs = json.loads(sys.stdin.readline())
    pids = []
    for i, job in enumerate(jobs):
        pid = os.fork()
        if pid == 0:
            code = 1
            try:
                fd = os.open(job["out"], os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
                os.dup2(fd, 1)
                os.dup2(fd, 2)
                os.dup2(os.open(os.devnull, os.O_RDONLY), 0)
                code = main(job["argv"])
            except SystemExit as exc:
                code = exc.code if isinstance(exc.code, int) else 1
            except BaseException:  # reported through the exit code and the output file
                import traceback

                traceback.print_exc()
            finally:
                sys.stdout.flush()
                sys.stderr.flush()
                os._exit(code)  # never return into the zygote's loop
        pids.append(pid)
        print(f"PID {i} {pid}", flush=True)
    for _ in pids:
        pid, status = os.wait()
        print(f"EXIT {pid} {os.waitstatus_to_exitcode(status)}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(zygote() if sys.argv[1:] == ["--zygote"] else main(sys.argv[1:]))
