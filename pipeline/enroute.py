"""Voyages at sea: which voyages have sailed and not arrived, and where their next plan starts (pure functions).

A voyage is *at sea* from its departure until a position report within `arrived_within_nm` of its destination
(or its status `arrived`). Its next plan starts from its latest position after departure (a noon report of its
vessel, or a position an operator gave) at that report's time. A report older than `max_report_age_h` at the
run's reference time is advanced along the voyage's current plan to the reference time (the plan says so); with
no current plan it is used as it is, and the plan says how old it is.

Positions are (lat, lon) in degrees, times naive UTC (`numpy.datetime64`), hours as floats.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.routing.geodesy import gc_distance_nm, gc_interpolate

START_PORT = "port"
START_REPORT = "noon report"
START_OPERATOR = "operator position"
START_ADVANCED = "advanced along plan"
# statuses of a voyage that is over (or never sails): never re-planned
DONE_STATUSES = frozenset({"arrived", "cancelled", "canceled", "completed"})


@dataclass(frozen=True)
class Position:
    """A reported position of a voyage's vessel; `kind` is START_REPORT or START_OPERATOR."""

    utc: np.datetime64
    lat: float
    lon: float
    kind: str = START_REPORT


@dataclass(frozen=True)
class PlanStart:
    """Where a plan starts: the port at departure, or a position at sea at a time."""

    kind: str  # START_PORT | START_REPORT | START_OPERATOR | START_ADVANCED
    lat: float
    lon: float
    utc: np.datetime64
    position_utc: np.datetime64 | None = None  # time of the report it came from (None: the port)
    advanced_h: float = 0.0  # hours the report was moved on along the current plan
    note: str | None = None

    def columns(self) -> dict:
        """The plan's start as route-row columns (`routes.start_*`)."""
        return {"start_kind": self.kind, "start_lat": float(self.lat), "start_lon": float(self.lon),
                "start_utc": _plain(self.utc), "start_position_utc": _plain(self.position_utc),
                "start_advanced_h": float(self.advanced_h), "start_note": self.note}


def _plain(t):
    return None if t is None else np.datetime64(t, "s").item()


def _t(x) -> np.datetime64:
    return np.datetime64(x, "s") if not isinstance(x, np.datetime64) else x.astype("datetime64[s]")


def _hours(a, b) -> float:
    return float((_t(b) - _t(a)) / np.timedelta64(1, "s")) / 3600.0


def label(t) -> str:
    return str(np.datetime64(t, "m")).replace("T", " ")


def port_start(voyage: dict) -> PlanStart:
    return PlanStart(START_PORT, float(voyage["dep_lat"]), float(voyage["dep_lon"]), _t(voyage["depart_utc"]))


def has_arrived(voyage: dict, positions: list[Position], arrived_within_nm: float) -> bool:
    """Status `arrived` (or over), or a position after departure within `arrived_within_nm` of the destination."""
    if str(voyage.get("status") or "").strip().lower() in DONE_STATUSES:
        return True
    dep = _t(voyage["depart_utc"])
    return any(p.utc > dep and gc_distance_nm(p.lat, p.lon, float(voyage["arr_lat"]), float(voyage["arr_lon"]))
               <= arrived_within_nm for p in positions)


def latest_position(voyage: dict, positions: list[Position], ref_utc) -> Position | None:
    """The newest position after departure and not after `ref_utc` (an operator's wins over a report of the
    same time)."""
    dep, ref = _t(voyage["depart_utc"]), _t(ref_utc)
    after = [p for p in positions if dep < _t(p.utc) <= ref]
    if not after:
        return None
    return max(after, key=lambda p: (_t(p.utc), p.kind == START_OPERATOR))


def position_on_plan(legs: list[dict], at_utc) -> tuple[float, float] | None:
    """Where a plan puts the ship at `at_utc`: along the great circle of the leg sailed then, in proportion to the
    leg's time (legs: dicts with lat0, lon0, lat1, lon1, etd_utc, eta_utc). Before the first leg, or waiting
    before a leg: that leg's start; after the last: its end; None without legs."""
    if not legs:
        return None
    at = _t(at_utc)
    legs = sorted(legs, key=lambda g: _t(g["etd_utc"]))
    if at <= _t(legs[0]["etd_utc"]):
        return float(legs[0]["lat0"]), float(legs[0]["lon0"])
    for g in legs:
        etd, eta = _t(g["etd_utc"]), _t(g["eta_utc"])
        if at < etd:  # waiting at the leg's start node (a plan that heaves to before it)
            return float(g["lat0"]), float(g["lon0"])
        if etd <= at <= eta:
            span = _hours(etd, eta)
            frac = 0.0 if span <= 0 else min(1.0, max(0.0, _hours(etd, at) / span))
            lat, lon = gc_interpolate(float(g["lat0"]), float(g["lon0"]), float(g["lat1"]), float(g["lon1"]), frac)
            return float(lat), float(lon)
    return float(legs[-1]["lat1"]), float(legs[-1]["lon1"])


def replan_start(voyage: dict, position: Position | None, plan_legs: list[dict], ref_utc,
                 max_report_age_h: float) -> PlanStart | None:
    """Where the next plan of a voyage at sea starts (None: nothing to start from, neither a position after
    departure nor a current plan)."""
    ref = _t(ref_utc)
    if position is None:
        on_plan = position_on_plan(plan_legs, ref)
        if on_plan is None:
            return None
        return PlanStart(START_ADVANCED, on_plan[0], on_plan[1], ref, None, 0.0,
                         f"no position report after departure; position of the current plan at {label(ref)}")
    age_h = _hours(position.utc, ref)
    if age_h <= max_report_age_h:
        return PlanStart(position.kind, position.lat, position.lon, _t(position.utc), _t(position.utc))
    on_plan = position_on_plan(plan_legs, ref)
    if on_plan is None:
        return PlanStart(position.kind, position.lat, position.lon, _t(position.utc), _t(position.utc), 0.0,
                         f"{position.kind} of {label(position.utc)} is {age_h:.0f} h old (more than "
                         f"{max_report_age_h:g} h) and there is no current plan to advance it along")
    return PlanStart(START_ADVANCED, on_plan[0], on_plan[1], ref, _t(position.utc), age_h,
                     f"{position.kind} of {label(position.utc)} is {age_h:.0f} h old (more than "
                     f"{max_report_age_h:g} h): advanced {age_h:.0f} h along the current plan")


def voyage_from(voyage: dict, start: PlanStart) -> dict:
    """The voyage as a routing job sees it when it starts at `start`: departure = the start position and time
    (the destination, RTA, vessel and limits unchanged), with the start's route-row columns beside."""
    out = dict(voyage)
    if start.kind != START_PORT:
        out.update(dep_lat=float(start.lat), dep_lon=float(start.lon), depart_utc=_plain(start.utc),
                   dep_name=f"{start.kind} {label(start.position_utc or start.utc)}")
    out.update(start.columns())
    return out


@dataclass(frozen=True)
class Selection:
    """What a fleet run does with one voyage: plan it from `start`, or not (`start` None) because of `why`."""

    voyage: dict
    start: PlanStart | None
    why: str | None = None


def select_starts(voyages: list[dict], positions: dict[int, list[Position]], plans: dict[str, list[dict]], *,
                  cycle_utc, ref_utc, lookahead_h: float, max_report_age_h: float, arrived_within_nm: float,
                  max_voyage_h: float, explicit: bool = False,
                  given: dict[str, list[Position]] | None = None) -> list[Selection]:
    """Each voyage's plan start for a run on the cycle `cycle_utc` at the reference time `ref_utc` (≥ the cycle).

    - a voyage with a position after its departure (its vessel's reports in `positions` by IMO, an operator's in
      `given` by voyage ID) (not after `ref_utc`) is at sea: re-planned from it (see
      `replan_start`), unless it has arrived (a position within `arrived_within_nm` of its destination, or
      its status) or its RTA has passed;
    - else a voyage departing within `lookahead_h` after the cycle with status `planned` is planned from its port;
    - else a voyage that departed before the cycle, within `max_voyage_h`, RTA still ahead, is at sea without a
      report: re-planned from where its current plan puts it at `ref_utc` (none: not planned, said why).
    With `explicit` (voyages named by the operator) every voyage gets a plan attempt: from its position at sea,
    else from its port.
    """
    cycle, ref = _t(cycle_utc), _t(ref_utc)
    out = []
    for v in voyages:
        vid, dep, rta = str(v.get("voyage_id")), _t(v["depart_utc"]), _t(v["rta_utc"])
        status = str(v.get("status") or "planned").strip().lower()
        mine = (positions.get(int(v["imo"]), []) if v.get("imo") is not None else []) + (given or {}).get(vid, [])
        legs = plans.get(vid, [])
        if has_arrived(v, mine, arrived_within_nm):
            if explicit:
                out.append(Selection(v, port_start(v) if dep >= cycle else None,
                                     None if dep >= cycle else f"voyage {vid} has arrived (status or a position "
                                     f"within {arrived_within_nm:g} NM of its destination): nothing to re-plan"))
            continue
        pos = latest_position(v, mine, ref)
        if pos is not None and (explicit or rta > ref):
            out.append(Selection(v, replan_start(v, pos, legs, ref, max_report_age_h)))
        elif explicit or (status == "planned" and cycle <= dep < cycle + np.timedelta64(int(lookahead_h * 3600), "s")):
            out.append(Selection(v, port_start(v)))
        elif dep < cycle and rta > ref and _hours(dep, ref) <= max_voyage_h and status not in DONE_STATUSES:
            start = replan_start(v, None, legs, ref, max_report_age_h)
            out.append(Selection(v, start, None if start is not None else
                                 f"voyage {vid} departed {label(dep)} and has neither a position report since nor a "
                                 "current plan: import its noon reports to re-plan it from its position"))
    return out


# An operator's position is refused beyond this many hours after the voyage's RTA: the voyage has ended (and a
# position then would keep re-planning a ship that is no longer on it)
POSITION_AFTER_RTA_MAX_H = 72.0
# ... and when reaching it from the nearest known position in time (the departure port at departure, a noon report
# of the vessel) needs more than this many times the vessel's design speed (at least an hour apart)
POSITION_MAX_SPEED_FACTOR = 2.0


def position_problem(voyage: dict, at_utc, lat: float, lon: float, *, at_sea: bool, reports: list[Position],
                     top_speed_kn: float) -> str | None:
    """Why an operator's position of `voyage` at `at_utc` cannot be right (None: it can): before the departure,
    more than POSITION_AFTER_RTA_MAX_H after the RTA, on land (`at_sea` False, from the land mask), or farther from
    the known position nearest in time — the departure port at the departure time, or one of `reports` (noon
    reports of the vessel) — than POSITION_MAX_SPEED_FACTOR × `top_speed_kn` could sail in the time between."""
    at, dep, rta = _t(at_utc), _t(voyage["depart_utc"]), _t(voyage["rta_utc"])
    if at < dep:
        return (f"{label(at)} is before its departure {label(dep)}: a position is of a voyage at sea; give a time "
                "after the departure")
    if _hours(rta, at) > POSITION_AFTER_RTA_MAX_H:
        return (f"{label(at)} is {_hours(rta, at) / 24:.1f} days after its RTA {label(rta)}: the voyage has ended "
                f"(more than {POSITION_AFTER_RTA_MAX_H:g} h after the RTA); check the date")
    if not at_sea:
        return f"{lat:.4f},{lon:.4f} is on land (global land mask): check the position (LAT,LON order, signs)"
    known = [Position(dep, float(voyage["dep_lat"]), float(voyage["dep_lon"]), START_PORT)] + \
        [p for p in reports if _t(p.utc) >= dep]
    ref = min(known, key=lambda p: abs(_hours(p.utc, at)))
    hours = abs(_hours(ref.utc, at))
    dist = float(gc_distance_nm(ref.lat, ref.lon, lat, lon))
    limit = POSITION_MAX_SPEED_FACTOR * top_speed_kn * max(hours, 1.0)
    if dist > limit:
        what = "the departure port" if ref.kind == START_PORT else "the vessel's noon report"
        return (f"{lat:.4f},{lon:.4f} is {dist:,.0f} NM from {what} at {label(ref.utc)} ({ref.lat:.2f},{ref.lon:.2f}), "
                f"{hours:.1f} h apart: {dist / max(hours, 1.0):.0f} kn, more than {POSITION_MAX_SPEED_FACTOR:g} × the "
                f"vessel's design speed {top_speed_kn:g} kn; check the position and the time")
    return None
