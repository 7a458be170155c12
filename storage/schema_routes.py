"""Warehouse schema for the routes tables (named migrations, applied in order)."""

from storage.warehouse import Migration

MIGRATIONS: list[Migration] = []
