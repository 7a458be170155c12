"""Noon-import memory benchmark: peak resident memory of `jitroute noon import` against the file's size.

Generates a demo fleet (pipeline.synthetic.fleet) whose noon_reports.csv is about `--mb` MB, stores its vessels
in a fresh data root (set-up), then runs the command as a user would, under `/usr/bin/time -v`, and reads its
peak RSS ("Maximum resident set size"). The same is done once with `jitroute --help` (the interpreter and the
imports alone) for comparison. Target: peak RSS ≤ 3 × file size. Prints the figures; always exits 0.

    .venv/bin/python bench/noon_import.py [--mb 130] [--keep DIR]   (--keep: the file is made once and reused)
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import pandas as pd  # noqa: E402

from flows.settings import load_settings  # noqa: E402
from pipeline.synthetic.fleet import generate_fleet, write_fleet  # noqa: E402
from storage import fleet_store  # noqa: E402

TARGET_RATIO = 3.0
JITROUTE = Path(sys.executable).with_name("jitroute")


def make_file(out: Path, mb: float, days: int = 365) -> tuple[Path, Path]:
    """(noon_reports.csv of about `mb` MB, a fresh data root holding its vessels); a file already in `out` is reused."""
    folder = out / "fleet"
    if not (folder / "noon_reports.csv").exists():
        probe = generate_fleet("2020-12-01T00", n_vessels=4, days=days, seed=11)
        per_vessel = len(probe.noon.to_csv(index=False).encode()) / 4
        fleet = generate_fleet("2020-12-01T00", n_vessels=max(1, round(mb * 1e6 / per_vessel)), days=days, seed=11)
        write_fleet(fleet, folder)
    root = out / "data"
    shutil.rmtree(root, ignore_errors=True)
    fleet_store.import_vessels(load_settings(data_root=root).layout.ensure().warehouse,
                               pd.read_csv(folder / "vessels.csv"))
    return folder / "noon_reports.csv", root


def peak_rss_mb(args: list[str]) -> tuple[float, str]:
    """(peak RSS in MB, stdout) of the command `args` run under /usr/bin/time -v."""
    done = subprocess.run(["/usr/bin/time", "-v", *args], capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(args)} failed ({done.returncode}): {done.stderr[-2000:]}")
    kb = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", done.stderr).group(1))
    return kb / 1024.0, done.stdout


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mb", type=float, default=130.0, help="size of the noon-report file to generate, MB")
    ap.add_argument("--keep", type=Path, default=None, help="keep the generated file and data root in this folder")
    a = ap.parse_args()
    out = a.keep or Path(tempfile.mkdtemp(prefix="noon-import-"))
    out.mkdir(parents=True, exist_ok=True)
    try:
        csv, root = make_file(out, a.mb)
        size_mb = csv.stat().st_size / 2**20
        base_mb, _ = peak_rss_mb([str(JITROUTE), "--help"])
        peak_mb, said = peak_rss_mb([str(JITROUTE), "noon", "import", str(csv), "--data", str(root)])
        ratio = peak_mb / size_mb
        print(said.strip().splitlines()[0] if said.strip() else "")
        print(f"file {size_mb:.1f} MiB; peak RSS {peak_mb:.0f} MiB = {ratio:.2f} × the file "
              f"(target ≤ {TARGET_RATIO:.0f} ×: {'met' if ratio <= TARGET_RATIO else 'missed'}); "
              f"`jitroute --help` alone peaks at {base_mb:.0f} MiB")
    finally:
        if a.keep is None:
            shutil.rmtree(out, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
