"""From stored rows to the planning problem, and from a plan to its table rows and voyages.

Times: the planner works in hours after `as_of`; rows carry naive-UTC timestamps.
Each planned leg becomes a voyage (status planned, tagged with the plan): its departure is the leg's planned
departure and its RTA the leg's planned arrival — for a ballast leg, the start of loading (the leg leaves late
enough to sail no faster than it needs, down to `problem.SLOWEST_BALLAST_SHARE` of the planning speed, so the weather
routing slows down instead of waiting at anchor; the plan's fuel is costed at that speed); for a laden leg, the
arrival at the planning speed for its cargo weight, at the draft of that weight.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import pandas as pd

from pipeline.performance.model import model_from_stored, reference_model
from pipeline.planning.fuel import (DEFAULT_BALLAST_DRAFT_M, DEFAULT_LADEN_DRAFT_M, ballast_curve, draft_at,
                                    laden_curve, speed_and_fuel_per_nm)
from pipeline.planning.inputs import split_list
from pipeline.planning.problem import SLOWEST_BALLAST_SHARE, Contract, FleetPlan, PlanData, PlanVessel

DEFAULT_PORT_HOURS = 24.0
DEFAULT_PENALTY = 500_000.0


class Replan(NamedTuple):
    """What a re-plan keeps (see `replan`)."""
    committed: dict[str, str]  # contract code → why it is not planned again
    kept_plan_voyages: list[str]  # voyages of earlier plans kept (sailed, or of a committed contract)
    replaced: list[str]  # voyages of earlier plans the new plan replaces
    busy: dict[int, tuple[pd.Timestamp, str, float, float]]  # imo → (free from, at port, its lat, its lon)


def _hours(ts, as_of: pd.Timestamp) -> float:
    return (pd.Timestamp(ts) - as_of) / pd.Timedelta(hours=1)


def _num(v, default):
    return default if v is None or (isinstance(v, float) and math.isnan(v)) or v is pd.NA else float(v)


def plan_vessels(fleet: pd.DataFrame, models: dict[int, dict], as_of: pd.Timestamp) -> tuple[list[PlanVessel], dict[int, str]]:
    """Vessels (rows of vessels joined to their availability) as the planner sees them, and per IMO where its fuel
    figures come from ("model vN (form)" or "design data")."""
    out, source = [], {}
    for r in fleet.to_dict("records"):
        imo = int(r["imo"])
        model = model_from_stored(models.get(imo), imo)
        rpm_max = _num(r.get("rpm_max"), 100.0)
        if model is None:
            model = reference_model(_num(r.get("design_speed_kn"), 13.0), rpm_max, _num(r.get("design_fuel_tph"), 1.5))
            source[imo] = "design data (fuel ∝ rpm³)"
        else:
            source[imo] = f"model v{model.version} ({model.form})"
        design = _num(r.get("design_speed_kn"), 13.0)
        laden_d, ballast_d = _drafts(r)
        dwt = _num(r.get("dwt"), 0.0)
        laden_kn, laden_t = speed_and_fuel_per_nm(model, _num(r.get("laden_speed_kn"), design), laden_d, rpm_max)
        ballast_kn, ballast_t = speed_and_fuel_per_nm(model, _num(r.get("ballast_speed_kn"), design), ballast_d, rpm_max)
        curve = laden_curve(model, _num(r.get("laden_speed_kn"), design), dwt, laden_d, ballast_d, rpm_max) if dwt > 0 else ()
        slower = ballast_curve(model, ballast_kn, ballast_d, rpm_max, SLOWEST_BALLAST_SHARE)
        until = r.get("until_utc")
        out.append(PlanVessel(
            imo=imo, name=str(r.get("name") or imo), dwt_t=dwt, start_port=str(r["from_port"]),
            start_h=max(0.0, _hours(r["from_utc"], as_of)),
            end_port=r.get("until_port") if isinstance(r.get("until_port"), str) else None,
            end_h=math.inf if until is None or pd.isna(until) else _hours(until, as_of),
            port_h=_num(r.get("port_hours"), DEFAULT_PORT_HOURS), daily_cost=_num(r.get("daily_cost"), 0.0),
            ports=split_list(r.get("ports")), cargo_types=split_list(r.get("cargo_types")),
            laden_speed_kn=laden_kn, ballast_speed_kn=ballast_kn, laden_fuel_t_per_nm=laden_t,
            ballast_fuel_t_per_nm=ballast_t, laden_curve=curve, ballast_curve=slower))
    return out, source


def _drafts(r: dict) -> tuple[float, float]:
    """(laden draft at full deadweight, ballast draft), m, of an availability row."""
    return _num(r.get("laden_draft_m"), DEFAULT_LADEN_DRAFT_M), _num(r.get("ballast_draft_m"), DEFAULT_BALLAST_DRAFT_M)


def vessel_drafts(fleet: pd.DataFrame) -> dict[int, tuple[float, float]]:
    """IMO → (laden draft at full deadweight, ballast draft), m, as `plan_rows` takes them."""
    return {int(r["imo"]): _drafts(r) for r in fleet.to_dict("records")}


def plan_contracts(contracts: pd.DataFrame, as_of: pd.Timestamp, default_penalty: float = DEFAULT_PENALTY) -> list[Contract]:
    return [Contract(code=str(r["code"]), cargo_type=str(r["cargo_type"]), min_t=float(r["min_t"]), max_t=float(r["max_t"]),
                     load_port=str(r["load_port"]), discharge_port=str(r["discharge_port"]),
                     early_h=_hours(r["early_utc"], as_of), late_h=_hours(r["late_utc"], as_of),
                     penalty=_num(r.get("penalty"), default_penalty))
            for r in contracts.to_dict("records")]


def plan_rows(plan: FleetPlan, data: PlanData, plan_id: str, as_of: pd.Timestamp,
              ports: dict[str, tuple[float, float]], vessel_drafts: dict[int, tuple[float, float]] | None = None
              ) -> tuple[dict, pd.DataFrame, pd.DataFrame, pd.DataFrame]:
    """(fleet_plans row, fleet_plan_legs rows, fleet_plan_unassigned rows, voyages rows) of a plan."""
    def at(h):
        return (as_of + pd.Timedelta(hours=float(h))).round("s")

    legs, voyages = [], []
    dwt = {v.imo: v.dwt_t for v in data.vessels}
    for s in plan.schedules:
        for leg in s.legs:
            vid = f"{plan_id}-{leg.imo}-{leg.seq}"
            legs.append({"plan_id": plan_id, "imo": leg.imo, "seq": leg.seq, "kind": leg.kind,
                         "contract_code": leg.contract, "from_port": leg.from_port, "to_port": leg.to_port,
                         "dist_nm": leg.dist_nm, "depart_utc": at(leg.depart_h), "arrive_utc": at(leg.arrive_h),
                         "fuel_t": leg.fuel_t, "lift_t": leg.lift_t, "voyage_id": vid})
            laden_d, ballast_d = (vessel_drafts or {}).get(leg.imo, (DEFAULT_LADEN_DRAFT_M, DEFAULT_BALLAST_DRAFT_M))
            draft = draft_at(leg.lift_t, dwt[leg.imo], laden_d, ballast_d) if leg.kind == "laden" else ballast_d
            voyages.append({"voyage_id": vid, "imo": leg.imo, "dep_name": leg.from_port, "dep_lat": ports[leg.from_port][0],
                            "dep_lon": ports[leg.from_port][1], "arr_name": leg.to_port, "arr_lat": ports[leg.to_port][0],
                            "arr_lon": ports[leg.to_port][1], "depart_utc": at(leg.depart_h), "rta_utc": at(leg.arrive_h),
                            "draft_m": draft, "trim_m": 0.0, "rpm_options": None,
                            "status": "planned", "plan_id": plan_id})
    left = [{"plan_id": plan_id, "contract_code": data.contracts[j].code, "penalty": data.contracts[j].penalty,
             "reason": why} for j, why in sorted(plan.unassigned.items())]
    fuel_t = float(sum(s.fuel_t for s in plan.schedules))
    row = {"plan_id": plan_id, "as_of_utc": as_of, "solver": plan.solver, "solve_status": plan.status,
           "gap": None if not np.isfinite(plan.gap) else float(plan.gap), "runtime_s": plan.runtime_s,
           "stopped_by": plan.stopped_by or None,
           "n_contracts": len(data.contracts), "n_assigned": len(data.contracts) - len(plan.unassigned),
           "n_unassigned": len(plan.unassigned), "n_vessels_used": len(plan.schedules), "fuel_price": data.fuel_price,
           "fuel_t": fuel_t, "fuel_cost": plan.fuel_cost,
           "out_of_service_days": float(sum(s.out_of_service_days for s in plan.schedules)),
           "out_of_service_cost": plan.out_of_service_cost, "penalty_cost": plan.penalty_cost, "total_cost": plan.cost}
    return row, pd.DataFrame(legs), pd.DataFrame(left), pd.DataFrame(voyages)


def replan(voyages: pd.DataFrame, as_of: pd.Timestamp) -> Replan:
    """What a plan as of `as_of` keeps of the stored voyages, and when and where each vessel is free again.

    `voyages`: every stored voyage (storage.planning_store.voyages_for_replan): voyage_id, imo, plan_id (NULL: from a
    voyages file), status, depart_utc, rta_utc, arr_name, arr_lat, arr_lon, contract_code and kind (of the plan leg
    that made it), port_hours (of the vessel), reported_utc (newest position reported since its departure).

    A plan voyage has sailed when its departure is at or before `as_of`, a position of it was reported since its
    departure (an operator's, or a noon report of its vessel before its RTA: whatever `as_of` says, the report is a
    fact, the planned time a wish), or its status is no longer "planned". A contract is committed once any voyage serving it has sailed (the ballast towards its load port or
    its laden leg): every voyage of it is kept — the laden leg too, though it departs later — and it is not planned
    again. Every other plan voyage is replaced by the new plan. Voyages from a voyages file are always kept.

    A vessel is busy until the last kept voyage still under way at `as_of` ends (its RTA, plus the vessel's time in
    port at a discharge or a port call; none after a last ballast to an end port): it is free from then, at that
    voyage's arrival port, so the planner cannot book it elsewhere meanwhile (a vessel with a kept voyage in the
    future is held until that voyage ends: it may not be given work before it either, which the planner's one start
    per vessel cannot express)."""
    if voyages is None or not len(voyages):
        return Replan({}, [], [], {})
    v = voyages.copy()
    from_plan = v["plan_id"].notna()
    status = v["status"].where(v["status"].notna(), "planned").astype(str)
    sailed = from_plan & ((v["depart_utc"] <= as_of) | v["reported_utc"].notna() | (status != "planned"))
    done: dict[str, str] = {}
    for r in v[sailed & v["contract_code"].notna()].sort_values("depart_utc").to_dict("records"):
        code = str(r["contract_code"])
        if code not in done:
            how = (f"position reported {pd.Timestamp(r['reported_utc']):%Y-%m-%d %H:%M} UTC"
                   if pd.notna(r["reported_utc"]) else f"departed {pd.Timestamp(r['depart_utc']):%Y-%m-%d %H:%M} UTC")
            done[code] = (f"under way on voyage {r['voyage_id']} (vessel {int(r['imo'])}, {how}) of plan {r['plan_id']}: "
                          "its voyages are kept, not planned again")
    kept = ~from_plan | sailed | v["contract_code"].isin(list(done))
    busy: dict[int, tuple[pd.Timestamp, str, float, float]] = {}
    for r in v[kept].to_dict("records"):
        # time in port after a discharge or a call; none after a ballast leg (its contract's laden voyage is kept
        # and ends later, or it is the last ballast to an end port)
        port_h = 0.0 if r["kind"] == "ballast" else _num(r["port_hours"], DEFAULT_PORT_HOURS)
        free = pd.Timestamp(r["rta_utc"]) + pd.Timedelta(hours=port_h)
        if free <= as_of:
            continue
        imo = int(r["imo"])
        if imo not in busy or free > busy[imo][0]:
            named = isinstance(r["arr_name"], str) and r["arr_name"].strip()
            port = r["arr_name"] if named else f"arrival of {r['voyage_id']}"
            busy[imo] = (free, port, float(r["arr_lat"]), float(r["arr_lon"]))
    return Replan(done, sorted(v.loc[kept & from_plan, "voyage_id"].astype(str)),
                  sorted(v.loc[~kept, "voyage_id"].astype(str)), busy)


def apply_commitments(fleet: pd.DataFrame, busy: dict[int, tuple[pd.Timestamp, str, float, float]]) -> pd.DataFrame:
    """Vessels busy with kept voyages become available where and when the last of those ends (when that is after
    their availability's start; the availability row's port otherwise)."""
    fleet = fleet.copy()
    for imo, (free_from, port, _, _) in busy.items():
        at = (fleet["imo"] == imo) & (pd.to_datetime(fleet["from_utc"]) < free_from)
        fleet.loc[at, "from_utc"] = free_from
        fleet.loc[at, "from_port"] = port
    return fleet
