"""The bounds the label searches prune with (compiled): the finish bounds as one structure, the least fuel to
finish in the hours left, the least cost of every plan a label can still become, and the one pruning rule built
from them that every label search applies. Certified: they never drop a label of an optimal plan (the proofs:
docs/search-methods.md, "The exact DP"; the tables are built by `bound_tables.finish_bounds`)."""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from pipeline.routing.objectives import LATE_STEP_T, OBJ_JIT


class FinishBounds(NamedTuple):
    """The bound tables of a label search over a graph of L+2 lines × P nodes, R engine settings, legs (i, a) →
    (i + 1, a + s − max_shift), hours after the objective's t_ref. Built by `bound_tables.label_bounds` (or by hand for a
    search that bounds otherwise: bfoa's polish)."""

    lams: np.ndarray  # (K,) prices of time (t of fuel per hour)
    m_lam: np.ndarray  # (K, L+2, P) least Σ d·(φ + λ_k·τ) from each node to the arrival (t)
    t_min: np.ndarray  # (L+2, P) least hours from each node to the arrival
    tau: np.ndarray  # (L+2, P, 2·max_shift + 1, R) least hours per NM of each leg at each setting
    phi: np.ndarray  # (L+2, P, 2·max_shift + 1, R) least fuel per NM (t) of each leg at each setting
    ld: np.ndarray  # (L+2, P) latest departure from each node that can still make the RTA (h)


def is_on_time(o, upper: float) -> bool:
    """Whether a plan costing `upper` is on time under the objective `o` (then late plans cannot beat it)."""
    return upper < (LATE_STEP_T if o.kind == OBJ_JIT else 9999.9)


@numba.njit(cache=True)
def fuel_to_finish_lb(m_lam, lams, t_min, hours):
    """Least fuel (t) to finish within `hours` from a node whose bound tables are m_lam[k] (least Σ d·(φ + λ_k·τ))
    and t_min (least Σ d·τ): max over k of m_lam[k] − λ_k·hours; inf when even t_min does not fit."""
    if hours < t_min:
        return np.inf
    best = 0.0
    for k in range(lams.shape[0]):
        best = max(best, m_lam[k] - lams[k] * hours)
    return best


@numba.njit(cache=True)
def cost_lb_nb(o, fuel_lb, hours_lb):
    """A lower bound on the cost under the objective `o` of every plan burning at least fuel_lb (t) and taking at
    least hours_lb (h, the passage): jit prices a plan at least at its fuel plus, when even hours_lb is after the
    RTA, the lateness of that earliest arrival (the penalty grows with the hours late); the thesis function prices a
    plan arriving by T_req at least 0.85 + 3·F/F_target and a later one at least T/T_req + 9999.9."""
    if fuel_lb == np.inf or hours_lb == np.inf:
        return np.inf
    if o.kind == OBJ_JIT:
        if hours_lb > o.t_req_h + 1e-9:
            return fuel_lb + LATE_STEP_T + o.late_t_per_h * (hours_lb - o.t_req_h)
        return fuel_lb
    late = max(hours_lb, o.t_req_h) / o.t_req_h + 9999.9
    if hours_lb >= o.t_req_h:
        return late
    return min(0.85 + 3.0 * fuel_lb / o.f_target, late)


@numba.njit(cache=True)
def priced_out(o, fuel_lb, hours_lb, upper, tol, on_time):
    """Whether every plan burning at least fuel_lb (t) and taking at least hours_lb (h) costs more than `upper` under
    the objective `o` (`cost_lb_nb`). With an on-time `upper` every plan kept arrives by the RTA (the deadline)."""
    if o.kind != OBJ_JIT and on_time:  # the thesis function prices an on-time plan at least 0.85 + 3·F/F_target
        return fuel_lb == np.inf or 0.85 + 3.0 * fuel_lb / o.f_target > upper + tol
    return cost_lb_nb(o, fuel_lb, hours_lb) > upper + tol


@numba.njit(cache=True, inline="always")  # in the DPs' innermost loops: a call there cost the BFOA's polish 3.5 % CPU
def label_priced_out(o, fb, i, a, t, fuel, upper, tol, on_time):
    """The pruning rule of every label search: whether a label at node (i, a) at time t (h after t_ref) having burnt
    `fuel` (t) so far (or a lower bound of what it will have there) is sure to cost more than `upper` (+ tol): its
    fuel plus the least fuel to finish (`fb`, a FinishBounds) by the deadline, arriving no sooner than t + the least
    hours left. The deadline is the RTA when `upper` is on time (`on_time`: late plans cannot beat it), else the
    planning horizon."""
    deadline = o.t_dep_h + (o.t_req_h if on_time else o.max_hours)
    lb = fuel + fuel_to_finish_lb(fb.m_lam[:, i, a], fb.lams, fb.t_min[i, a], deadline - t)
    return priced_out(o, lb, t - o.t_dep_h + fb.t_min[i, a], upper, tol, on_time)
