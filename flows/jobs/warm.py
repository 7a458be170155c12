"""`jitroute warm`: compile the refit, fleet-planning and routing kernels into numba's cache ahead of the first nightly.

numba compiles each kernel on its first call and keeps the machine code in its cache folder, one per digest of the
pipeline's sources (pipeline.compile_cache: by default pipeline/__pycache__/numba/jitroute-<digest>), so later
processes of the same code load it in milliseconds. Without this step the first voyage on
every dask worker pays the compilation (minutes on 2 cores) in silence. `make install` runs it; it refits a small
generated fleet in a throw-away data root, plans a small generated fleet by column generation and routes one short demo voyage in calm water with each solver asked for, through the same code as a fleet run's worker (exports
too), then records a stamp of the sources it compiled, so a fleet run can tell (and say) when the cache is cold.
"""

from __future__ import annotations

import json
import logging
import time
from pathlib import Path

import numpy as np

LOG = logging.getLogger("jitroute.warm")

from pipeline.compile_cache import PIPELINE, cache_dir, sources_digest


def stamp_path() -> Path:
    """Where the stamp lives: in numba's cache folder for the sources as they are now."""
    return cache_dir() / "jitroute-warm.json"


def remove_in_tree_cache() -> int:
    """Remove the kernels numba cached beside the sources (pipeline/**/__pycache__/*.nbi, *.nbc) before the cache
    was keyed on the sources' digest: nothing loads them any more. Returns how many files were removed."""
    n = 0
    for pattern in ("*.nbi", "*.nbc"):
        for p in PIPELINE.glob(f"**/__pycache__/{pattern}"):
            p.unlink(missing_ok=True)
            n += 1
    return n


def is_warm(solver: str = "bfoa") -> bool:
    """The kernels of `solver` were compiled for the pipeline sources as they are now."""
    try:
        stamp = json.loads(stamp_path().read_text())
    except (OSError, ValueError):
        return False
    return stamp.get("digest") == sources_digest() and solver in stamp.get("solvers", [])


def cold_cache_warning(solver: str) -> str | None:
    """The line a fleet run logs when its solver's kernels are not in the cache yet (None: they are)."""
    if is_warm(solver):
        return None
    return (f"the {solver} routing kernels are not compiled for this code yet: the first voyage on each dask worker "
            "compiles them into numba's cache (minutes on 2 cores, once); `jitroute warm` (run by `make install`) "
            "does it ahead")


def _warm_job(solver: str):
    from pipeline.routing.job import RouteJob, RoutingOptions
    from pipeline.synthetic.fleet import PORTS, true_model

    model = true_model(14.0, 105.0, 1.4, np.random.default_rng(0))
    (la0, lo0), (la1, lo1) = PORTS["Keelung"], PORTS["Naha"]
    depart = np.datetime64("2020-12-01T13:00", "s")
    voyage = {"voyage_id": "warm", "imo": 9140607, "dep_name": "Keelung", "dep_lat": la0, "dep_lon": lo0,
              "arr_name": "Naha", "arr_lat": la1, "arr_lon": lo1, "depart_utc": depart.item(),
              "rta_utc": (depart + np.timedelta64(30, "h")).item(), "draft_m": 11.0, "trim_m": 0.5,
              "rpm_options": [63.0, 73.5, 84.0, 94.5, 105.0], "max_hs_m": 7.0, "max_wind_kn": 50.0}
    vessel = {"imo": 9140607, "name": "WARM", "rpm_max": 105.0}
    return RouteJob(voyage=voyage, vessel=vessel, model=model.to_json(), run_id="warm", cycle=None, exports=True,
                    options=RoutingOptions(solver=solver))


def _warm_refit() -> None:
    """Import a small generated fleet into a throw-away data root and refit it: compiles the fit kernels
    (pipeline/performance) a nightly's refit needs."""
    import tempfile

    from flows.jobs.refit import import_fleet_folder, import_noon_file, refit_job
    from pipeline.synthetic.fleet import generate_fleet, write_fleet

    with tempfile.TemporaryDirectory(prefix="jitroute-warm-") as tmp:
        root = Path(tmp) / "data"
        write_fleet(generate_fleet("2020-12-01T00", n_vessels=2, days=120, seed=1), Path(tmp) / "fleet")
        import_fleet_folder(folder=str(Path(tmp) / "fleet"), data_root=str(root))
        import_noon_file(path=str(Path(tmp) / "fleet" / "noon_reports.csv"), data_root=str(root))
        refit_job(data_root=str(root))


def _warm_planning() -> None:
    """Plan a small generated fleet by column generation: compiles the fleet planner's pricing kernel (colgen.py)."""
    from pipeline.planning import milp, problem
    from pipeline.synthetic.contracts import random_instance

    vessels, contracts, dist = random_instance(3, 8, seed=1, horizon_days=20, n_ports=5)
    milp.solve(problem.build(vessels, contracts, dist, fuel_price=600.0), max_labels=3)  # too few: column generation


def warm_job(solvers: list[str] | None = None) -> dict:
    """Route one short voyage with each solver (default the fleet's, bfoa) so numba compiles and caches every kernel
    a fleet run needs; returns {solver: seconds} and whether anything had to be compiled."""
    from flows.jobs.route_worker import route_one

    solvers = list(solvers or ["bfoa"])
    remove_in_tree_cache()
    cold = [s for s in solvers if not is_warm(s)]
    if cold:
        LOG.info("compiling the routing kernels (%s) into numba's cache under %s unless they are there already: "
                 "a few minutes on 2 cores the first time", ", ".join(cold), cache_dir())
    seconds = {}
    t0 = time.monotonic()
    _warm_refit()
    seconds["refit"] = round(time.monotonic() - t0, 1)
    LOG.info("refit ready (%.1f s)", seconds["refit"])
    t0 = time.monotonic()
    _warm_planning()
    seconds["planning"] = round(time.monotonic() - t0, 1)
    LOG.info("fleet planner ready (%.1f s)", seconds["planning"])
    for solver in solvers:
        t0 = time.monotonic()
        res = route_one(_warm_job(solver), None)
        seconds[solver] = round(time.monotonic() - t0, 1)
        if res["route"]["status"] not in ("ok", "late"):
            raise RuntimeError(f"warming {solver}: the test voyage was not routed: {res['route']['reason']}")
        LOG.info("%s ready (%.1f s)", solver, seconds[solver])
    try:
        done = set(json.loads(stamp_path().read_text()).get("solvers", [])) if stamp_path().exists() and not cold else set()
    except (OSError, ValueError):
        done = set()
    stamp_path().parent.mkdir(parents=True, exist_ok=True)
    stamp_path().write_text(json.dumps({"digest": sources_digest(), "solvers": sorted(done | set(solvers))}) + "\n")
    return {"seconds": seconds, "compiled": cold}
