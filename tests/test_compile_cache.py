"""numba's compile cache never runs code older than the source tree (pipeline.compile_cache).

numba keys a cached kernel on its own file only; these tests edit a *callee* in another file (a kernel, and a
constant compiled in) in a copy of the tree and show the caller's cached result follow the edit.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from pipeline import compile_cache

REPO = Path(__file__).resolve().parents[1]

# Two callers whose callee lives in another file: baseline._shortest_nb calls geodesy.gc_distance_nm, and the
# fleet planner's colgen.ballast_fuel_t_nb compiles in problem.SLOWEST_BALLAST_SHARE.
PROBE = """
import json, os
import numpy as np
from pipeline.routing.baseline import _shortest_nb
from pipeline.planning.colgen import ballast_fuel_t_nb

lat = np.array([[0.0], [0.0], [0.0]])
lon = np.array([[0.0], [1.0], [2.0]])
dist = _shortest_nb(lat, lon, np.ones((2, 1, 1), np.bool_), 0, np.full((3, 1), -1, np.int64))
# 100 NM at 10 kn, ready at 0 h, loading at 100 h: departs as late as the slowest share allows
fuel = ballast_fuel_t_nb(100.0, 0.0, 100.0, 10.0, 0.05, np.empty(0), np.empty(0))
hits = sum(sum(k.stats.cache_hits.values()) for k in (_shortest_nb, ballast_fuel_t_nb))
print(json.dumps({"dist_nm": float(dist[0]), "fuel_t": float(fuel), "hits": hits,
                  "cache": os.environ["NUMBA_CACHE_DIR"]}))
"""


def _copy_tree(dst: Path) -> Path:
    shutil.copytree(REPO / "pipeline", dst / "pipeline", ignore=shutil.ignore_patterns("__pycache__"))
    return dst


def _probe(tree: Path, cache_root: Path) -> dict:
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    env.update(PYTHONPATH=str(tree), JITROUTE_NUMBA_CACHE=str(cache_root))
    out = subprocess.run([sys.executable, "-c", PROBE], env=env, cwd=tree, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


def _edit(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text, f"{path} no longer holds {old!r}: update this test"
    path.write_text(text.replace(old, new))


@pytest.mark.slow  # three child processes that compile (about 10 s CPU)
def test_an_edited_callee_in_another_file_reaches_the_cached_caller(tmp_path):
    tree, root = _copy_tree(tmp_path / "tree"), tmp_path / "cache"
    first = _probe(tree, root)
    again = _probe(tree, root)
    assert again["hits"] == 2 and again["cache"] == first["cache"], "the unchanged tree must load from the cache"
    assert (again["dist_nm"], again["fuel_t"]) == (first["dist_nm"], first["fuel_t"])
    assert 119.0 < first["dist_nm"] < 121.0  # 2 degrees of longitude on the equator

    _edit(tree / "pipeline/routing/geodesy.py", "return 2.0 * EARTH_RADIUS_NM", "return 4.0 * EARTH_RADIUS_NM")
    _edit(tree / "pipeline/planning/problem.py", "SLOWEST_BALLAST_SHARE = 0.7", "SLOWEST_BALLAST_SHARE = 1.0")
    edited = _probe(tree, root)
    assert edited["cache"] != first["cache"]
    assert edited["dist_nm"] == 2 * first["dist_nm"]  # the callee's edit, not the old cached machine code
    # share 0.7: departs at 100 - 10/0.7 h and sails at 7 kn; share 1.0: departs at 90 h and sails at 10 kn
    assert abs(first["fuel_t"] - 100 * 0.05 * 0.7 ** 2) < 1e-9 and abs(edited["fuel_t"] - 100 * 0.05) < 1e-9


def test_the_digest_follows_the_content_of_every_pipeline_file(tmp_path):
    tree = _copy_tree(tmp_path / "tree") / "pipeline"
    before = compile_cache.sources_digest(tree)
    target = tree / "routing" / "geodesy.py"
    os.utime(target, (time.time() + 60, time.time() + 60))  # a touch alone is not a change
    assert compile_cache.sources_digest(tree) == before
    target.write_text(target.read_text() + "\n# edited\n")
    assert compile_cache.sources_digest(tree) != before


def test_a_child_process_keeps_its_parents_root(tmp_path):
    """A dask worker inherits NUMBA_CACHE_DIR=<root>/jitroute-<digest>: its root is the same, whatever its digest."""
    own = tmp_path / "numba"
    assert compile_cache.cache_root({"NUMBA_CACHE_DIR": str(own)}) == own
    assert compile_cache.cache_root({"NUMBA_CACHE_DIR": str(own / "jitroute-0123456789abcdef")}) == own
    assert compile_cache.cache_root({"JITROUTE_NUMBA_CACHE": str(tmp_path / "x"), "NUMBA_CACHE_DIR": str(own)}) \
        == tmp_path / "x"


def test_old_digest_folders_are_removed_but_recent_ones_kept(tmp_path):
    now = time.time()
    ages_h = {"jitroute-current": 50.0, "jitroute-a": 1.0, "jitroute-b": 2.0, "jitroute-c": 3.0, "jitroute-d": 4.0,
              "jitroute-busy": 0.0}
    for name, age_h in ages_h.items():
        (tmp_path / name).mkdir()
        used = tmp_path / name / compile_cache.USED
        used.touch()
        os.utime(used, (now - age_h * 3600, now - age_h * 3600))
    (tmp_path / "not-ours").mkdir()
    removed = compile_cache.prune(tmp_path, tmp_path / "jitroute-current", keep=3, idle_s=600)
    # kept: the current one, the two used last (busy, a), and none other; folders that are not ours stay
    assert sorted(p.name for p in removed) == ["jitroute-b", "jitroute-c", "jitroute-d"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["jitroute-a", "jitroute-busy", "jitroute-current",
                                                          "not-ours"]
