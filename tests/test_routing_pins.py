"""Plans pinned bit for bit: the same instance and seed must give the same plan, cost and work count.

The values were recorded with the code before the solver interfaces were restructured (named kernel
structures, solver registry) and held through it; the BFOA pins were re-recorded once when its random stream
moved from numba's global generator to an explicit numpy Generator. The DP pins were recorded with the
time-bucket DP, later kept as `bucket_h=0.5` (two `-bucket` pins) and deleted with them when nothing used it any more. The A* pins were re-recorded when A* started giving each route of
its sweep the best engine plan for the RTA (before, it arrived early at high rpm). All were re-recorded once more
when the physical performance form changed (weather is a loss in every direction, Kwon's shape): since then the
bucketed DP finds a slightly dearer plan than the exact DP on the storm case. The exact DP's work counts fell
when it began to price each leg at its least hours and fuel before sailing it (same plans), and the BFOA pins
were re-recorded when its best plan began to be polished by the DP in a corridor (equal or cheaper plans). They were
re-recorded again when the BFOA began to start bacteria on offset routes, to shift whole blocks of lines, to stop
after cycles without a gain and to polish its plan again while that gains (wavy-bfoa-2 and storm-bfoa-4 cheaper; the
storm DP's work count follows from its BFOA incumbent). A*'s work counts fell when the best engine plan of each
route began to be found on the route alone with the DP's bounds and within 0.1 % (engine_limits.best_engine_plan),
once per distinct route of the sweep (same plans). All were re-recorded when speed became a decision between the
lowest and highest setting: the solvers also choose the constant rpm at which the base route arrives at the RTA, a
plan that costs more than that constant-speed voyage returns it, and the baseline is that voyage (rpm now pinned
to 3 decimals, not truncated; the DP's work counts grew with the fourth setting). The BFOA pins were re-recorded
when its polish began to keep at most 16 labels per node and stop its cycles after 2 without a gain, polishing up to
6 rounds instead (storm-bfoa-4 now the bucketed DP's plan, 0.47 % dearer; the storm DP's work count follows from its
BFOA incumbent). All but the constant-speed baselines were re-recorded when speed became continuous: each plan's
speeds are refined between the lowest and the highest rpm after the search (continuous_speed.py; every plan equal
or cheaper: the storm plans 1.0 % cheaper, the wavy plans 0.24 %). The exact DP's work counts fell again when its
bound began to be priced leg by leg in the weather each leg can meet while a plan can sail it (same plans). A refactor that changes any of them
changed an algorithm: change a pin only in a commit that changes the algorithm (or its random stream) on
purpose and says so. The costs were re-recorded once more when the continuous-speed refinement stopped taking its
dot products through BLAS (math.fsum instead of `g @ h`), whose summation order follows the CPU's kernel: since
then every field here, the cost's last bit included, is the same under every OpenBLAS core type, and
`test_pins_hold_under_other_blas_kernels` proves it on this machine. The BFOA work counts grew (the plans, costs
and rpm the same, bit for bit) when its polish's fuel window went from 0.3 % to 2 % of the plan's cost, which lets
it walk a detour one node wider or earlier; the storm DP's work count follows from its BFOA incumbent. The thesis
BFOA's grew again (same plan) when its polish began to keep 4 × the labels per node.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from routing_cases import FAST, field, moving_storm, problem, solve, wavy

# name → (status, cost as float.hex, n_evals, node offset per inner line (None: not on this graph), rpm per leg to 3 decimals)
PINS = {
    "wavy-bfoa-1": ('ok', '0x1.fb3adc92200e8p+5', 442, [0, 0, 0, 0, 0, 0, 0, 0], [79.019, 79.019, 79.412, 79.412, 81.932, 83.804, 83.804, 84.79, 84.693]),
    "wavy-bfoa-2": ('ok', '0x1.fb3adc92200e8p+5', 440, [0, 0, 0, 0, 0, 0, 0, 0], [79.019, 79.019, 79.412, 79.412, 81.932, 83.804, 83.804, 84.79, 84.693]),
    "wavy-dp": ('ok', '0x1.fb3adc92200e8p+5', 7884, [0, 0, 0, 0, 0, 0, 0, 0], [79.019, 79.019, 79.412, 79.412, 81.932, 83.804, 83.804, 84.79, 84.693]),
    "wavy-astar": ('ok', '0x1.fb3adc92200e8p+5', 2355, [0, 0, 0, 0, 0, 0, 0, 0], [79.019, 79.019, 79.412, 79.412, 81.932, 83.804, 83.804, 84.79, 84.693]),
    "wavy-gc": ('ok', '0x1.fc77d7d0372bcp+5', 0, [0, 0, 0, 0, 0, 0, 0, 0], [81.92, 81.92, 81.92, 81.92, 81.92, 81.92, 81.92, 81.92, 81.92]),
    "wavy-rhumb": ('ok', '0x1.f81b1b05b7d7dp+5', 0, None, [81.613, 81.613, 81.613, 81.613, 81.613, 81.613, 81.613, 81.613, 81.613]),
    "thesis-bfoa-3": ('ok', '0x1.ff5c6329c7382p+1', 391, [0, 0, 0, 0, 0, 0], [84.784, 84.784, 89.143, 89.143, 90.2, 90.2, 88.783]),
    "storm-gc": ('ok', '0x1.100fd89f06a5bp+7', 0, [0, 0, 0, 0, 0, 0, 0, 0, 0, 0], [82.168, 82.168, 82.168, 82.168, 82.168, 82.168, 82.168, 82.168, 82.168, 82.168, 82.168]),
    "storm-bfoa-4": ('ok', '0x1.cc493afcf2c94p+6', 1115, [1, 2, 2, 3, 3, 3, 3, 3, 2, 1], [77.748, 81.436, 77.604, 75.522, 73.629, 73.253, 74.388, 77.889, 77.889, 80.013, 82.229]),
    "storm-dp": ('ok', '0x1.cc39f7306677ap+6', 21869, [1, 2, 2, 3, 3, 3, 3, 3, 2, 1], [77.771, 81.405, 77.663, 75.594, 73.636, 73.257, 74.394, 76.616, 78.935, 80.031, 82.109]),
    "storm-astar": ('ok', '0x1.cc39f7306677ap+6', 7015, [1, 2, 2, 3, 3, 3, 3, 3, 2, 1], [77.771, 81.405, 77.663, 75.594, 73.636, 73.257, 74.394, 76.616, 78.935, 80.031, 82.109]),
}


def _offsets(plan, space):
    out = []
    for i, (la, lo) in enumerate(plan.waypoints[1:-1], start=1):
        d = (space.lat[i] - la) ** 2 + (space.lon[i] - lo) ** 2
        j = int(np.argmin(d))
        assert d[j] < 1e-18, f"waypoint {i} is not a node of line {i}"
        out.append(j - space.centre)
    return out


def _plans():
    fld = field(wavy(2))
    pr = problem((30.0, -160.0), (33.0, -145.0), 72, n_lines=8, n_points=9)
    sp = pr.search_space()
    yield "wavy-bfoa-1", solve(pr, fld, solver="bfoa", seed=1, params=FAST, space=sp), sp
    yield "wavy-bfoa-2", solve(pr, fld, solver="bfoa", seed=2, params=FAST, space=sp), sp
    for name in ("dp", "astar", "gc"):
        yield f"wavy-{name}", solve(pr, fld, solver=name, space=sp), sp
    yield "wavy-rhumb", solve(pr, fld, solver="rhumb"), None
    prt = problem((35.0, -140.0), (28.0, -132.0), 52, rpm_options=(80, 100), objective="thesis", n_lines=6, n_points=9)
    spt = prt.search_space()
    yield "thesis-bfoa-3", solve(prt, field(wavy(3)), solver="bfoa", seed=3, params=FAST, space=spt), spt
    storm = field(moving_storm(5, 33.0, 225.0, drift_kn=(-10.0, 0.0), hs_peak=6.0), step_h=6, hours=240)
    prs = problem((30.0, -160.0), (35.0, -130.0), 150, max_hs_m=7.0, n_lines=10, n_points=11)
    sps = prs.search_space()
    yield "storm-gc", solve(prs, storm, solver="gc", space=sps), sps
    yield "storm-bfoa-4", solve(prs, storm, solver="bfoa", seed=4, params=FAST, space=sps), sps
    yield "storm-dp", solve(prs, storm, solver="dp", space=sps), sps
    yield "storm-astar", solve(prs, storm, solver="astar", space=sps), sps


@pytest.fixture(scope="module")
def plans():
    return {name: (plan, space) for name, plan, space in _plans()}


@pytest.mark.parametrize("name", sorted(PINS))
def test_plan_is_pinned(plans, name):
    plan, space = plans[name]
    status, cost_hex, n_evals, offsets, rpm = PINS[name]
    got = (plan.status, float(plan.cost).hex(), plan.n_evals, _offsets(plan, space) if space is not None else None,
           [round(g["rpm"], 3) for g in plan.legs])
    assert got == (status, cost_hex, n_evals, offsets, rpm)


def _cpu_flags() -> set[str]:
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return set()
    line = next((ln for ln in text.splitlines() if ln.startswith("flags")), "")
    return set(line.split(":", 1)[-1].split())


# Prescott (SSE3, which Linux's /proc/cpuinfo calls "pni") runs on any x86-64 made since 2004; Haswell needs AVX2. Each
# sums a dot product in its own order, so a plan that took its arithmetic through BLAS would differ in its last bits
# under one of them.
CORE_TYPES = {"Prescott": ("pni", "SSE3"), "Haswell": ("avx2", "AVX2")}


@pytest.mark.slow
@pytest.mark.skipif(not _cpu_flags(), reason="machine capability: no CPU flags in /proc/cpuinfo (not Linux on x86-64), "
                                             "and OpenBLAS core types are an x86-64 matter")
@pytest.mark.parametrize("core", sorted(CORE_TYPES))
def test_pins_hold_under_other_blas_kernels(core):
    """The pinned plans, recomputed in a process whose OpenBLAS uses `core`'s kernels, match the pins bit for bit."""
    flag, name = CORE_TYPES[core]
    if flag not in _cpu_flags():
        pytest.skip(f"machine capability: this CPU has no {name}, which OpenBLAS's {core} kernels need")
    script = ("from test_routing_pins import PINS, _plans, _offsets\n"
              "for name, plan, space in _plans():\n"
              "    got = (plan.status, float(plan.cost).hex(), plan.n_evals,\n"
              "           _offsets(plan, space) if space is not None else None, [round(g['rpm'], 3) for g in plan.legs])\n"
              "    if got != PINS[name]:\n"
              "        print(name, got)\n")
    env = dict(os.environ, OPENBLAS_CORETYPE=core)
    env.pop("OPENBLAS_L2_SIZE", None)
    out = subprocess.run([sys.executable, "-c", script], cwd=Path(__file__).parent, env=env, capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout == "", f"plans that differ from their pins under OPENBLAS_CORETYPE={core}:\n{out.stdout}"
