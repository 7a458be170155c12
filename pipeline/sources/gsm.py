"""JMA GSM (global spectral model): 10 m wind, one GRIB2 file per lead time, listed in the RISH day folders."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from pipeline.decode.jma import decode_gsm
from pipeline.sources import rish
from pipeline.sources.source import Selection, Source


def select(names: list[str], cycle: np.datetime64, steps_h: list[int], optional_h: Sequence[int] = ()) -> Selection:
    """The cycle's GSM files at the lead times it must have (`steps_h`, a gap when not listed) and at the optional
    ones it lists (`optional_h`: the 00/12 UTC cycles' leads past 132 h)."""
    files = [f for f in rish.prefer_resolution(rish.files_for_cycle(names, cycle)) if f.model == "GSM"]
    extra = [f.name for f in files if f.first_lead_h in optional_h and f.first_lead_h not in steps_h]
    return Selection([f.name for f in files if f.first_lead_h in steps_h] + extra, len(steps_h) + len(extra),
                     rish.coverage(files, steps_h)["GSM"])


GSM = Source("GSM", "wind", "rish_url", rish.day_folder_url, select, decode_gsm)
