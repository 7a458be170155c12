"""Gantt-style picture of a fleet plan: one row per vessel of the fleet (an idle vessel's row says so), its ballast
legs, port calls (named on the bar) and laden legs in time, each contract's load window behind its loading, and the
contracts left listed below.

Matplotlib's object API (Agg, headless), as plots.py. `plan_gantt_figure` returns the Figure, `plan_gantt_png`
writes it.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib.dates as mdates
import pandas as pd
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from pipeline.export.plots import _save

KIND_COLOURS = {"ballast": "#9ecae1", "laden": "#3182bd", "port": "#fd8d3c", "window": "#d9d9d9"}


def plan_gantt_figure(plan: dict, legs: pd.DataFrame, windows: dict[str, tuple] | None = None,
                      unassigned: pd.DataFrame | None = None, names: dict[int, str] | None = None,
                      fleet: list[int] | None = None) -> Figure:
    """`legs`: fleet_plan_legs rows; `windows`: contract code → (early, late) of its load window (UTC); `fleet`: every
    vessel's IMO (those with no leg get an "idle" row; by default only vessels with legs are drawn)."""
    names = names or {}
    busy = [int(i) for i in dict.fromkeys(legs["imo"])] if len(legs) else []
    vessels = busy + [int(i) for i in dict.fromkeys(fleet or []) if int(i) not in set(busy)]
    has_left = unassigned is not None and len(unassigned)
    height = 1.9 + 0.55 * max(1, len(vessels))
    fig = Figure(figsize=(12, height))
    # fixed margins in inches (as plots.py): ticks and the axis label below, the line of contracts left under them
    fig.subplots_adjust(left=0.16, right=0.98, bottom=(0.6 + (0.25 if has_left else 0.0)) / height,
                        top=1.0 - 0.55 / height)
    ax = fig.add_subplot()
    for y, imo in enumerate(vessels):
        mine = legs[legs["imo"] == imo].sort_values("seq")
        prev_end = None
        for leg in mine.to_dict("records"):
            dep, arr = mdates.date2num(pd.Timestamp(leg["depart_utc"])), mdates.date2num(pd.Timestamp(leg["arrive_utc"]))
            if leg["kind"] == "laden" and windows and leg["contract_code"] in windows:
                e, l = (mdates.date2num(pd.Timestamp(t)) for t in windows[leg["contract_code"]])
                ax.barh(y, l - e, left=e, height=0.8, color=KIND_COLOURS["window"], zorder=1)
            if prev_end is not None and dep > prev_end:  # in port (loading/discharging) or waiting
                ax.barh(y, dep - prev_end, left=prev_end, height=0.35, color=KIND_COLOURS["port"], zorder=2)
                ax.text((prev_end + dep) / 2, y + 0.42, str(leg["from_port"]), ha="center", va="top", fontsize=6,
                        color="#a63603", zorder=4, clip_on=True)
            ax.barh(y, max(arr - dep, 1e-3), left=dep, height=0.55, color=KIND_COLOURS[leg["kind"]], zorder=3,
                    edgecolor="white", lw=0.5)
            if leg["kind"] == "laden":
                ax.text((dep + arr) / 2, y, str(leg["contract_code"]), ha="center", va="center", fontsize=7,
                        color="white", zorder=4, clip_on=True)
            prev_end = arr
        if mine.empty:
            ax.text(0.01, y, "idle: no contract in this plan", transform=ax.get_yaxis_transform(), va="center",
                    fontsize=7, color="#636363", style="italic", bbox={"fc": "white", "ec": "none", "pad": 1})
    ax.set_yticks(range(len(vessels)), [f"{names.get(int(i), '')} {i}".strip() for i in vessels], fontsize=8)
    ax.set_ylim(len(vessels) - 0.4, -0.6)  # top to bottom; idle rows keep their room
    ax.xaxis.set_major_formatter(mdates.DateFormatter("%d %b"))
    ax.grid(True, axis="x", lw=0.3, alpha=0.5)
    ax.set_xlabel("UTC")
    cost = plan.get("total_cost")
    ax.set_title(f"Fleet plan {plan.get('plan_id')} as of {pd.Timestamp(plan.get('as_of_utc')):%Y-%m-%d %H:%M} UTC\n"
                 f"{plan.get('n_assigned')} of {plan.get('n_contracts')} contracts on {len(busy)} of {len(vessels)} vessels · "
                 f"cost {cost:,.0f} ({plan.get('solve_status')})" if cost is not None else "", fontsize=10)
    ax.legend(handles=[Patch(color=KIND_COLOURS[k], label=lab) for k, lab in
                       (("ballast", "ballast"), ("laden", "laden"), ("port", "in port / waiting"),
                        ("window", "load window"))], fontsize=7, loc="upper right", ncols=4)
    if has_left:
        codes = ", ".join(str(c) for c in unassigned["contract_code"])
        fig.text(0.01, 0.01, f"left ({len(unassigned)}, reasons in fleet_plan_unassigned): "
                 + (codes[:160] + ("…" if len(codes) > 160 else "")), fontsize=7, va="bottom")
    return fig


def plan_gantt_png(path, plan: dict, legs: pd.DataFrame, windows=None, unassigned=None, names=None,
                   fleet: list[int] | None = None) -> Path:
    return _save(plan_gantt_figure(plan, legs, windows, unassigned, names, fleet), path)
