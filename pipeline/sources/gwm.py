"""JMA GWM (global wave model): significant height, direction and period, a few GRIB2 files each covering a
range of lead times, listed in the RISH day folders (0.25° preferred over 0.5° for the same range)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from pipeline.decode.jma import decode_gwm
from pipeline.sources import rish
from pipeline.sources.source import Selection, Source

FILES_PER_CYCLE = 2  # the lead ranges JMA splits a GWM run into


def select(names: list[str], cycle: np.datetime64, steps_h: list[int], optional_h: Sequence[int] = ()) -> Selection:
    """Every GWM file of the cycle; a complete cycle has FILES_PER_CYCLE covering `steps_h`, and a listed file of
    only optional leads (the 00/12 UTC cycles' FD0600-1100) is expected too."""
    files = [f for f in rish.prefer_resolution(rish.files_for_cycle(names, cycle)) if f.model == "GWM"]
    last = max(steps_h) if len(steps_h) else -1
    extra = sum(f.first_lead_h > last for f in files)
    return Selection([f.name for f in files], FILES_PER_CYCLE + extra, rish.coverage(files, steps_h)["GWM"])


GWM = Source("GWM", "waves", "rish_url", rish.day_folder_url, select, decode_gwm)
