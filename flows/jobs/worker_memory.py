"""A worker process's memory: what it frees after each voyage, and LLVM's code pages it drops.

glibc keeps memory a voyage freed in its arenas until `malloc_trim`; and numba's start and kernel loads run code
spread over most of `libllvmlite.so` (about 70 MB resident) that a worker routing with cached kernels never runs
again. Both are given back here, by the routing worker (flows/jobs/route_worker.py); its picture process
(flows/jobs/picture_process.py), which never loads numba, gives back the memory its drawings freed.
"""

from __future__ import annotations

import ctypes
import functools
from pathlib import Path


@functools.cache
def _malloc_trim():
    try:
        return ctypes.CDLL("libc.so.6").malloc_trim
    except (OSError, AttributeError):  # not glibc: nothing to do
        return None


def release_free_memory() -> None:
    """Give the memory freed by a voyage back to the system (glibc's malloc_trim, about a millisecond). Without it
    a worker's resident memory creeps up voyage after voyage (freed weather windows and plots stay in malloc's
    arenas), unless the worker was started by a dask nanny, which sets MALLOC_TRIM_THRESHOLD_. Then drop the
    resident code pages of LLVM (`drop_code_pages`)."""
    trim = _malloc_trim()
    if trim is not None:
        trim(0)
    drop_code_pages()


CODE_PAGES_OF = ("libllvmlite",)  # shared libraries whose code is mostly run once, when numba starts and loads kernels
MADV_DONTNEED = 4


@functools.cache
def _madvise():
    try:
        madvise = ctypes.CDLL("libc.so.6", use_errno=True).madvise
    except (OSError, AttributeError):  # not glibc/Linux: nothing to do
        return None
    madvise.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int]
    return madvise


def drop_code_pages_after_kernel_loads() -> bool:
    """From now on, drop LLVM's code pages (`drop_code_pages`) after each numba kernel this process loads from the
    cache. A worker loads about 27 kernels in its first voyage, each load running LLVM code that is not run again;
    dropped as it goes, that code never piles up, which lowers the worker's peak by about 35 MB. Returns False where
    numba's cache has no `load_overload` to follow (a numba that changed it: nothing is done)."""
    from numba.core import caching

    load = getattr(caching.Cache, "load_overload", None)
    if load is None:
        return False
    if getattr(load, "drops_code_pages", False):
        return True

    @functools.wraps(load)
    def load_overload(self, *args, **kwargs):
        try:
            return load(self, *args, **kwargs)
        finally:
            drop_code_pages()

    load_overload.drops_code_pages = True  # type: ignore[attr-defined]  # the mark that it is installed
    caching.Cache.load_overload = load_overload
    return True


def drop_code_pages(libraries: tuple[str, ...] = CODE_PAGES_OF) -> int:
    """Unmap from this process the resident pages of the executable code of `libraries` (their read-only `r-xp`
    mappings, madvise MADV_DONTNEED); returns the bytes of the mappings so advised.

    LLVM's start-up (numba's import and its first kernel load) runs code spread over most of `libllvmlite.so`, and
    those pages stay counted in the worker's resident memory (about 70 MB) although a worker routing with cached
    kernels never runs them again. Code pages are never written, so a page that is needed again is read back from
    the page cache (a minor fault); the file's pages stay in the page cache, shared by every process that maps it."""
    madvise = _madvise()
    if madvise is None:
        return 0
    try:
        maps = Path("/proc/self/maps").read_text().splitlines()
    except OSError:  # no /proc: nothing to do
        return 0
    dropped = 0
    for line in maps:
        fields = line.split(maxsplit=5)
        if len(fields) == 6 and fields[1] == "r-xp" and any(name in fields[5] for name in libraries):
            start, end = (int(x, 16) for x in fields[0].split("-"))
            if madvise(start, end - start, MADV_DONTNEED) == 0:
                dropped += end - start
    return dropped
