"""The warehouse's lowest layer: the all-or-nothing block and the error for a damaged file. Its own module so the
modules whose checks every writer connection runs (storage/route_history.py) need not import storage/warehouse.py,
which calls them; everything else reaches both as `warehouse.transaction` and `warehouse.WarehouseCorruptError`."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import duckdb


class WarehouseCorruptError(RuntimeError):
    """The warehouse file is damaged; the message names it and how to recover from the snapshot."""


@contextlib.contextmanager
def transaction(con: duckdb.DuckDBPyConnection) -> Iterator[duckdb.DuckDBPyConnection]:
    """BEGIN … COMMIT on `con`; when the block (or the COMMIT) fails, ROLLBACK and re-raise: all or nothing."""
    con.execute("BEGIN TRANSACTION")
    try:
        yield con
        con.execute("COMMIT")
    except Exception:
        try:
            con.execute("ROLLBACK")
        except duckdb.TransactionException:  # a failed COMMIT has ended the transaction (rolled back): say why it failed
            pass
        raise
