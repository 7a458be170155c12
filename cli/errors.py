"""Errors that mean "the input or the data root is not as it must be": one line naming what and what to do, exit 2.

Their messages (bad dates or cycles, unknown vessels or voyages, a damaged or busy cube or warehouse, …)
already say everything; a traceback would bury them. Prefect logs a flow's exception with its traceback
before re-raising it, so the traceback of these errors is also dropped from Prefect's run loggers (the log
line with the message stays).
"""

from __future__ import annotations

import logging

# By class name (any base class counts), so this module imports none of the layers below.
USER_ERRORS = {"CycleError", "UnknownVesselError", "FleetRunError", "NoonFileError", "FileNotFoundError",
               "WarehouseBusyError", "WarehouseCorruptError", "WarehouseWriteError", "RoutingInputError",
               "VoyageGeometryError", "ServeError", "TimeoutError", "CubeError", "ExportPathError", "WeatherMapError",
               "FleetFileError", "SettingsError", "UnknownSolverError", "PlanningInputError", "NoSeaRoute"}


# Errors that are not the user's input but the state of the data, one line each with their own exit code:
# weather too old (or none) to route on.
EXIT_CODES = {"StaleWeatherError": 4}


def exit_code_of(exc: BaseException | None) -> int | None:
    """The exit code of `exc` (or an exception it was raised from) when it is one of EXIT_CODES, else None."""
    seen = 0
    while exc is not None and seen < 10:
        for cls in type(exc).__mro__:
            if cls.__name__ in EXIT_CODES:
                return EXIT_CODES[cls.__name__]
        exc, seen = exc.__cause__ or exc.__context__, seen + 1
    return None


def is_user_error(exc: BaseException | None) -> bool:
    """`exc` (or an exception it was raised from) is one the user can act on from its message alone."""
    seen = 0
    while exc is not None and seen < 10:
        if any(cls.__name__ in USER_ERRORS for cls in type(exc).__mro__):
            return True
        exc, seen = exc.__cause__ or exc.__context__, seen + 1
    return False


def user_error_of(exc: BaseException) -> BaseException:
    """The user error in `exc`'s chain (the one whose message to show)."""
    seen = 0
    cur: BaseException | None = exc
    while cur is not None and seen < 10:
        if any(cls.__name__ in USER_ERRORS or cls.__name__ in EXIT_CODES for cls in type(cur).__mro__):
            return cur
        cur, seen = cur.__cause__ or cur.__context__, seen + 1
    return exc


class _NoUserErrorTracebacks(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        if record.exc_info and (is_user_error(record.exc_info[1]) or exit_code_of(record.exc_info[1]) is not None):
            record.exc_info, record.exc_text = None, None
        return True


def quiet_user_error_tracebacks() -> None:
    for name in ("prefect.flow_runs", "prefect.task_runs"):
        logging.getLogger(name).addFilter(_NoUserErrorTracebacks())
