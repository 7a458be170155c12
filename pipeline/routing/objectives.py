"""Route cost from total hours T and fuel F (tonnes). Lower is better; infeasible is +inf.

`thesis` (kept exactly as published): with T_req the required passage time,
    T ≥ T_req:          Q = T/T_req + 9999.9
    T ≤ 0.85·T_req:     Q = 0.85 + 3·F/F_target
    otherwise:          Q = T/T_req + 3·F/F_target
`jit` (default): fuel, plus a steep penalty for arriving after the RTA (a fixed 1000 t plus
`late_t_per_h` per hour late, so any on-time plan beats every late one and the least-late plan
wins among late ones), plus a mild `early_t_per_h` per hour of arriving before RTA − window.
"""

from __future__ import annotations

from typing import NamedTuple

import numba

OBJ_THESIS, OBJ_JIT = 0, 1
OBJECTIVES = {"thesis": OBJ_THESIS, "jit": OBJ_JIT}
LATE_STEP_T = 1000.0


class Objective(NamedTuple):
    """When the voyage runs and how a plan is priced, as the kernels see it. Times are hours after the
    weather's t_ref (`t_dep_h`) or durations in hours; `max_hours` is the planning horizon (a longer passage is
    infeasible); `f_target` (t) scales fuel in the thesis function."""

    kind: int  # OBJ_THESIS or OBJ_JIT
    t_dep_h: float
    max_hours: float
    t_req_h: float
    window_h: float
    f_target: float
    early_t_per_h: float
    late_t_per_h: float


def objective(kind: str, *, t_dep_h: float, max_hours: float, t_req_h: float, window_h: float = 6.0,
              f_target: float = 1.0, early_t_per_h: float = 0.2, late_t_per_h: float = 1.0e4) -> Objective:
    return Objective(OBJECTIVES[kind], float(t_dep_h), float(max_hours), float(t_req_h), float(window_h),
                     float(f_target), float(early_t_per_h), float(late_t_per_h))


@numba.njit(cache=True)
def route_cost_nb(o, hours, fuel_t):
    """Cost under the objective `o` of a passage of `hours` burning `fuel_t` tonnes."""
    t_req_h, window_h, f_target_t = o.t_req_h, o.window_h, o.f_target
    if o.kind == OBJ_THESIS:
        if hours >= t_req_h:
            return hours / t_req_h + 9999.9
        if hours <= 0.85 * t_req_h:
            return 0.85 + 3.0 * fuel_t / f_target_t
        return hours / t_req_h + 3.0 * fuel_t / f_target_t
    cost = fuel_t
    if hours > t_req_h + 1e-9:
        cost += LATE_STEP_T + o.late_t_per_h * (hours - t_req_h)
    elif hours < t_req_h - window_h:
        cost += o.early_t_per_h * (t_req_h - window_h - hours)
    return cost
