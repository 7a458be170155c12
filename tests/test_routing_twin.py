"""The compiled kernels against their pure-Python twin: the same code run with NUMBA_DISABLE_JIT=1 (in a child
process, since the switch is read at import) must make the same search on small cases: the random draws come
from one explicit numpy Generator that numba reproduces exactly, so the same moves are tried and the same plan
is found. Costs agree to rounding only: interpreted numpy keeps float32 weather samples in float32 where the
compiled code promotes them to float64."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

TESTS = Path(__file__).resolve().parent
CASES = r'''
import json, sys
sys.path.insert(0, sys.argv[1])
from routing_cases import field, problem, solve, wavy, moving_storm
from pipeline.routing.solve import BfoaParams, DpOptions

tiny = BfoaParams(n_bacteria=5, n_chemo=3, n_cycles=4, ed_every=2, steps_to_die=6)
out = {}
pr = problem((30.0, -160.0), (33.0, -145.0), 72, n_lines=5, n_points=7)
sp = pr.search_space()
fld = field(wavy(2))
for seed in (1, 2):
    p = solve(pr, fld, solver="bfoa", seed=seed, params=tiny, space=sp)
    out[f"bfoa-{seed}"] = [p.status, float(p.cost).hex(), p.n_evals, p.waypoints, [g["rpm"] for g in p.legs]]
storm = field(moving_storm(5, 33.0, 225.0, drift_kn=(-10.0, 0.0), hs_peak=6.0), step_h=6, hours=240)
prs = problem((30.0, -160.0), (35.0, -130.0), 150, max_hs_m=7.0, n_lines=5, n_points=7, objective="thesis")
sps = prs.search_space()
for solver, opts in (("bfoa", tiny), ("dp", DpOptions(incumbent=None)), ("astar", None)):
    p = solve(prs, storm, solver=solver, seed=3, options=opts, space=sps)
    out[f"storm-{solver}"] = [p.status, float(p.cost).hex(), p.n_evals, p.waypoints, [g["rpm"] for g in p.legs]]
print(json.dumps(out))
'''


def _run(disable_jit: bool) -> dict:
    env = dict(os.environ, NUMBA_DISABLE_JIT="1" if disable_jit else "0")
    res = subprocess.run([sys.executable, "-c", CASES, str(TESTS)], env=env, capture_output=True, text=True, timeout=900,
                         cwd=TESTS.parent)
    assert res.returncode == 0, res.stderr[-3000:]
    return json.loads(res.stdout.strip().splitlines()[-1])


def test_compiled_kernels_equal_their_pure_python_twin():
    compiled, twin = _run(False), _run(True)  # both load the shipped land structure (a pure-Python build takes minutes)
    assert compiled.keys() == twin.keys()
    for name in compiled:
        assert compiled[name][0] == "ok", (name, compiled[name])
        (status, cost, n_evals, waypoints, rpm), (t_status, t_cost, t_evals, t_waypoints, t_rpm) = compiled[name], twin[name]
        assert (status, n_evals) == (t_status, t_evals), name
        assert np.allclose(waypoints, t_waypoints, rtol=0, atol=1e-9), name
        # the continuous speed refinement (continuous_speed.py) steers by finite differences of the voyage's fuel,
        # so the last bits where the compiled and interpreted sums differ move its rpm by ~1e-4
        assert np.allclose(rpm, t_rpm, rtol=0, atol=2e-3), name
        assert float.fromhex(cost) == pytest.approx(float.fromhex(t_cost), rel=1e-6), name
