"""Ingest log and cycle status in the warehouse."""

from __future__ import annotations

from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pandas as pd

from schemas.tables.ingest import CYCLES, INGEST_LOG
from storage import warehouse

LOG_COLUMNS = INGEST_LOG.names


def utcnow() -> datetime:
    return datetime.now(timezone.utc).replace(tzinfo=None)


def record_files(db_path: Path, rows: list[dict]) -> None:
    """Append log rows (dicts with exactly LOG_COLUMNS keys: another key, or one missing, raises) in one transaction."""
    if not rows:
        return
    INGEST_LOG.check_rows(rows)
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
        row = {"cycle": pd.Timestamp(np.datetime64(cycle, "ns")).to_pydatetime(), "complete": complete,
               "n_files_expected": n_expected, "n_files_ok": n_ok, "missing": missing or None, "written_at": utcnow()}
        CYCLES.check_keys(row)
        con.execute(f"INSERT OR REPLACE INTO cycles ({', '.join(row)}) VALUES ({', '.join('?' * len(row))})",
                    list(row.values()))


def cycle_status(db_path: Path) -> pd.DataFrame:
    if not Path(db_path).exists():
        return pd.DataFrame(columns=CYCLES.names)
    with warehouse.connect(db_path) as con:
        return con.execute("SELECT * FROM cycles ORDER BY cycle").fetchdf()
