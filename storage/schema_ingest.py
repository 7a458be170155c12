"""Warehouse schema for the ingest tables (named migrations, applied in order)."""

from storage.warehouse import Migration

MIGRATIONS: list[Migration] = []
