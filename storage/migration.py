"""One named step of the warehouse's schema (storage/warehouse.py applies them in order, once each). Its own module so
the schema modules (storage/schema_*.py) that list them do not import the warehouse that imports them."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Migration:
    name: str  # unique, e.g. "ingest_001_log"
    sql: str
