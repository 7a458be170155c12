"""Fuel per nautical mile laden and in ballast, from a vessel's performance model, in calm water.

The planner sails each leg at the vessel's planning speed (laden / ballast; default its design speed). The rpm
giving that speed through water at the leg's draft is found by bisection on the model's speed (monotone in rpm
for every form), and fuel per NM = fuel rate at that rpm / speed. A vessel without an active model uses
`reference_model` from its design data (speed ∝ rpm, fuel ∝ rpm³: fuel per NM ∝ speed²). When the model cannot
reach the planning speed at `rpm_max`, the planning speed becomes the speed at `rpm_max`.
"""

from __future__ import annotations

import math

from pipeline.performance.model import PerformanceModel

DEFAULT_LADEN_DRAFT_M = 11.5
DEFAULT_BALLAST_DRAFT_M = 7.0


def speed_and_fuel_per_nm(model: PerformanceModel, speed_kn: float, draft_m: float, rpm_max: float,
                          trim_m: float = 0.0) -> tuple[float, float]:
    """(speed sailed, kn; fuel, t/NM) at `speed_kn` (or the most the model gives at `rpm_max`) and `draft_m`."""
    top = float(model.stw_kn(rpm_max, draft_m, trim_m))
    if not math.isfinite(top) or top <= 0:
        raise ValueError(f"vessel {model.imo}: its performance model gives no speed at {rpm_max:g} rpm, "
                         f"draft {draft_m:g} m; refit it or give design data")
    speed = min(float(speed_kn), top)
    lo, hi = 0.0, float(rpm_max)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if float(model.stw_kn(mid, draft_m, trim_m)) < speed:
            lo = mid
        else:
            hi = mid
    fuel_tph = float(model.fuel_tph(hi, draft_m, trim_m))
    return speed, fuel_tph / speed
