"""Fuel per nautical mile laden and in ballast, from a vessel's performance model, in calm water.

The planner sails each leg at the vessel's planning speed (laden / ballast; default its design speed). The rpm
giving that speed through water at the leg's draft is found by bisection on the model's speed (monotone in rpm
for every form), and fuel per NM = fuel rate at that rpm / speed. A vessel without an active model uses
`reference_model` from its design data (speed ∝ rpm, fuel ∝ rpm³: fuel per NM ∝ speed²). When the model cannot
reach the planning speed at `rpm_max`, the planning speed becomes the speed at `rpm_max`.

Laden figures depend on the weight lifted (`laden_curve`): the draft with `cargo_t` aboard is taken linear in
the weight between the ballast draft (no cargo) and the laden draft (full deadweight) — a wall-sided hull, whose
displacement grows linearly with draft —, and speed and fuel per NM come from the model at that draft, at
`CARGO_SHARES` of the deadweight.
"""

from __future__ import annotations

import math

from pipeline.performance.model import PerformanceModel

DEFAULT_LADEN_DRAFT_M = 11.5
DEFAULT_BALLAST_DRAFT_M = 7.0
CARGO_SHARES = (0.25, 0.5, 0.75, 1.0)  # of the deadweight: the weights the laden figures are taken at


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


def draft_at(cargo_t: float, dwt_t: float, laden_draft_m: float, ballast_draft_m: float) -> float:
    """Draft (m) with `cargo_t` aboard: linear in the weight from the ballast draft to the laden draft at `dwt_t`."""
    share = min(1.0, max(0.0, cargo_t / dwt_t)) if dwt_t > 0 else 1.0
    return ballast_draft_m + share * (laden_draft_m - ballast_draft_m)


def laden_curve(model: PerformanceModel, speed_kn: float, dwt_t: float, laden_draft_m: float, ballast_draft_m: float,
                rpm_max: float) -> tuple[tuple[float, float, float], ...]:
    """(cargo t, speed kn, fuel t/NM) at `CARGO_SHARES` of the deadweight, sailing `speed_kn` (or the most the model
    gives at `rpm_max` at that draft)."""
    return tuple((share * dwt_t, *speed_and_fuel_per_nm(model, speed_kn, draft_at(share * dwt_t, dwt_t, laden_draft_m,
                                                                                   ballast_draft_m), rpm_max))
                 for share in CARGO_SHARES)


def ballast_curve(model: PerformanceModel, speed_kn: float, draft_m: float, rpm_max: float, slowest_share: float,
                  n: int = 4) -> tuple[tuple[float, float], ...]:
    """(speed kn, fuel t/NM) in ballast at `n` speeds from `slowest_share` of `speed_kn` to `speed_kn`, fuel made
    non-decreasing in speed (a fit's noise must not make a faster leg cheaper: the planner relies on it)."""
    out, most = [], 0.0
    for i in range(n):
        speed, fuel = speed_and_fuel_per_nm(model, speed_kn * (slowest_share + (1 - slowest_share) * i / (n - 1)),
                                            draft_m, rpm_max)
        most = max(most, fuel)
        if not out or speed > out[-1][0]:
            out.append((speed, most))
    return tuple(out)
