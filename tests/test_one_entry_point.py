"""The Python API and the command line plan a voyage through one function with one set of defaults: the
product's (pipeline.routing.options: RoutingOptions and DEFAULT_SOLVER_OPTIONS, the registry's defaults)."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from pipeline.routing.options import DEFAULT_SOLVER_OPTIONS, RoutingOptions


def test_solve_takes_the_products_defaults():
    from pipeline.routing import solve as api
    from pipeline.routing.solvers import SOLVERS

    dp = api.product_options("dp")
    assert dp == SOLVERS["dp"].make_options(DEFAULT_SOLVER_OPTIONS["dp"])
    assert (dp.gap, dp.slot_h, dp.max_wait_h, dp.wait_free_first) == (1e-3, 1.0, 6.0, True)  # label + grid DP
    # the swarm's plan is polished once when the finer corridors walk it on, as often as it gains on the graph alone
    assert api.product_options("bfoa") == replace(SOLVERS["bfoa"].options(), polish_rounds=1)
    assert api.product_options("bfoa", refine_split=1) == SOLVERS["bfoa"].options()
    assert RoutingOptions(solver="bfoa", refine_split=1, solver_options={"polish_rounds": "3"}).solver_overrides() == {
        "polish_rounds": "3"}
    defaults = api.solve.__kwdefaults__
    product = RoutingOptions()
    assert defaults["solver"] == product.solver and defaults["seed"] == product.seed
    assert defaults["limits"] == product.limits and defaults["limits"].active
    assert defaults["continuous"] == product.continuous_speed and defaults["savings"] is True


@pytest.mark.slow  # refits a generated vessel and plans one voyage twice with the grid DP
def test_the_api_and_the_cli_give_the_same_plan(tmp_path):
    """`solve(problem, weather, solver="dp")` and `jitroute route --solver dp` on the same voyage (calm water)."""
    from typer.testing import CliRunner

    from cli.fleet import _import_fleet
    from cli.main import app
    from flows.jobs.refit import refit_job
    from pipeline.performance.model import model_from_stored
    from pipeline.routing.job import calm_weather
    from pipeline.routing.solve import solve
    from pipeline.routing.voyage import problem_from_voyage
    from pipeline.synthetic.fleet import PORTS, generate_fleet, write_fleet
    from storage import fleet_store

    root = tmp_path / "data"
    fleet = generate_fleet("2020-12-01T00", n_vessels=1, days=120, seed=1)
    write_fleet(fleet, tmp_path / "fleet")
    _import_fleet(tmp_path / "fleet", root)
    refit_job(data_root=str(root))
    warehouse = root / "warehouse.duckdb"
    vessel = fleet_store.load_vessels(warehouse).iloc[0].to_dict()
    imo = int(vessel["imo"])
    (la0, lo0), (la1, lo1) = PORTS["Keelung"], PORTS["Naha"]
    depart, rta = "2020-12-01T13", "2020-12-02T19"

    res = CliRunner().invoke(app, ["route", "--from", f"{la0},{lo0}", "--to", f"{la1},{lo1}", "--depart", depart,
                                   "--rta", rta, "--imo", str(imo), "--calm", "--solver", "dp", "--json",
                                   "--data", str(root)])
    assert res.exit_code == 0, res.output
    cli_plan = json.loads(res.stdout[res.stdout.index("{"):])

    voyage = {"voyage_id": "adhoc", "imo": imo, "dep_lat": la0, "dep_lon": lo0, "arr_lat": la1, "arr_lon": lo1,
              "depart_utc": np.datetime64(depart, "s"), "rta_utc": np.datetime64(rta, "s"), "rpm_options": None}
    model = model_from_stored(fleet_store.active_model(warehouse, imo), imo)
    problem = problem_from_voyage(voyage, model, rpm_max=vessel.get("rpm_max"), barred_rpm=vessel.get("barred_rpm"))
    api_plan = solve(problem, calm_weather(problem), solver="dp").to_json()

    for p in (cli_plan, api_plan):
        p.pop("runtime_s", None)
    assert api_plan["status"] in ("ok", "late") and api_plan["legs"]
    assert api_plan == cli_plan
