"""SIGTERM ends every `jitroute` command within a few seconds, cleanly.

Operators, systemd and Prefect cancellation stop runs with SIGTERM. Two parts, installed once by
`cli.main.main`:

- a watcher thread woken through `signal.set_wakeup_fd`: the interpreter writes the signal number to that
  pipe from its C-level handler, whatever Python handler is active (Prefect swaps in its own during a flow
  run) and however busy the main thread is. On the first SIGTERM the watcher cancels this process's downloads
  at once (their sockets are shut down, so blocked reads return; their `.part` files are removed) and arms
  a GRACE_S timer that ends the process if unwinding takes longer; a second SIGTERM ends it at once;
- a Python handler that raises SystemExit(143) in the main thread (Prefect re-sends SIGTERM to it after
  its own teardown), so `finally` blocks, transactions and locks unwind.

Nothing half-written becomes visible either way: cube cycles stay hidden until their state is written last,
warehouse writes are transactions, downloads are renamed into place only when complete.
"""

from __future__ import annotations

import os
import signal
import sys
import threading

EXIT_SIGTERM = 128 + signal.SIGTERM  # 143, what shells and systemd expect after SIGTERM
GRACE_S = 5.0
_grace_s = GRACE_S  # `jitroute serve` lengthens it: its flow runs finish first (deploy/serve.py)

_stopping = threading.Event()
_lock = threading.Lock()


def _cancel_downloads() -> None:
    from pipeline.sources.fetch import cancel_downloads

    cancel_downloads()


def _force_exit() -> None:
    _cancel_downloads()  # parts of downloads started since
    try:
        sys.stderr.write("jitroute: stopped by SIGTERM\n")
        sys.stderr.flush()
    finally:
        os._exit(EXIT_SIGTERM)


def _begin_stop() -> bool:
    """Cancel downloads and arm the grace timer; True the first time only."""
    with _lock:
        if _stopping.is_set():
            return False
        _stopping.set()
    _cancel_downloads()
    timer = threading.Timer(_grace_s, _force_exit)
    timer.daemon = True
    timer.start()
    return True


def _watch(fd: int) -> None:
    seen = 0
    while True:
        try:
            data = os.read(fd, 64)
        except OSError:
            return
        for signum in data:
            if signum != signal.SIGTERM:
                continue
            seen += 1
            if seen == 1:
                _begin_stop()
            else:  # a second SIGTERM (from the operator, or re-sent after Prefect's teardown): no more waiting
                _force_exit()


def _on_sigterm(signum, frame) -> None:
    _begin_stop()  # normally done by the watcher already
    raise SystemExit(EXIT_SIGTERM)


def set_grace_s(seconds: float) -> None:
    """How long the first SIGTERM lets this process unwind before it is ended."""
    global _grace_s
    _grace_s = float(seconds)


def install() -> None:
    """Install the watcher and the handler (main thread only, as Python requires for signals)."""
    if threading.current_thread() is not threading.main_thread():
        return
    r, w = os.pipe()
    os.set_blocking(w, False)
    signal.set_wakeup_fd(w, warn_on_full_buffer=False)
    threading.Thread(target=_watch, args=(r,), daemon=True, name="sigterm-watch").start()
    signal.signal(signal.SIGTERM, _on_sigterm)
