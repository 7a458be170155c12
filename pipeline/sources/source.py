"""What the ingest needs to know about one weather source; each source is one module, registered in registry.py."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import xarray as xr

from schemas.cube_variables import provided_by

ROLES = ("wind", "waves", "currents")  # what the cycle assembly does with a source's decoded files


@dataclass(frozen=True)
class Selection:
    """The files a cycle needs from one source's index page."""

    names: list[str]
    n_expected: int  # files a complete cycle has from this source (and the listed files of optional leads)
    gaps_h: list[int] | None = None  # leads no listed file covers (None: not a lead-time product)


@dataclass(frozen=True)
class Source:
    """One source: where its files are listed, which of them a cycle needs, how one file is decoded.

    A file's URL is its index page's URL + its listed name. Forecast files (roles wind, waves) are regridded to the
    routing grid as they are decoded; current analyses are concatenated over time and regridded once by the cycle
    assembly.
    """

    name: str  # also the raw-store folder, the ingest log's `source` and the settings' `<name>_max_bytes`
    role: str  # one of ROLES
    url_setting: str  # the settings.sources field holding the base URL
    index_url: Callable[[str, np.datetime64], str]  # (base URL, cycle) → URL of the HTML index listing the files
    # (listed names, cycle, steps_h, optional_h): the leads a cycle must have, and those it may add (taken when listed)
    select: Callable[..., Selection]
    decode: Callable[[Path], xr.Dataset]  # raises DecodeError for a corrupt file
    primary: bool = True  # a cycle exists when a primary source lists files for it; the others are listed only then
    listing_may_fail: bool = False  # an unreachable index leaves the cycle incomplete instead of failing the listing
    thread_safe_decode: bool = True  # False: decoded in one thread (HDF5 is not thread-safe)
    needs_token: bool = False  # requests carry the Earthdata bearer token

    def __post_init__(self):
        if self.role not in ROLES:
            raise ValueError(f"source {self.name}: role {self.role!r} is not one of {ROLES}")

    @property
    def variables(self) -> tuple[str, ...]:
        """The cube variables this source provides (schemas/cube_variables.py)."""
        return provided_by(self.name)
