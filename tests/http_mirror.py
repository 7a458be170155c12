"""A loopback HTTP server (127.0.0.1, ephemeral port) serving a folder, with fault injection."""

from __future__ import annotations

import contextlib
import functools
import threading
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path


class FaultyHandler(SimpleHTTPRequestHandler):
    faults: dict[str, str] = {}
    hits: dict[str, int] = {}

    def log_message(self, *args):  # keep test output clean
        pass

    def do_GET(self):
        name = self.path.rsplit("/", 1)[-1]
        self.hits[self.path] = self.hits.get(self.path, 0) + 1
        fault = next((f for key, f in self.faults.items() if name == key or self.path.endswith(key)), None)
        if fault == "404":
            self.send_error(404)
        elif fault == "500":
            self.send_error(500)
        elif fault and fault.startswith("500x"):  # fail the first N requests, then serve
            if self.hits[self.path] <= int(fault[4:]):
                self.send_error(500)
            else:
                super().do_GET()
        elif fault == "truncate":  # announce the full length, send half, drop the connection
            path = Path(self.translate_path(self.path))
            data = path.read_bytes()
            self.send_response(200)
            self.send_header("Content-Length", str(len(data)))
            self.end_headers()
            self.wfile.write(data[: len(data) // 2])
            self.wfile.flush()
            self.close_connection = True
        elif fault and fault.startswith("redirect:"):
            self.send_response(302)
            self.send_header("Location", fault[len("redirect:"):])
            self.end_headers()
        else:
            super().do_GET()


@contextlib.contextmanager
def serve(folder: Path, faults: dict[str, str] | None = None):
    """Serve `folder`; yields the base URL 'http://127.0.0.1:PORT/'."""
    handler = type("Handler", (FaultyHandler,), {"faults": dict(faults or {}), "hits": {}})
    server = ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(handler, directory=str(folder)))
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}/", handler
    finally:
        server.shutdown()
        server.server_close()
