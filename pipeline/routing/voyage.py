"""From a warehouse voyage row (+ its vessel's model) to a `RoutingProblem`."""

from __future__ import annotations

import math

import numpy as np

from pipeline.engine_ranges import parse_barred_rpm
from pipeline.performance.model import PerformanceModel
from pipeline.routing.options import RoutingOptions
from pipeline.routing.problem import RoutingInputError, RoutingProblem


def _num(v, default=None):
    try:
        f = float(v)
    except (TypeError, ValueError):
        return default
    return default if math.isnan(f) else f


def rpm_options_of(voyage: dict, rpm_max: float | None) -> tuple[float, ...]:
    opts = voyage.get("rpm_options")
    if opts is None or (isinstance(opts, float) and math.isnan(opts)) or len(opts) == 0:
        if not rpm_max:
            raise RoutingInputError(f"voyage {voyage.get('voyage_id')}: no allowed rpm settings and no rpm_max for the vessel")
        return tuple(round(rpm_max * f, 1) for f in (0.6, 0.7, 0.8, 0.9, 1.0))
    return tuple(float(r) for r in opts)


def problem_from_voyage(voyage: dict, model: PerformanceModel, *, rpm_max: float | None = None,
                        objective: str = RoutingOptions.objective, window_h: float = RoutingOptions.arrival_window_h,
                        n_lines: int | None = RoutingOptions.n_lines, n_points: int = RoutingOptions.n_points,
                        d_point_nm: float | None = RoutingOptions.d_point_nm,
                        land_clearance_nm: float = RoutingOptions.land_clearance_nm,
                        port_approach_nm: float = RoutingOptions.port_approach_nm, base: str = "gc",
                        barred_rpm=None) -> RoutingProblem:
    """The voyage as a routing problem; `barred_rpm` is its vessel's barred speed ranges (the vessels column as
    text, or (low, high) pairs): a listed setting inside one is moved to the range's nearer edge, said on the plan."""
    vid = str(voyage.get("voyage_id"))
    try:
        barred = parse_barred_rpm(barred_rpm) if barred_rpm is None or isinstance(barred_rpm, str) else tuple(barred_rpm)
    except ValueError as e:
        raise RoutingInputError(f"voyage {vid}: vessel {voyage.get('imo')}: {e}") from None
    for k in ("dep_lat", "dep_lon", "arr_lat", "arr_lon"):
        if _num(voyage.get(k)) is None:
            raise RoutingInputError(f"voyage {vid}: {k} is missing")
    # the model is consulted only at engine speeds it was fitted on: settings beyond them are clipped (said on the plan)
    rpm_options, rpm_note = model.clip_rpm_options(rpm_options_of(voyage, rpm_max), f"voyage {vid}")
    moved = {}
    for r in rpm_options:
        for lo, hi in barred:
            if lo < r < hi:
                moved[r] = lo if r - lo < hi - r else hi
    if moved:
        rpm_options = tuple(sorted({moved.get(r, r) for r in rpm_options}))
        note = (f"voyage {vid}: setting(s) {', '.join(f'{r:g}' for r in moved)} rpm lie in the engine's barred range(s) "
                f"{', '.join(f'{lo:g}-{hi:g}' for lo, hi in barred)}: moved to {', '.join(f'{v:g}' for v in moved.values())}")
        rpm_note = note if rpm_note is None else f"{rpm_note}; {note}"
    model = model.fouled_at(np.datetime64(voyage["depart_utc"], "s"))  # the hull as it will be on the voyage
    return RoutingProblem(
        dep=(float(voyage["dep_lat"]), float(voyage["dep_lon"])), arr=(float(voyage["arr_lat"]), float(voyage["arr_lon"])),
        depart_utc=np.datetime64(voyage["depart_utc"], "s"), rta_utc=np.datetime64(voyage["rta_utc"], "s"), model=model,
        rpm_options=rpm_options, rpm_note=rpm_note, draft_m=_num(voyage.get("draft_m"), 10.0),
        trim_m=_num(voyage.get("trim_m"), 0.0), max_hs_m=_num(voyage.get("max_hs_m")),
        max_wind_kn=_num(voyage.get("max_wind_kn")), objective=objective, window_h=window_h, voyage_id=vid,
        imo=int(voyage["imo"]) if voyage.get("imo") is not None else None, dep_name=str(voyage.get("dep_name") or "departure"),
        arr_name=str(voyage.get("arr_name") or "destination"), n_lines=n_lines, n_points=n_points, d_point_nm=d_point_nm,
        land_clearance_nm=land_clearance_nm, port_approach_nm=port_approach_nm, base=base, barred_rpm=barred)
