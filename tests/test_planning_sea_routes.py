"""The planner on the global sea routes: distances through canals carry the canal's time, and a missing distance
removes only the arcs that need it."""

from __future__ import annotations

import math

import pytest

from pipeline.planning import brute, milp, problem
from pipeline.planning.problem import Contract, PlanVessel
from pipeline.planning.sea_distances import avoiding, canal_map, distance_map, hours, sea_distance

SHANGHAI = (31.0, 122.7)
ROTTERDAM = (52.0, 3.7)
SINGAPORE = (1.15, 103.75)


def test_a_distance_through_suez_carries_the_canal_time():
    d = sea_distance("Rotterdam", ROTTERDAM, "Shanghai", SHANGHAI)
    assert d.reason is None and d.passages.split(";") == [
        "dover", "casquets_w", "ushant_sw", "finisterre_s", "sao_vicente_se", "gibraltar", "suez", "bab_el_mandeb",
        "singapore"]
    assert d.dist_nm == pytest.approx(10489, rel=0.03)  # searoute 1.6.0: 10,489 NM
    assert d.canal_h == 14.0 + 12.0  # passages.py: Suez transit 14 h, waiting 12 h
    assert 100 < d.canal_nm < 130  # the canal (104 NM from Port Said to Port Tewfik) and its breakwater approaches
    # through Suez the voyage is (dist - canal) at the ship's speed plus the canal's hours
    assert hours(d.dist_nm, 12.0, (d.canal_nm, d.canal_h)) == pytest.approx((d.dist_nm - d.canal_nm) / 12.0 + 26.0)
    v = PlanVessel(1, "A", 50000, "Rotterdam", 0.0, port_h=24.0, laden_speed_kn=12.0, ballast_speed_kn=13.0)
    c = Contract("C1", "grain", 10000, 40000, "Rotterdam", "Shanghai", 0.0, 100.0, 1e6)
    data = problem.build([v], [c], distance_map([d]), 500.0, canals=canal_map([d]))
    assert data.per_vessel[0].dur_h[0] == pytest.approx(48.0 + (d.dist_nm - d.canal_nm) / 12.0 + 26.0)
    plan = milp.solve(data)
    (laden,) = [leg for s in plan.schedules for leg in s.legs if leg.kind == "laden"]
    assert laden.arrive_h - laden.depart_h == pytest.approx((d.dist_nm - d.canal_nm) / 12.0 + 26.0)
    # without the canal map the same distance would be sailed at 12 kn all the way: 24 h shorter than the truth
    bare = problem.build([v], [c], distance_map([d]), 500.0)
    assert data.per_vessel[0].dur_h[0] - bare.per_vessel[0].dur_h[0] == pytest.approx(26.0 - d.canal_nm / 12.0)


def test_a_missing_start_distance_leaves_the_cargo_to_be_lifted_after_another():
    # the vessel starts at X, which has no sea route to B's load port L2 (e.g. a port refused), but it can lift A
    # (X → L1 → D1) and then B (D1 → L2 → D2): before, B was taken away from the vessel altogether
    dist = {("X", "L1"): 100.0, ("L1", "D1"): 500.0, ("D1", "L2"): 200.0, ("L2", "D2"): 400.0,
            ("X", "L2"): math.nan, ("D1", "D2"): 300.0, ("L1", "L2"): 250.0, ("D2", "L1"): 600.0}
    v = PlanVessel(1, "A", 50000, "X", 0.0, port_h=12.0, laden_speed_kn=12.0, ballast_speed_kn=13.0, daily_cost=1000)
    a = Contract("A", "grain", 10000, 40000, "L1", "D1", 0.0, 200.0, 1e6)
    b = Contract("B", "grain", 10000, 40000, "L2", "D2", 0.0, 500.0, 1e6)
    data = problem.build([v], [a, b], dist, 500.0)
    va = data.per_vessel[0]
    assert va.contracts == [0, 1] and ("s", 1) not in va.arcs and (0, 1) in va.arcs
    assert 1 not in data.reasons
    for plan in (brute.solve(data), milp.solve(data)):
        assert plan.status == "optimal" and not plan.unassigned
        assert [s.sequence for s in plan.schedules] == [(0, 1)]
    # with no way into B at all (no start arc, no earlier cargo reaching it) it is left with a reason that says so
    cut = {**dist, ("D1", "L2"): math.nan}
    data = problem.build([v], [a, b], cut, 500.0)
    plan = milp.solve(data)
    assert list(plan.unassigned) == [1] and "no sea route from any start port" in plan.unassigned[1]


def test_distances_are_refused_with_the_layer_s_reason():
    land = sea_distance("Singapore", SINGAPORE, "Tokyo city", (35.68, 139.76))
    assert math.isnan(land.dist_nm) and "on land" in land.reason and land.canal_h == 0.0


@pytest.mark.slow
def test_a_fleet_avoiding_suez_plans_with_the_cape_distance(tmp_path, monkeypatch):
    """The fleet's avoided passages (JITROUTE_AVOID_PASSAGES, the setting its voyages are routed with) hold for the
    planner's distances too: Singapore–Rotterdam goes round the Cape, and the stored table keeps the Suez route."""
    from flows.jobs.planning import complete_distances
    from flows.settings import load_settings
    from storage import planning_store

    monkeypatch.setenv("JITROUTE_AVOID_PASSAGES", "suez")
    avoid = load_settings(data_root=tmp_path).routing.avoid_passages
    assert avoid == ("suez",)
    db = tmp_path / "warehouse.duckdb"
    ports = {"Rotterdam": ROTTERDAM, "Singapore": SINGAPORE}
    (suez,) = complete_distances(db, ports, {("Singapore", "Rotterdam")})
    (cape,) = complete_distances(db, ports, {("Singapore", "Rotterdam")}, avoid)
    assert "suez" in suez.passages.split(";") and suez.canal_h == 26.0
    assert "suez" not in (cape.passages or "") and cape.canal_h == 0.0 and cape.canal_nm == 0.0
    # searoute 1.6.0 (bench/sea_routes_searoute.json): round the Cape of Good Hope 11,839 NM, through Suez 8,351 NM
    assert cape.dist_nm == pytest.approx(11839, rel=0.03) and suez.dist_nm == pytest.approx(8351, rel=0.03)
    stored = planning_store.load_port_distances(db)
    assert len(stored) == 1 and "suez" in stored["passages"][0]
    # a pair whose route sails none of the avoided passages is the stored one
    assert avoiding([suez], {"panama"}) == [suez]
