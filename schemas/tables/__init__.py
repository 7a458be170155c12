"""Every warehouse table, defined once (schemas.table.Table), by area; `TABLES`: name → Table."""

from schemas.table import Table
from schemas.tables import fleet, ingest, planning, routes, warehouse

TABLES: dict[str, Table] = {t.name: t for area in (warehouse, ingest, fleet, routes, planning) for t in area.TABLES}
