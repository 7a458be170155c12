"""Warehouse tables: weather ingest (the per-file log and per-cycle status)."""

from schemas.table import Column, Table

INGEST_LOG = Table('ingest_log', 'weather files fetched: one row per file and attempt', (
    Column('run_id', 'VARCHAR', None, 'ingest run that fetched the file'),
    Column('source', 'VARCHAR', None, 'weather source: GSM (wind) | GWM (waves) | OSCAR (currents)', not_null=True),
    Column('cycle', 'TIMESTAMP', 'UTC', 'forecast cycle the file was fetched for, its init time (UTC)'),
    Column('file_name', 'VARCHAR', None, 'file name', not_null=True),
    Column('url', 'VARCHAR', None, 'where the file was fetched from'),
    Column('bytes', 'BIGINT', 'byte', 'file size, bytes'),
    Column('sha256', 'VARCHAR', None, 'SHA-256 of the file'),
    Column('status', 'VARCHAR', None,
           'ok (fetched) | skipped (already had) | missing (not found, or no answer in time) | corrupt (did not '
           'decode) | error (refused, e.g. no permission)', not_null=True, allowed=('ok', 'skipped', 'missing', 'corrupt', 'error')),
    Column('error', 'VARCHAR', None, 'what went wrong'),
    Column('started_at', 'TIMESTAMP', 'UTC', 'fetch start (UTC)'),
    Column('finished_at', 'TIMESTAMP', 'UTC', 'fetch end (UTC)'),
))

CYCLES = Table('cycles', 'weather forecast cycles: complete or what is missing', (
    Column('cycle', 'TIMESTAMP', 'UTC', 'forecast cycle, its init time (UTC)'),
    Column('complete', 'BOOLEAN', None, 'true when every expected file is in the weather cube', not_null=True),
    Column('n_files_expected', 'INTEGER', None, 'files the cycle needs'),
    Column('n_files_ok', 'INTEGER', None, 'files fetched or already had'),
    Column('missing', 'VARCHAR', None, 'what is missing, e.g. "GSM FD0512; GWM 90-132 h"'),
    Column('written_at', 'TIMESTAMP', 'UTC', 'when the status was written (UTC)'),
), primary_key=('cycle',))

TABLES = (INGEST_LOG, CYCLES,)
