"""The `verify` job: stored plans and their baselines re-sailed in the analysed weather of the cube's later cycles.

For each plan whose passage meets the analysed valid times (the complete cycles' leads up to
`verification.ANALYSIS_LEAD_H`) and that is not verified yet with the newest cycle: its window of every complete
cycle that can tell (each older cycle's short leads, the newest cycle whole), merged by
pipeline/routing/verification.py, the plan and its baseline sailed through it, one plan_verification row each.
"""

from __future__ import annotations

import json
import logging
import math
from typing import Any
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from flows.jobs.route_worker import window_field
from flows.runner import PLAIN
from flows.settings import load_settings
from pipeline.performance.model import model_from_stored
from pipeline.routing import verification as vf
from pipeline.routing.problem import RoutingInputError, WeatherWindow
from pipeline.routing.solvers import solver_spec
from pipeline.sources.cycles import label as cycle_label
from storage import cube_window, fleet_store, verification_store
from storage.cube_location import CubeError

LOG = logging.getLogger("jitroute.verify")


def _plain(x):
    """A warehouse value as plain Python (None for NaN/NaT)."""
    if x is None or (isinstance(x, float) and x != x):
        return None
    if hasattr(x, "to_pydatetime"):
        return None if x != x else x.to_pydatetime()
    if isinstance(x, np.generic):
        return x.item()
    return x


def _cycle_windows(cycles: list[np.datetime64], window: WeatherWindow, lead_h: float) -> list[tuple[np.datetime64, WeatherWindow]]:
    """(cycle, the part of `window` to read of it): of the newest (first) the whole window; of each older one its
    valid times up to `lead_h`, when they reach into the window or end at most `lead_h` before it (so the analysed
    valid time just before the departure is there to interpolate from)."""
    out = []
    lead = np.timedelta64(int(lead_h * 3600), "s")
    for k, c in enumerate(cycles):
        c_s = np.datetime64(c, "s")
        if k == 0:
            out.append((c, window))
        elif c_s + lead >= window.from_utc - lead and c_s <= window.to_utc:
            out.append((c, window._replace(from_utc=c_s, to_utc=c_s + lead)))
    return out


def _fields(cube_url: str, options: dict, cycles: list[np.datetime64], window: WeatherWindow, lead_h: float):
    options_json = json.dumps(options or {}, sort_keys=True)
    fields = []
    for c, w in _cycle_windows(cycles, window, lead_h):
        try:
            fields.append(window_field(cube_url, options_json, str(np.datetime_as_string(np.datetime64(c, "s"))), None, w))
        except (KeyError, CubeError) as exc:  # retired, being re-written or damaged meanwhile: one cycle less
            LOG.warning("cycle %s left out of the verification: %s", cycle_label(c), exc)
    return fields


def _baseline_legs(plan: dict, legs: list[dict]) -> list[dict] | None:
    lat, lon, rpm = (plan.get(k) for k in ("baseline_lat_deg", "baseline_lon_deg", "baseline_leg_rpm"))
    if lat is not None and lon is not None and rpm is not None and len(lat) >= 2:
        return vf.constant_rpm_legs(list(lat), list(lon), list(rpm))
    try:
        if solver_spec(str(plan.get("solver"))).is_baseline:  # the constant-speed voyage itself: its own baseline
            return legs
    except RoutingInputError:  # a solver no longer registered: no baseline to compare with
        pass
    return None


def verification_row(plan: dict, v: vf.Verification, weather: vf.VerificationWeather, now: datetime) -> dict:
    rta = np.datetime64(_plain(plan["rta_utc"]), "s")
    late_h = float((v.plan_eta_utc - rta) / np.timedelta64(1, "s")) / 3600.0 if v.plan_eta_utc is not None else None
    until = weather.analysed_until_utc

    def t(x):
        return None if x is None else np.datetime64(x, "s").item()
    return {
        "run_id": str(plan["run_id"]), "voyage_id": str(plan["voyage_id"]),
        "plan_kind": "port" if (plan.get("start_kind") or "port") == "port" else "re-plan at sea",
        "cycle": _plain(plan.get("cycle")), "cycles_used": ", ".join(cycle_label(c) for c in weather.cycles),
        "newest_cycle": t(weather.cycles[-1]) if weather.cycles else None, "analysis_lead_h": vf.ANALYSIS_LEAD_H,
        "analysed_until_utc": t(until), "hours_analysed": v.hours_analysed, "hours_total": v.hours_total,
        "coverage": v.coverage, "claimed_fuel_t": _plain(plan.get("fuel_t")), "realised_fuel_t": v.plan_fuel_t,
        "claimed_eta_utc": _plain(plan.get("eta_utc")), "realised_eta_utc": t(v.plan_eta_utc), "realised_late_h": late_h,
        "claimed_baseline_fuel_t": _plain(plan.get("honest_baseline_fuel_t")),
        "realised_baseline_fuel_t": v.baseline_fuel_t if math.isfinite(v.baseline_fuel_t) else None,
        "realised_baseline_eta_utc": t(v.baseline_eta_utc), "claimed_savings_pct": _plain(plan.get("savings_total_pct")),
        "realised_savings_pct": v.realised_savings_pct if math.isfinite(v.realised_savings_pct) else None,
        "verified_at": now,
    }


def verify_plans_job(data_root: str | None = None, run_id: str | None = None, *, run=PLAIN) -> dict:
    """Re-sail the stored plans that the cube's analysed weather now covers (or run `run_id`'s), store a
    plan_verification row for each; returns a summary: cycles, n_verified, n_whole, n_skipped (why), and the claimed
    and realised savings over the verified plans with a baseline (fuel-weighted)."""
    s = load_settings(data_root=Path(data_root) if data_root else None)
    layout = s.layout.ensure()
    loc = layout.cube_store
    cycles = list(cube_window.complete_cycles_newest_first(loc.url, loc.options))
    out: dict[str, Any] = {"run_id": run_id, "newest_cycle": cycle_label(cycles[0]) if cycles else None, "n_cycles": len(cycles),
           "n_candidates": 0, "n_verified": 0, "n_whole": 0, "skipped": []}
    if not cycles:
        out["skipped"].append("no complete cycle in the cube: nothing to verify with")
        return out
    lead = np.timedelta64(int(vf.ANALYSIS_LEAD_H * 3600), "s")
    plans = verification_store.plans_to_verify(layout.warehouse, analysed_from_utc=cycles[-1],
                                               analysed_until_utc=np.datetime64(cycles[0], "s") + lead,
                                               newest_cycle=cycles[0], run_id=run_id)
    out["n_candidates"] = len(plans)
    legs_of = verification_store.plan_legs(layout.warehouse, plans)
    voyages = {str(v["voyage_id"]): {k: _plain(x) for k, x in v.items()} for v in fleet_store.load_voyages(
        layout.warehouse, voyage_ids=sorted({str(p["voyage_id"]) for p in plans})).to_dict("records")} if plans else {}
    vessels = {int(v["imo"]): v for v in fleet_store.load_vessels(layout.warehouse).to_dict("records")} if plans else {}
    rows: list[dict] = []
    now = datetime.now(timezone.utc).replace(tzinfo=None)
    models: dict[tuple, dict | None] = {}
    for p in plans:
        key = (str(p["run_id"]), str(p["voyage_id"]))
        legs, voyage = legs_of.get(key), voyages.get(key[1])
        if not legs or voyage is None:
            out["skipped"].append(f"{key[1]} (run {key[0]}): " + ("no legs stored" if not legs else "voyage no longer in voyages"))
            continue
        mkey = (int(p["imo"]), _plain(p.get("model_version")))
        if mkey not in models:
            m = model_from_stored(fleet_store.model_version(layout.warehouse, *mkey), mkey[0])
            models[mkey] = m.to_json() if m is not None else None
        model_json = models[mkey]
        if model_json is None:
            out["skipped"].append(f"{key[1]} (run {key[0]}): performance model version {mkey[1]} of vessel {mkey[0]} "
                                  "is not usable now (refit it)")
            continue
        depart = np.datetime64(_plain(p["depart_utc"]), "s")
        try:
            vessel = vf.sailing_vessel({**voyage, "depart_utc": depart}, model_json,
                                       rpm_max=_plain(vessels.get(int(p["imo"]), {}).get("rpm_max")))
        except RoutingInputError as exc:
            out["skipped"].append(f"{key[1]} (run {key[0]}): {exc}")
            continue
        base = _baseline_legs(p, legs)
        window = vf.verification_window([legs] + ([base] if base else []), depart, float(p["hours"]))
        fields = _fields(loc.url, loc.options, cycles, window, vf.ANALYSIS_LEAD_H)
        if not fields:
            out["skipped"].append(f"{key[1]} (run {key[0]}): no cycle could be read for its window")
            continue
        weather = vf.verification_weather(fields)
        v = vf.verify(legs, base, depart, weather, vessel, claimed_savings_pct=_plain(p.get("savings_total_pct")) or math.nan)
        if v is None or v.coverage == vf.NOT_VERIFIED:
            out["skipped"].append(f"{key[1]} (run {key[0]}): " + ("no headway in the weather that came" if v is None
                                                                   else "its passage meets no analysed weather"))
            continue
        rows.append(verification_row(p, v, weather, now))
    verification_store.write_verifications(layout.warehouse, rows)
    out["n_verified"] = len(rows)
    out["n_whole"] = sum(r["coverage"] == vf.VERIFIED for r in rows)
    out.update(_totals(rows))
    LOG.info("verified %d plan(s) in the analysed weather up to cycle %s (%d wholly)%s", out["n_verified"],
             out["newest_cycle"], out["n_whole"], f"; {len(out['skipped'])} skipped" if out["skipped"] else "")
    return out


def _totals(rows: list[dict]) -> dict:
    """Claimed and realised savings over the rows with a realised baseline, fuel-weighted (as fleet_savings)."""
    both = [r for r in rows if r["realised_baseline_fuel_t"] and r["claimed_baseline_fuel_t"] and r["claimed_fuel_t"]]
    if not both:
        return {"n_compared": 0, "claimed_savings_pct": None, "realised_savings_pct": None}
    return {"n_compared": len(both),
            "claimed_savings_pct": 100 * (1 - sum(r["claimed_fuel_t"] for r in both) / sum(r["claimed_baseline_fuel_t"] for r in both)),
            "realised_savings_pct": 100 * (1 - sum(r["realised_fuel_t"] for r in both)
                                          / sum(r["realised_baseline_fuel_t"] for r in both))}


def verification_sentence(v: dict | None) -> str | None:
    """The verification's outcome in one sentence for the nightly summary (None: nothing verified)."""
    if not v or not v.get("n_verified"):
        return None
    n, whole = v["n_verified"], v.get("n_whole", 0)
    cover = "wholly" if whole == n else (f"{whole} wholly, {n - whole} partly" if whole else "partly")
    text = (f"Verified {n} plan{'s' if n != 1 else ''} ({cover}) in the analysed weather up to cycle "
            f"{v.get('newest_cycle')}")
    if v.get("realised_savings_pct") is not None:
        text += (f": claimed saving {v['claimed_savings_pct']:.1f} %, realised {v['realised_savings_pct']:.1f} % "
                 f"({v['n_compared']} with a baseline, fuel-weighted)")
    return text + "."
