"""A local S3 server (moto, as the test suite's) that counts what it serves, for benches: requests and response
bytes by method and by part of the object root (`cubes`, `exports`, other).

    python bench/s3_counting_server.py PORT

`GET /__counts` returns the counts as JSON, `POST /__reset` zeroes them (neither reaches moto).
"""

from __future__ import annotations

import json
import sys
import threading
from collections import defaultdict


def counting(app):
    counts: dict = defaultdict(lambda: {"requests": 0, "bytes": 0})
    lock = threading.Lock()

    def part(path: str) -> str:
        return "cubes" if "/cubes/" in path else "exports" if "/exports/" in path else "other"

    def wrapped(environ, start_response):
        path, method = environ.get("PATH_INFO", ""), environ.get("REQUEST_METHOD", "")
        if path == "/__counts":
            with lock:
                body = json.dumps(dict(counts)).encode()
            start_response("200 OK", [("Content-Type", "application/json"), ("Content-Length", str(len(body)))])
            return [body]
        if path == "/__reset":
            with lock:
                counts.clear()
            start_response("200 OK", [("Content-Length", "0")])
            return [b""]
        return served(f"{method} {part(path)}", app(environ, start_response))

    def served(key: str, body):
        # the request is counted as it arrives, before its body is sent: a client that has its answer is sure to find
        # it counted (counted after the body, a reset just after the answer could come before the count, and the
        # request would be counted in the next interval)
        with lock:
            counts[key]["requests"] += 1
        n = 0
        try:
            for chunk in body:
                n += len(chunk)
                yield chunk
        finally:
            if hasattr(body, "close"):
                body.close()
            with lock:
                counts[key]["bytes"] += n

    return wrapped


def main() -> None:
    from moto.moto_server.werkzeug_app import DomainDispatcherApplication, MotoRequestHandler, create_backend_app
    from werkzeug.serving import make_server

    port = int(sys.argv[1])
    server = make_server("127.0.0.1", port, counting(DomainDispatcherApplication(create_backend_app)), True,
                         request_handler=MotoRequestHandler)
    server.serve_forever()


if __name__ == "__main__":
    main()
