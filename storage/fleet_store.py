"""Reads and writes of the fleet tables: vessels, noon reports, performance models, voyages.

Plain values in and out (DataFrames, dicts, tuples): building model objects from stored rows is the
pipeline's job (`pipeline.performance.model.model_from_stored`).
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Sequence
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pandas as pd

from schemas.tables import TABLES
from schemas.tables.fleet import BUNKER_LOGS, HULL_PERFORMANCE_MONTHLY, PERF_MODELS, VESSELS, VOYAGE_POSITIONS, VOYAGES
from schemas.tables.fleet import NOON_REPORTS as NOON
from schemas.tables.fleet import NOON_REPORTS_HISTORY as NOON_HISTORY
from schemas.tables.fleet import NOON_REPORTS_REJECTED as NOON_REJECTED
from storage import warehouse

NOON_COLUMNS = NOON.names
VESSEL_COLUMNS = VESSELS.names
VOYAGE_COLUMNS = VOYAGES.names_except("plan_id")  # a voyages file's columns (fleet plans set plan_id)


def _utcnow() -> datetime:
    return datetime.now(timezone.utc).replace(tzinfo=None)


def _upsert(db_path: Path, table: str, df: pd.DataFrame, columns: list[str], key: str) -> int:
    df = df.reindex(columns=columns)
    with warehouse.connect(db_path) as con:
        con.register("incoming", df)
        with warehouse.transaction(con):
            con.execute(f"DELETE FROM {table} WHERE {key} IN (SELECT {key} FROM incoming)")
            con.execute(f"INSERT INTO {table} ({', '.join(columns)}) SELECT {', '.join(columns)} FROM incoming")
    return len(df)


def import_vessels(db_path: Path, df: pd.DataFrame, rejected: pd.DataFrame | None = None) -> int:
    """Upsert good vessel rows; rows refused by validation go to `vessels_rejected` with their reason."""
    df = df.reindex(columns=VESSEL_COLUMNS)
    df["barred_rpm"] = df["barred_rpm"].astype(object).where(df["barred_rpm"].notna(), None)  # text, NULL when absent
    n = _upsert(db_path, "vessels", df, VESSEL_COLUMNS, "imo")
    _store_rejected(db_path, "vessels_rejected", rejected, ["imo"])
    return n


def import_voyages(db_path: Path, df: pd.DataFrame, rejected: pd.DataFrame | None = None) -> int:
    """Upsert good voyage rows; rows refused by validation go to `voyages_rejected` with their reason."""
    df = df.copy()
    for c in ("depart_utc", "rta_utc"):
        df[c] = pd.to_datetime(df[c], utc=True).dt.tz_localize(None)
    if "status" not in df:
        df["status"] = "planned"
    df["rpm_options"] = [None if r is None or (isinstance(r, float) and r != r)
                         else list(map(float, r)) if not isinstance(r, str)
                         else [float(x) for x in r.strip("[]").split(",") if x.strip()]
                         for r in df["rpm_options"]]
    taken = sorted(set(df["voyage_id"]) & set(plan_voyage_ids(db_path)))
    if taken:  # validation refuses these (validate_voyages' plan_voyages); never replace a plan's voyage here
        raise ValueError(f"voyage(s) {', '.join(taken)} are voyages of a fleet plan: a voyages file may not replace "
                         "them; give the imported voyages other IDs")
    n = _upsert(db_path, "voyages", df, VOYAGE_COLUMNS, "voyage_id")
    _store_rejected(db_path, "voyages_rejected", rejected, ["voyage_id", "imo"])
    return n


def plan_voyage_ids(db_path: Path) -> dict[str, str]:
    """voyage_id → plan_id of the stored voyages a fleet plan made."""
    if not Path(db_path).exists():
        return {}
    with warehouse.connect(db_path, write=False) as con:
        return {str(v): str(p) for v, p in con.execute(
            "SELECT voyage_id, plan_id FROM voyages WHERE plan_id IS NOT NULL").fetchall()}


def _store_rejected(db_path: Path, table: str, rejected: pd.DataFrame | None, keys: list[str]) -> None:
    """Refused rows (`raw`, `reason`, `source_file` + `keys` as far as readable) into `table` (its definition's
    columns: schemas/tables); the same raw row refused
    for the same reason is stored once, so re-imports add nothing."""
    if rejected is None or not len(rejected):
        return
    rej = pd.DataFrame({k: rejected[k] if k in rejected else None for k in keys})
    if "imo" in rej:
        rej["imo"] = pd.to_numeric(rej["imo"], errors="coerce").astype("Int64")
    for k in ("voyage_id", "bill_no"):
        if k in rej:
            rej[k] = rej[k].astype("string")
    rej["raw"] = rejected["raw"].astype("string")
    rej["reason"] = rejected["reason"].astype("string")
    rej["source_file"] = rejected["source_file"].astype("string") if "source_file" in rejected else None
    rej["rejected_at"] = _utcnow()
    cols = [*keys, "raw", "reason", "source_file", "rejected_at"]
    TABLES[table].check_keys(cols)
    rej = rej.drop_duplicates(subset=["raw", "reason"])
    with warehouse.connect(db_path) as con:
        con.register("rej_df", rej[cols])
        con.execute(f"INSERT INTO {table} ({', '.join(cols)}) SELECT r.* FROM rej_df r WHERE NOT EXISTS "
                    f"(SELECT 1 FROM {table} x WHERE x.raw = r.raw AND x.reason = r.reason)")


def known_imos(db_path: Path) -> set[int]:
    if not Path(db_path).exists():
        return set()
    with warehouse.connect(db_path, write=False) as con:
        return {int(r[0]) for r in con.execute("SELECT imo FROM vessels").fetchall()}


def import_noon(db_path: Path, good: pd.DataFrame, rejected: pd.DataFrame, *, replace: bool = False) -> dict[str, int]:
    """Insert validated rows; rows identical to stored ones are no-ops, conflicting ones are rejected — or, with
    `replace`, replace the stored ones, which are kept in `noon_reports_history` ("replaced by <source_file>").

    Returns counts: inserted, already_present, rejected (incl. conflicts), conflicts, replaced, excluded (reports an
    operator excluded, kept out), duplicates_in_file.
    """
    return import_noon_chunks(db_path, [(good, rejected)], replace=replace)


# DuckDB's memory while a noon file is staged (beyond it DuckDB spills to temporary files), and while the staged
# rows are stored: the commit merges the new keys into noon_reports' primary-key index, held in memory, so that
# limit grows with the reports (32 MB + 64 bytes a report, stored and new: 96 MB for 1 M reports, which needs
# more than 72 MB; without a limit DuckDB takes ~600 MB for them)
IMPORT_MEMORY_LIMIT = "32MB"
STORE_MEMORY_BASE_MB, STORE_MEMORY_PER_REPORT_B = 32, 64
_NOON_VALUES = [c for c in NOON.names if c not in ("imo", "ts_utc", "source_file")]


def import_noon_chunks(db_path: Path, chunks: Iterable[tuple[pd.DataFrame, pd.DataFrame]], *,
                       replace: bool = False) -> dict[str, int]:
    """`import_noon` for a file read and validated chunk by chunk, all or nothing: each chunk's rows are staged
    in temporary tables (which DuckDB spills to disk beyond IMPORT_MEMORY_LIMIT and drops with the connection),
    then ONE transaction stores them, so memory follows the chunk, not the file, and a file that fails half-way
    stores nothing. (Rows inserted inside a transaction stay in memory until it commits, so the chunks are not
    inserted in it one by one.) A (vessel, time) already taken by an earlier chunk of the same file is rejected as
    `duplicate timestamp in file`, as within a chunk. With `replace`, a row differing from the stored report of its
    vessel and time replaces it (the stored one is kept in noon_reports_history).

    A report of a (vessel, time) an operator excluded (`exclude_noon`) is not stored again: counted as `excluded`.

    Returns counts: inserted, already_present, rejected (incl. conflicts and duplicates), conflicts, replaced,
    excluded, duplicates_in_file.
    """
    same = " AND ".join(f"(n.{c} IS NOT DISTINCT FROM g.{c})" for c in _NOON_VALUES)
    cols = ", ".join(NOON.names)
    rejected_cols = NOON_REJECTED.names
    with warehouse.connect(db_path) as con:
        # a large file's staged rows spill to disk instead of growing the process (this connection only)
        con.execute(f"SET memory_limit = '{IMPORT_MEMORY_LIMIT}'")
        con.execute(f"CREATE TEMP TABLE stage AS SELECT {cols}, 0::BIGINT AS seq FROM noon_reports LIMIT 0")
        con.execute("CREATE TEMP TABLE stage_rejected AS SELECT * FROM noon_reports_rejected LIMIT 0")
        n_rejected, seq = 0, 0
        for good, rejected in chunks:
            good = NOON.take(good).assign(seq=np.arange(seq, seq + len(good), dtype=np.int64))
            seq += len(good)
            con.register("g_df", good)
            con.execute(f"INSERT INTO stage SELECT {cols}, seq FROM g_df")
            con.unregister("g_df")
            n_rejected += len(rejected)
            _stage_noon_rejected(con, rejected)
        n_reports = con.execute("SELECT (SELECT count(*) FROM noon_reports) + (SELECT count(*) FROM stage)").fetchall()[0][0]
        con.execute(f"SET memory_limit = '{STORE_MEMORY_BASE_MB + n_reports * STORE_MEMORY_PER_REPORT_B // 2**20}MB'")
        with warehouse.transaction(con):
            # a (vessel, time) of an earlier chunk: the first row keeps it (validation did the same within a chunk)
            # (a grouped count first, which spills to disk: the window's sort of every staged row may not fit the limit)
            any_dup = con.execute("SELECT EXISTS (SELECT 1 FROM stage GROUP BY imo, ts_utc HAVING count(*) > 1)").fetchall()[0][0]
            dups = con.execute(f"SELECT {cols} FROM stage QUALIFY row_number() OVER (PARTITION BY imo, ts_utc ORDER BY seq) > 1 "
                               "ORDER BY seq" if any_dup else f"SELECT {cols} FROM stage LIMIT 0").fetchdf()
            if len(dups):
                con.execute("DELETE FROM stage WHERE seq IN (SELECT seq FROM stage QUALIFY "
                            "row_number() OVER (PARTITION BY imo, ts_utc ORDER BY seq) > 1)")
            # a report an operator excluded (noon_reports_history "excluded: …") stays out when the file is
            # imported again (a cumulative noon file holds it still), corrected or not: the exclusion is of the period
            n_excluded = con.execute(
                "SELECT count(*) FROM stage g WHERE EXISTS (SELECT 1 FROM noon_reports_history h WHERE h.imo = g.imo "
                "AND h.ts_utc = g.ts_utc AND h.reason LIKE 'excluded:%') AND NOT EXISTS "
                "(SELECT 1 FROM noon_reports n WHERE n.imo = g.imo AND n.ts_utc = g.ts_utc)").fetchall()[0][0]
            if n_excluded:
                con.execute("DELETE FROM stage g WHERE EXISTS (SELECT 1 FROM noon_reports_history h WHERE h.imo = g.imo "
                            "AND h.ts_utc = g.ts_utc AND h.reason LIKE 'excluded:%') AND NOT EXISTS "
                            "(SELECT 1 FROM noon_reports n WHERE n.imo = g.imo AND n.ts_utc = g.ts_utc)")
            g = "stage g"
            present = con.execute(f"SELECT count(*) FROM {g} JOIN noon_reports n USING (imo, ts_utc) WHERE {same}").fetchall()[0][0]
            conflicts = con.execute(f"SELECT g.* EXCLUDE (seq) FROM {g} JOIN noon_reports n USING (imo, ts_utc) "
                                    f"WHERE NOT ({same}) ORDER BY g.seq").fetchdf()
            replaced = 0
            if replace and len(conflicts):
                con.execute(f"INSERT INTO noon_reports_history ({', '.join(NOON_HISTORY.names)}) "
                            f"SELECT {', '.join(f'n.{c}' for c in NOON.names)}, ?, 'replaced by ' || "
                            f"coalesce(nullif(g.source_file, ''), 'a corrected report') FROM noon_reports n "
                            f"JOIN {g} USING (imo, ts_utc) WHERE NOT ({same})", [_utcnow()])
                con.execute(f"DELETE FROM noon_reports n USING {g} WHERE n.imo = g.imo AND n.ts_utc = g.ts_utc "
                            f"AND NOT ({same})")
                replaced, conflicts = len(conflicts), conflicts.head(0)
            # stored by vessel and time, so a refit's read is mostly in order already (see `load_for_refit`)
            con.execute(f"INSERT INTO noon_reports ({cols}) SELECT {', '.join(f'g.{c}' for c in NOON.names)} "
                        f"FROM {g} ANTI JOIN noon_reports n USING (imo, ts_utc) ORDER BY g.imo, g.ts_utc")
            n_good = con.execute("SELECT count(*) FROM stage").fetchall()[0][0]
            for extra, why in ((conflicts, "conflicts with a stored report for the same vessel and time"),
                               (dups, "duplicate timestamp in file")):
                if len(extra):
                    extra["raw"] = _raw_text(extra[[c for c in NOON.names if c != "source_file"]])
                    extra["reason"] = why
                    n_rejected += len(extra)
                    _stage_noon_rejected(con, extra)
            # the same raw row rejected for the same reason is stored once: re-imports add nothing
            con.execute(f"INSERT INTO noon_reports_rejected ({', '.join(rejected_cols)}) "
                        f"SELECT {', '.join(rejected_cols)} FROM stage_rejected r "
                        "WHERE NOT EXISTS (SELECT 1 FROM noon_reports_rejected x WHERE x.raw = r.raw AND x.reason = r.reason) "
                        "QUALIFY row_number() OVER (PARTITION BY r.raw, r.reason) = 1")
        con.execute("DROP TABLE stage")
        con.execute("DROP TABLE stage_rejected")
    return {"inserted": int(n_good - present - len(conflicts) - replaced), "already_present": int(present),
            "rejected": n_rejected, "conflicts": len(conflicts), "replaced": int(replaced),
            "excluded": int(n_excluded), "duplicates_in_file": len(dups)}


def _stage_noon_rejected(con, rejected: pd.DataFrame) -> None:
    """Refused rows into the temporary `stage_rejected` (as noon_reports_rejected holds them)."""
    if not len(rejected):
        return
    rej = rejected.reindex(columns=NOON_REJECTED.names)  # what validation could read of the row; the rest empty
    for c in NOON_REJECTED.columns:
        if c.duckdb == "DOUBLE":
            rej[c.name] = pd.to_numeric(rej[c.name], errors="coerce")
    rej["imo"] = pd.to_numeric(rej["imo"], errors="coerce").astype("Int64")
    rej["ts_utc"] = pd.to_datetime(rej["ts_utc"], errors="coerce")
    rej["rejected_at"] = _utcnow()
    con.register("rej_df", rej)
    con.execute(f"INSERT INTO stage_rejected SELECT {', '.join(NOON_REJECTED.names)} FROM rej_df")
    con.unregister("rej_df")


def exclude_noon(db_path: Path, imo: int, from_utc, to_utc, reason: str) -> int:
    """Move vessel `imo`'s stored reports with from_utc ≤ ts_utc ≤ to_utc (naive UTC) to `noon_reports_history`
    ("excluded: <reason>"): refits no longer see them. Returns how many."""
    with warehouse.connect(db_path) as con:
        with warehouse.transaction(con):
            args = [int(imo), pd.Timestamp(from_utc).to_pydatetime(), pd.Timestamp(to_utc).to_pydatetime()]
            n = con.execute("SELECT count(*) FROM noon_reports WHERE imo = ? AND ts_utc BETWEEN ? AND ?", args).fetchone()[0]
            con.execute(f"INSERT INTO noon_reports_history ({', '.join(NOON_HISTORY.names)}) "
                        f"SELECT {', '.join(NOON_COLUMNS)}, ?, ? FROM noon_reports "
                        "WHERE imo = ? AND ts_utc BETWEEN ? AND ?", [_utcnow(), f"excluded: {reason}", *args])
            con.execute("DELETE FROM noon_reports WHERE imo = ? AND ts_utc BETWEEN ? AND ?", args)
    return int(n)


BUNKER_COLUMNS = BUNKER_LOGS.names


def import_bunkers(db_path: Path, good: pd.DataFrame, rejected: pd.DataFrame | None = None) -> dict[str, int]:
    """Insert validated bunker-log rows; a row identical to a stored one is a no-op, one that differs from the
    stored row of the same (imo, bill_no, fuel_type) is not stored. Rows refused by validation go to
    `bunker_logs_rejected` with their reason and raw text. Returns counts and the conflicting rows."""
    _store_rejected(db_path, "bunker_logs_rejected", rejected, ["imo", "bill_no"])
    good = BUNKER_LOGS.take(good)
    key = "imo, bill_no, fuel_type"
    same = " AND ".join(f"(b.{c} IS NOT DISTINCT FROM g.{c})" for c in ("date_utc", "port", "supplier", "received_t", "rob_t"))
    with warehouse.connect(db_path) as con:
        con.register("g", good)
        with warehouse.transaction(con):
            present = con.execute(f"SELECT count(*) FROM g JOIN bunker_logs b USING ({key}) WHERE {same}").fetchone()[0]
            conflicts = con.execute(f"SELECT g.* FROM g JOIN bunker_logs b USING ({key}) WHERE NOT ({same})").fetchdf()
            con.execute(f"INSERT INTO bunker_logs ({', '.join(BUNKER_COLUMNS)}) SELECT {', '.join(f'g.{c}' for c in BUNKER_COLUMNS)} "
                        f"FROM g ANTI JOIN bunker_logs b USING ({key})")
    return {"inserted": int(len(good) - present - len(conflicts)), "already_present": int(present), "conflicts": conflicts}


def load_reports(db_path: Path, imos: list[int] | None = None, columns: Sequence[str] | None = None) -> pd.DataFrame:
    """All stored noon reports (optionally of some vessels, only some columns), ordered by vessel and time, in one query.

    Asking only for the columns a caller needs (e.g. `refit.REPORT_COLUMNS`) makes a fleet-wide read several times faster.
    """
    unknown = sorted(set(columns or ()) - set(NOON_COLUMNS))
    if unknown:
        raise ValueError(f"noon_reports has no column(s) {', '.join(unknown)}; known: {', '.join(NOON_COLUMNS)}")
    select = ", ".join(columns) if columns else "*"
    with warehouse.connect(db_path, write=False) as con:
        if imos:
            return con.execute(f"SELECT {select} FROM noon_reports WHERE imo IN (SELECT unnest(?)) ORDER BY imo, ts_utc",
                               [list(map(int, imos))]).fetchdf()
        return con.execute(f"SELECT {select} FROM noon_reports ORDER BY imo, ts_utc").fetchdf()


def load_for_refit(db_path: Path, imos: list[int] | None, columns: Sequence[str]
                   ) -> tuple[dict[str, np.ndarray], dict[int, dict], dict[int, int], list[tuple]]:
    """What a refit reads, in one read-only connection: (noon-report `columns` as float64 arrays — "imo"
    as int64, "ts_utc" as datetime64[us] — ordered by vessel and time; `active_models`; `next_versions`;
    `fitted_models`).

    The rows come as stored, through Arrow (no pandas), and are put in order here, which is cheaper
    than an ORDER BY in the query: `import_noon` stores each import by vessel and time, so one
    import is in order already and chronological imports need only a stable sort by vessel.
    NULLs read as NaN.
    """
    unknown = sorted(set(columns) - set(NOON_COLUMNS))
    if unknown:
        raise ValueError(f"noon_reports has no column(s) {', '.join(unknown)}; known: {', '.join(NOON_COLUMNS)}")
    cols = [c for c in dict.fromkeys(["imo", *columns]) if c != "ts_utc"]
    query = f"SELECT {', '.join(cols)}, epoch_us(ts_utc) AS ts_us FROM noon_reports"
    with warehouse.connect(db_path, write=False) as con:
        if imos:
            table = con.sql(query + " WHERE imo IN (SELECT unnest(?))", params=[list(map(int, imos))]).to_arrow_table()
        else:
            table = con.sql(query).to_arrow_table()
        active, versions, fitted = _active_models(con), _next_versions(con), _fitted_models(con)
    arrays = {c: table.column(c).to_numpy() for c in table.column_names}
    imo, ts_us = arrays.pop("imo").astype(np.int64), arrays.pop("ts_us")
    order = None if _ordered(imo, ts_us) else _order(imo, ts_us)
    out = {"imo": imo if order is None else imo[order]}
    for c in columns:
        if c == "ts_utc":
            v = ts_us.astype("datetime64[us]")
        elif c == "imo":
            continue
        else:
            v = arrays[c].astype(np.float64, copy=False)
        out[c] = v if order is None else v[order]
    return out, active, versions, fitted


def _ordered(imo: np.ndarray, ts: np.ndarray) -> bool:
    """Rows ordered by vessel, then strictly by time (compared in place: no differences of the 8-byte columns made)."""
    a, b = imo[:-1], imo[1:]
    return bool((b >= a).all() and ((b > a) | (ts[1:] > ts[:-1])).all())


def _order(imo: np.ndarray, ts: np.ndarray) -> np.ndarray:
    """Permutation ordering rows by vessel, then time. Rows stored in time order (as imports of
    daily files leave them) only need a stable sort by vessel, which is much cheaper; checked."""
    order = np.argsort(imo, kind="stable")
    return order if _ordered(imo[order], ts[order]) else np.lexsort((ts, imo))


def active_models(db_path: Path) -> dict[int, dict]:
    """imo → {"version", "form", "months_dd", "data_to_utc", "speed": {name: coef}, "fuel": {name: coef}} of
    active models: plain values (pipeline.performance.model builds models from them)."""
    with warehouse.connect(db_path, write=False) as con:
        return _active_models(con)


def model_version(db_path: Path, imo: int, version: int | None = None) -> dict | None:
    """Vessel `imo`'s model `version` (None: the active one) as `active_models` gives models, with its "status"; None
    if there is no such model."""
    with warehouse.connect(db_path, write=False) as con:
        if version is None:
            return _active_models(con).get(int(imo))
        found = _active_models(con, "imo = ? AND version = ?", [int(imo), int(version)]).get(int(imo))
        if found:
            found["status"] = con.execute("SELECT any_value(status) FROM perf_models WHERE imo = ? AND version = ?",
                                          [int(imo), int(version)]).fetchone()[0]
        return found


def _active_models(con, where: str = "active", params: list | None = None) -> dict[int, dict]:
    rows = con.execute("SELECT imo, version, form, target, coefficients, months_dd, data_to_utc, envelope FROM perf_models "
                       f"WHERE {where}", params or []).fetchall()
    out: dict[int, dict] = {}
    for imo, version, form, target, coefs, months, data_to, envelope in rows:
        d = out.setdefault(int(imo), {"version": int(version), "form": form, "months_dd": months or 0.0, "data_to_utc": data_to,
                                      "envelope": envelope})
        d[target] = json.loads(coefs)
    return out


def fitted_models(db_path: Path) -> list[tuple]:
    """(imo, version, data_hash, active) of every stored model version."""
    with warehouse.connect(db_path, write=False) as con:
        return _fitted_models(con)


def _fitted_models(con) -> list[tuple]:
    return con.execute("SELECT imo, version, any_value(data_hash), bool_or(active) FROM perf_models "
                       "GROUP BY imo, version ORDER BY imo, version").fetchall()


def next_versions(db_path: Path) -> dict[int, int]:
    with warehouse.connect(db_path, write=False) as con:
        return _next_versions(con)


def _next_versions(con) -> dict[int, int]:
    return {int(i): int(v) + 1 for i, v in con.execute("SELECT imo, max(version) FROM perf_models GROUP BY imo").fetchall()}


FIT_COLUMNS = PERF_MODELS.names_except("flag")  # a flag is set on the active model later (`save_fits(flags=…)`)


def save_fits(db_path: Path, rows: list[dict], *, reactivate: dict[int, tuple[int, str]] | None = None,
              flags: dict[int, str] | None = None) -> dict[int, dict]:
    """Store fit rows (one per vessel and target); activating one deactivates the vessel's older models.

    `reactivate`: imo → (stored version, reason) to make active again (instead of storing a copy);
    `flags`: imo → why new reports contradict its active model (kept on the active rows). One transaction.
    Returns the active models afterwards (as `active_models`), read in the same connection.
    """
    reactivate, flags = reactivate or {}, flags or {}
    if not rows and not reactivate and not flags:
        return active_models(db_path)
    with warehouse.connect(db_path) as con:
        with warehouse.transaction(con):
            for imo, text in flags.items():
                con.execute("UPDATE perf_models SET flag = ? WHERE active AND imo = ?", [text, int(imo)])
            if reactivate:
                pairs = pd.DataFrame([{"imo": int(i), "version": int(v), "reason": r} for i, (v, r) in reactivate.items()])
                con.register("again", pairs)
                con.execute("UPDATE perf_models SET active = false, status = 'superseded' WHERE active AND imo IN (SELECT imo FROM again)")
                con.execute("UPDATE perf_models p SET active = true, status = 'active', flag = NULL, reason = a.reason "
                            "FROM again a WHERE p.imo = a.imo AND p.version = a.version")
            if rows:
                PERF_MODELS.check_rows(rows, columns=[c for c in FIT_COLUMNS if c != "fitted_at"])
                df = pd.DataFrame(rows)
                df["fitted_at"] = _utcnow()
                con.register("fits", df[FIT_COLUMNS])
                con.execute("UPDATE perf_models SET active = false, status = 'superseded' "
                            "WHERE active AND imo IN (SELECT imo FROM fits WHERE active)")
                con.execute(f"INSERT INTO perf_models ({', '.join(FIT_COLUMNS)}) SELECT {', '.join(FIT_COLUMNS)} FROM fits")
        return _active_models(con)


def load_vessels(db_path: Path) -> pd.DataFrame:
    with warehouse.connect(db_path, write=False) as con:
        return con.execute("SELECT * FROM vessels ORDER BY imo").fetchdf()


def load_voyages(db_path: Path, *, voyage_ids: list[str] | None = None, departing_after=None) -> pd.DataFrame:
    q = "SELECT * FROM voyages WHERE true"
    params: list = []
    if voyage_ids:
        q += " AND voyage_id IN (SELECT unnest(?))"
        params.append(list(voyage_ids))
    if departing_after is not None:
        q += " AND depart_utc >= ?"
        params.append(pd.Timestamp(departing_after).tz_localize(None) if pd.Timestamp(departing_after).tzinfo else pd.Timestamp(departing_after))
    with warehouse.connect(db_path, write=False) as con:
        return con.execute(q + " ORDER BY depart_utc, voyage_id", params).fetchdf()


def active_model(db_path: Path, imo: int) -> dict | None:
    """The active model of vessel `imo` as `active_models` gives it (plain values), or None."""
    return active_models(db_path).get(int(imo))


def _raw_text(df: pd.DataFrame) -> pd.Series:
    """Each row as 'v1|v2|…' text, as validation keeps rejected rows (`validate.raw_text`, same format)."""
    cols = [df[c].astype("string").fillna("") for c in df.columns]
    out = cols[0]
    for c in cols[1:]:
        out = out + "|" + c
    return out.astype(object)


HULL_COLUMNS = HULL_PERFORMANCE_MONTHLY.names


def save_hull_performance(db_path: Path, monthly: dict[int, tuple[int | None, pd.DataFrame]]) -> None:
    """Replace the hull-performance months of each vessel in `monthly` (imo → (model version, months from
    `pipeline.performance.hull.monthly_speed_loss`)). One transaction."""
    if not monthly:
        return
    frames = [df.assign(imo=int(imo), model_version=version) for imo, (version, df) in monthly.items() if len(df)]
    with warehouse.connect(db_path) as con:
        with warehouse.transaction(con):
            con.execute("DELETE FROM hull_performance_monthly WHERE imo IN (SELECT unnest(?))", [[int(i) for i in monthly]])
            if frames:
                df = pd.concat(frames, ignore_index=True)
                df["computed_at"] = _utcnow()
                df["month"] = pd.to_datetime(df["month"]).dt.date
                con.register("hull_df", HULL_PERFORMANCE_MONTHLY.take(df))
                con.execute(f"INSERT INTO hull_performance_monthly ({', '.join(HULL_COLUMNS)}) "
                            f"SELECT {', '.join(HULL_COLUMNS)} FROM hull_df")


def positions_after(db_path: Path, imos: list[int], since_utc) -> pd.DataFrame:
    """Positions of these vessels reported after `since_utc` (noon reports with a position), ordered by vessel and
    time: imo, ts_utc, lat, lon."""
    if not imos:
        return pd.DataFrame(columns=["imo", "ts_utc", "lat", "lon"])
    since = pd.Timestamp(since_utc)
    since = since.tz_convert(None) if since.tzinfo else since
    with warehouse.connect(db_path, write=False) as con:
        return con.execute(
            "SELECT imo, ts_utc, lat, lon FROM noon_reports WHERE imo IN (SELECT unnest(?)) AND ts_utc > ? "
            "AND lat IS NOT NULL AND lon IS NOT NULL ORDER BY imo, ts_utc",
            [[int(i) for i in imos], since.to_pydatetime()]).fetchdf()


def voyage_fingerprints(db_path: Path, voyage_ids: list[str]) -> dict[str, str]:
    """voyage_id → digest of what a plan depends on (storage.schema_routes.VOYAGE_FINGERPRINT_SQL), as stored with
    each plan so `latest_routes` can tell a plan made for a voyage since changed."""
    from storage.schema_routes import VOYAGE_FINGERPRINT_SQL

    if not voyage_ids:
        return {}
    with warehouse.connect(db_path, write=False) as con:
        rows = con.execute(f"SELECT v.voyage_id, {VOYAGE_FINGERPRINT_SQL} FROM voyages v "
                           "WHERE v.voyage_id IN (SELECT unnest(?))", [list(voyage_ids)]).fetchall()
    return {str(k): str(f) for k, f in rows}


def add_position(db_path: Path, voyage_id: str, ts_utc, lat: float, lon: float, note: str | None = None) -> None:
    """Store an operator's position of a voyage at sea (the same voyage and time again replaces it)."""
    if not (-90.0 <= float(lat) <= 90.0 and -180.0 <= float(lon) <= 360.0):
        raise ValueError(f"voyage {voyage_id}: position {lat},{lon} is not a latitude, longitude in degrees")
    t = pd.Timestamp(ts_utc)
    t = t.tz_convert(None) if t.tzinfo else t
    with warehouse.connect(db_path) as con:
        row = {"voyage_id": voyage_id, "ts_utc": t.to_pydatetime(), "lat": float(lat), "lon": float(lon), "note": note,
               "entered_at": _utcnow()}
        VOYAGE_POSITIONS.check_keys(row)
        con.execute(f"INSERT OR REPLACE INTO voyage_positions ({', '.join(row)}) VALUES ({', '.join('?' * len(row))})",
                    list(row.values()))


def voyage_positions(db_path: Path, voyage_ids: list[str]) -> pd.DataFrame:
    """Operators' positions of these voyages: voyage_id, ts_utc, lat, lon, ordered by voyage and time."""
    with warehouse.connect(db_path, write=False) as con:
        return con.execute("SELECT voyage_id, ts_utc, lat, lon FROM voyage_positions WHERE voyage_id IN (SELECT unnest(?)) "
                           "ORDER BY voyage_id, ts_utc", [list(voyage_ids)]).fetchdf()
