"""OSCAR surface currents: file naming, choice of the files a forecast cycle needs, and the source entry.

Names: v1 `oscar_vel{N}.nc[.gz]` (N = days since 1992-10-05 of the analysis), v1 yearly
`oscar_vel{YYYY}.nc`, v2 `oscar_currents_{final|interim|nrt}_YYYYMMDD.nc`. When several v2
kinds exist for one day, final beats interim beats nrt.
"""

from __future__ import annotations

from collections.abc import Sequence

import re
from dataclasses import dataclass

import numpy as np

from pipeline.decode.oscar import decode_oscar
from pipeline.sources.source import Selection, Source

V1_RE = re.compile(r"^oscar_vel(?P<n>\d{1,5})\.nc(?P<gz>\.gz)?$")
V2_RE = re.compile(r"^oscar_currents_(?P<kind>final|interim|nrt)_(?P<date>\d{8})\.nc$")
V1_EPOCH_DAY = np.datetime64("1992-10-05", "D")
KIND_RANK = {"final": 0, "interim": 1, "nrt": 2, "v1": 3, "year": 4}


@dataclass(frozen=True)
class OscarFile:
    name: str
    time: np.datetime64  # analysis time (first time in the file for yearly files)
    kind: str  # final | interim | nrt | v1 | year
    gz: bool = False


def parse_oscar_name(name: str) -> OscarFile | None:
    m = V2_RE.match(name)
    if m:
        d = m["date"]
        return OscarFile(name, np.datetime64(f"{d[:4]}-{d[4:6]}-{d[6:]}", "ns"), m["kind"])
    m = V1_RE.match(name)
    if m:
        n = int(m["n"])
        if 1992 <= n <= 2100 and len(m["n"]) == 4 and not m["gz"] and n > 1991:
            # four digits in the year range: a yearly file
            return OscarFile(name, np.datetime64(f"{n}-01-01", "ns"), "year")
        return OscarFile(name, np.datetime64(V1_EPOCH_DAY + np.timedelta64(n, "D"), "ns"), "v1", bool(m["gz"]))
    return None


def files_for_window(names: list[str], start: np.datetime64, end: np.datetime64) -> list[OscarFile]:
    """The latest analysis at or before `start` plus every analysis in (start, end]; one per time."""
    files = [f for f in (parse_oscar_name(n) for n in names) if f is not None and f.kind != "year"]
    best: dict[np.datetime64, OscarFile] = {}
    for f in files:
        if f.time not in best or KIND_RANK[f.kind] < KIND_RANK[best[f.time].kind]:
            best[f.time] = f
    times = sorted(best)
    start, end = np.datetime64(start, "ns"), np.datetime64(end, "ns")
    before = [t for t in times if t <= start]
    chosen = ([before[-1]] if before else []) + [t for t in times if start < t <= end]
    return [best[t] for t in chosen]


def index_url(base_url: str, cycle: np.datetime64) -> str:
    """OSCAR lists every analysis in one folder."""
    return base_url.rstrip("/") + "/"


def select(names: list[str], cycle: np.datetime64, steps_h: list[int], optional_h: Sequence[int] = ()) -> Selection:
    """The analyses covering the valid times every cycle has (latest at or before the cycle, then every later one);
    the optional leads past them (the 00/12 UTC cycles' to 264 h) get the latest of these persisted, as any lead
    past the newest analysis does."""
    files = files_for_window(names, cycle, cycle + np.timedelta64(max(steps_h), "h"))
    return Selection([f.name for f in files], len(files))


# Currents are worth little alone (listed only when the forecast is) and wind and waves are still worth ingesting
# without them (an unreachable OSCAR leaves the cycle incomplete).
OSCAR = Source("OSCAR", "currents", "oscar_url", index_url, select, decode_oscar, primary=False,
               listing_may_fail=True, thread_safe_decode=False, needs_token=True)
