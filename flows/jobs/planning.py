"""The fleet planning job: import the planning files, complete the sea distances, plan, store the plan and its
voyages, draw its Gantt chart."""

from __future__ import annotations

import logging
import secrets
from pathlib import Path

import pandas as pd

from flows.jobs.refit import read_table
from flows.runner import PLAIN
from flows.settings import load_settings
from pipeline.export.plan_gantt import plan_gantt_png
from pipeline.planning import milp, problem
from pipeline.planning.inputs import split_list, validate_availability, validate_contracts, validate_ports
from pipeline.planning.sea_distances import (PortDistance, avoiding, canal_map, distance_map, needed_pairs,
                                             sea_distance)
from pipeline.planning.work_budget import WorkBudget
from pipeline.planning.voyages import (DEFAULT_PENALTY,
                                       apply_commitments, plan_contracts, plan_rows, plan_vessels, replan,
                                       vessel_drafts)
from pipeline.timestamps import parse_iso_utc
from storage import fleet_store, planning_store, warehouse

LOG = logging.getLogger("jitroute.planning")
DEFAULT_FUEL_PRICE = 600.0  # per tonne


class PlanningInputError(ValueError):
    """The planning inputs cannot be used as given (the message names the file and what to do)."""


def parse_as_of(as_of: str | None) -> pd.Timestamp:
    if as_of is None:
        return pd.Timestamp.now(tz="UTC").tz_localize(None).floor("s")
    ts, why = parse_iso_utc(as_of)
    if ts is None:
        raise PlanningInputError(f"--as-of {as_of!r}: {why}; give ISO 8601, e.g. 2020-12-01T00:00Z")
    return ts


# Building the problem checks every vessel × contract × contract arc in Python: its time and memory grow with that
# product (15 vessels × 1,000 contracts: 3 s CPU and 0.6 GB before the solver starts; 10 × 10,000 would be ~60 GB),
# and no time limit can interrupt it. Past this size the plan is refused, not started.
MAX_ARC_CHECKS = 16_000_000
MAX_TIME_LIMIT_S = 6 * 3600.0  # as long as a fleet's routing may take; a flow run cannot hold the data root for days
MAX_EFFORT = 300.0  # effort 1 is about a CPU minute on the bench's 50 x 200 fleet: 300, some hours


def check_parameters(fuel_price: float, penalty: float, effort: float = 1.0, time_limit_s: float | None = None
                     ) -> None:
    """The plan's own numbers (CLI options, flow parameters): PlanningInputError naming the bad one. A negative fuel
    price or penalty would make the cheapest plan a nonsense one (and it would become the active plan). The time
    limit (a safety cap) may be None: none."""
    from pipeline.planning.inputs import MAX_FUEL_PRICE, MAX_MONEY

    checks = [("--fuel-price", fuel_price, MAX_FUEL_PRICE), ("--penalty", penalty, MAX_MONEY),
              ("--effort", effort, MAX_EFFORT)]
    if time_limit_s is not None:
        checks.append(("--time-limit", time_limit_s, MAX_TIME_LIMIT_S))
    for name, value, top in checks:
        try:
            x = float(value)
        except (TypeError, ValueError):
            raise PlanningInputError(f"{name} {str(value)[:40]!r} is not a number") from None
        above_0 = name in ("--time-limit", "--effort")
        if not 0 <= x <= top or (above_0 and x <= 0):
            raise PlanningInputError(f"{name} {x:g}: give a number {'above 0' if above_0 else '≥ 0'} "
                                     f"and at most {top:g}")


def check_size(n_vessels: int, n_contracts: int) -> None:
    """PlanningInputError when the problem is larger than the planner builds in bounded time and memory."""
    if n_vessels * n_contracts ** 2 > MAX_ARC_CHECKS:
        most = int((MAX_ARC_CHECKS / max(n_vessels, 1)) ** 0.5)
        raise PlanningInputError(
            f"{n_contracts} open contracts for {n_vessels} vessels: the planner takes at most {most} contracts for "
            f"{n_vessels} vessels at a time (vessels × contracts² ≤ {MAX_ARC_CHECKS:,}; its time and memory grow with "
            "that and no time limit can stop the build); plan a shorter horizon (the contracts whose window opens "
            "soonest) or part of the fleet")


def _refuse_going_back(db: Path, as_of: pd.Timestamp) -> None:
    """A re-plan goes forward in time: one as of a time before the active plan's would take voyages that plan
    counted as sailed for unsailed ones and replace them."""
    active = planning_store.active_plan_as_of(db)
    if active is not None and as_of < active[1]:
        raise PlanningInputError(
            f"--as-of {as_of:%Y-%m-%dT%H:%M}Z is before the active plan {active[0]}'s as-of {active[1]:%Y-%m-%dT%H:%M}Z: "
            f"a re-plan cannot go back in time (voyages sailed by then would be planned again); "
            f"give --as-of {active[1]:%Y-%m-%dT%H:%M}Z or later (default: now)")


def _stored(db: Path, table: str) -> pd.DataFrame:
    with warehouse.connect(db, write=False) as con:
        return con.execute(f"SELECT * FROM {table}").fetchdf()


def import_planning_files(db: Path, contracts: str, availability: str | None, ports: str | None,
                          as_of: pd.Timestamp) -> dict:
    """Validate the given files against what is stored (ports before availability before contracts) and store
    good and refused rows in one transaction."""
    parts: dict[str, tuple[pd.DataFrame, pd.DataFrame]] = {}
    if ports:
        parts["ports"] = validate_ports(read_table(Path(ports)), Path(ports).name)
        known_ports = set(parts["ports"][0]["port"])
    else:
        known_ports = set()
    if db.exists():
        known_ports |= set(_stored(db, "ports")["port"]) - (set(parts["ports"][1]["port"].dropna()) if ports else set())
    if not known_ports:
        raise PlanningInputError("no ports known: give --ports FILE (port, lat, lon of each pilot station)")
    imos = fleet_store.known_imos(db)
    if not imos:
        raise PlanningInputError(f"no vessels in {db}: import vessels.csv first (`jitroute fleet import FOLDER`)")
    if availability:
        parts["availability"] = validate_availability(read_table(Path(availability)), known_imos=imos,
                                                      ports=known_ports, source=Path(availability).name)
        avail = parts["availability"][0]
    else:
        avail = _stored(db, "vessel_availability")
    if avail.empty:
        refused = parts["availability"][1] if availability else None
        why = (f": all {len(refused)} rows of {availability} refused, e.g. {refused['reason'].iloc[0]}"
               if refused is not None and len(refused) else "")
        raise PlanningInputError(f"no vessel availability{why}; give --availability FILE (imo, from_utc, from_port, …)")
    vessels = fleet_store.load_vessels(db)
    dwt = vessels[vessels["imo"].isin(avail["imo"])]["dwt"].dropna()
    types = [split_list(x) for x in avail["cargo_types"]]
    carried = None if any(t is None for t in types) else set[str]().union(*(t for t in types if t is not None))
    parts["contracts"] = validate_contracts(read_table(Path(contracts)), as_of=as_of, ports=known_ports,
                                            max_dwt_t=float(dwt.max()) if len(dwt) else None, cargo_types=carried,
                                            source=Path(contracts).name)
    counts = planning_store.import_inputs(db, parts)
    for kind, (_, bad) in parts.items():
        for row in bad.to_dict("records"):
            LOG.warning("%s: row refused (%s): %r", row.get("source_file"), row["reason"], str(row["raw"])[:200])
    return {"counts": counts, "contracts": parts["contracts"][0], "contracts_rejected": parts["contracts"][1]}


def complete_distances(db: Path, ports: dict[str, tuple[float, float]], pairs: set[tuple[str, str]],
                       avoid=()) -> list[PortDistance]:
    """Stored distances of `pairs`, computing (and storing) those missing or made for other positions; with the
    passages `avoid` closed (the fleet's routing.avoid_passages) those through them computed again without them
    (sea_distances.avoiding; not stored)."""
    stored = planning_store.load_port_distances(db)
    known = {(r["port_a"], r["port_b"]): PortDistance(r["port_a"], r["port_b"], r["lat_a"], r["lon_a"], r["lat_b"],
                                                      r["lon_b"], float("nan") if pd.isna(r["dist_nm"]) else r["dist_nm"],
                                                      r["gc_nm"], r["reason"] if isinstance(r["reason"], str) else None,
                                                      r["passages"] if isinstance(r["passages"], str) else None,
                                                      0.0 if pd.isna(r["canal_nm"]) else float(r["canal_nm"]),
                                                      0.0 if pd.isna(r["canal_h"]) else float(r["canal_h"]))
             for r in stored.to_dict("records")}
    todo = needed_pairs(ports, known, pairs)
    if todo:
        LOG.info("computing %d sea distances (shortest sea route over the whole ocean)", len(todo))
        new = [sea_distance(a, ports[a], b, ports[b]) for a, b in todo]
        planning_store.save_port_distances(db, pd.DataFrame([r.__dict__ for r in new]))
        for r in new:
            known[(r.port_a, r.port_b)] = r
            if r.reason:
                LOG.warning("ports %s and %s: %s", r.port_a, r.port_b, r.reason)
    rows = [known[tuple(sorted(p))] for p in {tuple(sorted(p)) for p in pairs if p[0] != p[1]}]
    return avoiding(rows, avoid) if avoid else rows


def plan_fleet_job(contracts: str, availability: str | None = None, ports: str | None = None, as_of: str | None = None,
                   data_root: str | None = None, fuel_price: float = DEFAULT_FUEL_PRICE,
                   penalty: float = DEFAULT_PENALTY, effort: float = 1.0, time_limit_s: float | None = None,
                   picture: bool = True, *, run=PLAIN) -> dict:
    """Plan the fleet as of `as_of` (default now) for the contracts of `contracts`; returns the plan summary. The
    planner's search gets `effort` (pipeline/planning/work_budget.py: 1 the default, counted in work, so the same
    inputs give the same plan on any machine); `time_limit_s`, when given, is a wall-clock safety cap on building
    the problem and the search."""
    check_parameters(fuel_price, penalty, effort, time_limit_s)
    t_as_of = parse_as_of(as_of)
    s = load_settings(data_root=Path(data_root) if data_root else None)
    layout = s.layout.ensure()
    db = layout.warehouse
    _refuse_going_back(db, t_as_of)
    imported = run.step(import_planning_files, db, contracts, availability, ports, t_as_of, name="import-planning-files")
    good = imported["contracts"]
    port_rows = _stored(db, "ports")
    port_pos = {r["port"]: (float(r["lat"]), float(r["lon"])) for r in port_rows.to_dict("records")}
    fleet, models = planning_store.load_planning_fleet(db)
    keep = replan(planning_store.voyages_for_replan(db), t_as_of)
    done = keep.committed
    fleet = apply_commitments(fleet, keep.busy)
    for _, name, lat, lon in keep.busy.values():  # a vessel free at the end of a voyage from a file: at its port
        port_pos.setdefault(name, (lat, lon))
    open_contracts = good[~good["code"].isin(list(done))]
    check_size(len(fleet), len(open_contracts))
    vessels, fuel_source = plan_vessels(fleet, models, t_as_of)
    cons = plan_contracts(open_contracts, t_as_of, penalty)
    pairs = {(c.load_port, c.discharge_port) for c in cons}
    pairs |= {(v.start_port, c.load_port) for v in vessels for c in cons}
    pairs |= {(a.discharge_port, b.load_port) for a in cons for b in cons}
    pairs |= {(c.discharge_port, v.end_port) for v in vessels for c in cons if v.end_port}
    dists = run.step(complete_distances, db, port_pos, pairs, tuple(s.routing.avoid_passages), name="sea-distances")
    budget = WorkBudget.of_effort(float(effort), wall_limit_s=time_limit_s)  # the safety cap covers the build too
    data = problem.build(vessels, cons, distance_map(dists), fuel_price, canals=canal_map(dists))
    plan = run.step(milp.solve, data, budget=budget, name="plan")
    plan_id = f"plan-{t_as_of:%Y%m%dT%H%M}-{secrets.token_hex(3)}"
    row, legs, left, voyages = plan_rows(plan, data, plan_id, t_as_of, port_pos, vessel_drafts(fleet))
    stored = planning_store.save_plan(db, row, legs, left, voyages, keep.replaced)
    png = None
    if picture:
        png = layout.exports / "plans" / f"{plan_id}.png"
        windows = {r["code"]: (r["early_utc"], r["late_utc"]) for r in good.to_dict("records")}
        names = {int(r["imo"]): str(r["name"]) for r in fleet.to_dict("records")}
        plan_gantt_png(png, row, legs, windows, left, names, fleet=list(names))
        planning_store.set_plan_picture(db, plan_id, str(png))
    summary = {**{k: (v.isoformat() if isinstance(v, pd.Timestamp) else v) for k, v in row.items()},
               "gantt_png": str(png) if png else None, **stored,
               "fuel_source": {str(k): v for k, v in fuel_source.items()},
               "no_sea_route": [f"{d.port_a}–{d.port_b}: {d.reason}" for d in dists if d.reason],
               "imported": imported["counts"],
               "committed": [{"code": k, "reason": v} for k, v in done.items()],
               "contracts_refused": [{"code": r.get("code"), "reason": r["reason"]}
                                     for r in imported["contracts_rejected"].to_dict("records")],
               "vessels": _vessel_lines(legs, plan, data),
               "unassigned": left.to_dict("records") if len(left) else []}
    run.publish(key="fleet-plan", markdown=f"Fleet plan {plan_id}: {row['n_assigned']} of {row['n_contracts']} contracts "
                                           f"assigned, cost {row['total_cost']:,.0f} ({row['solve_status']})",
                description="fleet plan")
    return summary


def _vessel_lines(legs: pd.DataFrame, plan, data) -> list[dict]:
    out = []
    for sched in plan.schedules:
        v = data.vessels[sched.k]
        mine = legs[legs["imo"] == v.imo] if len(legs) else legs
        out.append({"imo": v.imo, "name": v.name, "contracts": [data.contracts[j].code for j in sched.sequence],
                    "fuel_t": sched.fuel_t, "fuel_cost": sched.fuel_cost, "out_of_service_days": sched.out_of_service_days,
                    "out_of_service_cost": sched.out_of_service_cost,
                    "legs": [{k: (x.isoformat() if isinstance(x, pd.Timestamp) else x) for k, x in r.items()
                              if k in ("seq", "kind", "contract_code", "from_port", "to_port", "dist_nm", "depart_utc",
                                       "arrive_utc", "fuel_t", "voyage_id")} for r in mine.to_dict("records")]})
    return out
