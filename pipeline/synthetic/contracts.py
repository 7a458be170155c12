"""Random fleet-planning instances (vessels, cargo contracts, port distances) for tests and the planning bench.

Ports are points on a plane (NM), distances straight lines; windows spread over `horizon_days`. Seeded."""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np

from pipeline.planning.problem import Contract, PlanVessel

CARGO_TYPES = ("grain", "coal", "ore", "fertiliser")


def random_instance(n_vessels: int, n_contracts: int, *, seed: int = 0, n_ports: int | None = None,
                    horizon_days: float = 60.0, window_days: float = 4.0, width_nm: float = 3000.0,
                    penalty: float = 600_000.0):
    """(vessels, contracts, {(port, port): NM}) of a random instance."""
    rng = np.random.default_rng(seed)
    n_ports = n_ports or max(4, min(40, n_contracts // 2 + 2))
    ports = [f"P{i:02d}" for i in range(n_ports)]
    xy = rng.uniform(0, width_nm, (n_ports, 2))
    dist = {(a, b): float(math.hypot(*(xy[i] - xy[j]))) for (i, a), (j, b) in itertools.combinations(enumerate(ports), 2)}
    vessels = []
    light = np.random.default_rng(seed + 10_000)  # weight curves on their own stream: the rest stays as it was
    for k in range(n_vessels):
        dwt = float(rng.choice([35_000, 60_000, 80_000]))
        types = frozenset(rng.choice(CARGO_TYPES, size=int(rng.integers(2, len(CARGO_TYPES) + 1)), replace=False))
        speed = float(rng.uniform(11.5, 14.0))
        vessels.append(PlanVessel(
            imo=9_000_000 + k, name=f"V{k:02d}", dwt_t=dwt, start_port=str(rng.choice(ports)),
            start_h=float(rng.uniform(0, 5 * 24)), port_h=float(rng.uniform(24, 48)),
            daily_cost=float(rng.uniform(8_000, 15_000)), cargo_types=types, laden_speed_kn=speed,
            ballast_speed_kn=speed + 0.5, laden_fuel_t_per_nm=float(rng.uniform(0.08, 0.12)),
            ballast_fuel_t_per_nm=float(rng.uniform(0.06, 0.09))))
        v = vessels[-1]  # laden at half the deadweight: a little faster on less fuel
        half = (0.5 * dwt, speed + float(light.uniform(0.0, 0.5)), v.laden_fuel_t_per_nm * float(light.uniform(0.75, 0.95)))
        vessels[-1] = dataclasses.replace(v, laden_curve=(half, (dwt, speed, v.laden_fuel_t_per_nm)))
    contracts = []
    for j in range(n_contracts):
        lp, dp = rng.choice(n_ports, 2, replace=False)
        early = float(rng.uniform(0, horizon_days * 24))
        lo = float(rng.choice([20_000, 30_000, 50_000, 70_000]))
        contracts.append(Contract(
            code=f"C{j:03d}", cargo_type=str(rng.choice(CARGO_TYPES)), min_t=lo, max_t=lo * 1.1,
            load_port=ports[lp], discharge_port=ports[dp], early_h=early,
            late_h=early + float(rng.uniform(1, window_days)) * 24, penalty=float(rng.uniform(0.5, 1.5)) * penalty))
    return vessels, contracts, dist


DEMO_PORTS = ("Busan", "Shanghai", "Qingdao", "Kaohsiung", "Keelung", "Hong Kong", "Manila", "Naha", "Guam")


def write_demo_planning(vessels, start, out_dir, *, n_contracts: int = 12, seed: int = 11,
                        ports: tuple[str, ...] = DEMO_PORTS) -> dict[str, str]:
    """ports.csv, availability.csv and contracts.csv for the demo fleet (`vessels`: its vessels table), between the
    demo `ports` (of `pipeline.synthetic.fleet.PORTS`), load windows over the 3 weeks from `start` (UTC). One contract is
    bad on purpose (its window has zero length) and is refused on import."""
    from pathlib import Path

    import pandas as pd

    from pipeline.synthetic.fleet import PORTS

    rng = np.random.default_rng(seed)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    start = pd.Timestamp(start)
    names = sorted(ports)
    pd.DataFrame([{"port": p, "lat": PORTS[p][0], "lon": PORTS[p][1]} for p in names]).to_csv(out / "ports.csv", index=False)
    avail = []
    for r in vessels.to_dict("records"):
        avail.append({"imo": r["imo"], "from_utc": (start + pd.Timedelta(hours=int(rng.integers(0, 72)))).isoformat(),
                      "from_port": str(rng.choice(names)), "until_utc": "", "until_port": "", "port_hours": 24,
                      "daily_cost": int(rng.integers(8, 16)) * 1000, "ports": "",
                      "cargo_types": ";".join(sorted(rng.choice(CARGO_TYPES, size=3, replace=False)))})
    pd.DataFrame(avail).to_csv(out / "availability.csv", index=False)
    dwt = sorted(vessels["dwt"])
    rows = []
    for j in range(n_contracts):
        lp, dp = rng.choice(len(names), 2, replace=False)
        early = start + pd.Timedelta(hours=int(rng.integers(24, 21 * 24)))
        lo = float(dwt[int(rng.integers(0, len(dwt)))]) * 0.8
        rows.append({"code": f"K{j + 1:03d}", "cargo_type": str(rng.choice(CARGO_TYPES)), "min_t": round(lo, -2),
                     "max_t": round(lo * 1.1, -2), "load_port": names[lp], "discharge_port": names[dp],
                     "early_utc": early.isoformat(), "late_utc": (early + pd.Timedelta(days=3)).isoformat(),
                     "penalty": 400_000})
    rows.append({**rows[0], "code": f"K{n_contracts + 1:03d}", "late_utc": rows[0]["early_utc"]})  # window of zero length
    pd.DataFrame(rows).to_csv(out / "contracts.csv", index=False)
    return {k: str(out / f"{k}.csv") for k in ("ports", "availability", "contracts")}
