"""Processes of a test, found by a tag in their environment: whatever a command starts (dask workers,
Prefect servers, flow-run subprocesses) inherits the tag, so after the command ends any process still
carrying it is an orphan of ours."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import httpx

TAG_VAR = "JITROUTE_TEST_TAG"
VENV_BIN = Path(sys.executable).parent


def new_tag() -> str:
    return uuid.uuid4().hex


def tagged_env(tag: str, **extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("PREFECT_API_")}
    env.update({TAG_VAR: tag, "PREFECT_SERVER_ANALYTICS_ENABLED": "false", "PYTHONUNBUFFERED": "1"})
    env.update(extra)
    return env


def tagged_pids(tag: str) -> list[int]:
    """PIDs of live processes (not zombies) whose environment carries `tag`."""
    needle = f"{TAG_VAR}={tag}".encode()
    found = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            if needle not in (d / "environ").read_bytes().split(b"\0"):
                continue
            state = (d / "stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if state != "Z":
            found.append(int(d.name))
    return found


def wait_until_gone(tag: str, timeout_s: float = 30.0) -> list[int]:
    """Poll until no tagged process is left (processes may take a moment to exit); returns those still there."""
    deadline = time.monotonic() + timeout_s
    while True:
        left = tagged_pids(tag)
        if not left or time.monotonic() > deadline:
            return left
        time.sleep(0.2)


def describe(pids: list[int]) -> str:
    out = []
    for pid in pids:
        try:
            cmd = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        out.append(f"{pid}: {cmd[:200]}")
    return "\n".join(out)


def kill_tagged(tag: str) -> None:
    for pid in tagged_pids(tag):
        try:
            os.kill(pid, signal.SIGKILL)
        except OSError:
            pass


def poll(what: str, fn, timeout_s: float, every_s: float = 1.0):
    """`fn()`'s first truthy value, asked every `every_s` until `timeout_s`; else AssertionError naming `what`."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        out = fn()
        if out:
            return out
        time.sleep(every_s)
    raise AssertionError(f"timed out after {timeout_s:.0f} s waiting for {what}")


def port_open(port: int, proc: subprocess.Popen, log: Path) -> bool:
    """Whether 127.0.0.1:`port` accepts connections; AssertionError with the log's tail if `proc` has exited."""
    assert proc.poll() is None, f"{proc.args[0]} exited with {proc.returncode}:\n{log.read_text()[-3000:]}"
    with socket.socket() as s:
        return s.connect_ex(("127.0.0.1", port)) == 0


def start(args: list[str], env: dict, log: Path, cwd: Path | None = None) -> subprocess.Popen:
    """A background process of the test, its output in `log`, in its own session (stopped by `stop`)."""
    return subprocess.Popen(args, env=env, cwd=cwd, stdout=open(log, "w"), stderr=subprocess.STDOUT,
                            start_new_session=True)


def stop(procs: list[subprocess.Popen], tag: str) -> list[int]:
    """Terminate the processes, then kill whatever still carries the tag; returns PIDs that outlived even that."""
    for p in procs:
        if p.poll() is None:
            p.terminate()
    for p in procs:
        try:
            p.wait(timeout=10)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()
    kill_tagged(tag)
    return wait_until_gone(tag, 15)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def prefect(*args: str, env: dict, cwd: Path | None = None, timeout_s: float = 300) -> str:
    """What the installed `prefect --no-prompt <args>` prints; AssertionError with its output when it fails."""
    r = subprocess.run([str(VENV_BIN / "prefect"), "--no-prompt", *args], cwd=cwd, env=env, capture_output=True, text=True,
                       timeout=timeout_s)
    assert r.returncode == 0, (args, r.stdout[-3000:], r.stderr[-3000:])
    return r.stdout


def jitroute(*args: str, env: dict, timeout_s: float = 600, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """Run the installed `jitroute` command as a user would."""
    return subprocess.run([str(VENV_BIN / "jitroute"), *args], env=env, cwd=cwd, capture_output=True, text=True,
                          timeout=timeout_s)


@dataclass
class Served:
    """A Prefect server and `jitroute serve` registered with it (`prefect_server_and_serve`)."""
    api: str  # http://127.0.0.1:<port>/api
    env: dict[str, str]  # the environment of a Prefect client of that server (the tag, PREFECT_API_URL)
    serve: subprocess.Popen
    logs: Path  # server.log and serve.log

    def log(self, name: str) -> str:
        """The last 3000 characters of `name`.log, for an assertion's message."""
        return (self.logs / f"{name}.log").read_text()[-3000:]


@contextmanager
def prefect_server_and_serve(tmp_path: Path, serve_args: list[str], **env: str) -> Iterator[Served]:
    """A real `prefect server start` on a free port of 127.0.0.1, once healthy `jitroute serve <serve_args>` talking to
    it (run in `tmp_path`, Prefect's home in it, `env` added to both environments), their output in `tmp_path/logs`.
    On leaving, both are stopped with SIGINT (as Ctrl-C would) and, when the body passed, AssertionError names any
    process of theirs (dask workers, flow-run subprocesses) still running 30 s later; those are killed either way."""
    tag = new_tag()
    port = free_port()
    api = f"http://127.0.0.1:{port}/api"
    server_env = tagged_env(tag, PREFECT_HOME=str(tmp_path / "prefect_home"), PREFECT_LOGGING_LEVEL="INFO", **env)
    logs = tmp_path / "logs"
    logs.mkdir()
    procs: list[subprocess.Popen] = []
    try:
        server = start([str(VENV_BIN / "prefect"), "server", "start", "--host", "127.0.0.1", "--port", str(port)],
                       server_env, logs / "server.log")
        procs.append(server)

        def healthy() -> bool:
            try:
                return httpx.get(f"{api}/health", timeout=2).status_code == 200
            except httpx.HTTPError:
                assert server.poll() is None, (logs / "server.log").read_text()[-3000:]
                return False

        poll("the Prefect server", healthy, 120, 0.5)
        client_env = dict(server_env, PREFECT_API_URL=api)
        serve = start([str(VENV_BIN / "jitroute"), "serve", *serve_args], client_env, logs / "serve.log", cwd=tmp_path)
        procs.insert(0, serve)  # stopped first, the server after it
        yield Served(api, client_env, serve, logs)
    finally:
        for proc in procs:
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
                try:
                    proc.wait(timeout=60)
                except subprocess.TimeoutExpired:
                    proc.kill()
        left = wait_until_gone(tag, 30)
        kill_tagged(tag)
    assert not left, f"processes left running after serve and the server stopped:\n{describe(left)}"
