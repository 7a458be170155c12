"""The first run after installing: `jitroute warm` (what `make install` ends with), then the demo cold and warm.

A fresh clone has no numba cache. This starts from an empty one (NUMBA_CACHE_DIR in a temporary folder, so the
checkout's own cache is left alone) and times, each in a fresh process:
  1. `jitroute warm`                 — the compile cost, paid by `make install`;
  2. `jitroute demo --data D`        — the first demo after installing (mirror, fleet, ingest, refit, routing);
  3. `jitroute demo --data D` again  — the warm demo (mirror kept, cycles already complete).
It prints the three wall times and the ratio first demo / warm demo. Target: ≤ 1.5.
With --no-warm step 1 is skipped, to show what the first demo costs without it.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent


def timed(args: list[str], env: dict) -> float:
    t0 = time.monotonic()
    r = subprocess.run([str(BIN / "jitroute"), *args], env=env, capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"jitroute {' '.join(args)} failed ({r.returncode}):\n{r.stderr[-3000:]}")
    return time.monotonic() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--no-warm", action="store_true", help="skip `jitroute warm` (the first demo compiles)")
    ap.add_argument("--keep", action="store_true", help="keep the temporary folder")
    a = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="jitroute-first-run-"))
    env = {k: v for k, v in os.environ.items() if not k.startswith("PREFECT_API_")}
    env.update(NUMBA_CACHE_DIR=str(tmp / "numba_cache"), PREFECT_HOME=str(tmp / "prefect"),
               PREFECT_LOGGING_LEVEL="WARNING", PREFECT_SERVER_ANALYTICS_ENABLED="false")
    try:
        warm_s = None if a.no_warm else timed(["warm"], env)
        cold_s = timed(["demo", "--data", str(tmp / "data")], env)
        again_s = timed(["demo", "--data", str(tmp / "data")], env)
    finally:
        if not a.keep:
            shutil.rmtree(tmp, ignore_errors=True)
    print(f"jitroute warm (make install):  {'skipped' if warm_s is None else f'{warm_s:6.0f} s'}")
    print(f"first demo after install:      {cold_s:6.0f} s")
    print(f"second demo (warm):            {again_s:6.0f} s")
    print(f"ratio first / warm demo:       {cold_s / again_s:6.2f}  (target <= 1.5)")


if __name__ == "__main__":
    main()
