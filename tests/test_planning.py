"""Fleet operation planning: input validation, sea distances, the exact planner against brute force, plans stored
as voyages and re-planning, the `plan fleet` command."""

from __future__ import annotations

import dataclasses
import json
import math

import duckdb
import numpy as np
import pandas as pd
import pytest

from pipeline.planning import brute, milp, problem
from pipeline.planning.inputs import validate_availability, validate_contracts, validate_ports
from pipeline.planning.work_budget import WorkBudget
from pipeline.planning.problem import Contract, PlanVessel
from pipeline.synthetic.contracts import random_instance

# ---------------------------------------------------------------------------------------------- the planner


def _with_ends(vessels, rng):
    """Give some vessels an end port and time, so the end constraints are exercised."""
    out = []
    for v in vessels:
        if rng.random() < 0.5:
            v = dataclasses.replace(v, end_port=v.start_port, end_h=float(rng.uniform(15, 40)) * 24)
        out.append(v)
    return out


@pytest.mark.slow
def test_the_milp_plan_costs_what_brute_force_finds_on_many_small_random_instances():
    rng = np.random.default_rng(5)
    n_assigned = 0
    for seed in range(150):
        n_v, n_c = int(rng.integers(1, 4)), int(rng.integers(2, 7))
        vessels, contracts, dist = random_instance(n_v, n_c, seed=seed, horizon_days=20, n_ports=5)
        data = problem.build(_with_ends(vessels, rng), contracts, dist, fuel_price=600.0)
        exact, ref = milp.solve(data), brute.solve(data)
        assert exact.status == "optimal"
        assert exact.cost == pytest.approx(ref.cost, rel=1e-9), f"seed {seed}"
        lifted = [j for s in exact.schedules for j in s.sequence]
        assert len(lifted) == len(set(lifted)) and len(lifted) + len(exact.unassigned) == n_c
        n_assigned += len(lifted)
        bound = milp.arc_lower_bound(data)
        assert bound <= ref.cost * (1 + 1e-9) + 1e-6
    assert n_assigned > 150  # the instances are not trivially "leave everything"


@pytest.mark.slow
def test_column_generation_proves_a_bound_no_higher_than_the_optimum_when_enumeration_is_capped():
    for seed in range(12):
        vessels, contracts, dist = random_instance(3, 7, seed=seed, horizon_days=20, n_ports=5)
        data = problem.build(vessels, contracts, dist, fuel_price=600.0)
        best = brute.solve(data).cost
        capped = milp.solve(data, max_labels=3)  # forces column generation
        assert capped.cost >= best - 1e-6
        assert capped.cost * (1 - capped.gap) <= best * (1 + 1e-9) + 1e-6, f"seed {seed}"
        assert capped.status == ("optimal" if capped.gap <= 1e-9 else "feasible")


def test_column_generation_reaches_an_lp_bound_never_above_the_optimum_and_prices_every_negative_column():
    """The set-partitioning LP bound (colgen.generate from no columns at all) against brute force on many small
    instances, some with end ports; and the compiled pricing against every column brute force enumerates, under
    random duals: its least reduced cost equals theirs (pricing may repeat a contract, but these load windows are
    shorter than two contracts' port time, so no path can), and every column it returns has a negative reduced
    cost."""
    from pipeline.planning import colgen

    rng = np.random.default_rng(17)
    tight = 0
    for seed in range(60):
        vessels, contracts, dist = random_instance(int(rng.integers(1, 4)), int(rng.integers(2, 8)), seed=100 + seed,
                                                   horizon_days=20, n_ports=5)
        data = problem.build(_with_ends(vessels, rng), contracts, dist, fuel_price=600.0)
        best = brute.solve(data).cost
        _, bound, converged, _ = colgen.generate(data, [])
        assert converged
        assert bound <= best * (1 + 1e-9) + 1e-6, f"seed {seed}"
        tight += bound >= best * (1 - 1e-9)
        pi = -rng.uniform(0, 1.2, len(contracts)) * np.array([c.penalty for c in contracts])
        for k in range(len(vessels)):
            mu = -float(rng.uniform(0, 2e5))
            exact = min([0.0] + [c - sum(contracts[j].penalty + pi[j] for j in seq) - mu
                                 for c, seq in brute.best_per_subset(data, k).values() if seq])
            least, cols = colgen.price(data, k, pi, mu, max_new=1000)
            assert least == pytest.approx(exact, rel=1e-9, abs=1e-6), f"seed {seed} vessel {k}"
            assert bool(cols) == (exact < -colgen.EPS)
            for col in cols:
                assert col.cost - sum(contracts[j].penalty + pi[j] for j in col.sequence) - mu < 0
    assert tight > 30  # small instances mostly have LP = optimum


@pytest.mark.slow
def test_the_exact_finish_reaches_the_optimum_where_the_lp_bound_is_below_it():
    """Column generation forced (max_labels=3), then the MILP over every column within the gap: proven optimal and
    equal to the reference — brute force on small instances, HiGHS on the MILP over every enumerated column on
    instances with wider windows, where the LP bound is often strictly below the optimum (so rounding or a dive
    alone need not be optimal, and the LP bound alone proves nothing)."""
    from pipeline.planning import colgen
    from pipeline.planning.routes import vessel_columns

    rng = np.random.default_rng(23)
    fractional = 0
    for seed in range(40):
        small = seed % 2 == 0
        if small:
            vessels, contracts, dist = random_instance(int(rng.integers(2, 4)), int(rng.integers(4, 7)),
                                                       seed=300 + seed, horizon_days=20, n_ports=5)
        else:
            vessels, contracts, dist = random_instance(5, 20, seed=700 + seed, horizon_days=25, n_ports=8,
                                                       window_days=6)
        data = problem.build(_with_ends(vessels, rng) if small else vessels, contracts, dist, fuel_price=600.0)
        if small:
            best = brute.solve(data).cost
        else:
            every = [col for k in range(len(vessels)) for col in vessel_columns(data, k)[0]]
            sequences, _, finished = milp._set_partitioning(data, every, WorkBudget(), 0.0, 1.0)
            assert finished
            best = problem.assemble(data, sequences, solver="t", status="", gap=0.0, runtime_s=0.0).cost
        _, bound, _, _ = colgen.generate(data, [])
        fractional += bound < best - 1.0
        plan = milp.solve(data, max_labels=3)
        assert plan.status == "optimal" and plan.gap == 0.0, f"seed {seed}"
        assert plan.cost == pytest.approx(best, rel=1e-9), f"seed {seed}"
    assert fractional >= 5  # the case the finish is for is exercised


def test_columns_within_a_reduced_cost_are_exactly_those_brute_force_finds():
    """gap_columns.vessel_columns_within under random duals and slacks: the same sets of contracts as brute force
    with reduced cost ≤ the slack, each at its least cost (the completion bound never prunes one of them)."""
    from pipeline.planning import gap_columns

    rng = np.random.default_rng(29)
    n_sets = n_cut = 0
    for seed in range(80):
        vessels, contracts, dist = random_instance(int(rng.integers(1, 3)), int(rng.integers(3, 8)), seed=500 + seed,
                                                   horizon_days=20, n_ports=5)
        data = problem.build(_with_ends(vessels, rng), contracts, dist, fuel_price=600.0)
        pi = -rng.uniform(0, 1.2, len(contracts)) * np.array([c.penalty for c in contracts])
        for k in range(len(vessels)):
            mu = -float(rng.uniform(0, 2e5))
            rc = {key: c - sum(contracts[j].penalty + pi[j] for j in seq) - mu
                  for key, (c, seq) in brute.best_per_subset(data, k).items() if seq}
            ranked = sorted(rc.values()) + [np.inf]  # a slack between two reduced costs: no tie to round
            cut = int(rng.integers(1, len(ranked))) if rc else 0
            slack = 0.5 * (ranked[cut - 1] + ranked[cut]) if 0 < cut < len(ranked) - 1 else ranked[0] + 1.0
            cols, complete = gap_columns.vessel_columns_within(data, k, pi, mu, slack)
            assert complete
            got = {frozenset(c.sequence): c.cost for c in cols}
            want = {key: brute.best_per_subset(data, k)[key][0] for key, r in rc.items() if r <= slack}
            assert got.keys() == want.keys(), f"seed {seed} vessel {k}"
            for key, cost in want.items():
                assert got[key] == pytest.approx(cost, rel=1e-9), f"seed {seed} vessel {k}"
            n_sets += len(want)
            n_cut += len(want) < len(rc)
    assert n_sets > 100 and n_cut > 20  # the slack does cut


def test_local_search_from_an_empty_or_a_worse_plan_ends_feasible_between_the_optimum_and_its_start():
    from pipeline.planning import local_search
    from pipeline.planning.problem import assemble

    rng = np.random.default_rng(9)
    gained = 0
    for seed in range(40):
        vessels, contracts, dist = random_instance(int(rng.integers(2, 4)), int(rng.integers(3, 7)), seed=seed,
                                                   horizon_days=20, n_ports=5)
        data = problem.build(vessels, contracts, dist, fuel_price=600.0)
        best = brute.solve(data)
        worst_first = {s.k: s.sequence[:1] for s in best.schedules}  # a worse plan: each vessel keeps its first only
        for start in ({}, worst_first):
            before = assemble(data, start, solver="t", status="", gap=0.0, runtime_s=0.0)
            after = assemble(data, local_search.improve(data, start), solver="t", status="", gap=0.0, runtime_s=0.0)
            assert best.cost - 1e-6 <= after.cost <= before.cost + 1e-6, f"seed {seed}"
            gained += after.cost < before.cost - 1e-6
    assert gained > 20  # the moves do something


def test_a_hand_computed_plan():
    # start A at t=0; contract: load B (120 NM from A), discharge C (240 NM), window [24 h, 48 h]; 12 kn both ways
    v = PlanVessel(imo=9074729, name="X", dwt_t=50_000, start_port="A", start_h=0.0, port_h=12.0, daily_cost=2400.0,
                   laden_speed_kn=12.0, ballast_speed_kn=12.0, laden_fuel_t_per_nm=0.1, ballast_fuel_t_per_nm=0.05)
    c = Contract("K1", "grain", 40_000, 45_000, "B", "C", early_h=24.0, late_h=48.0, penalty=1e6)
    data = problem.build([v], [c], {("A", "B"): 120.0, ("B", "C"): 240.0, ("A", "C"): 300.0}, fuel_price=500.0)
    plan = milp.solve(data)
    (s,) = plan.schedules
    # ballast 10 h at 12 kn, 14 h to spare before loading at 24 h: it leaves at 24 - 10/0.7 h and sails 0.7 × 12 kn,
    # on 0.7² of the fuel per NM (no curve: ∝ speed²); load 12 h, sail 20 h, discharge 12 h: busy 44 h, ends at 68 h
    assert s.load_start_h == (24.0,) and s.end_h == pytest.approx(68.0)
    assert s.fuel_t == pytest.approx(120 * 0.05 * 0.49 + 240 * 0.1)
    assert s.out_of_service_days == pytest.approx((68.0 - 44.0) / 24.0)
    assert plan.cost == pytest.approx(500.0 * s.fuel_t + 2400.0 * 1.0)
    assert [leg.kind for leg in s.legs] == ["ballast", "laden"]
    assert s.legs[0].depart_h == pytest.approx(24.0 - 10.0 / 0.7) and s.legs[0].fuel_t == pytest.approx(2.94)
    assert s.legs[0].arrive_h == 24.0 and s.legs[1].depart_h == 36.0 and s.legs[1].lift_t == 45_000
    # with 4 h to spare it sails 120 NM in 14 h (8.57 kn); with none, at 12 kn
    assert v.ballast_leg(120.0, 10.0, 24.0) == pytest.approx((10.0, 120 * 0.05 * (120 / 14 / 12) ** 2))
    assert v.ballast_leg(120.0, 14.0, 24.0) == pytest.approx((14.0, 6.0))
    curved = dataclasses.replace(v, ballast_curve=((8.0, 0.02), (12.0, 0.05)))
    assert curved.ballast_leg(120.0, 10.0, 24.0)[1] == pytest.approx(120 * (0.02 + 0.03 * (120 / 14 - 8) / 4))
    # a penalty below the cost leaves it, saying why
    cheap = problem.build([v], [dataclasses.replace(c, penalty=1000.0)], {("A", "B"): 120.0, ("B", "C"): 240.0},
                          fuel_price=500.0)
    left = milp.solve(cheap)
    assert not left.schedules and left.cost == 1000.0 and "penalty" in left.unassigned[0]


def test_each_contract_no_vessel_can_lift_gets_its_reason_and_the_others_are_planned():
    v = PlanVessel(imo=9074729, name="X", dwt_t=50_000, start_port="A", start_h=0.0, cargo_types=frozenset({"grain"}),
                   ports=frozenset({"A", "B", "C", "D"}))
    good = Contract("OK", "grain", 40_000, 45_000, "B", "C", 24.0, 96.0, 1e6)
    cons = [good,
            dataclasses.replace(good, code="HEAVY", min_t=60_000, max_t=70_000),
            dataclasses.replace(good, code="COAL", cargo_type="coal"),
            dataclasses.replace(good, code="PORT", discharge_port="E"),
            dataclasses.replace(good, code="LATE", early_h=0.0, late_h=1.0),
            dataclasses.replace(good, code="NOSEA", discharge_port="D")]
    dist = {("A", "B"): 120.0, ("B", "C"): 240.0, ("A", "C"): 300.0, ("B", "E"): 100.0, ("B", "D"): math.nan}
    plan = milp.solve(problem.build([v], cons, dist, fuel_price=500.0))
    assert [cons[j].code for j in plan.schedules[0].sequence] == ["OK"]
    why = {cons[j].code: r for j, r in plan.unassigned.items()}
    assert "deadweight 50000 t below the minimum 60000 t" in why["HEAVY"]
    assert "cannot carry coal" in why["COAL"]
    assert "may not call E" in why["PORT"]
    assert "before the window closes" in why["LATE"]
    assert "no sea route B → D" in why["NOSEA"]


def test_a_medium_fleet_is_planned_exactly_in_seconds():
    vessels, contracts, dist = random_instance(6, 16, seed=2)
    plan = milp.solve(problem.build(vessels, contracts, dist, fuel_price=600.0), time_limit_s=30)
    assert plan.status == "optimal" and plan.gap == 0.0 and plan.runtime_s < 10


# ---------------------------------------------------------------------------------------------- validation


def _raw(rows):
    return pd.DataFrame(rows, dtype=object).astype(str).replace("None", "")


def test_contract_rows_are_refused_with_their_reason_and_nothing_else_is_lost():
    base = dict(code="K1", cargo_type="grain", min_t="40000", max_t="45000", load_port="Busan", discharge_port="Qingdao",
                early_utc="2020-12-05T00:00Z", late_utc="2020-12-08T00:00Z", penalty="")
    rows = [base,
            {**base, "code": "K2", "late_utc": "2020-12-05T00:00Z"},
            {**base, "code": "K3", "early_utc": "2020-11-01", "late_utc": "2020-11-03"},
            {**base, "code": "K4", "load_port": "Atlantis"},
            {**base, "code": "K5", "min_t": "300000", "max_t": "310000"},
            {**base, "code": "K6", "cargo_type": "uranium"},
            {**base, "code": "K7", "discharge_port": "Busan"},
            {**base, "code": "K8", "min_t": "50000"},
            {**base, "code": "K9", "early_utc": "05/12/2020"},
            {**base, "code": "KD"}, {**base, "code": "KD"},
            {**base, "code": "a/b"}]
    good, bad = validate_contracts(_raw(rows), as_of=pd.Timestamp("2020-12-01"), ports={"Busan", "Qingdao"},
                                   max_dwt_t=200_000, cargo_types={"grain", "coal"}, source="contracts.csv")
    assert list(good["code"]) == ["K1"] and good["early_utc"].iloc[0] == pd.Timestamp("2020-12-05")
    why = dict(zip(bad["code"].where(bad["code"].notna(), "?") + "#" + bad.index.astype(str), bad["reason"]))
    reasons = list(bad["reason"])
    assert len(bad) == len(rows) - 1
    assert any("zero length" in r for r in reasons)
    assert any("window closed before the planning time" in r for r in reasons)
    assert any("unknown load_port" in r for r in reasons)
    assert any("above every vessel's deadweight" in r for r in reasons)
    assert any("no vessel may carry this cargo type" in r for r in reasons)
    assert any("load_port and discharge_port are the same" in r for r in reasons)
    assert any("min_t above max_t" in r for r in reasons)
    assert any("ambiguous timestamp" in r for r in reasons)
    assert sum("duplicate code" in r for r in reasons) == 2
    assert any("path separator" in r for r in reasons), why
    assert set(bad["source_file"]) == {"contracts.csv"} and bad["raw"].str.contains("|", regex=False).all()


def test_ports_on_land_and_availability_without_a_window_are_refused():
    ports = _raw([dict(port="Busan", lat="34.95", lon="129.15"), dict(port="Tokyo city", lat="35.68", lon="139.76"),
                   dict(port="Nowhere", lat="95", lon="0"), dict(port="Yokohama", lat="35.3", lon="139.8")])
    good, bad = validate_ports(ports)
    assert list(good["port"]) == ["Busan"]
    assert "on land" in bad["reason"].iloc[0] and "out of range lat" in bad["reason"].iloc[1]
    # 35.3,139.8 is at sea but on the corner of a land cell (Futtsu): no leg can leave it; the suggestion can
    (why,) = bad.loc[bad["port"] == "Yokohama", "reason"]
    assert why.startswith("touches land in the land mask")
    from pipeline.planning.sea_distances import sea_distance

    lat, lon = (float(x) for x in why.split("e.g. ")[1].split(" ")[0].split(","))
    assert math.isnan(sea_distance("Yokohama", (35.3, 139.8), "Nagoya", (34.5, 137.0)).dist_nm)
    assert sea_distance("Yokohama", (lat, lon), "Nagoya", (34.5, 137.0)).reason is None
    base = dict(imo="9074729", from_utc="2020-12-01", from_port="Busan", until_utc="", until_port="", ports="",
                cargo_types="grain;coal", daily_cost="9000")
    avail = _raw([base, {**base, "imo": "9176187", "until_utc": "2020-11-30"}, {**base, "imo": "9074728"},
                  {**base, "imo": "9176187", "from_port": "Atlantis"}, {**base, "imo": "9176187", "ports": "Busan;Atlantis"}])
    good, bad = validate_availability(avail, known_imos={9074729, 9176187}, ports={"Busan"})
    assert list(good["imo"]) == [9074729] and good["cargo_types"].iloc[0] == "grain;coal" and good["ports"].iloc[0] is None
    assert [r.split(":")[0] for r in bad["reason"]] == [
        "available nowhere", "IMO number fails its check digit", "unknown from_port (not in the ports file)",
        "unknown port(s) in ports"]


# ---------------------------------------------------------------------------------------------- distances, fuel


def test_sea_distances_follow_the_routing_graph_and_a_port_on_land_is_reported():
    from pipeline.planning.sea_distances import sea_distance

    d = sea_distance("Busan", (34.95, 129.15), "Shanghai", (30.9, 122.75))
    assert d.reason is None and d.gc_nm <= d.dist_nm < 1.3 * d.gc_nm
    land = sea_distance("Busan", (34.95, 129.15), "Tokyo city", (35.68, 139.76))
    assert math.isnan(land.dist_nm) and "on land" in land.reason


def test_fuel_per_nm_from_design_data_follows_the_cubic_law():
    from pipeline.performance.model import reference_model
    from pipeline.planning.fuel import speed_and_fuel_per_nm

    m = reference_model(14.0, 100.0, 1.4)
    s12, f12 = speed_and_fuel_per_nm(m, 12.0, 10.0, 100.0)
    s7, f7 = speed_and_fuel_per_nm(m, 7.0, 10.0, 100.0)
    assert s12 == pytest.approx(12.0) and f12 / f7 == pytest.approx((12.0 / 7.0) ** 2, rel=1e-6)
    assert speed_and_fuel_per_nm(m, 20.0, 10.0, 100.0)[0] == pytest.approx(14.0)  # capped at rpm_max


def test_laden_fuel_and_speed_follow_the_weight_lifted():
    from pipeline.performance.model import PerformanceModel
    from pipeline.planning.fuel import ballast_curve, draft_at, laden_curve

    # physical form: speed falls 0.2 kn per metre of draft, fuel rate grows 5 % per metre at the same rpm
    m = PerformanceModel(form="physical", speed_coef=np.array([2.5, 0.12, -0.2, 0.0, 0.0, 0.0, 0.0]),
                         fuel_coef=np.array([0.0, 1.0, 0.05, 0.0, 0.0, 0.0]))
    assert draft_at(30_000, 60_000, 12.0, 6.0) == pytest.approx(9.0) and draft_at(90_000, 60_000, 12.0, 6.0) == 12.0
    curve = laden_curve(m, 12.0, 60_000, 12.0, 6.0, 100.0)
    assert [w for w, _, _ in curve] == [15_000, 30_000, 45_000, 60_000]
    fuel = [f for _, _, f in curve]
    assert all(s == pytest.approx(12.0) for _, s, _ in curve) and fuel == sorted(fuel) and fuel[-1] > 1.1 * fuel[0]
    v = PlanVessel(imo=1, name="a", dwt_t=60_000, start_port="A", start_h=0.0, laden_curve=curve)
    assert v.laden_at(37_500) == pytest.approx((12.0, 0.5 * (fuel[1] + fuel[2])))
    assert v.laden_at(1_000) == pytest.approx(curve[0][1:]) and v.laden_at(1e9) == pytest.approx(curve[-1][1:])
    slow = ballast_curve(m, 12.0, 6.0, 100.0, 0.7)
    assert [s for s, _ in slow] == pytest.approx([8.4, 9.6, 10.8, 12.0]) and [f for _, f in slow] == sorted(f for _, f in slow)
    # in a plan: the same contract lifted at half the weight costs the half-weight fuel and sails at its speed
    c = Contract("C1", "grain", 10_000, 30_000, "A", "B", 0.0, 100.0, penalty=1e9)
    data = problem.build([v], [c], {("A", "B"): 600.0}, fuel_price=500.0)
    s = problem.schedule(data, 0, (0,))
    assert s.fuel_t == pytest.approx(600.0 * v.laden_at(30_000)[1]) and s.legs[0].lift_t == 30_000


# ---------------------------------------------------------------------------------------------- end to end


@pytest.fixture(scope="module")
def planned(tmp_path_factory):
    """A data root with a 4-vessel demo fleet, planned once as of 2020-12-01."""
    from flows.jobs.planning import plan_fleet_job
    from flows.jobs.refit import import_fleet_folder
    from pipeline.synthetic.contracts import write_demo_planning
    from pipeline.synthetic.fleet import generate_fleet, write_fleet

    root = tmp_path_factory.mktemp("plan") / "data"
    fl = generate_fleet("2020-12-01T00", n_vessels=4, days=30, seed=3)
    write_fleet(fl, root.parent / "fleet")
    import_fleet_folder(str(root.parent / "fleet"), data_root=str(root))
    files = write_demo_planning(fl.vessels, "2020-12-01T00", root.parent / "plan", n_contracts=6, seed=4,
                                ports=("Busan", "Shanghai", "Qingdao", "Kaohsiung", "Keelung"))
    first = plan_fleet_job(files["contracts"], files["availability"], files["ports"], "2020-12-01T00:00Z",
                           data_root=str(root))
    return root, files, first


@pytest.mark.slow  # the planning job end to end on an imported demo fleet
def test_a_plan_is_stored_with_its_legs_and_its_voyages(planned):
    root, files, s = planned
    assert s["solve_status"] == "optimal" and s["n_assigned"] >= 1
    assert s["contracts_refused"] == [{"code": "K007", "reason": "window of zero length: late_utc is not after early_utc"}]
    con = duckdb.connect(str(root / "warehouse.duckdb"), read_only=True)
    legs = con.execute("SELECT * FROM fleet_plan_legs WHERE plan_id = ? ORDER BY imo, seq", [s["plan_id"]]).fetchdf()
    voy = con.execute("SELECT * FROM voyages WHERE plan_id = ? ORDER BY voyage_id", [s["plan_id"]]).fetchdf()
    assert len(legs) == len(voy) == s["voyages_added"] and set(voy["status"]) == {"planned"}
    both = legs.merge(voy, on="voyage_id")
    assert (both["depart_utc_x"] == both["depart_utc_y"]).all() and (both["arrive_utc"] == both["rta_utc"]).all()
    assert (both["from_port"] == both["dep_name"]).all()
    stopped_by = con.execute("SELECT stopped_by FROM fleet_plans WHERE plan_id = ?", [s["plan_id"]]).fetchone()[0]
    assert stopped_by == s["stopped_by"] == "proven optimal"
    n_left = con.execute("SELECT count(*) FROM fleet_plan_unassigned WHERE plan_id = ?", [s["plan_id"]]).fetchone()[0]
    assert n_left == s["n_unassigned"] and s["n_assigned"] + n_left == s["n_contracts"] == 6
    n_dist = con.execute("SELECT count(*) FROM port_distances").fetchone()[0]
    assert n_dist > 0
    assert con.execute("SELECT count(*) FROM contracts_rejected").fetchone()[0] == 1
    con.close()
    assert (root / "exports" / "plans" / f"{s['plan_id']}.png").stat().st_size > 10_000


@pytest.mark.slow  # the planning job end to end on an imported demo fleet
def test_re_planning_replaces_unsailed_voyages_of_the_old_plan_and_keeps_those_at_sea(planned):
    from flows.jobs.planning import plan_fleet_job

    root, files, first = planned
    con = duckdb.connect(str(root / "warehouse.duckdb"), read_only=True)
    deps = con.execute("SELECT depart_utc FROM voyages WHERE plan_id = ? ORDER BY depart_utc", [first["plan_id"]]).fetchdf()
    con.close()
    as_of = pd.Timestamp(deps["depart_utc"].iloc[0]) + pd.Timedelta(minutes=1)  # the first voyage has sailed
    second = plan_fleet_job(files["contracts"], None, None, as_of.isoformat(), data_root=str(root))
    assert second["superseded_plans"] == [first["plan_id"]]
    con = duckdb.connect(str(root / "warehouse.duckdb"), read_only=True)
    # every voyage of the contract under way is kept (its laden leg too, departing later), the rest replaced
    under_way = con.execute("SELECT count(*) FROM fleet_plan_legs WHERE plan_id = ? AND contract_code = "
                            "(SELECT contract_code FROM fleet_plan_legs WHERE plan_id = ? ORDER BY depart_utc LIMIT 1)",
                            [first["plan_id"], first["plan_id"]]).fetchall()[0][0]
    left_of_first = con.execute("SELECT count(*) FROM voyages WHERE plan_id = ?", [first["plan_id"]]).fetchone()[0]
    status = dict(con.execute("SELECT plan_id, status FROM fleet_plans").fetchall())
    con.close()
    assert second["voyages_kept"] == under_way >= 1 and second["voyages_replaced"] == len(deps) - under_way
    assert left_of_first == under_way and status == {first["plan_id"]: "superseded", second["plan_id"]: "active"}
    # the contract under way is not planned again; its vessel plans on from the end of that contract's discharge
    con = duckdb.connect(str(root / "warehouse.duckdb"), read_only=True)
    code, imo = con.execute("SELECT DISTINCT l.contract_code, l.imo FROM fleet_plan_legs l JOIN voyages v USING (voyage_id) "
                            "WHERE l.plan_id = ?", [first["plan_id"]]).fetchall()[0]
    end = con.execute("SELECT arrive_utc FROM fleet_plan_legs WHERE plan_id = ? AND contract_code = ? AND kind = 'laden'",
                      [first["plan_id"], code]).fetchone()[0]
    again = con.execute("SELECT count(*) FROM fleet_plan_legs WHERE plan_id = ? AND contract_code = ?",
                        [second["plan_id"], code]).fetchone()[0]
    first_new = con.execute("SELECT min(depart_utc) FROM fleet_plan_legs WHERE plan_id = ? AND imo = ?",
                            [second["plan_id"], imo]).fetchone()[0]
    con.close()
    assert again == 0 and [r["code"] for r in second["committed"]] == [code]
    assert first_new is None or first_new >= end


@pytest.mark.slow  # end to end through the `jitroute` command on a warehouse
def test_plan_fleet_command_prints_json_and_refuses_a_bad_as_of_or_no_time(planned, monkeypatch):
    from typer.testing import CliRunner

    from cli.main import app

    root, files, _ = planned
    r = CliRunner().invoke(app, ["plan", "fleet", "--contracts", files["contracts"], "--as-of", "2020-12-05T00:00Z",
                                 "--data", str(root), "--json"])
    assert r.exit_code == 0, r.output
    out = json.loads(r.output)
    assert out["solve_status"] == "optimal" and {"vessels", "unassigned", "total_cost"} <= set(out)
    assert out["stopped_by"] == "proven optimal"
    shown = CliRunner().invoke(app, ["plan", "fleet", "--contracts", files["contracts"], "--as-of", "2020-12-06T00:00Z",
                                     "--data", str(root), "--effort", "0.5", "--time-limit", "600"])
    assert shown.exit_code == 0, shown.output
    assert "search: proven optimal" in shown.output
    bad = CliRunner().invoke(app, ["plan", "fleet", "--contracts", files["contracts"], "--as-of", "01/12/2020",
                                   "--data", str(root)])
    assert bad.exit_code == 2
    no_time = CliRunner().invoke(app, ["plan", "fleet", "--contracts", files["contracts"], "--time-limit", "0",
                                       "--data", str(root)])
    assert no_time.exit_code == 2 and "--time-limit" in no_time.output


@pytest.mark.slow  # the planning job end to end on an imported demo fleet
def test_a_routing_run_says_which_voyages_came_from_a_plan(planned, tmp_path):
    import shutil

    from storage import route_store, warehouse

    root, _, _ = planned
    db = tmp_path / "w.duckdb"
    shutil.copyfile(root / "warehouse.duckdb", db)
    with warehouse.connect(db) as con:
        plan_id, vid = con.execute("SELECT plan_id, voyage_id FROM voyages WHERE plan_id IS NOT NULL LIMIT 1").fetchone()
        con.execute("INSERT INTO route_runs (run_id, started_at, status) VALUES ('r1', now(), 'ok')")
        con.execute("INSERT INTO routes (run_id, voyage_id, status, fuel_t) VALUES ('r1', ?, 'ok', 5.0), "
                    "('r1', 'V-from-file', 'ok', 3.0)", [vid])
    assert route_store.run_summary(db, "r1")["from_plans"] == {plan_id: 1}
