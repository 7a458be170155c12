"""A RISH-style mirror of GSM/GWM GRIB2 forecasts and OSCAR currents, from the analytic weather.

Layout (what `jitroute mirror` writes and the demo ingests through `file://`):

    out_dir/rish/YYYY/MM/DD/index.html           Apache-style listing of the day folder
    out_dir/rish/YYYY/MM/DD/Z__C_RJTD_...grib2.bin
    out_dir/oscar/index.html
    out_dir/oscar/oscar_vel{N}.nc                 v1 layout, N = days since 1992-10-05

Deterministic for a seed. Day folders also list files jitroute must ignore.
"""

from __future__ import annotations

import html
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from pipeline.routing.land import is_sea
from pipeline.synthetic import weather
from pipeline.synthetic.grib_writer import jma_grid, write_gsm_file, write_gwm_file
from pipeline.synthetic.oscar_writer import V1_EPOCH, write_oscar_v1

GWM_SPLIT_H = 84  # JMA splits GWM files at 84 h: FD0000-0312 and FD0318-0512
LONG_CYCLES_UTC = (0, 12)  # the cycles JMA runs on past 132 h
OSCAR_EVERY_DAYS = 5


def lead_code_ddhh(hours: int) -> str:
    return f"{hours // 24:02d}{hours % 24:02d}"


def gsm_name(cycle: np.datetime64, lead_h: int) -> str:
    return f"Z__C_RJTD_{_stamp(cycle)}0000_GSM_GPV_Rgl_FD{lead_code_ddhh(lead_h)}_grib2.bin"


def gwm_name(cycle: np.datetime64, first_h: int, last_h: int, res_deg: float = 0.5) -> str:
    res = "0p5deg" if abs(res_deg - 0.5) < 1e-9 else "0p25deg"
    return f"Z__C_RJTD_{_stamp(cycle)}0000_GWM_GPV_Rgl_Gll{res}_FD{lead_code_ddhh(first_h)}-{lead_code_ddhh(last_h)}_grib2.bin"


def oscar_v1_name(time: np.datetime64) -> str:
    return f"oscar_vel{int((np.datetime64(time, 'D') - np.datetime64(V1_EPOCH, 'D')).astype(int))}.nc"


def _stamp(cycle: np.datetime64) -> str:
    return np.datetime_as_string(np.datetime64(cycle, "h"), unit="h").replace("-", "").replace("T", "")


def write_index(folder: Path, extra: Sequence[str] = ()) -> Path:
    """An Apache-like index.html listing every file in `folder` (plus `extra` names)."""
    names = sorted([p.name for p in folder.iterdir() if p.is_file() and p.name != "index.html"] + list(extra))
    rows = "\n".join(f'<tr><td><a href="{html.escape(n)}">{html.escape(n)}</a></td></tr>' for n in names)
    page = (f"<html><head><title>Index of {folder.name}</title></head><body><h1>Index of {folder.name}</h1>\n"
            f'<table><tr><th>Name</th></tr>\n<tr><td><a href="../">Parent Directory</a></td></tr>\n{rows}\n</table></body></html>\n')
    out = folder / "index.html"
    out.write_text(page)
    return out


def _cycle_times(start: np.datetime64, end: np.datetime64, cycles: Sequence[int]) -> list[np.datetime64]:
    days = np.arange(np.datetime64(start, "D"), np.datetime64(end, "D") + 1)
    return [np.datetime64(d, "h") + np.timedelta64(int(c), "h") for d in days for c in cycles]


def write_cycle(rish_dir: Path, cycle: np.datetime64, *, seed: int = 0, max_lead_h: int = 132, step_h: int = 6,
                res_deg: float = 0.5, gwm_land_as: str = "bitmap", long_lead_h: int | None = None,
                long_step_h: int = 12) -> list[Path]:
    """All GSM files and the GWM files of one cycle into its day folder. With `long_lead_h`, a 00 or 12 UTC cycle goes
    on to it every `long_step_h` past max_lead_h, as JMA's do (GSM FD0600…FD1100, GWM FD0600-1100); the demo and
    most tests leave it out (every lead is a global file to write and decode)."""
    day = np.datetime_as_string(np.datetime64(cycle, "D"))
    folder = rish_dir / day[:4] / day[5:7] / day[8:10]
    folder.mkdir(parents=True, exist_ok=True)
    lat, lon = jma_grid(res_deg)
    L, O = np.meshgrid(lat, lon, indexing="ij")
    land = ~is_sea(L, O)
    t0 = weather.hours_since_epoch(np.datetime64(cycle, "ns"))
    steps = list(range(0, max_lead_h + 1, step_h))
    long_steps = []
    if long_lead_h is not None and int(np.datetime_as_string(np.datetime64(cycle, "h"))[11:13]) in LONG_CYCLES_UTC:
        long_steps = list(range(max_lead_h + long_step_h, long_lead_h + 1, long_step_h))
    steps += long_steps
    written = []
    waves = {"swh": [], "mwd": [], "mwp": []}
    for s in steps:
        u, v = weather.wind_uv(t0 + s, L, O, seed)
        fields = {"prmsl": 101325.0 - 30.0 * np.hypot(u, v) ** 2, "u10": u, "v10": v, "t2m": 288.0 - 0.4 * np.abs(L)}
        written.append(write_gsm_file(folder / gsm_name(cycle, s), cycle, s, fields, res_deg))
        swh, mwd, mwp = weather.waves(t0 + s, L, O, seed)
        waves["swh"].append(swh)
        waves["mwd"].append(mwd)
        waves["mwp"].append(mwp)
    for lo, hi in ((0, GWM_SPLIT_H), (GWM_SPLIT_H + step_h, max_lead_h), (max_lead_h + 1, long_lead_h or -1)):
        idx = [i for i, s in enumerate(steps) if lo <= s <= hi]
        if not idx:
            continue
        part = {k: np.stack([v[i] for i in idx]) for k, v in waves.items()}
        name = gwm_name(cycle, steps[idx[0]], steps[idx[-1]], res_deg)
        written.append(write_gwm_file(folder / name, cycle, [steps[i] for i in idx], part, land, res_deg, gwm_land_as))
    return written


def write_mirror(out_dir: Path, start, end, *, seed: int = 0, cycles: Sequence[int] = (0, 12), max_lead_h: int = 132,
                 step_h: int = 6, res_deg: float = 0.5, oscar_res_deg: float = 1 / 3, progress=None,
                 long_lead_h: int | None = None, long_step_h: int = 12) -> Path:
    """Write the mirror for every cycle of the days start..end (inclusive); returns `out_dir`.

    `progress(done, total, label)`, if given, is called after each cycle.
    """
    out_dir = Path(out_dir)
    rish = out_dir / "rish"
    oscar = out_dir / "oscar"
    oscar.mkdir(parents=True, exist_ok=True)
    cycle_list = _cycle_times(np.datetime64(start), np.datetime64(end), cycles)
    for k, c in enumerate(cycle_list):
        write_cycle(rish, c, seed=seed, max_lead_h=max_lead_h, step_h=step_h, res_deg=res_deg, long_lead_h=long_lead_h,
                    long_step_h=long_step_h)
        if progress:
            progress(k + 1, len(cycle_list), str(c))
    for folder in {p.parent for p in rish.rglob("*.bin")}:
        write_index(folder, extra=["Z__C_RJTD_20201201000000_MSM_GPV_Rjp_Lsurf_FH00-15_grib2.bin", "README.txt"])
    # OSCAR v1: 5-daily analyses from before the first cycle to past the last valid time
    first = np.datetime64(np.datetime64(start, "D") - np.timedelta64(OSCAR_EVERY_DAYS, "D"), "D")
    last = np.datetime64(end, "D") + np.timedelta64(max_lead_h // 24 + 2, "D")
    epoch_day = np.datetime64(V1_EPOCH, "D")
    first = epoch_day + ((first - epoch_day) // OSCAR_EVERY_DAYS) * OSCAR_EVERY_DAYS
    def uv(t, la, lo):
        return weather.currents_uv(weather.hours_since_epoch(np.datetime64(t, "ns")), la, lo)
    for day in np.arange(first, last + 1, OSCAR_EVERY_DAYS):
        path = oscar / oscar_v1_name(day)
        if not path.exists():
            write_oscar_v1(path, [np.datetime64(day, "ns")], uv, oscar_res_deg)
    write_index(oscar)
    return out_dir
