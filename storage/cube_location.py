"""Where a store lives (a local path or an object-store URL with its fsspec options), and the errors of a cube.

Kept apart from storage/cube.py (xarray, dask) so a routing worker that only reads windows (cube_window.py)
imports neither.
"""

from __future__ import annotations

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

        options = self.options
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

        fs, root = fsspec.core.url_to_fs(self.url, **self.options)
        fs.invalidate_cache()
        return fs.exists(f"{root}/{key}")

    def read_text(self, key: str) -> str:
        if self.local is not None:
            return (self.local / key).read_text()
        import fsspec

        fs, root = fsspec.core.url_to_fs(self.url, **self.options)
        return fs.cat_file(f"{root}/{key}").decode()


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
