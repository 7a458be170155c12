"""Damaged or busy stores end a command with one line naming the file and the recovery, never a traceback.

Their messages (`storage.cube.CubeError`, `storage.warehouse.WarehouseCorruptError`, `WarehouseBusyError`)
already say everything; a traceback would bury them. Prefect logs a flow's exception with its traceback
before re-raising it, so the traceback of these errors is also dropped from Prefect's run loggers (the log
line with the message stays).
"""

from __future__ import annotations

import logging
import sys


def is_store_error(exc: BaseException | None) -> bool:
    """`exc` (or an exception it was raised from) is a damaged/busy cube or warehouse."""
    cube_mod, wh_mod = sys.modules.get("storage.cube"), sys.modules.get("storage.warehouse")
    kinds = ((cube_mod.CubeError,) if cube_mod else ()) + ((wh_mod.WarehouseCorruptError, wh_mod.WarehouseBusyError) if wh_mod else ())
    seen = 0
    while exc is not None and seen < 10:
        if kinds and isinstance(exc, kinds):
            return True
        exc, seen = exc.__cause__ or exc.__context__, seen + 1
    return False


class _NoStoreTracebacks(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        if record.exc_info and is_store_error(record.exc_info[1]):
            record.exc_info, record.exc_text = None, None
        return True


def quiet_store_tracebacks() -> None:
    for name in ("prefect.flow_runs", "prefect.task_runs"):
        logging.getLogger(name).addFilter(_NoStoreTracebacks())
