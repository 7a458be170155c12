"""The DuckDB warehouse: one file under the data root, one writer at a time, named migrations.

DuckDB lets only one process hold a file open for writing, and a reader in another process
blocks the writer. So the pipeline keeps connections short (open, write in a transaction,
close) and retries while another process holds the file; analysts read the snapshot copy
(`warehouse.snapshot.duckdb`, replaced atomically after every checked write, copied while the writer still
holds the file so it is never torn or older than the last checked write; a fleet run's batches reach it when the
run ends) or the main file when the pipeline is idle. The snapshot is written in DuckDB storage format `SNAPSHOT_STORAGE_VERSION`, so
DuckDB readers from that release on (BI drivers bundle older DuckDBs) open it, whatever DuckDB
the pipeline runs.

The snapshot is also the recovery copy, so it must never be a copy of a damaged warehouse: a writer first
checks the warehouse (every table read whole, so DuckDB verifies the checksum of every block in use) and
refuses to write to a damaged one; a new snapshot is published only after the copy passes the same check, and
the previous `SNAPSHOT_GENERATIONS - 1` verified snapshots are kept as `warehouse.snapshot.1.duckdb`, ….

The big append-only history, `route_legs`, is not in the DuckDB file but in one Parquet file per run beside it
(storage/route_history.py), so what a write checks and copies does not grow with the years of legs; a writer checks
that each listed file is there with its recorded size.

Schema lives in `storage/schema_*.py` modules as ordered lists of named migrations; each
name is applied once and recorded in `schema_migrations`.
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
import hashlib
import os
import shutil
import struct
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import duckdb

from storage import route_history, run_owners
from storage.migration import Migration
from storage.warehouse_base import WarehouseCorruptError, transaction


# The oldest DuckDB release whose readers open the analysts' snapshot (its storage format number is
# SNAPSHOT_STORAGE_NUMBER, in the file header).
SNAPSHOT_STORAGE_VERSION = "v1.1.0"
SNAPSHOT_STORAGE_NUMBER = 64
# Verified snapshots kept: the newest (`warehouse.snapshot.duckdb`, the analysts' copy) and older ones. A command
# writes several times within seconds; the newest snapshot becomes an older generation only once it is this old,
# so the older generations stay copies from earlier commands rather than from the same one.
SNAPSHOT_GENERATIONS = 3
SNAPSHOT_MIN_AGE_S = 600.0
# DuckDB's buffer while a warehouse is checked (`verify`): each block is read once, so caching them is no use, and
# without a limit a check would keep up to the whole file in memory
CHECK_MEMORY_LIMIT = "32MB"



class WarehouseBusyError(RuntimeError):
    pass


class WarehouseWriteError(RuntimeError):
    """The warehouse (or its snapshot) cannot be written: disk full, read-only or immutable; the message names the
    file and what to do."""


_CORRUPT_SIGNS = ("not a valid duckdb database", "corrupt database file", "checksum", "serialization error")


def _corrupt(path: Path, exc: Exception) -> WarehouseCorruptError:
    first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    snap = newest_good_snapshot(path)
    if snap is None:
        return WarehouseCorruptError(
            f"warehouse {path} is damaged ({first}) and no snapshot beside it passes the check; "
            f"move it aside (`mv {path} {path}.damaged`) and rebuild it by re-importing the fleet and re-running the ingest")
    return WarehouseCorruptError(
        f"warehouse {path} is damaged ({first}); nothing was written. Recover it from the newest good snapshot {snap}: "
        f"`mv {path} {path}.damaged && cp {snap} {path}`, then re-run (work since that snapshot is re-done by the re-run)")


def _is_corrupt(exc: Exception) -> bool:
    return any(sign in str(exc).lower() for sign in _CORRUPT_SIGNS)


_NO_SPACE_SIGNS = ("no space left", "file too large", "disk quota")
_NO_WRITE_SIGNS = ("operation not permitted", "permission denied", "read-only file system")


def _unwritable(path: Path, exc: Exception) -> WarehouseWriteError | None:
    """The one-line error for a write the file system refused (full, read-only, immutable); None for other errors."""
    text = str(exc).lower()
    first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    if any(sign in text for sign in _NO_SPACE_SIGNS):
        return WarehouseWriteError(f"no space to write warehouse {path} ({first}): free space on its disk and re-run "
                                   "(what this command had not committed is not in the warehouse)")
    if any(sign in text for sign in _NO_WRITE_SIGNS):
        return WarehouseWriteError(f"warehouse {path} cannot be written ({first}): make it writable (permissions, "
                                   f"`chattr -i`, a read-write mount) and re-run; analysts can still read "
                                   f"{snapshot_path(path)}")
    return None


@functools.cache  # the schema modules' lists are constants: made once per process
def _all_migrations() -> tuple[Migration, ...]:
    # Imported here so each schema module can be edited on its own.
    from storage import schema_docs, schema_fleet, schema_ingest, schema_planning, schema_routes

    schema = [*schema_ingest.MIGRATIONS, *schema_fleet.MIGRATIONS, *schema_routes.MIGRATIONS, *schema_planning.MIGRATIONS]
    schema.append(schema_routes.views_migration(after=[m.name for m in schema]))
    return (*schema, schema_docs.comments_migration(after=[m.name for m in schema]))


@functools.lru_cache(maxsize=4)
def _migrations_digest(migrations: tuple[Migration, ...]) -> str:
    """The name of the template of `migrations` (names and SQL), computed once per list rather than per warehouse."""
    return hashlib.sha1("\0".join(f"{m.name}\0{m.sql}" for m in migrations).encode()).hexdigest()[:16]


# A folder of migrated, empty warehouses that `connect` copies for a new warehouse instead of running every migration
# on it (about 0.3 s CPU a warehouse); None (the default): each new warehouse is migrated from scratch. The tests set
# one per session (tests/conftest.py), so the hundreds of warehouses they create pay the migrations once.
_TEMPLATE_FOLDER: Path | None = None
_TEMPLATES_LOCK = threading.Lock()


def use_templates(folder: Path | None) -> None:
    """New warehouses are copies of `folder/migrated-<digest of the migrations>.duckdb`, made there on first need by
    migrating an empty file; a different list of migrations (names or SQL) gets its own template, so a copy always
    holds exactly what migrating from scratch gives. None: migrate every new warehouse from scratch."""
    global _TEMPLATE_FOLDER
    with _TEMPLATES_LOCK:
        _TEMPLATE_FOLDER = None if folder is None else Path(folder)


def _from_template(path: Path) -> None:
    """Create the new warehouse `path` as a copy of the template of the current migrations (see `use_templates`);
    nothing when no template folder is set. Never replaces a warehouse another process created meanwhile."""
    folder = _TEMPLATE_FOLDER
    if folder is None:
        return
    template = folder / f"migrated-{_migrations_digest(tuple(_all_migrations()))}.duckdb"
    with _TEMPLATES_LOCK:
        if not template.exists():
            folder.mkdir(parents=True, exist_ok=True)
            building = template.with_name(template.name + f".tmp{os.getpid()}")
            con = _open(building, read_only=False, wait_s=0.0)
            try:
                migrate(con)
                con.execute("CHECKPOINT")
            finally:
                con.close()
            os.replace(building, template)
    copy = path.with_name(path.name + f".tmp{os.getpid()}-{threading.get_ident()}")  # threads may race to create it
    shutil.copyfile(template, copy)
    try:
        os.link(copy, path)  # fails if `path` exists by now: that warehouse is kept
    except OSError:
        pass
    finally:
        copy.unlink(missing_ok=True)


def _open(path: Path, read_only: bool, wait_s: float) -> duckdb.DuckDBPyConnection:
    deadline = time.monotonic() + wait_s
    delay = 0.05
    while True:
        try:
            # a writer creates a new warehouse in the snapshot's storage format, so the snapshot is a byte copy
            # (readers pass no setting: a reader in the same process as another plain connection can share it)
            config = {} if read_only else {"storage_compatibility_version": SNAPSHOT_STORAGE_VERSION}
            return duckdb.connect(str(path), read_only=read_only, config=config)
        except duckdb.Error as exc:
            if _is_corrupt(exc):
                raise _corrupt(path, exc) from exc
            if not isinstance(exc, duckdb.IOException):
                raise
            refused = _unwritable(path, exc)
            if refused is not None:  # not another process's lock: waiting would not help
                raise refused from exc
            # another process holds the file lock
            if "lock" not in str(exc).lower() or time.monotonic() >= deadline:
                raise WarehouseBusyError(
                    f"warehouse {path} is held by another process ({exc}); "
                    "close other connections (analysts: use warehouse.snapshot.duckdb) and retry"
                ) from exc
            time.sleep(delay)
            delay = min(delay * 2, 1.0)


def migrate(con: duckdb.DuckDBPyConnection) -> list[str]:
    """Apply every migration not yet recorded; returns the names applied."""
    con.execute(
        "CREATE TABLE IF NOT EXISTS schema_migrations (name VARCHAR PRIMARY KEY, applied_at TIMESTAMP)"
    )
    done = {r[0] for r in con.execute("SELECT name FROM schema_migrations").fetchall()}
    applied = []
    for m in _all_migrations():
        if m.name in done:
            continue
        with transaction(con):
            con.execute(m.sql)
            con.execute("INSERT INTO schema_migrations VALUES (?, now())", [m.name])
        applied.append(m.name)
    return applied


# warehouse file → the read-only connection `one_reader` holds open for this thread's reads of it
_READERS: contextvars.ContextVar[dict] = contextvars.ContextVar("warehouse_readers", default={})  # noqa: B039 (replaced, never changed)


@contextlib.contextmanager
def one_reader(path: Path) -> Iterator[duckdb.DuckDBPyConnection]:
    """Within the block, every read-only `connect(path, write=False)` of this thread (and of the code it calls) is
    served by one connection, opened once: a job that reads a dozen tables before it writes pays DuckDB's open once
    (about 0.1 s on a busy machine) instead of a dozen times. Nothing may write the same file inside the block
    (DuckDB refuses a writer beside a reader of the same process); `connect(path)` for writing raises."""
    path = Path(path)
    with connect(path, write=False) as con:
        token = _READERS.set({**_READERS.get(), path.resolve(): con})
        try:
            yield con
        finally:
            _READERS.reset(token)


@contextlib.contextmanager
def connect(path: Path, *, write: bool = True, wait_s: float = 60.0,
            checked: bool = True) -> Iterator[duckdb.DuckDBPyConnection]:
    """Short-lived connection. Writers get the warehouse checked and the schema migrated, and the snapshot is
    refreshed on close. `checked=False`: a writer without the check, the migrations and the snapshot, for the
    appends of a job that opened a checked writer first and opens one again when it ends (a fleet run stores each
    batch of voyages so, between its `begin_run` and its end), so the snapshot follows at the end."""
    path = Path(path)
    shared = _READERS.get().get(path.resolve()) if _READERS.get() else None
    if shared is not None:
        if write:
            raise RuntimeError(f"warehouse {path} is open for reading (warehouse.one_reader) in this thread: write it "
                               "after that block")
        yield shared
        return
    if write:
        path.parent.mkdir(parents=True, exist_ok=True)
        if not path.exists():
            _from_template(path)
    elif not path.exists():
        raise FileNotFoundError(f"warehouse {path} does not exist yet: run `jitroute demo` or an ingest first")
    con = _open(path, read_only=not write, wait_s=wait_s)
    try:
        if write and checked:
            _check(con)  # before anything is written to it
            migrate(con)
            route_history.keep_legs_in_parquet(con)
            run_owners.reap_dead_runs(con)
        yield con
        if write and checked:  # while we still hold the file, so no other writer changes it during the copy
            con.execute("CHECKPOINT")
            publish_snapshot(con, path)
    except duckdb.Error as exc:
        if _is_corrupt(exc):  # a damaged block met while reading or writing
            raise _corrupt(path, exc) from exc
        refused = _unwritable(path, exc)
        if refused is not None:
            raise refused from exc
        raise
    finally:
        con.close()


def snapshot_path(path: Path) -> Path:
    path = Path(path)
    return path.with_name(path.stem + ".snapshot.duckdb")


def snapshot_generations(path: Path) -> list[Path]:
    """The snapshot files of the warehouse `path`, newest first: `<name>.snapshot.duckdb`, `<name>.snapshot.1.duckdb`, …"""
    snap = snapshot_path(path)
    return [snap] + [snap.with_name(f"{Path(path).stem}.snapshot.{k}.duckdb") for k in range(1, SNAPSHOT_GENERATIONS)]


def _check(con: duckdb.DuckDBPyConnection) -> None:
    """What a writer checks before it writes (`connect`, `check_before_writing`): every table's blocks (`verify`, with
    a small buffer) and the size of every listed route-legs file (storage/route_history.py). Raises what it finds."""
    con.execute(f"SET memory_limit = '{CHECK_MEMORY_LIMIT}'")
    verify(con)
    con.execute("RESET memory_limit")
    route_history.check_sizes(con)


def verify(con: duckdb.DuckDBPyConnection, database: str | None = None) -> None:
    """Read every row of every table of `database` (default: the current one) on `con` (DuckDB checks each block's
    checksum as it reads it); raises duckdb.Error on a damaged block. A cheap pass: one hash over each table, nothing
    kept."""
    where, prefix = ("current_database()", "") if database is None else (f"'{database}'", f'"{database}".')
    tables = con.execute("SELECT schema_name, table_name FROM duckdb_tables() "
                         f"WHERE database_name = {where} AND NOT temporary").fetchall()
    if tables:  # one query for all of them: a third of the CPU of one query a table
        con.execute(" UNION ALL ".join(f'SELECT count(*), sum(hash(t)) FROM {prefix}"{schema}"."{table}" AS t'
                                       for schema, table in tables)).fetchall()


def _first_line(exc: Exception) -> str:
    return str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__


def _check_attached(con: duckdb.DuckDBPyConnection, path: Path) -> str | None:
    """`check_file(path)` on an open connection: the file attached read-only, every table read (`verify`) and detached;
    None when it passes, else why not (one line). Half the CPU of opening the file as a database of its own."""
    quoted = str(path).replace("'", "''")
    con.execute(f"SET memory_limit = '{CHECK_MEMORY_LIMIT}'")
    try:
        try:
            con.execute(f"ATTACH '{quoted}' AS {_CHECKED} (READ_ONLY)")
        except duckdb.Error as exc:
            return _first_line(exc)
        try:
            verify(con, _CHECKED)
            return None
        except duckdb.Error as exc:
            return _first_line(exc)
        finally:
            con.execute(f"DETACH {_CHECKED}")
    finally:
        con.execute("RESET memory_limit")


_CHECKED = "jitroute_copy_being_checked"  # the name a copy is attached under while `_check_attached` reads it


def check_file(path: Path) -> str | None:
    """None when the DuckDB file `path` opens and passes `verify`, else why not (one line)."""
    try:
        con = duckdb.connect(str(path), read_only=True, config={"memory_limit": CHECK_MEMORY_LIMIT})
    except duckdb.Error as exc:
        return str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    try:
        verify(con)
        return None
    except duckdb.Error as exc:
        return str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    finally:
        con.close()


def newest_good_snapshot(path: Path) -> Path | None:
    """The newest snapshot of the warehouse `path` that exists and passes the check, or None."""
    return next((snap for snap in snapshot_generations(path) if snap.exists() and check_file(snap) is None), None)


def check_before_writing(path: Path, wait_s: float = 60.0) -> None:
    """Raise WarehouseCorruptError (naming the newest good snapshot) when the warehouse `path` exists and is
    damaged (its blocks, or a route-legs file missing or of the wrong size: route_history.HistoryDamagedError), so a
    command stops before it writes anything (cube, exports or rows), as a writer connection would. A missing warehouse
    passes."""
    path = Path(path)
    if not path.exists():
        return
    con = _open(path, read_only=True, wait_s=wait_s)
    try:
        _check(con)
    except duckdb.Error as exc:
        if _is_corrupt(exc):
            raise _corrupt(path, exc) from exc
        raise
    finally:
        con.close()


def publish_snapshot(con: duckdb.DuckDBPyConnection, path: Path) -> Path:
    """Copy the warehouse `path` open on `con` to `<name>.snapshot.duckdb` atomically for analysts, in storage
    format `SNAPSHOT_STORAGE_VERSION`: a byte copy when the warehouse is in that format (every warehouse created
    since), else written table by table (`COPY FROM DATABASE`: rows, constraints, comments, views), which is
    slower (seconds for tens of MB) — replace such a warehouse by its snapshot once to get the fast copy.

    Call it on a checkpointed write connection (as `connect` does), so no other writer changes the warehouse
    during the copy and a newer snapshot is never replaced by an older one.

    The copy is published only if it passes `check_file`; otherwise WarehouseCorruptError is raised and every
    snapshot is left as it was. The snapshot it replaces, once SNAPSHOT_MIN_AGE_S old, becomes
    `<name>.snapshot.1.duckdb` (and so on, up to SNAPSHOT_GENERATIONS files), so the last few verified copies stay.
    """
    path = Path(path)
    snap = snapshot_path(path)
    tmp = snap.with_name(snap.name + f".tmp{os.getpid()}")
    tmp.unlink(missing_ok=True)
    try:
        try:
            if storage_version_number(path) == SNAPSHOT_STORAGE_NUMBER:
                shutil.copyfile(path, tmp)
            else:
                _copy_in_snapshot_format(con, tmp)
        except OSError as exc:
            raise WarehouseWriteError(
                f"the snapshot {tmp} could not be written ({exc.strerror or exc}): free space (or make {snap.parent} "
                f"writable) and re-run; warehouse {path} holds this command's writes and the snapshots are as they were"
            ) from exc
        problem = _check_attached(con, tmp)
        if problem is not None:
            raise WarehouseCorruptError(
                f"the snapshot copy of warehouse {path} fails the check ({problem}), so it was not published and the "
                f"snapshots {snap.name} … are as they were; check the disk (space, errors) and re-run")
        if snap.exists() and time.time() - snap.stat().st_mtime >= SNAPSHOT_MIN_AGE_S:
            _keep_older_generations(path)
        os.replace(tmp, snap)
    finally:
        tmp.unlink(missing_ok=True)
        tmp.with_name(tmp.name + ".wal").unlink(missing_ok=True)
    return snap


def _keep_older_generations(path: Path) -> None:
    """Shift the snapshots one generation older (the oldest is dropped); the newest stays in place (a hard link is
    made for generation 1) so analysts never find the snapshot missing."""
    gens = snapshot_generations(path)
    for newer, older in reversed(list(zip(gens[1:-1], gens[2:]))):
        if newer.exists():
            os.replace(newer, older)
    if len(gens) > 1 and gens[0].exists():
        link = gens[1].with_name(gens[1].name + f".tmp{os.getpid()}")
        link.unlink(missing_ok=True)
        try:
            os.link(gens[0], link)
        except OSError:  # a file system without hard links
            shutil.copyfile(gens[0], link)
        os.replace(link, gens[1])


def _copy_in_snapshot_format(con: duckdb.DuckDBPyConnection, target: Path) -> None:
    source = con.execute("SELECT current_database()").fetchone()[0]
    quoted = str(target).replace("'", "''")
    con.execute(f"ATTACH '{quoted}' AS snapshot_out (STORAGE_VERSION '{SNAPSHOT_STORAGE_VERSION}')")
    try:
        con.execute(f'COPY FROM DATABASE "{source}" TO snapshot_out')
    finally:
        con.execute("DETACH snapshot_out")


def storage_version_number(path: Path) -> int:
    """The storage format number in a DuckDB file's header (bytes 8-11 "DUCK", then a little-endian uint64)."""
    with open(path, "rb") as fh:
        magic, number = struct.unpack("<8x4sQ", fh.read(20))
    if magic != b"DUCK":
        raise ValueError(f"{path} is not a DuckDB file")
    return number
