"""Ingest log and cycle status in the warehouse."""

from __future__ import annotations

from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pandas as pd

from storage import warehouse

LOG_COLUMNS = ["run_id", "source", "cycle", "file_name", "url", "bytes", "sha256", "status", "error", "started_at", "finished_at"]


def utcnow() -> datetime:
    return datetime.now(timezone.utc).replace(tzinfo=None)


def record_files(db_path: Path, rows: list[dict]) -> None:
    """Append log rows (dicts with LOG_COLUMNS keys) in one transaction."""
    if not rows:
        return
    df = pd.DataFrame.from_records(rows, columns=LOG_COLUMNS)
    for c in ("cycle", "started_at", "finished_at"):
        df[c] = pd.to_datetime(df[c])
    with warehouse.connect(db_path) as con:
        con.register("log_df", df)
        con.execute(f"INSERT INTO ingest_log ({', '.join(LOG_COLUMNS)}) SELECT {', '.join(LOG_COLUMNS)} FROM log_df")


def known_checksums(db_path: Path, file_names: list[str]) -> dict[str, str]:
    """Latest sha256 of files fetched ok before (to skip re-downloads)."""
    if not Path(db_path).exists() or not file_names:
        return {}
    with warehouse.connect(db_path) as con:
        rows = con.execute(
            "SELECT file_name, arg_max(sha256, finished_at) FROM ingest_log WHERE status IN ('ok', 'skipped') "
            "AND file_name IN (SELECT unnest(?)) GROUP BY file_name",
            [file_names],
        ).fetchall()
    return {name: sha for name, sha in rows if sha}


def set_cycle_status(db_path: Path, cycle, *, complete: bool, n_expected: int, n_ok: int, missing: str) -> None:
    with warehouse.connect(db_path) as con:
        con.execute(
            "INSERT OR REPLACE INTO cycles VALUES (?, ?, ?, ?, ?, ?)",
            [pd.Timestamp(np.datetime64(cycle, "ns")).to_pydatetime(), complete, n_expected, n_ok, missing or None, utcnow()],
        )


def cycle_status(db_path: Path) -> pd.DataFrame:
    if not Path(db_path).exists():
        return pd.DataFrame(columns=["cycle", "complete", "n_files_expected", "n_files_ok", "missing", "written_at"])
    with warehouse.connect(db_path) as con:
        return con.execute("SELECT * FROM cycles ORDER BY cycle").fetchdf()
