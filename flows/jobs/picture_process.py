"""Pictures drawn in a child process, so a routing worker never imports matplotlib.

matplotlib and drawing a map add about 80 MB to a process that holds them; a `dask worker` that routes and exports
would carry that for its whole life. A `PictureProcess` instead starts one child interpreter (`python -m
flows.jobs.picture_process`, the same code as its parent) at the first picture it is asked for, sends it each
picture as its name (pipeline/export/drawing.py) and plain arguments, pickled over a pipe, and gets the PNG bytes
back. A worker keeps one for its life (`of_this_process`: starting one and drawing its first picture costs about
0.7 s CPU, matplotlib's import and the land structure's load); the child exits when it is closed or when its parent
goes away (its input closes). A drawing that fails raises PictureError with the child's message; a child that died is
started again at the next picture.

The child stays lean (about 70 MB after its imports, peak 108 MB over bench/fleet.py's 200 voyages): it draws with
matplotlib's Figure and Agg (no pyplot), its coastlines and great circles come from numpy
(pipeline/routing/land_mask.py, sphere.py), and it never imports numba, scipy, pandas, xarray, zarr, s3fs or dask
(tests/test_worker_memory.py).
"""

from __future__ import annotations

import atexit
import functools
import gc
import os
import pickle
import struct
import subprocess
import sys
from pathlib import Path

from flows.jobs.worker_memory import release_free_memory
from pipeline.export.drawing import draw_here

CODE_ROOT = Path(__file__).resolve().parents[2]  # the checkout the child imports (the parent's own code)
_LENGTH = struct.Struct("<Q")


class PictureError(RuntimeError):
    """A picture the child process could not draw (the message is the child's error), or a child that died."""


def _send(stream, obj) -> None:
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(_LENGTH.pack(len(data)))
    stream.write(data)
    stream.flush()


def _receive(stream):
    head = stream.read(_LENGTH.size)
    if len(head) < _LENGTH.size:
        raise EOFError
    n = _LENGTH.unpack(head)[0]
    data = stream.read(n)
    if len(data) < n:
        raise EOFError
    return pickle.loads(data)


class PictureProcess:
    """A `draw(name, *args)` (pipeline/export/drawing.py) that draws in a child process started at the first
    picture. Use as a context manager, or call `close()`."""

    def __init__(self) -> None:
        self._child: subprocess.Popen | None = None

    def _started(self) -> subprocess.Popen:
        if self._child is None or self._child.poll() is not None:
            env = dict(os.environ, PYTHONPATH=os.pathsep.join(
                [str(CODE_ROOT)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]))
            self._child = subprocess.Popen([sys.executable, "-m", "flows.jobs.picture_process"], env=env,
                                           stdin=subprocess.PIPE, stdout=subprocess.PIPE, cwd=CODE_ROOT)
        return self._child

    def __call__(self, name: str, *args) -> bytes:
        child = self._started()
        try:
            _send(child.stdin, (name, args))
            ok, value = _receive(child.stdout)
        except (OSError, EOFError) as exc:
            self.close()
            raise PictureError(f"the picture process exited ({type(exc).__name__}) while drawing the {name}; "
                               "see the worker's log for why") from None
        if not ok:
            raise PictureError(value)
        return value

    @property
    def pid(self) -> int | None:
        return self._child.pid if self._child is not None and self._child.poll() is None else None

    def close(self) -> None:
        child, self._child = self._child, None
        if child is None:
            return
        try:
            if child.stdin is not None:
                child.stdin.close()
            child.wait(timeout=30)
        except (OSError, subprocess.TimeoutExpired):
            child.kill()
            child.wait()
        finally:
            if child.stdout is not None:
                child.stdout.close()

    def __enter__(self) -> PictureProcess:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


@functools.cache
def of_this_process() -> PictureProcess:
    """This process's picture process, kept between batches and tasks (its child starts at the first picture and is
    closed at exit)."""
    pictures = PictureProcess()
    atexit.register(pictures.close)
    return pictures


def serve(requests, replies) -> None:
    """The child's loop: each request (picture name, args) is answered (True, PNG bytes) or (False, its error),
    until the parent closes `requests`. After each picture, once the reply is sent, it collects the drawing's
    garbage and gives what it freed back to the system (flows/jobs/worker_memory.py)."""
    frozen = False
    while True:
        try:
            name, args = _receive(requests)
        except EOFError:
            return
        reply: tuple[bool, bytes | str]
        try:
            reply = (True, draw_here(name, *args))
        except Exception as exc:  # the parent records it as that picture's error
            reply = (False, f"{type(exc).__name__}: {exc}")
        _send(replies, reply)
        # a figure's artists, transforms and callbacks reference each other: about 5 MB a map that would otherwise
        # pile up until the next full collection (a child drawing route maps grew by 40 MB between two)
        gc.collect()
        if not frozen:  # what the first picture imported and loaded stays for the child's life: later
            gc.freeze()  # collections skip it (1 ms instead of 20-30 ms a picture)
            frozen = True
        release_free_memory()


if __name__ == "__main__":
    replies = os.fdopen(os.dup(sys.stdout.fileno()), "wb")
    os.dup2(sys.stderr.fileno(), sys.stdout.fileno())  # whatever a library prints goes to the log, not the replies
    serve(sys.stdin.buffer, replies)
