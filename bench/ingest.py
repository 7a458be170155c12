"""Ingest benchmark: one full forecast cycle from a generated mirror served over HTTP on 127.0.0.1.

ingest, flow engine  `ingest_weather` run by Prefect (a throw-away local API, as in the tests) into a
                     fresh data root: list, download over HTTP, checksum, decode GSM/GWM/OSCAR, regrid
                     to the routing grid, write the Zarr cube, record the ingest log in DuckDB.
ingest, plain        the same job without Prefect (`flows.jobs.ingest.ingest_cycle`, as the CLI runs it when
                     no Prefect API is configured): the same steps as plain function calls.
reference            decoding the same files in the same run with raw eccodes (`codes_get_values` of every
                     GRIB message, multi-field support on) and netCDF4 (every variable of every OSCAR file).

Writing the mirror and starting the Prefect API are set-up and are not timed. Each figure is the
best of a few runs. Target: ingest ≤ 2 × reference. Prints the figures; always exits 0.

    .venv/bin/python bench/ingest.py [--repeat 3]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
OUT = ROOT / "bench" / "out"
OUT.mkdir(parents=True, exist_ok=True)
_PREFECT_HOME = tempfile.TemporaryDirectory(prefix="prefect-", dir=OUT)
os.environ["PREFECT_HOME"] = _PREFECT_HOME.name  # a throw-away API database, never the user's
os.environ.setdefault("PREFECT_SERVER_ANALYTICS_ENABLED", "false")
os.environ["PREFECT_LOGGING_LEVEL"] = "ERROR"  # the mirror has no OSCAR before the cycle: expected warnings

import eccodes  # noqa: E402
import netCDF4  # noqa: E402

from flows.ingest import ingest_weather  # noqa: E402
from pipeline.synthetic.mirror import write_mirror  # noqa: E402
from storage.layout import DataLayout  # noqa: E402
from tests.http_mirror import serve  # noqa: E402

CYCLE = "2020-12-01T00"
TARGET_RATIO = 2.0


def reference(files: list[Path]) -> float:
    """Seconds to decode every GRIB message's values and every NetCDF variable of `files`."""
    t0 = time.perf_counter()
    eccodes.codes_grib_multi_support_on()
    for path in files:
        if path.suffix == ".nc":
            with netCDF4.Dataset(path) as nc:
                for var in nc.variables.values():
                    var[:]
            continue
        with open(path, "rb") as f:
            while (h := eccodes.codes_grib_new_from_file(f)) is not None:
                eccodes.codes_get_values(h)
                eccodes.codes_release(h)
    return time.perf_counter() - t0


def ingest(url: str, data_root: Path, engine: bool) -> tuple[float, dict]:
    kw = dict(data_root=str(data_root), rish_url=url + "rish/", oscar_url=url + "oscar/")
    t0 = time.perf_counter()
    if engine:
        report = ingest_weather(CYCLE, **kw)
    else:
        from flows.jobs.ingest import ingest_cycle

        report = ingest_cycle(CYCLE, **kw)
    return time.perf_counter() - t0, report


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    from prefect.testing.utilities import prefect_test_harness

    with tempfile.TemporaryDirectory(prefix="ingest-", dir=OUT) as tmp, prefect_test_harness(server_startup_timeout=180):
        tmp = Path(tmp)
        t = time.perf_counter()
        mirror = write_mirror(tmp / "mirror", "2020-12-01", "2020-12-01", cycles=(0,), seed=0)
        setup_s = time.perf_counter() - t
        times = {"flow": [], "fn": [], "ref": []}
        with serve(mirror) as (url, _):
            for k in range(a.repeat + 1):  # run 0 warms imports, eccodes tables and the API; not counted
                for engine in (True, False):
                    root = tmp / f"data-{k}-{int(engine)}"
                    seconds, report = ingest(url, root, engine)
                    if not report["complete"]:
                        print(f"ingest did not complete: {report}")
                        return 0
                    files = sorted(p for p in DataLayout(root).raw.rglob("*") if p.is_file())
                    ref_s = reference(files)
                    if k:
                        times["flow" if engine else "fn"].append(seconds)
                        times["ref"].append(ref_s)
        n_files = len(files)
        mb = sum(p.stat().st_size for p in files) / 1e6
        cube_mb = sum(p.stat().st_size for p in DataLayout(root).weather_cube.rglob("*") if p.is_file()) / 1e6
    flow_s, fn_s, ref_s = min(times["flow"]), min(times["fn"]), min(times["ref"])
    print(f"ingest bench: cycle {CYCLE}, {n_files} files ({mb:.1f} MB: GSM + GWM GRIB2, OSCAR NetCDF) over HTTP on "
          f"127.0.0.1 → Zarr cube {cube_mb:.1f} MB; mirror written in {setup_s:.1f} s; best of {a.repeat}")
    print(f"{'':44s}{'seconds':>9s}{'MB/s':>9s}{'ratio':>8s}")
    for label, s in (("ingest, Prefect flow engine", flow_s), ("ingest, plain job (no Prefect)", fn_s),
                     ("reference (raw eccodes + netCDF4 decode)", ref_s)):
        print(f"{label:44s}{s:9.2f}{mb / s:9.1f}{s / ref_s:7.2f}×")
    for label, s in (("flow engine", flow_s), (".fn", fn_s)):
        r = s / ref_s
        print(f"ratio ingest ({label}) / reference: {r:.2f}× (target ≤ {TARGET_RATIO:g}×): {'met' if r <= TARGET_RATIO else 'NOT met'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
