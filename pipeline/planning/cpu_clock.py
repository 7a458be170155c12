"""The planner's clock: CPU seconds of this process (time.process_time(), every thread of it), not the wall clock.

Every budget of the fleet planner (its time limit, the enumeration pacing, the share of diving, every deadline) is
read on this clock, so the same input gets the same search whether the host is quiet or busy: other processes' load
does not count, only what the search itself did. A deadline is a `cpu_s()` reading.
"""

from __future__ import annotations

import time


def cpu_s() -> float:
    """CPU seconds this process has used (user + system, all threads)."""
    return time.process_time()


def wall_s_for(cpu_left_s: float, cpu_used_s: float, wall_used_s: float) -> float:
    """The wall-clock limit to give a solver that counts only the wall clock (HiGHS) so that it gets about
    `cpu_left_s` CPU seconds: the time left divided by the share of a core this process got so far
    (`cpu_used_s` over `wall_used_s`; counted as a whole core before a tenth of a second has passed, and as at
    least a twentieth of one). It is 'about': when the host's load changes during the call, HiGHS gets more or
    less."""
    share = cpu_used_s / wall_used_s if wall_used_s > 0.1 else 1.0
    return max(0.0, cpu_left_s) / min(1.0, max(0.05, share))
