"""Warehouse schema for weather ingest: the per-file log and per-cycle status."""

from storage.migration import Migration

MIGRATIONS: list[Migration] = [
    Migration(
        "ingest_001_log",
        """
        CREATE TABLE ingest_log (
            run_id VARCHAR,
            source VARCHAR NOT NULL,          -- GSM | GWM | OSCAR
            cycle TIMESTAMP,                  -- forecast cycle (UTC) the file was fetched for
            file_name VARCHAR NOT NULL,
            url VARCHAR,
            bytes BIGINT,
            sha256 VARCHAR,
            status VARCHAR NOT NULL,          -- ok | missing | corrupt | skipped
            error VARCHAR,
            started_at TIMESTAMP,
            finished_at TIMESTAMP
        );
        CREATE TABLE cycles (
            cycle TIMESTAMP PRIMARY KEY,
            complete BOOLEAN NOT NULL,
            n_files_expected INTEGER,
            n_files_ok INTEGER,
            missing VARCHAR,                  -- what is missing, e.g. "GSM FD0512; GWM 90-132 h"
            written_at TIMESTAMP
        );
        """,
    ),
    Migration(
        "ingest_002_status_checks",
        # a file's status limited to the values the code writes: ok | skipped (already had) | missing | corrupt |
        # error (refused, e.g. no permission); DuckDB adds a CHECK only with CREATE TABLE, so the log is rebuilt
        """
        CREATE TABLE ingest_log_new (
            run_id VARCHAR,
            source VARCHAR NOT NULL,
            cycle TIMESTAMP,
            file_name VARCHAR NOT NULL,
            url VARCHAR,
            bytes BIGINT,
            sha256 VARCHAR,
            status VARCHAR NOT NULL CHECK (status IN ('ok', 'skipped', 'missing', 'corrupt', 'error')),
            error VARCHAR,
            started_at TIMESTAMP,
            finished_at TIMESTAMP
        );
        INSERT INTO ingest_log_new SELECT run_id, source, cycle, file_name, url, bytes, sha256, status, error, started_at,
            finished_at FROM ingest_log;
        DROP TABLE ingest_log;
        ALTER TABLE ingest_log_new RENAME TO ingest_log;
        """,
    ),
]
