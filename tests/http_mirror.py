"""A loopback HTTP server (127.0.0.1, ephemeral port) serving a folder, with fault injection.

Faults are keyed by file name (or path suffix):
  "404", "500"          that status on every request
  "500xN"               500 for the first N requests, then the file
  "truncate"            announce the full length, send half, drop the connection
  "stall" / "stallxN"   accept the request and never answer (the client's timeout fires); xN: first N only
  "reset" / "resetxN"   close the connection with a TCP reset before any response; xN: first N only
  "redirect:<url>"      302 to <url>
  "drip" / "drip:<s>"   announce the full length, then send one byte every <s> seconds (default 0.05)
                        until the client goes away or the server stops; `handler.dripping` is set when
                        the first byte has gone out
  "endless"             200 without a length, then zeros without end (until the client goes away)
  "huge"                announce 5 GB (Content-Length 5000000000), then zeros without end
  "redirect-loop"       302 to the same path, every time
Every request's path and headers are recorded in `handler.requests`; `handler.hits` counts them.
"""

from __future__ import annotations

import contextlib
import functools
import os
import socket
import struct
import threading
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

STALL_LIMIT_S = 30.0  # a stalled request is released at the latest when the server stops


class FaultyHandler(SimpleHTTPRequestHandler):
    faults: dict[str, str] = {}
    hits: dict[str, int] = {}
    requests: list[tuple[str, dict[str, str]]] = []
    stop: threading.Event = threading.Event()
    dripping: threading.Event = threading.Event()

    def log_message(self, *args):  # keep test output clean
        pass

    def _first_n(self, fault: str, kind: str) -> bool:
        """True when `fault` is `kind` (always) or `kindxN` and this is one of the first N requests."""
        if fault == kind:
            return True
        return fault.startswith(kind + "x") and self.hits[self.path] <= int(fault[len(kind) + 1:])

    def _send_first_half(self) -> bytes:
        """Headers announcing the whole file, then only its first half; returns the whole file's bytes."""
        data = Path(self.translate_path(self.path)).read_bytes()
        self.send_response(200)
        self.send_header("Content-Length", str(len(data)))
        self.end_headers()
        self.wfile.write(data[: len(data) // 2])
        self.wfile.flush()
        return data

    def _drip(self, interval_s: float) -> None:
        data = Path(self.translate_path(self.path)).read_bytes()
        self.send_response(200)
        self.send_header("Content-Length", str(len(data)))
        self.end_headers()
        try:
            for k in range(len(data)):
                self.wfile.write(data[k:k + 1])
                self.wfile.flush()
                self.dripping.set()
                if self.stop.wait(interval_s):  # the pace of the drip; returns at once when the server stops
                    break
        except (BrokenPipeError, ConnectionResetError):  # the client gave up
            pass
        self.close_connection = True

    def _zeros_until_gone(self) -> None:
        block = bytes(64 << 10)
        try:
            while not self.stop.is_set():
                self.wfile.write(block)
        except (BrokenPipeError, ConnectionResetError):  # the client stopped reading and closed
            pass
        self.close_connection = True

    def do_GET(self):
        name = self.path.rsplit("/", 1)[-1]
        self.hits[self.path] = self.hits.get(self.path, 0) + 1
        self.requests.append((self.path, dict(self.headers.items())))
        fault = next((f for key, f in self.faults.items() if name == key or self.path.endswith(key)), None) or ""
        if fault == "404":
            self.send_error(404)
        elif fault == "500" or self._first_n(fault, "500"):
            self.send_error(500)
        elif self._first_n(fault, "stall"):
            self.stop.wait(STALL_LIMIT_S)
            self.close_connection = True
        elif self._first_n(fault, "reset"):
            self.connection.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            os.close(self.connection.detach())  # linger 0: the peer gets a TCP RST, no response
            self.close_connection = True
        elif fault == "truncate":  # announce the full length, send half, drop the connection
            self._send_first_half()
            self.close_connection = True
        elif fault == "drip" or fault.startswith("drip:"):
            self._drip(float(fault.split(":", 1)[1]) if ":" in fault else 0.05)
        elif fault in ("endless", "huge"):
            self.send_response(200)
            if fault == "huge":
                self.send_header("Content-Length", "5000000000")
            self.end_headers()
            self._zeros_until_gone()
        elif fault == "redirect-loop":
            self.send_response(302)
            self.send_header("Location", self.path)
            self.send_header("Content-Length", "0")
            self.end_headers()
        elif fault.startswith("redirect:"):
            self.send_response(302)
            self.send_header("Location", fault[len("redirect:"):])
            self.end_headers()
        else:
            super().do_GET()


@contextlib.contextmanager
def serve(folder: Path, faults: dict[str, str] | None = None):
    """Serve `folder`; yields (the base URL 'http://127.0.0.1:PORT/', the handler class with hits/requests)."""
    handler = type("Handler", (FaultyHandler,), {"faults": dict(faults or {}), "hits": {}, "requests": [],
                                                 "stop": threading.Event(),
                                                 "dripping": threading.Event()})
    server = ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(handler, directory=str(folder)))
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}/", handler
    finally:
        handler.stop.set()
        server.shutdown()
        server.server_close()
