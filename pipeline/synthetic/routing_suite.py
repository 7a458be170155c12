"""The routing benchmark suite: voyages of the kinds a router meets, whose DP optima the repository stores.

Every instance is ≤ 5,000 NM, sails hourly analytic weather with a storm moving east across the North
Pacific (pipeline.synthetic.weather, `voyage_weather`, the same as bench/routing.py's), or across the southern
Indian Ocean (`storm_track`), and the reference performance model (14 kn · 1.5 t/h at 100 rpm). Together they cover
short and ocean voyages, east- and west-bound passages in the westerlies, a strait between land masses, a storm
against weather limits, tight and loose RTAs, both objectives, the dateline and storms whose cheapest way round
the default BFOA once missed (see `INSTANCES`, field `kinds`).

The repository's `bench/optima.json` stores per instance the DP's plan (node per line, rpm index per leg), its cost
and the certified gap it was solved to, keyed by a hash of everything the optimum depends on (voyage, search space,
weather values, vessel, objective): `stored_optimum` returns it only while that hash is unchanged.
`bench/routing_suite.py` computes missing or stale optima (`--recompute-dp` all of them) and benchmarks the
solvers against them; `tests/test_routing_suite.py` checks the stored plans of the small instances. Shared by both,
so it lives here rather than in bench/.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from pipeline.performance.model import reference_model
from pipeline.routing import weather_field as wf
from pipeline.routing.solve import RoutingProblem, solve
from pipeline.synthetic import weather as synth

MODEL = reference_model(14.0, 100.0, 1.5)
DP_GAP = 0.001  # the DP's certified gap for the stored optima


@dataclass(frozen=True)
class SuiteInstance:
    name: str
    kinds: str  # what the instance exercises
    dep: tuple[float, float]
    arr: tuple[float, float]
    depart_utc: str
    n_lines: int
    n_points: int
    rta: tuple[str, float]  # ("slow" | "fast", factor): RTA = factor × the great-circle passage at that rpm
    rpm: tuple[float, ...] = (70.0, 85.0, 100.0)
    objective: str = "jit"
    max_hs_m: float | None = None
    max_wind_kn: float | None = None
    weather_seed: int = 3
    storm_track: str = "north-pacific"  # pipeline.synthetic.weather.STORM_TRACKS


INSTANCES = (
    SuiteInstance("transpac-east", "ocean, east-bound with the westerlies, dateline, moving storm (the 5,000 NM "
                  "bench voyage)", (33.0, 136.0), (33.5, -118.8), "2021-01-10T00:00", 60, 41, ("slow", 0.9)),
    SuiteInstance("transpac-west", "ocean, west-bound into the westerlies, dateline", (33.5, -118.8), (33.0, 136.0),
                  "2021-01-10T00:00", 40, 31, ("slow", 0.9)),
    SuiteInstance("short-coastal", "short voyage along the coast of Japan against the Kuroshio, tight RTA", (34.8, 139.9), (33.3, 135.6),
                  "2021-01-12T06:00", 10, 11, ("fast", 1.4)),
    SuiteInstance("luzon-strait", "strait between Taiwan and Luzon (land closes most of the graph), loose RTA",
                  (18.5, 116.0), (21.5, 124.5), "2021-01-10T00:00", 20, 21, ("slow", 1.2)),
    SuiteInstance("storm-limit", "storm leaving Japan a day after the ship and overtaking it, against Hs ≤ 6 m and "
                  "wind ≤ 40 kn limits, thesis objective", (36.0, 150.0), (42.0, -175.0), "2021-01-05T18:00", 30, 21,
                  ("slow", 0.92), objective="thesis", max_hs_m=6.0, max_wind_kn=40.0),
    SuiteInstance("hawaii-la-tight", "trades to the westerlies, tight RTA (3 % above full speed)", (21.0, -157.5),
                  (33.5, -118.8), "2021-01-10T00:00", 30, 21, ("fast", 1.03)),
    SuiteInstance("hawaii-la-loose", "the same voyage with a loose RTA (early-arrival penalty)", (21.0, -157.5),
                  (33.5, -118.8), "2021-01-10T00:00", 30, 21, ("slow", 1.25)),
    SuiteInstance("dateline-west", "west-bound across the dateline in the storm track", (47.0, -165.0),
                  (40.0, 160.0), "2021-01-08T00:00", 30, 21, ("slow", 0.95)),
    SuiteInstance("storm-head-on", "west-bound into a storm coming the other way, whose cheapest way round is a "
                  "short detour to the north: the swarm used to stall on wider or later detours (+1 to +3.6 %)",
                  (40.0, -150.0), (40.0, 170.0), "2021-01-09T00:00", 30, 21, ("slow", 0.95)),
    SuiteInstance("southern-indian", "Southern Ocean, east-bound from south of Africa across the southern Indian Ocean while a storm "
                  "overtakes the ship (southern hemisphere, clockwise): every seed used to stall +0.55 % above the "
                  "optimum", (-41.0, 25.0), (-44.0, 88.0), "2021-01-02T00:00", 40, 31, ("slow", 0.95),
                  storm_track="south-indian"),
)
BY_NAME = {s.name: s for s in INSTANCES}


def build(spec: SuiteInstance):
    """(problem with its RTA, search space, weather) of a suite instance."""
    depart = np.datetime64(spec.depart_utc, "s")
    loose = RoutingProblem(dep=spec.dep, arr=spec.arr, depart_utc=depart, rta_utc=depart + np.timedelta64(60, "D"),
                           model=MODEL, rpm_options=spec.rpm, n_lines=spec.n_lines, n_points=spec.n_points,
                           objective=spec.objective, max_hs_m=spec.max_hs_m, max_wind_kn=spec.max_wind_kn,
                           voyage_id=f"SUITE-{spec.name}")
    space = loose.search_space()
    kind, factor = spec.rta
    rpm = spec.rpm[0] if kind == "slow" else spec.rpm[-1]
    calm_kn = float(MODEL.stw_kn(rpm, loose.draft_m, loose.trim_m))
    slow_kn = float(MODEL.stw_kn(spec.rpm[0], loose.draft_m, loose.trim_m))
    weather = voyage_weather(space, depart, 1.6 * space.base_distance_nm / slow_kn + 24.0, seed=spec.weather_seed,
                             track=spec.storm_track)
    gc_h = space.base_distance_nm / calm_kn  # the great circle at that rpm in calm water
    rta = depart + np.timedelta64(int(round(factor * gc_h * 60)), "m")
    return replace(loose, rta_utc=rta), space, weather


def instance_hash(spec: SuiteInstance, problem, space, weather) -> str:
    """Hash of everything the optimum depends on: the description, the search space (land included), the
    weather values, the vessel model and the RTA."""
    fields = asdict(spec)
    if fields["storm_track"] == "north-pacific":
        del fields["storm_track"]  # added later: at its default it leaves the hashes (and so the stored optima) as they were
    h = hashlib.sha256(json.dumps(fields, sort_keys=True).encode())
    for a in (space.lat, space.lon, space.edge_ok, weather.values, problem.model.speed_coef, problem.model.fuel_coef):
        h.update(np.ascontiguousarray(a).tobytes())
    h.update(str(problem.rta_utc).encode())
    h.update(b"settings: listed + the constant-speed rpm")  # the solvers' decision space (solve.solver_instance)
    return h.hexdigest()[:16]


def read_optima(path: Path) -> dict:
    """The stored optima (bench/optima.json in the repository), {} when there are none."""
    try:
        return json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return {}


def stored_optimum(spec: SuiteInstance, digest: str, optima: dict) -> dict | None:
    """The stored DP result of the instance in `optima` (read_optima), None when there is none or the instance
    changed since (its hash differs)."""
    got = optima.get(spec.name)
    return got if got is not None and got.get("hash") == digest else None


def plan_cost(problem, space, weather, nodes, rpm_idx) -> float:
    """The cost of a stored plan under today's kernels: the plan sailed through the same solve() path."""
    from pipeline.routing.baseline import baseline as find_baseline, evaluate
    from pipeline.routing.solve import solver_instance

    inst, base_nodes = solver_instance(problem, space, weather)
    base = find_baseline(inst, base_nodes)
    if base.ok:
        inst.f_target = max(float(evaluate(inst, base.nodes, base.rpm_idx)[2]), 1e-6)  # as solve() sets it
    return float(evaluate(inst, np.asarray(nodes, np.int64), np.asarray(rpm_idx, np.int64))[0])


def solve_optimum(spec: SuiteInstance, problem, space, weather, gap: float = DP_GAP) -> tuple[dict, object]:
    """(record for optima.json, the DP plan): the DP's plan to within `gap` of the optimum over the settings on the
    graph itself (the search space the solvers' gaps are measured in: continuous=False, no refined speeds,
    refine_split=1: no finer corridors)."""
    import time

    from pipeline.routing.options import DpOptions

    t0 = time.thread_time()
    plan = solve(problem, weather, solver="dp", space=space, options=DpOptions(gap=gap), continuous=False, limits=None,
                 savings=False, refine_split=1)
    cpu_s = time.thread_time() - t0
    rec = {"hash": instance_hash(spec, problem, space, weather), "status": plan.status, "cost": plan.cost,
           "fuel_t": plan.fuel_t, "hours": plan.hours, "gap": gap, "dp_cpu_s": cpu_s, "legs_sailed": plan.n_evals,
           "distance_nm": space.base_distance_nm}
    if plan.legs:
        rec["nodes"] = route_nodes(space, plan)
        from pipeline.routing.solve import solver_instance

        settings = solver_instance(problem, space, weather)[0].rpm_options  # what the indexes point into
        rec["rpm_idx"] = [int(np.argmin(np.abs(settings - leg["rpm"]))) for leg in plan.legs]
    return rec, plan


def voyage_weather(space, depart_utc, hours: float, seed: int = 3, step_h: int = 1,
                   track: str = "north-pacific") -> wf.WeatherField:
    """Analytic weather every `step_h` hours (hourly by default) on a 1° grid covering every usable node, from one
    step before departure, its storm on `track` (pipeline.synthetic.weather.STORM_TRACKS). Longitudes run 0..360 east, which keeps a box across the dateline in one piece, unless
    the nodes' own longitudes (−180..180) give a narrower box: a voyage across the Greenwich meridian."""
    ok = space.node_ok
    lat = np.arange(np.floor(space.lat[ok].min()) - 2.0, np.ceil(space.lat[ok].max()) + 2.5, 1.0)
    lon_box = space.lon[ok] % 360.0
    as_given = space.lon[ok]
    if np.ptp(as_given) < np.ptp(lon_box):
        lon_box = as_given
    lon = np.arange(np.floor(lon_box.min()) - 2.0, np.ceil(lon_box.max()) + 2.5, 1.0)
    times = depart_utc - np.timedelta64(step_h, "h") + np.arange(
        0, int(np.ceil(hours)) + 2 * step_h, step_h).astype("timedelta64[h]")
    t_h = synth.hours_since_epoch(times)[:, None, None]
    la, lo = np.meshgrid(lat, lon, indexing="ij")
    u10, v10 = synth.wind_uv(t_h, la[None], lo[None], seed, track)
    swh, mwd, _ = synth.waves(t_h, la[None], lo[None], seed, track)
    uo, vo = synth.currents_uv(t_h, la[None], lo[None])
    return wf.from_arrays(lat, lon, times, u10=u10, v10=v10, swh=swh, mwd_deg=mwd,
                          uo=np.broadcast_to(uo, u10.shape), vo=np.broadcast_to(vo, u10.shape))


def route_nodes(space, plan) -> list[int]:
    """Node index per line of a plan's route (nearest node on each line to the waypoint)."""
    lat = np.array([plan.legs[0]["lat0"]] + [leg["lat1"] for leg in plan.legs])
    lon = np.array([plan.legs[0]["lon0"]] + [leg["lon1"] for leg in plan.legs])
    d = (space.lat - lat[:, None]) ** 2 + (((space.lon - lon[:, None]) + 180.0) % 360.0 - 180.0) ** 2
    nodes = np.argmin(d, axis=1)
    nodes[0] = nodes[-1] = space.centre  # the ports: only the centre node of the end lines is used
    return [int(n) for n in nodes]
