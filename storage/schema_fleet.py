"""Warehouse schema for the fleet tables (named migrations, applied in order)."""

from storage.warehouse import Migration

MIGRATIONS: list[Migration] = []
