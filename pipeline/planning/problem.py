"""The planning problem: vessels, cargo contracts and sea distances → what each vessel could do.

Conventions (all solvers share them, so their costs compare exactly):
- Times are hours after the planning time (`as_of`); a vessel is available from max(as_of, its available-from
  time) at its start port.
- A contract is one full cargo (one vessel, one cargo at a time). Loading starts inside [early, late] (the load
  window); the vessel then spends `port_h` loading, sails laden to the discharge port and spends `port_h`
  discharging. A vessel arriving before `early` waits.
- Lifted weight = min(max weight, deadweight); it must reach the contract's minimum weight.
- Distances are the global sea routes' (sea_distances.py); a route through a canal sails the canal's fairway in
  the canal's transit and waiting hours instead of at the vessel's speed (`build`'s `canals`), its fuel still
  counted per NM. A pair without a distance only removes the arcs that need it: a vessel whose start port has
  no sea route to a load port may still lift that cargo after another one.
- Legs are sailed at the vessel's ballast / laden planning speed; fuel per NM at that speed and draft
  (`fuel.py`). A ballast leg to a load port where the vessel would wait for the window leaves later and sails
  slower, down to `SLOWEST_BALLAST_SHARE` of its ballast speed, so that it arrives when loading starts; its fuel is
  taken at the speed sailed (`PlanVessel.ballast_curve`, or fuel per NM ∝ speed² without one). Loading still starts
  as early as the planning speed allows, so times do not depend on the speeds chosen. Laden, speed and fuel per NM depend on the weight lifted: `PlanVessel.laden_curve` holds them at
  several cargo weights (interpolated linearly between, held beyond). The weather routing of each leg later arrives
  just in time at the RTA the schedule gives.
- Cost of a plan = fuel price × fuel (ballast + laden, and the last ballast to the vessel's end port when it has
  one) + daily cost × days out of service + the penalty of every contract left unassigned. Days out of service of
  a used vessel = from its available-from time to the end of its last leg, less the days it spends carrying and
  handling cargo (so ballast sailing and waiting count). An unused vessel costs nothing.
- A vessel with an end (time, port) must reach that port by that time after its last discharge.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

HOURS_PER_DAY = 24.0
# A ballast leg leaves no earlier than it must to reach the load port when loading starts at this share of the
# planning speed: the weather routing may slow down that much instead of waiting at anchor; longer waits are
# spent in port before sailing, not drifting at sea.
SLOWEST_BALLAST_SHARE = 0.7


@dataclass(frozen=True)
class PlanVessel:
    imo: int
    name: str
    dwt_t: float
    start_port: str
    start_h: float  # available from, hours after as_of (≥ 0)
    end_port: str | None = None
    end_h: float = math.inf  # must be at end_port (if any) by then, hours after as_of
    port_h: float = 24.0  # average time in port per call, hours
    daily_cost: float = 0.0  # cost per day out of service (currency of fuel_price)
    ports: frozenset[str] | None = None  # ports it may call (None: any)
    cargo_types: frozenset[str] | None = None  # cargo types it may carry (None: any)
    laden_speed_kn: float = 12.0
    ballast_speed_kn: float = 13.0
    laden_fuel_t_per_nm: float = 0.1
    ballast_fuel_t_per_nm: float = 0.08
    # (cargo t, laden speed kn, fuel t/NM) at several cargo weights, by weight; empty: the laden figures above at any
    laden_curve: tuple[tuple[float, float, float], ...] = ()
    # (speed kn, fuel t/NM) in ballast, by speed, fuel not falling with speed; empty: ∝ speed² from the figures above
    ballast_curve: tuple[tuple[float, float], ...] = ()

    def ballast_at(self, speed_kn: float) -> float:
        """Fuel t/NM in ballast at `speed_kn`."""
        pts = self.ballast_curve
        if not pts:
            return self.ballast_fuel_t_per_nm * (speed_kn / self.ballast_speed_kn) ** 2
        return float(np.interp(speed_kn, [p[0] for p in pts], [p[1] for p in pts]))

    def ballast_leg(self, nm: float, ready_h: float, load_h: float) -> tuple[float, float]:
        """(departure, hours after as_of; fuel t) of a ballast leg of `nm` when the vessel is ready at `ready_h` and
        loading starts at `load_h` (reachable at the ballast speed): it leaves as late as sailing no slower than
        SLOWEST_BALLAST_SHARE of the ballast speed allows."""
        if nm <= 0:
            return ready_h, 0.0
        fastest_h = nm / self.ballast_speed_kn
        depart = max(ready_h, load_h - fastest_h / SLOWEST_BALLAST_SHARE)
        speed = min(self.ballast_speed_kn, nm / max(load_h - depart, fastest_h))
        return depart, nm * self.ballast_at(speed)

    def laden_at(self, cargo_t: float) -> tuple[float, float]:
        """(speed kn, fuel t/NM) laden with `cargo_t`."""
        pts = self.laden_curve
        if not pts:
            return self.laden_speed_kn, self.laden_fuel_t_per_nm
        if cargo_t <= pts[0][0]:
            return pts[0][1], pts[0][2]
        for (w0, s0, f0), (w1, s1, f1) in zip(pts, pts[1:]):
            if cargo_t <= w1:
                x = (cargo_t - w0) / (w1 - w0) if w1 > w0 else 1.0
                return s0 + x * (s1 - s0), f0 + x * (f1 - f0)
        return pts[-1][1], pts[-1][2]


@dataclass(frozen=True)
class Contract:
    code: str
    cargo_type: str
    min_t: float
    max_t: float
    load_port: str
    discharge_port: str
    early_h: float  # load window, hours after as_of
    late_h: float
    penalty: float  # cost of leaving it unassigned (e.g. chartered out on the spot market)


@dataclass
class VesselArcs:
    """What vessel k can do. Arc keys: ('s', j) start → contract j; (i, j) contract i → j; (j, 'e') contract j → end.
    Every value is per arc: ballast distance (NM), hours from ready-at-origin to possible load start at j
    (for start arcs: the arrival time at j's load port), and cost excluding out-of-service days."""

    k: int
    contracts: list[int]  # contracts the vessel may lift
    dur_h: dict[int, float]  # load start → end of discharge
    laden_nm: dict[int, float]
    lift_t: dict[int, float]
    laden_fuel_t: dict[int, float]  # fuel of the laden leg at the weight lifted
    arcs: dict[tuple, float] = field(default_factory=dict)  # arc → ballast NM
    travel_h: dict[tuple, float] = field(default_factory=dict)  # arc → ballast hours
    successors: tuple | None = None  # colgen's pricing arrays, built on first use


@dataclass
class PlanData:
    vessels: list[PlanVessel]
    contracts: list[Contract]
    fuel_price: float
    per_vessel: list[VesselArcs]
    reasons: dict[int, str]  # contract index → why no vessel can lift it (absent: some vessel can)

    def fuel_cost(self, k: int, ballast_nm: float = 0.0, laden_fuel_t: float = 0.0) -> float:
        """Cost of `ballast_nm` at the ballast speed and `laden_fuel_t`."""
        return self.fuel_price * (ballast_nm * self.vessels[k].ballast_fuel_t_per_nm + laden_fuel_t)

    def leg_cost(self, k: int, arc: tuple, ready_h: float, load_h: float) -> float:
        """Fuel cost of arc (origin, contract j) of vessel k — the ballast leg, slowed to arrive at `load_h`, and j's
        laden leg — when the vessel is ready at `ready_h` and loading starts at `load_h`."""
        va = self.per_vessel[k]
        return self.fuel_price * (self.vessels[k].ballast_leg(va.arcs[arc], ready_h, load_h)[1]
                                  + va.laden_fuel_t[arc[1]])


def _distance(dist_nm: dict, a: str, b: str) -> float | None:
    if a == b:
        return 0.0
    d = dist_nm.get((a, b))
    if d is None:
        d = dist_nm.get((b, a))
    return None if d is None or not math.isfinite(d) else float(d)


def _why_not(v: PlanVessel, c: Contract, dist_nm: dict) -> str | None:
    """Why vessel `v` can never lift contract `c` (None: it may). A missing distance from the vessel's start port
    to the load port is no reason: the vessel may still lift `c` after another cargo (its start arc is left out)."""
    if v.cargo_types is not None and c.cargo_type not in v.cargo_types:
        return f"cannot carry {c.cargo_type}"
    for p in (c.load_port, c.discharge_port):
        if v.ports is not None and p not in v.ports:
            return f"may not call {p}"
    if min(c.max_t, v.dwt_t) < c.min_t:
        return f"deadweight {v.dwt_t:.0f} t below the minimum {c.min_t:.0f} t"
    if _distance(dist_nm, c.load_port, c.discharge_port) is None:
        return f"no sea route {c.load_port} → {c.discharge_port}"
    if v.end_port is not None and _distance(dist_nm, c.discharge_port, v.end_port) is None:
        return f"no sea route from {c.discharge_port} to its end port {v.end_port}"
    return None


def _hours(canals: dict, a: str, b: str, nm: float, speed_kn: float) -> float:
    """Hours from a to b (`nm` NM) at `speed_kn`, a canal's share of the route at the canal's own pace
    (sea_distances.hours)."""
    canal_nm, canal_h = canals.get((a, b)) or canals.get((b, a)) or (0.0, 0.0)
    return (nm - canal_nm) / speed_kn + canal_h


def build(vessels: list[PlanVessel], contracts: list[Contract], dist_nm: dict[tuple[str, str], float],
          fuel_price: float, canals: dict[tuple[str, str], tuple[float, float]] | None = None) -> PlanData:
    """Every feasible arc per vessel, with its distance and time; `dist_nm` maps (port, port) → NM (either order;
    a pair absent or NaN has no sea route); `canals` (port, port) → (NM, hours) of the route through canals, sailed
    in those hours instead of at the vessel's speed (sea_distances.canal_map)."""
    canals = canals or {}
    per_vessel: list[VesselArcs] = []
    why: dict[int, list[str]] = {j: [] for j in range(len(contracts))}
    for k, v in enumerate(vessels):
        va = VesselArcs(k, [], {}, {}, {}, {})
        for j, c in enumerate(contracts):
            reason = _why_not(v, c, dist_nm)
            if reason is None:
                laden = _distance(dist_nm, c.load_port, c.discharge_port)
                lift = min(c.max_t, v.dwt_t)
                speed_kn, fuel_t_per_nm = v.laden_at(lift)
                dur = 2 * v.port_h + _hours(canals, c.load_port, c.discharge_port, laden, speed_kn)
                end_nm = 0.0 if v.end_port is None else _distance(dist_nm, c.discharge_port, v.end_port)
                to_end = 0.0 if v.end_port is None else _hours(canals, c.discharge_port, v.end_port, end_nm,
                                                               v.ballast_speed_kn)
                bal0 = _distance(dist_nm, v.start_port, c.load_port)
                arrive = None if bal0 is None else v.start_h + _hours(canals, v.start_port, c.load_port, bal0,
                                                                       v.ballast_speed_kn)
                if arrive is not None and arrive > c.late_h + 1e-9:
                    reason = f"cannot reach {c.load_port} before the window closes"
                elif max(arrive if arrive is not None else -math.inf, c.early_h, v.start_h) + dur + to_end > v.end_h + 1e-9:
                    reason = "cannot finish it before its availability ends"
                else:
                    va.contracts.append(j)
                    va.dur_h[j], va.laden_nm[j], va.lift_t[j] = dur, laden, lift
                    va.laden_fuel_t[j] = laden * fuel_t_per_nm
                    if arrive is not None:  # else lifted only after another cargo
                        va.arcs[("s", j)], va.travel_h[("s", j)] = bal0, arrive
                    va.arcs[(j, "e")], va.travel_h[(j, "e")] = end_nm, to_end
            if reason is not None:
                why[j].append(f"{v.name or v.imo}: {reason}")
        for i in va.contracts:
            ci = contracts[i]
            for j in va.contracts:
                if i == j:
                    continue
                cj = contracts[j]
                d = _distance(dist_nm, ci.discharge_port, cj.load_port)
                if d is None:
                    continue
                h = _hours(canals, ci.discharge_port, cj.load_port, d, v.ballast_speed_kn)
                ready = ci.early_h + va.dur_h[i] + h
                if ready > cj.late_h + 1e-9 or max(ready, cj.early_h) + va.dur_h[j] + va.travel_h[(j, "e")] > v.end_h + 1e-9:
                    continue
                va.arcs[(i, j)], va.travel_h[(i, j)] = d, h
        per_vessel.append(va)
    reasons = {j: _summary(contracts[j], r) for j, r in why.items() if len(r) == len(vessels)}
    reached = {a[1] for va in per_vessel for a in va.arcs}
    for j in range(len(contracts)):  # kept by some vessel, yet no start arc or earlier cargo of any leads to it
        if j not in reasons and j not in reached:
            reasons[j] = ("no vessel can reach it: no sea route from any start port to "
                          f"{contracts[j].load_port} in time, nor from another cargo's discharge port")
    return PlanData(vessels, contracts, float(fuel_price), per_vessel, reasons)


def _summary(c: Contract, reasons: list[str]) -> str:
    if not reasons:
        return "no vessel available"
    kinds = {r.split(": ", 1)[1] for r in reasons}
    if len(kinds) == 1:
        return f"no vessel can lift it: every vessel {next(iter(kinds))}"
    return "no vessel can lift it: " + "; ".join(reasons[:6]) + ("; …" if len(reasons) > 6 else "")


@dataclass(frozen=True)
class Leg:
    """One planned leg of a vessel: ballast (to a load port or the end port) or laden (load → discharge)."""

    imo: int
    seq: int
    kind: str  # ballast | laden
    contract: str | None
    from_port: str
    to_port: str
    dist_nm: float
    depart_h: float
    arrive_h: float  # arrival for laden legs; for ballast legs the time the vessel is wanted there (RTA)
    fuel_t: float
    lift_t: float = 0.0


@dataclass(frozen=True)
class VesselSchedule:
    k: int
    sequence: tuple[int, ...]
    load_start_h: tuple[float, ...]
    end_h: float
    fuel_t: float
    fuel_cost: float
    out_of_service_days: float
    out_of_service_cost: float
    legs: tuple[Leg, ...]

    @property
    def cost(self) -> float:
        return self.fuel_cost + self.out_of_service_cost


def schedule(data: PlanData, k: int, sequence: tuple[int, ...]) -> VesselSchedule | None:
    """The earliest schedule of vessel k lifting `sequence` in order (None: infeasible). Each load starts as early
    as the planning speeds allow: every cost item grows with time, except a ballast leg's fuel, which a later load
    start could lower further by a slower leg — the schedule takes the earliest start all the same (the convention
    every solver shares), so a plan never waits on purpose to save ballast fuel."""
    v, va = data.vessels[k], data.per_vessel[k]
    if not sequence:
        return VesselSchedule(k, (), (), v.start_h, 0.0, 0.0, 0.0, 0.0, ())
    legs: list[Leg] = []
    starts: list[float] = []
    ready, prev, busy, fuel_t = v.start_h, "s", 0.0, 0.0
    for j in sequence:
        arc = (prev, j)
        if arc not in va.arcs:
            return None
        c = data.contracts[j]
        arrive = va.travel_h[arc] if prev == "s" else ready + va.travel_h[arc]
        t = max(arrive, c.early_h)
        if t > c.late_h + 1e-9:
            return None
        from_port = v.start_port if prev == "s" else data.contracts[prev].discharge_port
        depart, ballast_t = v.ballast_leg(va.arcs[arc], ready, t)
        if from_port != c.load_port:
            legs.append(Leg(v.imo, len(legs), "ballast", c.code, from_port, c.load_port, va.arcs[arc], depart, t,
                            ballast_t))
        sail_h = va.dur_h[j] - 2 * v.port_h
        legs.append(Leg(v.imo, len(legs), "laden", c.code, c.load_port, c.discharge_port, va.laden_nm[j],
                        t + v.port_h, t + v.port_h + sail_h, va.laden_fuel_t[j], va.lift_t[j]))
        starts.append(t)
        fuel_t += ballast_t + va.laden_fuel_t[j]
        busy += va.dur_h[j]
        ready, prev = t + va.dur_h[j], j
    end_nm = va.arcs[(prev, "e")]
    end = ready + va.travel_h[(prev, "e")]
    if end > v.end_h + 1e-9:
        return None
    if v.end_port is not None and end_nm > 0:
        legs.append(Leg(v.imo, len(legs), "ballast", None, data.contracts[prev].discharge_port, v.end_port, end_nm,
                        ready, end, end_nm * v.ballast_fuel_t_per_nm))
    fuel_t += end_nm * v.ballast_fuel_t_per_nm
    oos_days = (end - v.start_h - busy) / HOURS_PER_DAY
    return VesselSchedule(k, tuple(sequence), tuple(starts), end, fuel_t, data.fuel_price * fuel_t, oos_days,
                          v.daily_cost * oos_days, tuple(legs))


@dataclass(frozen=True)
class FleetPlan:
    """A solved plan: one schedule per used vessel, why each contract is left, the cost items and how it was solved."""

    schedules: tuple[VesselSchedule, ...]
    unassigned: dict[int, str]  # contract index → reason
    fuel_cost: float
    out_of_service_cost: float
    penalty_cost: float
    solver: str
    status: str  # optimal | feasible (search stopped: gap below) | trivial
    gap: float  # proven relative optimality gap (0 when optimal)
    runtime_s: float  # wall-clock seconds, reported only (nothing in the search reads a clock but the safety cap)
    n_columns: int = 0  # columns (vessel sequences) the MILP chose among
    stopped_by: str = ""  # what ended the search: "proven optimal" | "effort: N units spent, gap G %" | ...
    work_units: float = 0.0  # work spent by the search (work_budget.py)

    @property
    def cost(self) -> float:
        return self.fuel_cost + self.out_of_service_cost + self.penalty_cost


def assemble(data: PlanData, sequences: dict[int, tuple[int, ...]], *, solver: str, status: str, gap: float,
             runtime_s: float, n_columns: int = 0, left_reason: str | None = None, stopped_by: str = "",
             work_units: float = 0.0) -> FleetPlan:
    """The plan of `sequences` (vessel index → contract indices in order), each scheduled earliest."""
    scheds = []
    for k, seq in sorted(sequences.items()):
        if seq:
            s = schedule(data, k, tuple(seq))
            if s is None:
                raise ValueError(f"vessel {data.vessels[k].imo}: sequence {seq} is not feasible")
            scheds.append(s)
    lifted = {j for s in scheds for j in s.sequence}
    left = {}
    for j in range(len(data.contracts)):
        if j in lifted:
            continue
        left[j] = data.reasons.get(j) or left_reason or (
            f"left to the spot market: lifting it costs more than its penalty "
            f"{data.contracts[j].penalty:.0f}, or its window clashes with contracts that save more")
    return FleetPlan(tuple(scheds), left, sum(s.fuel_cost for s in scheds), sum(s.out_of_service_cost for s in scheds),
                     sum(data.contracts[j].penalty for j in left), solver, status, gap, runtime_s, n_columns,
                     stopped_by, work_units)

