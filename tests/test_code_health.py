"""bench/code_health.py counts what it says on a small tree whose answers are known."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parents[1] / "bench" / "code_health.py"

TREE = {
    "pipeline/__init__.py": "",
    "pipeline/a.py": """
import numba
from pipeline import b
from pipeline.b import leaf


@numba.njit(cache=True)
def caller(x):
    return leaf(x) + b.leaf(x) + near(x)


@numba.njit(cache=True)
def near(x):
    return x


@numba.njit
def wide(a1, a2, a3, a4, a5, a6, a7, a8, a9, a10):
    return a1


def branchy(x):
""" + "".join(f"    if x == {k}:\n        return {k}\n" for k in range(11)) + "    return -1\n",
    "pipeline/b.py": """
import numba


def later():
    from pipeline import a  # a circle, closed only when later() runs
    return a


@numba.njit(cache=True)
def leaf(x):
    return x
""",
    "pipeline/routing/__init__.py": "",
    "pipeline/routing/r.py": "X = 1\nY = 2\nZ = 3\n",
    "storage/__init__.py": "",
    "storage/c.py": "from typing import TYPE_CHECKING\n\nfrom storage import d\n\nif TYPE_CHECKING:\n    from storage import e\n",
    "storage/d.py": "import storage.c\n",
    "storage/e.py": "from storage.c import TYPE_CHECKING\n",
}


def test_counts_of_a_known_tree(tmp_path):
    for name, text in TREE.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    out = subprocess.run([sys.executable, str(BENCH), "--root", str(tmp_path), "--json"], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    m = json.loads(out.stdout)
    assert (m["routing_files"], m["routing_lines"], m["routing_kernels"]) == (2, 3, 0)
    assert (m["kernels"], m["kernels_cached"]) == (4, 3)
    assert m["kernels_many_params"] == ["pipeline.a.wide (10)"]
    assert [c.split(":")[0] for c in m["complex_functions"]] == ["pipeline/a.py"] and "branchy" in m["complex_functions"][0]
    # two calls to b.leaf from another file; a.near is in caller's own file and is not counted
    assert m["cross_file_callers"] == ["pipeline.a.caller"]
    assert sorted(c.split(" (")[0] for c in m["cross_file_calls"]) == ["pipeline.a.caller -> pipeline.b.leaf"] * 2
    assert m["circles"] == [["storage.c", "storage.d", "storage.e"], ["pipeline.a", "pipeline.b"]]
    assert m["circles_at_import"] == [["storage.c", "storage.d"]]  # not the function's import, nor TYPE_CHECKING's
