"""The noon-report import job: a file read, validated and stored chunk by chunk, all or nothing.

Kept apart from the refit job so importing reports loads neither numba nor scipy (the refit's): the import's peak
memory is then mostly the chunk and DuckDB's bounded buffer (storage.fleet_store.IMPORT_MEMORY_LIMIT), not the
file (bench/noon_import.py measures it).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pandas as pd

from flows.runner import PLAIN
from flows.settings import load_settings
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


NOON_CHUNK_ROWS = 20_000  # rows read, validated and stored at a time: memory follows this, not the file


def read_table_chunks(path: Path, rows: int = NOON_CHUNK_ROWS) -> Iterator[pd.DataFrame]:
    """`read_table`, `rows` at a time (CSV by pandas' chunked reader, Parquet by row batches)."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such file")
    try:
        if path.suffix.lower() in (".parquet", ".pq"):
            import pyarrow.parquet as pq

            for batch in pq.ParquetFile(path).iter_batches(batch_size=rows):
                yield batch.to_pandas().astype("string").astype(object)
            return
        first = True
        with pd.read_csv(path, dtype=str, keep_default_na=False, na_values=[""], chunksize=rows) as reader:
            for df in reader:
                if first and not isinstance(df.index, pd.RangeIndex):  # surplus leading fields became an index
                    raise NoonFileError(f"{path}: line 2 has more fields than the header's {len(df.columns)} columns; "
                                        "fix the file and re-import")
                first = False
                yield df.reset_index(drop=True)
    except (ValueError, OSError, pd.errors.ParserError) as exc:
        if isinstance(exc, NoonFileError):
            raise
        raise NoonFileError(f"{path}: cannot be read as CSV/Parquet ({exc})") from exc


def import_noon_file(path: str, data_root: str | None = None, replace: bool = False, *, run=PLAIN) -> dict:
    """Validate a noon-report file and store good rows; bad rows go to noon_reports_rejected with a reason.
    The file is read, validated and stored NOON_CHUNK_ROWS rows at a time, in one transaction. `replace`: a row
    differing from the stored report of the same vessel and time replaces it (the stored one is kept in
    noon_reports_history) instead of being refused."""
    s = load_settings(data_root=Path(data_root) if data_root else None)
    db = s.layout.ensure().warehouse
    known = fleet_store.known_imos(db)
    n_rows, reasons = 0, {}  # type: int, dict[str, int]

    def validated():
        nonlocal n_rows
        for raw in read_table_chunks(Path(path)):
            good, bad = validate_noon(raw, known, source=Path(path).name)
            n_rows += len(raw)
            for reason, n in reason_counts(bad).items():
                reasons[reason] = reasons.get(reason, 0) + n
            yield good, bad

    counts: dict = fleet_store.import_noon_chunks(db, validated(), replace=replace)
    across = counts.pop("duplicates_in_file")  # a (vessel, time) repeated in another chunk of the file
    if across:
        reasons["duplicate timestamp in file"] = reasons.get("duplicate timestamp in file", 0) + across
    counts["rows"] = n_rows
    counts["reasons"] = reasons
    return counts
