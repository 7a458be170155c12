"""The relaxation step every label search takes (compiled): a label at node (i, a), leaving at t0 with f0 t burnt,
tries the leg to (i + 1, a2) at setting r. First the leg is priced at its least hours and fuel (`leg_priced_out`):
when even that misses the latest departure that still makes the RTA or prices the label out (`label_priced_out`),
it is not sailed. Otherwise it is sailed in the weather it meets (`sail_label_leg`), and the label's arrival is
kept only when the leg can be sailed and ends within the planning horizon. What a search then does with the arrival
(dominance per node and time, departure slots with waits) is its own.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from pipeline.routing.engine.bounds import FinishBounds, label_priced_out
from pipeline.routing.engine.leg import CODE, H, OK, sail_leg_nb


class Relax(NamedTuple):
    """What a label search's relaxations share: the graph, vessel, weather and objective (engine.leg's), the bound
    tables, and the cost a label must be able to beat (`upper` + `tol`; `on_time`: `upper` is on time, so late plans
    cannot beat it and a label must still be able to make the RTA). Built inside the search kernel."""

    g: object
    v: object
    w: object
    o: object
    fb: FinishBounds
    upper: float
    tol: float
    on_time: bool


@numba.njit(cache=True, inline="always")  # in the innermost loops of the DPs and the BFOA's polish
def leg_priced_out(x, i, a, a2, s, r, d_nm, t0, f0):
    """Whether the leg (i, a) → (i + 1, a2) (offset s = a2 − a + max_shift, d_nm long) at setting r, left at t0 with
    f0 burnt, need not be sailed: at its least hours and fuel (x.fb.tau, x.fb.phi) it already arrives after the
    latest departure that makes the RTA (when x.on_time) or prices the label out."""
    t1 = t0 + d_nm * x.fb.tau[i, a, s, r]
    if x.on_time and t1 > x.fb.ld[i + 1, a2]:
        return True
    return label_priced_out(x.o, x.fb, i + 1, a2, t1, f0 + d_nm * x.fb.phi[i, a, s, r], x.upper, x.tol, x.on_time)


@numba.njit(cache=True, inline="always")
def sail_label_leg(x, i, a, a2, r, t0, out):
    """The leg (i, a) → (i + 1, a2) sailed at setting r leaving at t0 (`out` receives engine.leg's leg record: its
    hours and fuel): the arrival time, or inf when the leg cannot be sailed then or ends past the planning horizon."""
    g = x.g
    sail_leg_nb(g.lat[i, a], g.lon[i, a], g.lat[i + 1, a2], g.lon[i + 1, a2], t0, x.v.rpm_options[r], x.v, x.w, out)
    if out[CODE] != OK:
        return np.inf
    t1 = t0 + out[H]
    if t1 - x.o.t_dep_h > x.o.max_hours:
        return np.inf
    return t1
