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

import numba

OBJ_THESIS, OBJ_JIT = 0, 1
OBJECTIVES = {"thesis": OBJ_THESIS, "jit": OBJ_JIT}
LATE_STEP_T = 1000.0


@numba.njit(cache=True)
def route_cost_nb(obj, hours, fuel_t, t_req_h, window_h, f_target_t, early_t_per_h, late_t_per_h):
    if obj == OBJ_THESIS:
        if hours >= t_req_h:
            return hours / t_req_h + 9999.9
        if hours <= 0.85 * t_req_h:
            return 0.85 + 3.0 * fuel_t / f_target_t
        return hours / t_req_h + 3.0 * fuel_t / f_target_t
    cost = fuel_t
    if hours > t_req_h + 1e-9:
        cost += LATE_STEP_T + late_t_per_h * (hours - t_req_h)
    elif hours < t_req_h - window_h:
        cost += early_t_per_h * (t_req_h - window_h - hours)
    return cost
