"""RISH archive listing: day-folder URLs, HTML index parsing, GSM/GWM file-name recognition.

Day folders live at `<base>/YYYY/MM/DD/` and hold an HTML index. Only names that match the GSM
or GWM patterns are taken; everything else is ignored. A listed name that is not a plain file
name (a `/`, `..`, a scheme or an absolute path) is rejected so nothing is ever written outside
the raw store.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from html.parser import HTMLParser
from urllib.parse import unquote

import numpy as np

GSM_RE = re.compile(r"^Z__C_RJTD_(?P<cycle>\d{10})0000_GSM_GPV_Rgl_FD(?P<dd>\d{2})(?P<hh>\d{2})_grib2\.bin$")
GWM_RE = re.compile(
    r"^Z__C_RJTD_(?P<cycle>\d{10})0000_GWM_GPV_Rgl_Gll(?P<res>0p5deg|0p25deg)_FD(?P<d0>\d{2})(?P<h0>\d{2})-(?P<d1>\d{2})(?P<h1>\d{2})_grib2\.bin$"
)


@dataclass(frozen=True)
class SourceFile:
    model: str  # "GSM" | "GWM"
    name: str
    cycle: np.datetime64
    first_lead_h: int
    last_lead_h: int
    res_deg: float


class UnsafeNameError(ValueError):
    pass


def parse_name(name: str) -> SourceFile | None:
    """Recognise a GSM/GWM file name; None for anything else."""
    m = GSM_RE.match(name)
    if m:
        lead = int(m["dd"]) * 24 + int(m["hh"])
        return SourceFile("GSM", name, _cycle(m["cycle"]), lead, lead, 0.5)
    m = GWM_RE.match(name)
    if m:
        return SourceFile("GWM", name, _cycle(m["cycle"]), int(m["d0"]) * 24 + int(m["h0"]),
                          int(m["d1"]) * 24 + int(m["h1"]), 0.5 if m["res"] == "0p5deg" else 0.25)
    return None


def _cycle(stamp: str) -> np.datetime64:
    return np.datetime64(f"{stamp[:4]}-{stamp[4:6]}-{stamp[6:8]}T{stamp[8:10]}", "ns")


def day_folder_url(base_url: str, day: np.datetime64) -> str:
    d = np.datetime_as_string(np.datetime64(day, "D"))
    return f"{base_url.rstrip('/')}/{d[:4]}/{d[5:7]}/{d[8:10]}/"


class _Links(HTMLParser):
    def __init__(self):
        super().__init__()
        self.hrefs: list[str] = []

    def handle_starttag(self, tag, attrs):
        if tag == "a":
            href = dict(attrs).get("href")
            if href:
                self.hrefs.append(href)


def check_plain_name(name: str) -> str:
    """Return `name` if it is a plain file name, else raise UnsafeNameError."""
    if not name or name in (".", "..") or "/" in name or "\\" in name or ".." in name or ":" in name or "\x00" in name:
        raise UnsafeNameError(f"refusing listed name {name!r}: not a plain file name")
    return name


def parse_index(html_text: str) -> tuple[list[str], list[str]]:
    """(plain file names, rejected hrefs) from an HTML index page. Folder links are skipped."""
    p = _Links()
    p.feed(html_text)
    names, rejected = [], []
    for href in p.hrefs:
        href = unquote(href.split("?", 1)[0].split("#", 1)[0])
        if href in ("../", "./", "/") or href.endswith("/") and href.count("/") == 1 and ".." not in href:
            continue  # parent or sub-folder link
        try:
            names.append(check_plain_name(href))
        except UnsafeNameError:
            rejected.append(href)
    return names, rejected


def files_for_cycle(names: list[str], cycle: np.datetime64) -> list[SourceFile]:
    """GSM and GWM files of one cycle, sorted by model and lead."""
    out = [f for f in (parse_name(n) for n in names) if f is not None and f.cycle == np.datetime64(cycle, "ns")]
    return sorted(out, key=lambda f: (f.model, f.first_lead_h, -f.res_deg))


def expected_gsm_leads(max_lead_h: int = 132, step_h: int = 6) -> list[int]:
    """The leads every cycle must have (h): 0..max_lead_h every step_h."""
    return list(range(0, max_lead_h + 1, step_h))


def long_gsm_leads(max_lead_h: int = 132, long_lead_h: int | None = 264, long_step_h: int = 12) -> list[int]:
    """The leads past max_lead_h that the 00 and 12 UTC cycles add (h): every long_step_h to long_lead_h (JMA:
    144..264 h every 12 h, FD0600…FD1100); empty when long_lead_h is None or not past max_lead_h."""
    if not long_lead_h:
        return []
    return list(range(max_lead_h + long_step_h, long_lead_h + 1, long_step_h))


def coverage(files: list[SourceFile], steps_h: list[int]) -> dict[str, list[int]]:
    """Steps of `steps_h` not covered by any listed GSM file / GWM file: {"GSM": [...], "GWM": [...]}."""
    gsm = {f.first_lead_h for f in files if f.model == "GSM"}
    gwm = [(f.first_lead_h, f.last_lead_h) for f in files if f.model == "GWM"]
    return {
        "GSM": [s for s in steps_h if s not in gsm],
        "GWM": [s for s in steps_h if not any(a <= s <= b for a, b in gwm)],
    }


def prefer_resolution(files: list[SourceFile]) -> list[SourceFile]:
    """When a GWM lead range exists at 0.25° and 0.5°, keep only the finer one."""
    best: dict[tuple, SourceFile] = {}
    for f in files:
        key = (f.model, f.first_lead_h, f.last_lead_h)
        if key not in best or f.res_deg < best[key].res_deg:
            best[key] = f
    return sorted(best.values(), key=lambda f: (f.model, f.first_lead_h))
