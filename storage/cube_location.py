"""Where a store lives (a local path or an object-store URL with its fsspec options), and the errors of a cube.

Kept apart from storage/cube.py (xarray, dask) so a routing worker that only reads windows (cube_window.py)
imports neither.
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import NamedTuple


class CubeError(RuntimeError):
    pass


class Location(NamedTuple):
    """Where a store lives: `url` as given (a local path, `file://…` or an object-store URL such as `s3://bucket/…`),
    the fsspec `options` for a URL (e.g. {"endpoint_url": …, "key": …, "secret": …} for S3), and `local`, the
    local path (None on an object store)."""

    url: str
    options: dict
    local: Path | None

    @property
    def name(self) -> str:
        return self.url.rstrip("/").rsplit("/", 1)[-1]

    def zarr_store(self, read_only: bool = False):
        """What zarr and xarray open: the local path, or an fsspec store for a URL."""
        if self.local is not None:
            return str(self.local)
        from zarr.storage import FsspecStore

        options = fs_options(self.url, self.options)
        if self.url.startswith(("s3://", "s3a://")):
            # s3fs asks every whole-object read for its size first (a HEAD) to split large objects into
            # concurrent ranges; cube chunks are small, so one GET per chunk, half the requests
            options = {"max_concurrency": 1, **options}
        return FsspecStore.from_url(self.url, storage_options=options, read_only=read_only)

    def has(self, key: str) -> bool:
        """Whether the object `key` (e.g. "zarr.json") exists in the store."""
        if self.local is not None:
            return (self.local / key).exists()
        import fsspec

        fs, root = fsspec.core.url_to_fs(self.url, **fs_options(self.url, self.options))
        fs.invalidate_cache()
        return fs.exists(f"{root}/{key}")

    def read_text(self, key: str) -> str:
        if self.local is not None:
            return (self.local / key).read_text()
        import fsspec

        fs, root = fsspec.core.url_to_fs(self.url, **fs_options(self.url, self.options))
        return fs.cat_file(f"{root}/{key}").decode()


S3_SCHEMES = ("s3://", "s3a://")


@functools.cache
def shared_s3_session():
    """The process's one aiobotocore session, given to every S3 filesystem it opens (fs_options): botocore loads
    the S3 service model (about 16 MB resident) once per session, and a routing worker opens two filesystems
    (the cube's reads, asynchronous, and its export staging). Pickled as a reference to this function, so a
    filesystem sent to another process gets that process's session."""
    from aiobotocore.session import AioSession

    class _SharedSession(AioSession):
        def __reduce__(self):
            return shared_s3_session, ()

    return _SharedSession()


def fs_options(url: str, options: dict | None) -> dict:
    """The fsspec options to open `url` with: `options`, plus the shared session for an S3 URL."""
    options = dict(options or {})
    if str(url).startswith(S3_SCHEMES) and "session" not in options:
        options["session"] = shared_s3_session()
    return options


def locate(store, storage_options: dict | None = None) -> Location:
    """The Location of `store`: a local path (str or Path), `file://…`, or a URL with its fsspec options."""
    if isinstance(store, Location):
        return store
    url = str(store)
    if url.startswith("file://"):
        return Location(url, {}, Path(url.removeprefix("file://")))
    if "://" in url:
        return Location(url.rstrip("/"), dict(storage_options or {}), None)
    return Location(url, {}, Path(url))


class CorruptChunkError(CubeError):
    """A chunk file of the cube cannot be decoded (damaged on disk); the message names it and the fix."""



DECODE_ERRORS = (RuntimeError, ValueError, OSError, KeyError)  # what zarr/numcodecs raise for a damaged chunk
