"""Warehouse tables: the warehouse's own bookkeeping."""

from schemas.table import Column, Table

SCHEMA_MIGRATIONS = Table('schema_migrations', 'schema changes applied to this warehouse, by name', (
    Column('name', 'VARCHAR', None, 'migration name'),
    Column('applied_at', 'TIMESTAMP', 'UTC', 'when it was applied (UTC)'),
), primary_key=('name',))

TABLES = (SCHEMA_MIGRATIONS,)
