"""Prefect flows `refit-performance`, `import-noon-reports` and `import-bunker-logs`."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from prefect import flow, get_run_logger, task
from prefect.cache_policies import NO_CACHE

from flows.settings import load_settings
from pipeline.performance.refit import REPORT_COLUMNS, Gate, check_form, fitted_from_rows, refit_fleet, storage_actions
from pipeline.performance.bunker import validate_bunker
from pipeline.performance.validate import NoonFileError, reason_counts, validate_noon
from storage import fleet_store


def read_table(path: Path) -> pd.DataFrame:
    """CSV or Parquet, every column as text (validation does the typing)."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such file")
    try:
        if path.suffix.lower() in (".parquet", ".pq"):
            return pd.read_parquet(path).astype("string").astype(object)
        df = pd.read_csv(path, dtype=str, keep_default_na=False, na_values=[""])
    except (ValueError, OSError, pd.errors.ParserError) as exc:
        raise NoonFileError(f"{path}: cannot be read as CSV/Parquet ({exc})") from exc
    if not isinstance(df.index, pd.RangeIndex):  # pandas took surplus leading fields as an index: columns shifted
        raise NoonFileError(f"{path}: line 2 has more fields than the header's {len(df.columns)} columns; fix the file and re-import")
    return df


@flow(name="import-noon-reports")
def import_noon_reports(path: str, data_root: str | None = None) -> dict:
    """Validate a noon-report file and store good rows; bad rows go to noon_reports_rejected with a reason."""
    s = load_settings(data_root=Path(data_root) if data_root else None)
    db = s.layout.ensure().warehouse
    raw = read_table(Path(path))
    good, bad = validate_noon(raw, fleet_store.known_imos(db), source=Path(path).name)
    counts = fleet_store.import_noon(db, good, bad)
    counts["rows"] = len(raw)
    counts["reasons"] = reason_counts(bad)
    return counts


@flow(name="import-bunker-logs")
def import_bunker_logs(path: str, data_root: str | None = None) -> dict:
    """Validate a bunker-log file and store good rows; rejected and conflicting rows are returned with a reason."""
    s = load_settings(data_root=Path(data_root) if data_root else None)
    db = s.layout.ensure().warehouse
    raw = read_table(Path(path))
    good, bad = validate_bunker(raw, fleet_store.known_imos(db), source=Path(path).name)
    counts = fleet_store.import_bunkers(db, good)
    conflicts = counts.pop("conflicts")
    counts.update(rows=len(raw), rejected=len(bad) + len(conflicts), reasons=reason_counts(bad),
                  conflicts=[f"{r.imo} {r.bill_no} {r.fuel_type}" for r in conflicts.itertuples()])
    return counts


@task(name="load-reports", cache_policy=NO_CACHE)
def load_reports(db: Path, imos: list[int] | None) -> tuple[dict[str, np.ndarray], dict, dict, dict]:
    """(noon-report columns a refit needs, active models, next versions, stored fits), read in one connection."""
    reports, active, versions, fitted = fleet_store.load_for_refit(db, imos, REPORT_COLUMNS)
    return reports, active, versions, fitted_from_rows(fitted)


@task(name="fit-vessels", cache_policy=NO_CACHE)  # no hashing of the fleet's report arrays
def fit_vessels(reports: dict[str, np.ndarray], active: dict, versions: dict, form: str, robust: bool | None,
                gate: Gate = Gate(), fitted: dict | None = None) -> tuple[list[dict], list[dict]]:
    return refit_fleet(reports, active, versions, form=form, robust=robust, gate=gate, fitted=fitted)


@flow(name="refit-performance")
def refit_performance(imos: list[int] | None = None, data_root: str | None = None, form: str = "best",
                      robust: bool | None = None) -> list[dict]:
    """Refit every (or the given) vessel's speed and fuel model ("best": every form, the best on held-out
    reports proposed); a model becomes active only if it passes the gate (settings.performance) and is
    not worse than the active one on the same held-out reports."""
    check_form(form)  # before anything is read
    s = load_settings(data_root=Path(data_root) if data_root else None)
    db = s.layout.ensure().warehouse
    logger = get_run_logger()
    known = fleet_store.known_imos(db)
    reports, active, versions, fitted = load_reports(db, imos)
    summaries_missing = []
    for imo in sorted(set(imos or known) - set(np.unique(reports["imo"]).tolist())):
        summaries_missing.append({"imo": imo, "n": 0, "changed": False,
                                  "reason": "no valid noon reports (all rejected or none imported): model unchanged"})
        logger.warning("vessel %s: no valid noon reports; model unchanged", imo)
    rows, summaries = fit_vessels(reports, active, versions, form, robust, s.performance, fitted)
    reactivate, flags = storage_actions(summaries)
    for imo, text in flags.items():
        logger.warning("vessel %s: %s", imo, text)
    fleet_store.save_fits(db, rows, reactivate=reactivate, flags=flags)
    return sorted(summaries + summaries_missing, key=lambda d: d["imo"])
