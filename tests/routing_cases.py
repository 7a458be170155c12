"""Small routing instances shared by the routing tests: analytic weather fields and voyages.

Weather is built from closed-form functions of latitude, longitude (and hours, for moving storms) so each
test states what the ship meets; nothing here is taken from the code under test.
"""

from __future__ import annotations

import numpy as np

from pipeline.performance.model import reference_model
from pipeline.routing.engine import leg as lk
from pipeline.routing import weather_field as wf
from pipeline.routing.baseline import shortest_route
from pipeline.routing.problem import Instance
from pipeline.routing.solve import BfoaParams, RoutingProblem

MODEL = reference_model(14.0, 100.0, 1.5)  # STW = 0.14·rpm kn, fuel = 1.5·(rpm/100)³ t/h in calm water
FAST = BfoaParams(n_bacteria=8, n_chemo=6, n_cycles=8)
T0 = "2020-12-01T06"


def problem(dep, arr, hours, **kw) -> RoutingProblem:
    base = dict(dep=dep, arr=arr, depart_utc=T0, rta_utc=np.datetime64(T0) + np.timedelta64(int(hours * 60), "m"),
                model=MODEL, rpm_options=(70, 85, 100), n_lines=10, n_points=11, voyage_id="VTEST")
    base.update(kw)
    return RoutingProblem(**base)



def constant_speed(pr: RoutingProblem, space, weather) -> tuple[float, float, float]:
    """(rpm, hours, fuel) of the space's shortest route at the one constant rpm between the extremes arriving at the RTA:
    bisection on the hours of the route sailed at one setting (the slowest when early even at it, the fastest when
    late even at it). Worked out here, apart from the product's baseline, so that tests can hold plans against it."""
    inst = Instance.build(pr, space, weather)
    nodes = shortest_route(space)

    def sail(rpm):
        v = inst.vessel._replace(rpm_options=np.array([rpm]))
        ct, cf = np.empty(len(nodes)), np.empty(len(nodes))
        code, _ = lk.sail_route_nb(nodes, np.zeros(len(nodes) - 1, np.int64), 0, inst.graph, v, inst.wx,
                                   inst.objective, ct, cf)
        assert code == lk.OK
        return ct[-1] - inst.t_dep_h, cf[-1]

    lo, hi = min(pr.rpm_options), max(pr.rpm_options)
    if sail(lo)[0] <= pr.t_req_h:
        return (lo, *sail(lo))
    if sail(hi)[0] > pr.t_req_h:
        return (hi, *sail(hi))
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if sail(mid)[0] <= pr.t_req_h else (mid, hi)
    return (hi, *sail(hi))

def field(fn, lat=(10.0, 50.0), lon=(180.0, 250.0), step=0.5, hours=400, step_h=None) -> wf.WeatherField:
    """A field on a regular grid from fn(LAT, LON) → {var: 2-D array} (static), or, with `step_h`, from
    fn(LAT, LON, hours since 2020-12-01T00) at valid times every `step_h` hours; unset variables are zero."""
    la = np.arange(lat[0], lat[1] + 1e-9, step)
    lo = np.arange(lon[0], lon[1] + 1e-9, step)
    LA, LO = np.meshgrid(la, lo, indexing="ij")
    t0 = np.datetime64("2020-12-01T00")
    hrs = np.array([0, hours]) if step_h is None else np.arange(0, hours + 1e-9, step_h)
    times = t0 + (hrs * 3600).astype("timedelta64[s]")
    shape = (len(times),) + LA.shape
    kw = {k: np.zeros(shape) for k in ("u10", "v10", "swh", "mwd_deg", "uo", "vo")}
    for n, h in enumerate(hrs):
        vals = fn(LA, LO) if step_h is None else fn(LA, LO, float(h))
        for k, v in vals.items():
            kw[k][n] = np.broadcast_to(v, LA.shape)
    return wf.from_arrays(la, lo, times, **kw)


def wavy(seed):
    """Smooth, non-uniform wind, waves and currents (different for every seed)."""
    rng = np.random.default_rng(seed)
    k = rng.uniform(0.1, 0.4, 4)
    ph = rng.uniform(0.0, 2 * np.pi, 4)

    def fn(LA, LO):
        u = 8 * np.sin(k[2] * LO + ph[2])
        v = 6 * np.cos(k[3] * LA + ph[3])
        return dict(swh=2.5 + 2.0 * np.sin(k[0] * LA + ph[0]) * np.cos(k[1] * LO + ph[1]), u10=u, v10=v,
                    uo=0.6 * np.sin(2 * k[1] * LA + ph[0]), vo=0.4 * np.cos(2 * k[0] * LO + ph[2]),
                    mwd_deg=(np.degrees(np.arctan2(-u, -v)) + 20.0) % 360.0)
    return fn


def moving_storm(seed, lat0, lon0, drift_kn=(20.0, 5.0), radius_nm=150.0, hs_peak=9.0, wind_peak_ms=25.0):
    """A storm of Gaussian profile drifting east/north at drift_kn from (lat0, lon0 east 0..360) at hour 0, over a
    `wavy(seed)` background (waves and wind of the storm come from its centre's north-west)."""
    base = wavy(seed)

    def fn(LA, LO, h):
        out = base(LA, LO)
        clat = lat0 + drift_kn[1] * h / 60.0
        clon = lon0 + drift_kn[0] * h / (60.0 * np.cos(np.radians(clat)))
        d_nm = 60.0 * np.hypot(LA - clat, (LO - clon) * np.cos(np.radians(clat)))
        g = np.exp(-0.5 * (d_nm / radius_nm) ** 2)
        out["swh"] = out["swh"] + hs_peak * g
        out["u10"] = out["u10"] + wind_peak_ms * g * 0.7
        out["v10"] = out["v10"] - wind_peak_ms * g * 0.7
        return out
    return fn


def solve(problem: RoutingProblem, weather: wf.WeatherField, *, solver: str = "bfoa", options=None, params=None,
          limits=None, savings: bool = False, refine_split: int = 1, **kw):
    """pipeline.routing.solve.solve as the routing tests pin the solvers: the bare search (the defaults of the
    solver's options class, no engine-change limits, no savings split, the graph's plan not refined on a finer graph)
    unless a test passes them. The product's defaults, which solve() itself takes, are tested in test_solver_contract
    (API and CLI give the same plan); the refinement in test_refine_graph."""
    from pipeline.routing.solve import solve as product_solve
    from pipeline.routing.solvers import SOLVERS

    spec = SOLVERS.get(solver)  # an unknown name: solve() refuses it
    shorthand = spec is None or isinstance(params, spec.options)
    if options is None and not shorthand:
        options = spec.options()
    return product_solve(problem, weather, solver=solver, options=options, params=params,
                         limits=limits, savings=savings, refine_split=refine_split, **kw)
