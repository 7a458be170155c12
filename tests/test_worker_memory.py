"""What keeps a routing worker small. Its pictures are drawn in a child process: the same PNGs, errors that name the
picture, a child that died is started again, the worker itself never imports matplotlib and the child never imports
numba (nor scipy or the data libraries). LLVM's code pages, run once at start-up, are dropped from the worker's
resident memory and come back when needed."""

from __future__ import annotations

import inspect
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from flows.jobs.picture_process import PictureError, PictureProcess
from pipeline.export.drawing import UnknownPictureError, draw_here

def llvm_code_kb(pid="self") -> int:
    """The resident kB of libllvmlite.so's executable code in process `pid`."""
    kb, ours = 0, False
    for line in open(f"/proc/{pid}/smaps"):
        head = line.split()
        if "-" in head[0] and len(head) >= 5:
            ours = len(head) == 6 and head[1] == "r-xp" and "libllvmlite" in head[5]
        elif ours and head[0] == "Rss:":
            kb += int(head[1])
    return kb


LLVM_CODE_KB = inspect.getsource(llvm_code_kb)  # the same, in a child's code


def native_libraries(pid) -> set[str]:
    """The installed packages whose compiled libraries process `pid` has mapped (site-packages/<package>/…)."""
    names = set()
    for line in open(f"/proc/{pid}/maps"):
        path = line.split(maxsplit=5)[-1]
        if "site-packages/" in path:
            names.add(path.split("site-packages/", 1)[1].split("/", 1)[0].split(".")[0])
    return names
HISTORY = {"bfoa": [5.0, 4.0, 4.2, 3.5], "dp_cost": 3.4}
FLEET = [({"voyage_id": "V1", "status": "ok"}, [{"lat0": 30.0, "lon0": 140.0, "lat1": 32.0, "lon1": 145.0}]),
         ({"voyage_id": "V2", "status": "failed"}, [])]


def test_the_child_draws_the_same_png_as_this_process():
    with PictureProcess() as draw:
        assert draw.pid is None  # nothing started before the first picture
        there = draw("convergence", HISTORY, "V1: BFOA best cost per cycle")
        assert draw.pid is not None and draw.pid != os.getpid()
    assert there.startswith(b"\x89PNG\r\n\x1a\n")
    assert there == draw_here("convergence", HISTORY, "V1: BFOA best cost per cycle")


def test_a_failed_drawing_says_why_and_the_child_goes_on():
    with PictureProcess() as draw:
        with pytest.raises(PictureError, match="UnknownPictureError: no picture named 'nope'"):
            draw("nope")
        with pytest.raises(PictureError, match="TypeError"):
            draw("fleet_map", 5)  # not a list of (route, legs)
        pid = draw.pid
        assert draw("fleet_map", FLEET, "two voyages").startswith(b"\x89PNG")
        assert draw.pid == pid  # the same child drew after the errors
        libraries = native_libraries(pid)
        assert "matplotlib" in libraries and not libraries & {"numba", "llvmlite", "scipy"}, libraries
    with pytest.raises(UnknownPictureError):
        draw_here("nope")


# what a worker's child draws: a route map over weather near a coast (land drawn), its convergence, the run's fleet
# map and a weather map, with the arguments' kinds the worker sends (dicts, lists, numpy arrays)
CHILD_PICTURES = """
import numpy as np
lat, lon = np.arange(30.0, 37.01, 0.5), np.arange(134.0, 142.01, 0.5)
hs = 2.0 + np.outer(np.sin(np.radians(lat)), np.cos(np.radians(lon)))
field = dict(lat=lat, lon=lon, hs_m=hs, u_ms=np.full_like(hs, 8.0), v_ms=np.full_like(hs, -3.0))
legs = [dict(lat0=34.9, lon0=139.8, lat1=34.0, lon1=138.0), dict(lat0=34.0, lon0=138.0, lat1=33.3, lon1=135.5)]
route = dict(voyage_id='V1', vessel_name='Pacific Trader', solver='bfoa', status='ok', fuel_t=12.5,
             baseline_fuel_t=13.0, savings_pct=3.8, eta_utc=np.datetime64('2020-12-02T06'))
step = dict(u10=np.full((15, 17), 6.0), v10=np.full((15, 17), -2.0), swh=hs, mwd=np.full((15, 17), 270.0),
            uo=np.zeros((15, 17)), vo=np.zeros((15, 17)))
pictures = [('route_map', (route, legs, legs[:1], field)), ('convergence', (HISTORY,)),
            ('fleet_map', (FLEET + [(dict(voyage_id='V3', status='late'), legs)], 'run')),
            ('weather_map', (lat, lon, step, 'waves', 'waves'))]
"""


def test_the_child_draws_every_picture_without_numba_scipy_or_the_data_libraries():
    """The child's loop (`serve`) in a fresh interpreter, as `python -m flows.jobs.picture_process` runs it: every
    kind of picture is drawn, and none of the libraries a routing worker holds for its voyages is imported (numba
    alone cost the child about 70 MB; its coastlines and great circles are numpy's)."""
    code = (f"import sys; sys.path.insert(0, {str(Path(__file__).parents[1])!r})\n"
            "import io\n"
            "from flows.jobs.picture_process import _receive, _send, serve\n"
            f"HISTORY, FLEET = {HISTORY!r}, {FLEET!r}\n"
            + CHILD_PICTURES +
            "requests, replies = io.BytesIO(), io.BytesIO()\n"
            "for name, args in pictures:\n"
            "    _send(requests, (name, args))\n"
            "requests.seek(0)\n"
            "serve(requests, replies)\n"
            "replies.seek(0)\n"
            "for name, _args in pictures:\n"
            "    ok, png = _receive(replies)\n"
            "    print(name, ok, png[:8] == b'\\x89PNG\\r\\n\\x1a\\n' and len(png) > 10_000)\n"
            "big = ('numba', 'llvmlite', 'scipy', 'pandas', 'pyarrow', 'xarray', 'zarr', 's3fs', 'dask', 'distributed',\n"
            "       'duckdb', 'matplotlib')\n"
            "print(*sorted({m.split('.')[0] for m in sys.modules} & set(big)))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.splitlines()
    assert out[:4] == ["route_map True True", "convergence True True", "fleet_map True True",
                       "weather_map True True"], out
    assert out[4] == "matplotlib", out  # drawn with matplotlib, and nothing else of the big libraries


def test_a_child_that_died_is_reported_and_started_again():
    with PictureProcess() as draw:
        draw("convergence", HISTORY)
        first = draw.pid
        os.kill(first, signal.SIGKILL)
        with pytest.raises(PictureError, match="picture process exited"):
            draw("convergence", HISTORY)
        assert draw("convergence", HISTORY).startswith(b"\x89PNG")  # a new child
        assert draw.pid not in (None, first)


@pytest.mark.parametrize("debug_plots", [False, True])
def test_a_routing_batch_with_exports_stages_pngs_without_importing_matplotlib(tmp_path, debug_plots):
    """What keeps a dask worker small: its voyages' route maps (and with debug_plots, their BFOA convergence plots) are
    drawn by its child. The operator's set has no convergence plot; the GeoJSON names the run."""
    code = (f"import sys; sys.path.insert(0, {str(Path(__file__).parents[1])!r})\n"
            "import numpy as np\n"
            "from flows.jobs.route_worker import route_batch\n"
            "from flows.jobs import picture_process\n"
            "from pipeline.performance.model import reference_model\n"
            "from pipeline.routing.job import RouteJob, RoutingOptions\n"
            "voyage = {'voyage_id': 'VPIC', 'imo': 1, 'dep_lat': 34.0, 'dep_lon': 141.0, 'arr_lat': 30.0,\n"
            "          'arr_lon': 147.0, 'depart_utc': np.datetime64('2020-12-01T02'),\n"
            "          'rta_utc': np.datetime64('2020-12-02T18'), 'rpm_options': [70, 85, 100]}\n"
            "job = RouteJob(voyage=voyage, vessel={'rpm_max': 100}, model=reference_model(14.0, 100.0, 1.5).to_json(),\n"
            "               run_id='r1', cycle=None, exports=True, options=RoutingOptions(n_lines=6, n_points=7),\n"
            f"               debug_plots={debug_plots})\n"
            f"out = route_batch([job], None, None, ({str(tmp_path / 'exports')!r}, {{}}))[0]\n"
            "print(out['route']['status'], sorted(f['name'] for f in out['staged']), out['export_errors'],\n"
            "      'matplotlib' in sys.modules, picture_process.of_this_process().pid is not None)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    debug = "'voyages/VPIC/VPIC.convergence.png', " if debug_plots else ""
    assert out == (f"ok [{debug}'voyages/VPIC/VPIC.geojson', 'voyages/VPIC/VPIC.png', "
                   "'voyages/VPIC/VPIC.rtz'] {} False True"), out
    pngs = sorted((tmp_path / "exports").rglob("*.png"))
    assert [p.name for p in pngs] == ["VPIC.convergence.png", "VPIC.png"][0 if debug_plots else 1:]
    (geojson,) = (tmp_path / "exports").rglob("*.geojson")
    route_feature = json.loads(geojson.read_text())["features"][0]["properties"]
    assert route_feature["kind"] == "route" and route_feature["run_id"] == "r1"
    assert all(p.read_bytes().startswith(b"\x89PNG") and p.stat().st_size > 10_000 for p in pngs)


def test_dropping_llvms_code_pages_shrinks_a_worker_and_numba_still_compiles_and_runs():
    """worker_memory.drop_code_pages: the resident code of libllvmlite.so falls, and LLVM runs again when needed."""
    code = (f"import sys; sys.path.insert(0, {str(Path(__file__).parents[1])!r})\n"
            "import numba\n"
            "from flows.jobs.worker_memory import drop_code_pages\n"
            + LLVM_CODE_KB +
            "@numba.njit\n"
            "def f(x):\n"
            "    return 3 * x + 1\n"
            "assert f(2) == 7\n"
            "before = llvm_code_kb()\n"
            "advised = drop_code_pages()\n"
            "after = llvm_code_kb()\n"
            "@numba.njit\n"
            "def g(x):\n"
            "    return x * x - 1\n"
            "print(before // 1024, after // 1024, advised > 0, f(5), g(4))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    before_mb, after_mb = int(out[0]), int(out[1])
    assert before_mb >= 20 and after_mb <= before_mb // 4, out  # compiling touched tens of MB; few stay
    assert out[2:] == ["True", "16", "15"], out  # a compiled kernel runs, and a new one compiles and runs


def test_kernels_loaded_from_the_cache_leave_llvms_code_pages_dropped():
    """worker_memory.drop_code_pages_after_kernel_loads: a cached kernel loads, runs right, and LLVM's code it ran to
    load does not stay resident."""
    code = (f"import sys; sys.path.insert(0, {str(Path(__file__).parents[1])!r})\n"
            "from flows.jobs.worker_memory import drop_code_pages_after_kernel_loads\n"
            "from pipeline.routing.geodesy import gc_distance_nm\n"
            + LLVM_CODE_KB +
            "assert drop_code_pages_after_kernel_loads() and drop_code_pages_after_kernel_loads()  # once is enough\n"
            "nm = gc_distance_nm(0.0, 0.0, 0.0, 1.0)\n"
            "print(round(nm, 2), gc_distance_nm.stats.cache_hits.total() if hasattr(gc_distance_nm.stats.cache_hits, 'total') "
            "else sum(gc_distance_nm.stats.cache_hits.values()), llvm_code_kb() // 1024)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert abs(float(out[0]) - 60.0) < 0.2, out  # 1° of the equator is 60 NM
    assert int(out[1]) == 1, out  # loaded from the cache (the worker's case), not compiled
    assert int(out[2]) <= 8, out  # MB of LLVM's code left resident after the load
