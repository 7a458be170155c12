"""The warehouse's big append-only history, `route_legs`, kept out of the DuckDB file: Parquet files beside the
warehouse, one per run and batch of voyages it stored, `<name>.history/route_legs/run_id=<id>/part-<k>.parquet`
(k = 0, 1, … in the order the run stored its batches), and `route_legs` a view over the files listed in
`route_leg_parts`.

Every write to the warehouse checks the DuckDB file whole and copies it to the analysts' snapshot
(storage/warehouse.py); with the legs out of it, what is checked and copied no longer grows with the years of legs
(a night's legs are ~40 times its routes). A run's file is written whole (a hidden name, then a rename), read back and
compared with the rows before its batch commits; the commit lists it in `route_leg_parts` (rows, bytes, SHA-256) in
the same transaction as the batch's routes, so a run killed before a batch commits leaves a file that no view shows
(the view reads only the listed files, not every file of a listed run), and the
snapshot, a copy of the DuckDB file, shows exactly the legs of the runs it holds (the files are never rewritten).
Every writer checks that each listed file is there with its recorded size (a stat a run); `check_digests` reads
them all against their SHA-256 (`jitroute warehouse check`).

The view names the folder by its absolute path: the snapshot shows the legs where the files are on this machine; a
moved data root gets the view made again by its next writer.
"""

from __future__ import annotations

import hashlib
import os
import re
from datetime import datetime, timezone
from pathlib import Path

import duckdb

from schemas.table import comment_sql
from schemas.tables.routes import ROUTE_LEG_PARTS, ROUTE_LEGS
from storage.warehouse_base import WarehouseCorruptError, transaction

VIEW = ROUTE_LEGS.name
PARTS = ROUTE_LEG_PARTS.name
# the folder of a file with no rows and every column of today's definition: the view's glob always matches a file,
# and a column no run has written yet reads as NULL (union by name)
COLUMNS_RUN = "_columns"
_PLAIN_RUN_ID = re.compile(r"[A-Za-z0-9][A-Za-z0-9._:+-]*")


class HistoryDamagedError(WarehouseCorruptError):
    """A file of the warehouse's history is missing or differs from what was recorded when it was written."""


def _quoted(text: str | os.PathLike) -> str:
    return "'" + str(text).replace("'", "''") + "'"


def warehouse_file(con: duckdb.DuckDBPyConnection) -> Path:
    return Path(con.execute("SELECT path FROM duckdb_databases() WHERE database_name = current_database()").fetchone()[0])


def history_dir(db_path: Path) -> Path:
    """The folder of the legs' files of the warehouse `db_path`: `<name>.history/route_legs` beside it."""
    db_path = Path(db_path).resolve()
    return db_path.with_name(db_path.stem + ".history") / VIEW


def part_name(index: int) -> str:
    """The file name of a run's `index`-th stored batch of legs (0 for a run stored whole)."""
    return f"part-{int(index)}.parquet"


def part_path(folder: Path, run_id: str, index: int = 0) -> Path:
    if not _PLAIN_RUN_ID.fullmatch(run_id) or run_id == COLUMNS_RUN:
        raise ValueError(f"run id {run_id!r} is not a plain name: its legs cannot be stored")
    return folder / f"run_id={run_id}" / part_name(index)


def _cast_list() -> str:
    return ", ".join(f"CAST({c.name} AS {c.duckdb}) AS {c.name}" for c in ROUTE_LEGS.columns)


def _view_sql(folder: Path) -> str:
    glob = _quoted(f"{folder}/run_id=*/*.parquet")
    # the run filter prunes whole folders; the file filter hides a file its run wrote but never listed (killed)
    return (f"CREATE OR REPLACE VIEW {VIEW} AS SELECT {_cast_list()} FROM read_parquet({glob}, hive_partitioning = true, "
            f"union_by_name = true, filename = true, hive_types = {{'run_id': VARCHAR}}) "
            f"WHERE run_id IN (SELECT run_id FROM {PARTS}) AND filename IN (SELECT {_quoted(str(folder) + '/')} || file "
            f"FROM {PARTS})")


def _columns_file(folder: Path) -> Path:
    """The file with no rows and today's columns, named by a digest of them (a new definition, a new file)."""
    digest = hashlib.sha256(_cast_list().encode()).hexdigest()[:12]
    return folder / f"run_id={COLUMNS_RUN}" / f"columns-{digest}.parquet"


def _kind(con) -> str | None:
    row = con.execute("SELECT 'BASE TABLE' FROM duckdb_tables() WHERE table_name = $1 AND database_name = current_database() "
                      "UNION ALL SELECT 'VIEW' FROM duckdb_views() WHERE view_name = $1 "
                      "AND database_name = current_database()", [VIEW]).fetchone()
    return row[0] if row else None


def _write_columns_file(con, folder: Path) -> None:
    target = _columns_file(folder)
    target.parent.mkdir(parents=True, exist_ok=True)
    columns = ", ".join(f"CAST(NULL AS {c.duckdb}) AS {c.name}" for c in ROUTE_LEGS.columns if c.name != "run_id")
    tmp = target.with_name(f".{target.name}.tmp{os.getpid()}")
    try:
        con.execute(f"COPY (SELECT {columns} WHERE false) TO {_quoted(tmp)} (FORMAT parquet)")
        os.replace(tmp, target)
    finally:
        tmp.unlink(missing_ok=True)
    for old in target.parent.glob("*.parquet"):  # the columns of an older definition
        if old != target:
            old.unlink(missing_ok=True)


def _view_is_current(con, folder: Path) -> bool:
    """The view reads `folder` and today's columns file is there. Cheap: the view is not bound (binding it reads
    every file's footer)."""
    row = con.execute("SELECT sql FROM duckdb_views() WHERE view_name = ? AND database_name = current_database()",
                      [VIEW]).fetchone()
    # DuckDB stores the file filter `filename IN (SELECT …)` as `filename = ANY(SELECT …)`
    return (row is not None and f"'{folder}/run_id=*/*.parquet'" in row[0]
            and ("filename IN" in row[0] or "filename = ANY" in row[0]) and _columns_file(folder).exists())


def keep_legs_in_parquet(con: duckdb.DuckDBPyConnection) -> None:
    """On a migrated writer connection: move the rows of a `route_legs` table into one file per run (once, for a
    warehouse made before the legs left it), and make the view again when its folder or columns changed."""
    if not _has_parts_table(con):
        return  # a warehouse migrated only part of the way (its legs move once route_leg_parts exists)
    folder = history_dir(warehouse_file(con))
    kind = _kind(con)
    if kind == "BASE TABLE":
        run_ids = [r[0] for r in con.execute(f"SELECT DISTINCT run_id FROM {VIEW} ORDER BY run_id").fetchall()]
        present = {r[0] for r in con.execute("SELECT column_name FROM duckdb_columns() WHERE table_name = ? AND "
                                             "database_name = current_database()", [VIEW]).fetchall()}
        # a column defined after the table was last altered (e.g. wait_h) is NULL in the moved rows
        columns = ", ".join(c.name if c.name in present else f"CAST(NULL AS {c.duckdb}) AS {c.name}"
                            for c in ROUTE_LEGS.columns)
        parts = [write_part(con, folder, rid, f"SELECT {columns} FROM {VIEW} WHERE run_id = {_quoted(rid)}")
                 for rid in run_ids]
        with transaction(con):
            record_parts(con, parts)
            con.execute(f"DROP TABLE {VIEW}")
    elif kind == "VIEW" and _view_is_current(con, folder):
        return
    folder.mkdir(parents=True, exist_ok=True)
    _write_columns_file(con, folder)
    con.execute(_view_sql(folder))
    con.execute(comment_sql([ROUTE_LEGS]))


def write_part(con: duckdb.DuckDBPyConnection, folder: Path, run_id: str, select_sql: str, index: int = 0) -> dict:
    """Write the legs `select_sql` gives (columns of route_legs, run_id `run_id` only) as the run's `index`-th file,
    whole or not at all, read it back and compare it with the rows; returns its `route_leg_parts` row (not yet
    recorded).

    Raises ValueError when the rows repeat a (voyage_id, leg) or lack one (the table's key, which no view enforces)."""
    target = part_path(Path(folder), run_id, index)
    if any(file == str(target.relative_to(folder)) for _r, file, _n, _s in _listed(con, run_id)):
        # a committed file is never replaced (a snapshot may show it)
        raise duckdb.ConstraintException(f"Duplicate key \"run_id: {run_id}\": the legs of run {run_id} "
                                         f"({target.name}) are stored")
    tmp = target.with_name(f".{target.name}.tmp{os.getpid()}")
    others = ", ".join(n for n in ROUTE_LEGS.names if n != "run_id")
    src = f"(SELECT * FROM ({select_sql}) WHERE run_id = {_quoted(run_id)})"
    n, n_keys, bad_keys, digest = con.execute(
        f"SELECT count(*), count(DISTINCT (voyage_id, leg)), count(*) FILTER (WHERE voyage_id IS NULL OR leg IS NULL), "
        f"coalesce(sum(hash({others})), 0) FROM {src}").fetchone()
    if n_keys != n or bad_keys:
        raise ValueError(f"legs of run {run_id}: {n - n_keys} repeated (voyage_id, leg) and {bad_keys} without one")
    target.parent.mkdir(parents=True, exist_ok=True)
    try:
        con.execute(f"COPY (SELECT {others} FROM {src} ORDER BY voyage_id, leg) TO {_quoted(tmp)} "
                    "(FORMAT parquet, COMPRESSION zstd)")
        back = con.execute(f"SELECT count(*), coalesce(sum(hash({others})), 0) FROM read_parquet({_quoted(tmp)})").fetchone()
        if tuple(back) != (n, digest):
            raise HistoryDamagedError(f"the legs file {tmp} of run {run_id} does not read back as written "
                                      f"({back[0]} rows, {n} written): check the disk and re-run")
        sha = _sha256(tmp)
        os.replace(tmp, target)
    finally:
        tmp.unlink(missing_ok=True)
    return {"run_id": run_id, "file": str(target.relative_to(folder)), "n_rows": int(n),
            "n_bytes": target.stat().st_size, "sha256": sha,
            "written_at": datetime.now(timezone.utc).replace(tzinfo=None)}


def record_parts(con: duckdb.DuckDBPyConnection, parts: list[dict]) -> None:
    """List the files in `route_leg_parts` (inside the caller's transaction: they join the view when it commits)."""
    columns = ROUTE_LEG_PARTS.names
    for part in parts:
        ROUTE_LEG_PARTS.check_keys(part)
        con.execute(f"INSERT INTO {PARTS} ({', '.join(columns)}) VALUES ({', '.join('?' * len(columns))})",
                    [part[c] for c in columns])


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _has_parts_table(con) -> bool:
    return con.execute("SELECT count(*) FROM duckdb_tables() WHERE table_name = ? AND database_name = current_database()",
                       [PARTS]).fetchone()[0] > 0


def _listed(con, run_id: str | None = None) -> list[tuple]:
    """(run_id, file, n_bytes, sha256) of the files listed (of `run_id` only, when given)."""
    if not _has_parts_table(con):
        return []  # a warehouse before the migration that lists them
    return con.execute(f"SELECT run_id, file, n_bytes, sha256 FROM {PARTS} WHERE ? IS NULL OR run_id = ? ORDER BY run_id",
                       [run_id, run_id]).fetchall()


def listed_files(con: duckdb.DuckDBPyConnection) -> list[Path]:
    """The legs files of the committed runs."""
    folder = history_dir(warehouse_file(con))
    return [folder / file for _run_id, file, _n, _sha in _listed(con)]


def check_sizes(con: duckdb.DuckDBPyConnection) -> None:
    """Raise HistoryDamagedError when a listed file is missing or its size is not the recorded one (a stat each)."""
    folder = history_dir(warehouse_file(con))
    for run_id, file, n_bytes, _sha in _listed(con):
        path = folder / file
        try:
            size = path.stat().st_size
        except OSError:
            raise HistoryDamagedError(_damaged(path, run_id, "is missing")) from None
        if size != n_bytes:
            raise HistoryDamagedError(_damaged(path, run_id, f"has {size} bytes, {n_bytes} when written"))


def check_digests(con: duckdb.DuckDBPyConnection) -> list[str]:
    """Every listed file read whole against its SHA-256: one line per file missing or changed (empty: all good)."""
    folder = history_dir(warehouse_file(con))
    problems = []
    for run_id, file, _n_bytes, sha in _listed(con):
        path = folder / file
        if not path.exists():
            problems.append(_damaged(path, run_id, "is missing"))
        elif _sha256(path) != sha:
            problems.append(_damaged(path, run_id, "differs from the file written (SHA-256)"))
    return problems


def _damaged(path: Path, run_id: str, what: str) -> str:
    return (f"the legs file {path} of run {run_id} {what}; nothing was written. Restore it from a backup of the "
            f"data root (the run's legs are also in exports/routes/route_legs/run_id={run_id}/, with UTC times), "
            f"or re-run the run's voyages")
