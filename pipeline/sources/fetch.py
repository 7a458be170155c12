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
  is raised at once, naming the file, since every later download would fail the same way.
"""

from __future__ import annotations

import errno
import functools
import hashlib
import os
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
    timeout_s: float = 60.0
    retries: int = 3
    backoff_s: float = 1.0
    allowed_redirect_hosts: tuple[str, ...] = ()
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


class _Missing(Exception):
    pass


class _Retryable(Exception):
    pass


def read_text(url: str, opts: FetchOptions = FetchOptions()) -> str:
    """GET a small text resource (an index page); raises FileNotFoundError / ConnectionError."""
    if url.startswith("file://"):
        p = Path(unquote(urlparse(url).path))
        if p.is_dir():
            p = p / "index.html"
        if not p.exists():
            raise FileNotFoundError(f"{url}: no such file or folder")
        return p.read_text(errors="replace")
    last = None
    for attempt in range(opts.retries + 1):
        try:
            with _client(opts) as client:
                resp = _get_following(client, url, opts, stream=False)
                return resp.text
        except _Missing as exc:
            raise FileNotFoundError(f"{url}: not found (HTTP 404)") from exc
        except _Retryable as exc:
            last = exc
            time.sleep(opts.backoff_s * (2**attempt)) if attempt < opts.retries else None
    raise ConnectionError(f"{url}: {last}")


@functools.cache
def _tls_context() -> ssl.SSLContext:
    """One verifying TLS context per process: loading the CA bundle costs ~20 ms, once per file otherwise."""
    return ssl.create_default_context()


def _client(opts: FetchOptions) -> httpx.Client:
    headers = {"User-Agent": "jitroute"}
    if opts.token:
        headers["Authorization"] = f"Bearer {opts.token}"
    return httpx.Client(timeout=opts.timeout_s, follow_redirects=False, headers=headers, verify=_tls_context())


def _origin(url: str) -> tuple[str, str | None, int | None]:
    u = urlparse(url)
    return u.scheme, u.hostname, u.port or {"http": 80, "https": 443}.get(u.scheme)


def _get_following(client: httpx.Client, url: str, opts: FetchOptions, stream: bool):
    host = urlparse(url).hostname
    origin = _origin(url)
    for _ in range(5):
        try:
            req = client.build_request("GET", url)
            if _origin(url) != origin:  # the token belongs to the first origin only
                req.headers.pop("Authorization", None)
            resp = client.send(req, stream=stream)
        except (httpx.TimeoutException, httpx.TransportError) as exc:
            raise _Retryable(f"{type(exc).__name__}: {exc}") from exc
        if resp.is_redirect:
            target = urljoin(url, resp.headers.get("location", ""))
            resp.close()
            new_host = urlparse(target).hostname
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
    for attempt in range(opts.retries + 1):
        try:
            n, digest = _download(url, part, opts)
            os.replace(part, dest)
            return FetchResult(url, dest, "ok", n, digest)
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
                time.sleep(opts.backoff_s * (2**attempt))
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


def _download(url: str, part: Path, opts: FetchOptions) -> tuple[int, str]:
    h = hashlib.sha256()
    n = 0
    if url.startswith("file://"):
        src = Path(unquote(urlparse(url).path))
        if not src.is_file():
            raise FileNotFoundError(f"{url}: no such file")
        with open(src, "rb") as fin, open(part, "wb") as fout:
            for chunk in iter(lambda: fin.read(CHUNK), b""):
                h.update(chunk)
                fout.write(chunk)
                n += len(chunk)
        return n, h.hexdigest()
    with _client(opts) as client:
        resp = _get_following(client, url, opts, stream=True)
        try:
            expected = resp.headers.get("content-length")
            with open(part, "wb") as fout:
                try:
                    for chunk in resp.iter_bytes(CHUNK):
                        h.update(chunk)
                        fout.write(chunk)
                        n += len(chunk)
                except (httpx.TransportError, httpx.TimeoutException) as exc:
                    raise _Retryable(f"connection broke after {n} bytes ({type(exc).__name__})") from exc
        finally:
            resp.close()
    if expected is not None and int(expected) != n:
        raise _Retryable(f"size mismatch: got {n} bytes, server announced {expected}")
    return n, h.hexdigest()
