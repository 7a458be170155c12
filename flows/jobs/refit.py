"""The refit job (speed and fuel models from noon reports) and the import jobs (fleet, noon reports, bunker logs)."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pandas as pd

from flows.jobs.noon_import import NOON_CHUNK_ROWS, import_noon_file, read_table, read_table_chunks  # noqa: F401
from flows.runner import PLAIN
from flows.settings import load_settings
from pipeline.fleet_validate import validate_vessels, validate_voyages
from pipeline.performance.bunker import validate_bunker
from pipeline.performance.refit import (DEFAULT_FORM, REPORT_COLUMNS, Gate, check_form, fitted_from_rows, gate_with,
                                        refit_fleet, storage_actions)
from pipeline.performance.validate import reason_counts
from storage import fleet_store

LOG = logging.getLogger("jitroute.refit")


class UnknownVesselError(ValueError):
    """A vessel asked for by IMO that is not in the warehouse."""


def exclude_noon_period(imo: int, from_utc: str, to_utc: str, reason: str, data_root: str | None = None, *, run=PLAIN) -> int:
    """Move vessel `imo`'s reports from `from_utc` to `to_utc` (inclusive) out of the refit's reach into
    noon_reports_history with `reason`; returns how many."""
    s = load_settings(data_root=Path(data_root) if data_root else None)
    db = s.layout.ensure().warehouse
    if int(imo) not in fleet_store.known_imos(db):
        raise UnknownVesselError(f"vessel {imo} not in {db}: import it with `jitroute fleet import`")
    return fleet_store.exclude_noon(db, int(imo), from_utc, to_utc, reason)


def import_fleet_folder(folder: str, data_root: str | None = None, *, run=PLAIN) -> dict:
    """Validate and store `vessels.csv` and `voyages.csv` of `folder` (vessels first: voyages need them);
    refused rows go to `vessels_rejected` / `voyages_rejected` with their reason."""
    s = load_settings(data_root=Path(data_root) if data_root else None)
    db = s.layout.ensure().warehouse
    out: dict = {}
    for name, validate, store in (("vessels", lambda raw, src: validate_vessels(raw, src), fleet_store.import_vessels),
                                  ("voyages", lambda raw, src: validate_voyages(raw, fleet_store.known_imos(db), src,
                                                                             fleet_store.plan_voyage_ids(db)),
                                   fleet_store.import_voyages)):
        path = Path(folder) / f"{name}.csv"
        good, bad = validate(read_table(path), path.name)
        out[name] = store(db, good, bad)
        out[f"{name}_rejected"] = reason_counts(bad)
        for _, row in bad.iterrows():
            LOG.warning("%s: row refused (%s): %r", path, row["reason"], row["raw"][:200])
    return out


def import_bunker_file(path: str, data_root: str | None = None, *, run=PLAIN) -> dict:
    """Validate a bunker-log file and store good rows; rejected and conflicting rows are returned with a reason."""
    s = load_settings(data_root=Path(data_root) if data_root else None)
    db = s.layout.ensure().warehouse
    raw = read_table(Path(path))
    vessels = fleet_store.load_vessels(db) if db.exists() else None
    dwt_t = dict(zip(vessels["imo"].astype(int), vessels["dwt"])) if vessels is not None and len(vessels) else {}
    good, bad = validate_bunker(raw, set(dwt_t) if vessels is not None else set(), source=Path(path).name, dwt_t=dwt_t)
    counts: dict = fleet_store.import_bunkers(db, good, bad)
    conflicts = counts.pop("conflicts")
    counts.update(rows=len(raw), rejected=len(bad) + len(conflicts), reasons=reason_counts(bad),
                  conflicts=[f"{r.imo} {r.bill_no} {r.fuel_type}" for r in conflicts.itertuples()])
    return counts


def load_reports(db: Path, imos: list[int] | None) -> tuple[dict[str, np.ndarray], dict, dict, dict]:
    """(noon-report columns a refit needs, active models, next versions, stored fits), read in one connection."""
    reports, active, versions, fitted = fleet_store.load_for_refit(db, imos, REPORT_COLUMNS)
    return reports, active, versions, fitted_from_rows(fitted)


def fit_vessels(reports: dict[str, np.ndarray], active: dict, versions: dict, form: str, robust: bool | None,
                gate: Gate = Gate(), fitted: dict | None = None) -> tuple[list[dict], list[dict]]:
    return refit_fleet(reports, active, versions, form=form, robust=robust, gate=gate, fitted=fitted)


HULL_REPORT_COLUMNS = ("imo", "ts_utc", "rpm", "draft_m", "trim_m", "wind_kn", "wind_dir_rel_deg", "wave_m",
                       "wave_dir_rel_deg", "stw_kn")


def update_hull_performance(db: Path, reports: dict[str, np.ndarray], active: dict, imos: list[int], flag_pct: float) -> int:
    """Speed loss against a clean hull, per month, of vessels `imos`' reports (as `load_reports` read them for the
    refit: no second read) under their `active` models (as `fleet_store.save_fits` returns them), stored in
    hull_performance_monthly; returns the number of vessels with a model."""
    from pipeline.performance.hull import monthly_speed_loss
    from pipeline.performance.model import model_from_stored

    if not imos:
        return 0
    rows = pd.DataFrame({c: reports[c] for c in HULL_REPORT_COLUMNS})
    rows = rows[rows["imo"].isin(imos)]
    out: dict = {}
    for imo, vessel_rows in rows.groupby("imo", sort=True):
        m = model_from_stored(active.get(int(imo)), int(imo))
        if m is not None:
            out[int(imo)] = (m.version, monthly_speed_loss(m, vessel_rows, flag_pct))
    fleet_store.save_hull_performance(db, out)
    return len(out)


def refit_job(imos: list[int] | None = None, data_root: str | None = None, form: str = DEFAULT_FORM,
              robust: bool | None = None, gate: list[str] | None = None, *, run=PLAIN) -> list[dict]:
    """Refit every (or the given) vessel's speed and fuel model in `form` (default the physical form; "best": every
    form, the physical one kept unless another is significantly better on held-out reports); a model becomes active only if it passes
    the gate (settings.performance, with `gate` "NAME=VALUE" overrides) and is not worse than the active
    one on the same held-out reports."""
    check_form(form)  # before anything is read
    s = load_settings(data_root=Path(data_root) if data_root else None)
    s = s.with_overrides(performance=gate_with(s.performance, gate))
    db = s.layout.ensure().warehouse
    known = fleet_store.known_imos(db)
    unknown = sorted(set(imos or ()) - set(known))
    if unknown:
        raise UnknownVesselError(f"vessel(s) {', '.join(map(str, unknown))} not in {db}: import them with "
                                 "`jitroute fleet import`")
    reports, active, versions, fitted = run.step(load_reports, db, imos, name="load-reports")
    summaries_missing = []
    for imo in sorted(set(imos or known) - set(np.unique(reports["imo"]).tolist())):
        summaries_missing.append({"imo": imo, "n": 0, "changed": False,
                                  "reason": "no valid noon reports (all rejected or none imported): model unchanged"})
        LOG.warning("vessel %s: no valid noon reports; model unchanged", imo)
    rows, summaries = run.step(fit_vessels, reports, active, versions, form, robust, s.performance, fitted,
                               name="fit-vessels")
    reactivate, flags = storage_actions(summaries)
    for imo, text in flags.items():
        if text:
            LOG.warning("vessel %s: %s", imo, text)
    active = run.step(fleet_store.save_fits, db, rows, reactivate=reactivate, flags=flags, name="save-fits")
    run.step(update_hull_performance, db, reports, active, sorted({int(x["imo"]) for x in summaries}),
             s.performance.hull_flag_pct, name="hull-performance")
    return sorted(summaries + summaries_missing, key=lambda d: d["imo"])
