"""The weather sources the ingest lists, fetches and decodes, in listing order. A new source is one module
defining a `Source` (pipeline/sources/source.py), added here."""

from __future__ import annotations

from pipeline.sources.gsm import GSM
from pipeline.sources.gwm import GWM
from pipeline.sources.oscar import OSCAR
from pipeline.sources.source import Source

SOURCES: tuple[Source, ...] = (GSM, GWM, OSCAR)
BY_NAME = {s.name: s for s in SOURCES}
