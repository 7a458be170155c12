"""Download one file over `https://`, `http://` or `file://`, the same way for all three.

- retries with exponential backoff on 5xx, timeouts and connection errors; 404 is `missing`
  at once (no retries);
- the body is written to `<name>.<pid>.<thread>.part` (one per writer, so two ingests of the
  same cycle never write into one file) and renamed only when complete and, when the server
  sent Content-Length, of that size; parts left by killed processes are removed;
- sha256 is computed while writing; a file already present with the expected checksum is
  not downloaded again (`skipped`);
- a redirect to another host is refused unless that host is allowed;
- a bearer token (Earthdata) is sent as a header to the URL's own origin only (never after a
  redirect to another host) and never appears in a message or a repr;
- a full or read-only data root (ENOSPC, EDQUOT, EFBIG, EROFS) is not retried: `LocalWriteError`
  is raised at once, naming the file, since every later download would fail the same way;
- `http_timeout_s` bounds each read only, so a server dripping a byte every few seconds would keep a
  download alive for months: a file also has a total deadline (`deadline_s`, all attempts together) and
  must arrive at `min_rate_bps` on average over every `rate_window_s`, else it is `missing` with the reason;
- a file may not exceed `max_bytes` (per source): an announced Content-Length above it is refused before
  any byte is written, a body that grows past it is stopped; index pages are capped at `max_index_bytes`;
- `cancel_downloads()` (called on SIGTERM) stops every download in this process at once: their sockets are
  shut down, their `.part` files removed, and `DownloadCancelled` is raised in each.
"""

from __future__ import annotations

import errno
import functools
import hashlib
import os
import socket
import ssl
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import unquote, urljoin, urlparse

import httpx

CHUNK = 1 << 20


@dataclass(frozen=True)
class FetchResult:
    url: str
    path: Path | None
    status: str  # ok | skipped | missing | error
    bytes: int = 0
    sha256: str | None = None
    error: str | None = None


@dataclass(frozen=True)
class FetchOptions:
    timeout_s: float = 60.0  # per connect / read
    retries: int = 3
    backoff_s: float = 1.0
    allowed_redirect_hosts: tuple[str, ...] = ()
    deadline_s: float = 1800.0  # one file, every attempt included
    min_rate_bps: float = 4096.0  # bytes per second, averaged over each rate window
    rate_window_s: float = 30.0
    max_bytes: int | None = None  # per file; None: no cap
    max_index_bytes: int = 16 << 20
    token: str | None = field(default=None, repr=False)  # never in a repr, a log line or a message


LOCAL_WRITE_ERRNOS = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS)


class LocalWriteError(OSError):
    """The data root cannot take the download (full, over quota, file too large, read-only)."""


def sha256_of(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(CHUNK), b""):
            h.update(chunk)
    return h.hexdigest()


class DownloadCancelled(Exception):
    """The process is stopping (SIGTERM): downloads were cancelled and their part files removed."""


class _Missing(Exception):
    pass


class _Refused(Exception):
    """Give up on this file at once, no retry (too large, deadline passed); the message says why."""


_CANCEL = threading.Event()
_ACTIVE_LOCK = threading.Lock()
_ACTIVE_PARTS: set[Path] = set()
_ACTIVE_SOCKETS: set[socket.socket] = set()


def cancel_downloads() -> list[Path]:
    """Stop every download of this process now (SIGTERM): shut their sockets down so blocked reads return,
    remove their part files; the downloading threads then raise DownloadCancelled. Returns the parts removed."""
    _CANCEL.set()
    with _ACTIVE_LOCK:
        socks, parts = list(_ACTIVE_SOCKETS), list(_ACTIVE_PARTS)
    for sock in socks:
        try:
            sock.shutdown(socket.SHUT_RDWR)
        except OSError:  # already closed
            pass
    for part in parts:
        part.unlink(missing_ok=True)
    return parts


def _check_cancelled() -> None:
    if _CANCEL.is_set():
        raise DownloadCancelled("downloads cancelled: the process is stopping")


class _Watch:
    """Deadline, minimum rate and size cap of one body being received."""

    def __init__(self, url: str, opts: FetchOptions, deadline: float, cap: int | None, what: str = "file"):
        self.url, self.opts, self.deadline, self.cap, self.what = url, opts, deadline, cap, what
        self.n = 0
        self.window_start = time.monotonic()
        self.window_bytes = 0

    def announced(self, content_length: str | None) -> None:
        if self.cap is not None and content_length is not None and content_length.isdigit() and int(content_length) > self.cap:
            raise _Refused(f"{self.url}: the server announces {int(content_length)} bytes, above the cap of {self.cap} "
                           f"bytes for this {self.what}; not downloaded (raise the source's max_bytes setting if it is real)")

    def got(self, k: int) -> None:
        _check_cancelled()
        self.n += k
        self.window_bytes += k
        if self.cap is not None and self.n > self.cap:
            raise _Refused(f"{self.url}: the body grew past the cap of {self.cap} bytes for this {self.what}; stopped")
        now = time.monotonic()
        if now > self.deadline:
            raise _Refused(f"{self.url}: not complete within the deadline of {self.opts.deadline_s:g} s "
                           f"({self.n} bytes received); stopped")
        elapsed = now - self.window_start
        if elapsed >= self.opts.rate_window_s:
            rate = self.window_bytes / elapsed
            if rate < self.opts.min_rate_bps:
                raise _Retryable(f"too slow: {rate:.0f} B/s over the last {elapsed:.0f} s, below the minimum of "
                                 f"{self.opts.min_rate_bps:g} B/s ({self.n} bytes received)")
            self.window_start, self.window_bytes = now, 0


def _stream_body(resp, watch: _Watch, sink) -> None:
    """Feed the response body to `sink(chunk)` as it arrives, under `watch`; the socket can be shut down by
    `cancel_downloads` meanwhile."""
    sock = None
    stream = resp.extensions.get("network_stream")
    if stream is not None:
        sock = stream.get_extra_info("socket")
    if sock is not None:
        with _ACTIVE_LOCK:
            _ACTIVE_SOCKETS.add(sock)
    try:
        watch.announced(resp.headers.get("content-length"))
        try:
            for chunk in resp.iter_bytes():  # as received: a drip returns control every few bytes
                watch.got(len(chunk))
                sink(chunk)
        except (httpx.TransportError, httpx.TimeoutException) as exc:
            _check_cancelled()
            raise _Retryable(f"connection broke after {watch.n} bytes ({type(exc).__name__})") from exc
    finally:
        if sock is not None:
            with _ACTIVE_LOCK:
                _ACTIVE_SOCKETS.discard(sock)


class _Retryable(Exception):
    pass


def read_text(url: str, opts: FetchOptions = FetchOptions()) -> str:
    """GET a small text resource (an index page), at most `opts.max_index_bytes`, under the same deadline and
    minimum rate as files; raises FileNotFoundError / ConnectionError (also for a page too large or too slow)."""
    if url.startswith("file://"):
        p = Path(unquote(urlparse(url).path))
        if p.is_dir():
            p = p / "index.html"
        if not p.exists():
            raise FileNotFoundError(f"{url}: no such file or folder")
        if p.stat().st_size > opts.max_index_bytes:
            raise ConnectionError(f"{url}: index of {p.stat().st_size} bytes, above the cap of {opts.max_index_bytes} bytes")
        return p.read_text(errors="replace")
    last = None
    deadline = time.monotonic() + opts.deadline_s
    for attempt in range(opts.retries + 1):
        _check_cancelled()
        try:
            with _client(opts) as client:
                resp = _get_following(client, url, opts, stream=True)
                body = bytearray()
                try:
                    _stream_body(resp, _Watch(url, opts, deadline, opts.max_index_bytes, "index page"), body.extend)
                finally:
                    resp.close()
                return bytes(body).decode(resp.charset_encoding or "utf-8", errors="replace")
        except _Missing as exc:
            raise FileNotFoundError(f"{url}: not found (HTTP 404)") from exc
        except (_Refused, PermissionError) as exc:
            raise ConnectionError(str(exc)) from exc
        except _Retryable as exc:
            last = exc
            if attempt < opts.retries:
                _pause(opts.backoff_s * (2**attempt), deadline)
    raise ConnectionError(f"{url}: {last}")


def _pause(seconds: float, deadline: float) -> None:
    """Back off before a retry, but never past the deadline, and wake at once when downloads are cancelled."""
    _CANCEL.wait(max(0.0, min(seconds, deadline - time.monotonic())))
    _check_cancelled()


@functools.cache
def _tls_context() -> ssl.SSLContext:
    """One verifying TLS context per process: loading the CA bundle costs ~20 ms, once per file otherwise."""
    return ssl.create_default_context()


def _client(opts: FetchOptions) -> httpx.Client:
    headers = {"User-Agent": "jitroute"}
    if opts.token:
        headers["Authorization"] = f"Bearer {opts.token}"
    return httpx.Client(timeout=opts.timeout_s, follow_redirects=False, headers=headers, verify=_tls_context())


def token_may_go_to(url: str) -> bool:
    """A bearer token may be sent to `url` only over https, or to this machine (a loopback mirror): never in clear
    text across a network."""
    import ipaddress

    u = urlparse(url)
    if u.scheme == "https":
        return True
    if u.scheme != "http" or not u.hostname:
        return False
    if u.hostname == "localhost":
        return True
    try:
        return ipaddress.ip_address(u.hostname).is_loopback
    except ValueError:
        return False


def _origin(url: str) -> tuple[str, str | None, int | None]:
    u = urlparse(url)
    return u.scheme, u.hostname, u.port or {"http": 80, "https": 443}.get(u.scheme)


def _get_following(client: httpx.Client, url: str, opts: FetchOptions, stream: bool):
    host = urlparse(url).hostname
    origin = _origin(url)
    for _ in range(5):
        try:
            req = client.build_request("GET", url)
            if _origin(url) != origin or not token_may_go_to(url):  # the first origin only, never in clear text
                req.headers.pop("Authorization", None)
            resp = client.send(req, stream=stream)
        except (httpx.TimeoutException, httpx.TransportError) as exc:
            raise _Retryable(f"{type(exc).__name__}: {exc}") from exc
        if resp.is_redirect:
            target = urljoin(url, resp.headers.get("location", ""))
            resp.close()
            new_host = urlparse(target).hostname
            scheme = urlparse(target).scheme
            if scheme not in ("http", "https"):
                raise PermissionError(f"{url}: redirect to a {scheme or 'relative'}: URL refused (only http and https "
                                      "redirects are followed; fix the mirror or point jitroute at the final URL)")
            if new_host != host and new_host not in opts.allowed_redirect_hosts:
                raise PermissionError(f"{url}: redirect to another host {new_host!r} refused (allow it with JITROUTE_ALLOWED_REDIRECT_HOSTS)")
            url = target
            continue
        if resp.status_code == 404:
            resp.close()
            raise _Missing()
        if resp.status_code >= 500 or resp.status_code == 429:
            resp.close()
            raise _Retryable(f"HTTP {resp.status_code}")
        if resp.status_code >= 400:
            resp.close()
            raise PermissionError(f"{url}: HTTP {resp.status_code}")
        return resp
    raise PermissionError(f"{url}: too many redirects")


def fetch(url: str, dest: Path, opts: FetchOptions = FetchOptions(), expected_sha256: str | None = None) -> FetchResult:
    """Download `url` to `dest` (atomic rename). Never raises for network or HTTP problems."""
    dest = Path(dest)
    if expected_sha256 and dest.exists() and sha256_of(dest) == expected_sha256:
        return FetchResult(url, dest, "skipped", dest.stat().st_size, expected_sha256)
    dest.parent.mkdir(parents=True, exist_ok=True)
    _remove_dead_parts(dest)
    part = dest.with_name(f"{dest.name}.{os.getpid()}.{threading.get_ident()}.part")
    last_error = "unknown error"
    deadline = time.monotonic() + opts.deadline_s
    for attempt in range(opts.retries + 1):
        _check_cancelled()
        if time.monotonic() >= deadline:
            return FetchResult(url, None, "missing", error=f"{last_error}; no further attempt: the deadline of "
                                                            f"{opts.deadline_s:g} s for this file has passed")
        with _ACTIVE_LOCK:
            _ACTIVE_PARTS.add(part)
        try:
            n, digest = _download(url, part, opts, deadline)
            os.replace(part, dest)
            return FetchResult(url, dest, "ok", n, digest)
        except DownloadCancelled:
            part.unlink(missing_ok=True)
            raise
        except _Refused as exc:
            part.unlink(missing_ok=True)
            return FetchResult(url, None, "missing", error=str(exc))
        except _Missing:
            part.unlink(missing_ok=True)
            return FetchResult(url, None, "missing", error=f"{url}: not found (HTTP 404)")
        except FileNotFoundError as exc:
            part.unlink(missing_ok=True)
            return FetchResult(url, None, "missing", error=str(exc))
        except PermissionError as exc:
            part.unlink(missing_ok=True)
            return FetchResult(url, None, "error", error=str(exc))
        except (_Retryable, OSError) as exc:
            part.unlink(missing_ok=True)
            if isinstance(exc, OSError) and exc.errno in LOCAL_WRITE_ERRNOS:
                raise LocalWriteError(exc.errno, f"cannot write {dest} ({os.strerror(exc.errno)}): "
                                                 "free space on the data root (or make it writable) and re-run") from exc
            last_error = f"{url}: {exc}"
            if attempt < opts.retries:
                _pause(opts.backoff_s * (2**attempt), deadline)
        finally:
            with _ACTIVE_LOCK:
                _ACTIVE_PARTS.discard(part)
    return FetchResult(url, None, "missing", error=f"{last_error} (after {opts.retries + 1} attempts)")


def _remove_dead_parts(dest: Path) -> None:
    """Delete `<dest>.<pid>.<thread>.part` files whose writing process no longer exists (it was killed)."""
    for p in dest.parent.glob(dest.name + ".*.part"):
        pid = p.name[len(dest.name) + 1:].split(".", 1)[0]
        if not pid.isdigit() or int(pid) == os.getpid():
            continue
        try:
            os.kill(int(pid), 0)
        except ProcessLookupError:
            p.unlink(missing_ok=True)
        except PermissionError:  # alive, owned by someone else
            pass


def _download(url: str, part: Path, opts: FetchOptions, deadline: float) -> tuple[int, str]:
    h = hashlib.sha256()
    n = 0
    if url.startswith("file://"):
        src = Path(unquote(urlparse(url).path))
        if not src.is_file():
            raise FileNotFoundError(f"{url}: no such file")
        watch = _Watch(url, opts, deadline, opts.max_bytes)
        watch.announced(str(src.stat().st_size))
        with open(src, "rb") as fin, open(part, "wb") as fout:
            for chunk in iter(lambda: fin.read(CHUNK), b""):
                watch.got(len(chunk))
                h.update(chunk)
                fout.write(chunk)
                n += len(chunk)
        return n, h.hexdigest()
    with _client(opts) as client:
        resp = _get_following(client, url, opts, stream=True)
        try:
            expected = resp.headers.get("content-length")
            with open(part, "wb") as fout:
                def sink(chunk: bytes) -> None:
                    h.update(chunk)
                    fout.write(chunk)

                watch = _Watch(url, opts, deadline, opts.max_bytes)
                _stream_body(resp, watch, sink)
                n = watch.n
        finally:
            resp.close()
    if expected is not None and int(expected) != n:
        raise _Retryable(f"size mismatch: got {n} bytes, server announced {expected}")
    return n, h.hexdigest()
