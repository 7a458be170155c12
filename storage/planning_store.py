"""Reads and writes of the planning tables: ports, vessel availability, contracts (+ refused rows), port
distances, fleet plans with their legs, and the voyages a plan makes.

Plain values in and out (DataFrames, dicts). Each write is one transaction: an import or a plan is stored
whole or not at all.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from schemas.tables.planning import (CONTRACTS, FLEET_PLAN_LEGS, FLEET_PLAN_UNASSIGNED, FLEET_PLANS, PORT_DISTANCES, PORTS,
                                     VESSEL_AVAILABILITY)
from storage import warehouse
from storage.fleet_store import VOYAGE_COLUMNS, _utcnow

# the tables' columns, from their definitions (schemas/tables/planning.py)
PORT_COLUMNS = PORTS.names
AVAILABILITY_COLUMNS = VESSEL_AVAILABILITY.names
CONTRACT_COLUMNS = CONTRACTS.names
DISTANCE_COLUMNS = PORT_DISTANCES.names
PLAN_COLUMNS = FLEET_PLANS.names
LEG_COLUMNS = FLEET_PLAN_LEGS.names
UNASSIGNED_COLUMNS = FLEET_PLAN_UNASSIGNED.names
PLANNED_VOYAGE_COLUMNS = [*VOYAGE_COLUMNS, "plan_id"]

# (table, its columns, key, rejected table, the key kept on a rejected row)
_INPUTS = {"ports": ("ports", PORT_COLUMNS, "port", "ports_rejected", "port"),
           "availability": ("vessel_availability", AVAILABILITY_COLUMNS, "imo", "vessel_availability_rejected", "imo"),
           "contracts": ("contracts", CONTRACT_COLUMNS, "code", "contracts_rejected", "code")}


def import_inputs(db_path: Path, parts: dict[str, tuple[pd.DataFrame, pd.DataFrame]]) -> dict[str, dict[str, int]]:
    """Upsert validated rows and store refused ones, for any of "ports", "availability", "contracts" (→ (good,
    rejected)), in one transaction. The same raw row refused for the same reason is stored once."""
    counts = {}
    with warehouse.connect(db_path) as con:
        with warehouse.transaction(con):
            for kind, (good, rejected) in parts.items():
                table, columns, key, rej_table, rej_key = _INPUTS[kind]
                con.register("incoming", good.reindex(columns=columns))
                con.execute(f"DELETE FROM {table} WHERE {key} IN (SELECT {key} FROM incoming)")
                con.execute(f"INSERT INTO {table} ({', '.join(columns)}) SELECT {', '.join(columns)} FROM incoming")
                con.unregister("incoming")
                n_rej = 0
                if rejected is not None and len(rejected):
                    rej = pd.DataFrame({rej_key: rejected[rej_key] if rej_key in rejected else None})
                    rej[rej_key] = (pd.to_numeric(rej[rej_key], errors="coerce").astype("Int64") if rej_key == "imo"
                                    else rej[rej_key].astype("string"))
                    rej["raw"] = rejected["raw"].astype("string")
                    rej["reason"] = rejected["reason"].astype("string")
                    rej["source_file"] = rejected["source_file"].astype("string") if "source_file" in rejected else None
                    rej["rejected_at"] = _utcnow()
                    rej = rej.drop_duplicates(subset=["raw", "reason"])
                    con.register("rej_df", rej)
                    con.execute(f"INSERT INTO {rej_table} ({rej_key}, raw, reason, source_file, rejected_at) "
                                f"SELECT r.* FROM rej_df r WHERE NOT EXISTS "
                                f"(SELECT 1 FROM {rej_table} x WHERE x.raw = r.raw AND x.reason = r.reason)")
                    con.unregister("rej_df")
                    n_rej = len(rejected)
                counts[kind] = {"imported": len(good), "rejected": n_rej}
    return counts


def load_port_distances(db_path: Path) -> pd.DataFrame:
    if not Path(db_path).exists():
        return pd.DataFrame(columns=DISTANCE_COLUMNS)
    with warehouse.connect(db_path, write=False) as con:
        return con.execute(f"SELECT {', '.join(DISTANCE_COLUMNS)} FROM port_distances").fetchdf()


def save_port_distances(db_path: Path, rows: pd.DataFrame) -> int:
    """Upsert computed distances (one row per sorted pair)."""
    if not len(rows):
        return 0
    df = rows.reindex(columns=DISTANCE_COLUMNS)
    df["computed_at"] = _utcnow()
    with warehouse.connect(db_path) as con:
        con.register("d", df)
        with warehouse.transaction(con):
            con.execute("DELETE FROM port_distances p USING d WHERE p.port_a = d.port_a AND p.port_b = d.port_b")
            con.execute(f"INSERT INTO port_distances ({', '.join(DISTANCE_COLUMNS)}) SELECT * FROM d")
    return len(df)


def save_plan(db_path: Path, plan: dict, legs: pd.DataFrame, unassigned: pd.DataFrame, voyages: pd.DataFrame,
              replaced: list[str] | None = None) -> dict:
    """Store a plan as the active one, in one transaction: earlier active plans become superseded and the voyages
    of earlier plans in `replaced` (pipeline.planning.voyages.replan) are deleted — but never one that has sailed
    meanwhile (status no longer planned, or a position reported since its departure); every other voyage is
    kept. Then the plan, its legs and unassigned contracts, and its voyages (status planned, tagged with plan_id).
    Returns {"superseded_plans": [...], "voyages_replaced": n, "voyages_kept": n, "voyages_added": n} (kept: voyages
    of earlier plans still stored)."""
    row = pd.DataFrame([{**plan, "created_at": _utcnow(), "status": "active", "superseded_at": None}]).reindex(
        columns=PLAN_COLUMNS)
    voyages = voyages.copy()
    voyages["status"] = "planned"
    with warehouse.connect(db_path) as con:
        with warehouse.transaction(con):
            older = [r[0] for r in con.execute("SELECT plan_id FROM fleet_plans WHERE status = 'active'").fetchall()]
            unsailed = ("voyage_id IN (SELECT unnest(?)) AND plan_id IS NOT NULL AND status = 'planned' AND "
                        f"{_REPORTED_SQL.format(v='voyages')} IS NULL")
            ids = list(replaced or [])
            n_replaced = con.execute(f"SELECT count(*) FROM voyages WHERE {unsailed}", [ids]).fetchall()[0][0]
            con.execute(f"DELETE FROM voyages WHERE {unsailed}", [ids])
            kept = con.execute("SELECT count(*) FROM voyages WHERE plan_id IS NOT NULL").fetchall()[0][0]
            if older:
                con.execute("UPDATE fleet_plans SET status = 'superseded', superseded_at = ? WHERE plan_id IN (SELECT unnest(?))",
                            [_utcnow(), older])
            con.register("p", row)
            con.execute(f"INSERT INTO fleet_plans ({', '.join(PLAN_COLUMNS)}) SELECT * FROM p")
            # an empty frame has untyped (object) columns DuckDB cannot compare or cast: a plan with no legs (every
            # contract refused or left) or none left over inserts nothing there
            if len(legs):
                con.register("l", legs.reindex(columns=LEG_COLUMNS))
                con.execute(f"INSERT INTO fleet_plan_legs ({', '.join(LEG_COLUMNS)}) SELECT * FROM l")
            if len(unassigned):
                con.register("u", unassigned.reindex(columns=UNASSIGNED_COLUMNS))
                con.execute(f"INSERT INTO fleet_plan_unassigned ({', '.join(UNASSIGNED_COLUMNS)}) SELECT * FROM u")
            if len(voyages):
                v = voyages.reindex(columns=PLANNED_VOYAGE_COLUMNS)
                con.register("v", v)
                taken = [r[0] for r in con.execute("SELECT voyage_id FROM voyages WHERE voyage_id IN (SELECT voyage_id FROM v)"
                                                   ).fetchall()]
                if taken:  # plan ids are random: only a voyages file could have taken one, and it is not overwritten
                    raise ValueError(f"voyage id(s) {', '.join(taken)} of plan {plan['plan_id']} already stored: "
                                     "plan again (a new plan id is drawn)")
                con.execute(f"INSERT INTO voyages ({', '.join(PLANNED_VOYAGE_COLUMNS)}) SELECT * FROM v")
    return {"superseded_plans": older, "voyages_replaced": int(n_replaced), "voyages_kept": int(kept),
            "voyages_added": len(voyages)}


def set_plan_picture(db_path: Path, plan_id: str, path: str) -> None:
    with warehouse.connect(db_path) as con:
        con.execute("UPDATE fleet_plans SET gantt_png = ? WHERE plan_id = ?", [path, plan_id])


def load_planning_fleet(db_path: Path) -> tuple[pd.DataFrame, dict[int, dict]]:
    """(vessels joined to their availability — only vessels with availability —, active models) for planning."""
    from storage.fleet_store import _active_models

    with warehouse.connect(db_path, write=False) as con:
        df = con.execute("SELECT v.*, a.* EXCLUDE (imo, source_file) FROM vessels v JOIN vessel_availability a "
                         "USING (imo) ORDER BY imo").fetchdf()
        return df, _active_models(con)


# The newest position reported of voyage row {v} since its departure: an operator's position of it, or a noon
# report of its vessel between its departure and its RTA (route-fleet takes both as the ship at sea); NULL: none
_REPORTED_SQL = ("greatest((SELECT max(p.ts_utc) FROM voyage_positions p WHERE p.voyage_id = {v}.voyage_id "
                 "AND p.ts_utc >= {v}.depart_utc), (SELECT max(n.ts_utc) FROM noon_reports n WHERE n.imo = {v}.imo "
                 "AND n.ts_utc > {v}.depart_utc AND n.ts_utc <= {v}.rta_utc AND n.lat IS NOT NULL))")


def voyages_for_replan(db_path: Path) -> pd.DataFrame:
    """Every stored voyage as a re-plan weighs it (pipeline.planning.voyages.replan): voyage_id, imo, plan_id,
    status, depart_utc, rta_utc, arr_name, arr_lat, arr_lon; contract_code and kind of the plan leg that made it
    (NULL for voyages from a voyages file); the vessel's port_hours; reported_utc, the newest position reported
    since its departure (an operator's, or a noon report of its vessel before its RTA; NULL: none)."""
    with warehouse.connect(db_path, write=False) as con:
        return con.execute(
            "SELECT v.voyage_id, v.imo, v.plan_id, v.status, v.depart_utc, v.rta_utc, v.arr_name, v.arr_lat, v.arr_lon, "
            f"l.contract_code, l.kind, a.port_hours, {_REPORTED_SQL.format(v='v')} AS reported_utc "
            "FROM voyages v LEFT JOIN fleet_plan_legs l ON l.voyage_id = v.voyage_id AND l.plan_id = v.plan_id "
            "LEFT JOIN vessel_availability a ON a.imo = v.imo ORDER BY v.imo, v.depart_utc").fetchdf()


def active_plan_as_of(db_path: Path) -> tuple[str, pd.Timestamp] | None:
    """(plan_id, as_of_utc) of the active plan, or None."""
    if not Path(db_path).exists():
        return None
    with warehouse.connect(db_path, write=False) as con:
        row = con.execute("SELECT plan_id, as_of_utc FROM fleet_plans WHERE status = 'active' "
                          "ORDER BY as_of_utc DESC LIMIT 1").fetchall()
    return None if not row else (str(row[0][0]), pd.Timestamp(row[0][1]))


def load_plan(db_path: Path, plan_id: str) -> tuple[dict, pd.DataFrame, pd.DataFrame]:
    with warehouse.connect(db_path, write=False) as con:
        plan = con.execute("SELECT * FROM fleet_plans WHERE plan_id = ?", [plan_id]).fetchdf()
        legs = con.execute("SELECT * FROM fleet_plan_legs WHERE plan_id = ? ORDER BY imo, seq", [plan_id]).fetchdf()
        left = con.execute("SELECT * FROM fleet_plan_unassigned WHERE plan_id = ? ORDER BY contract_code", [plan_id]).fetchdf()
    if plan.empty:
        raise KeyError(f"no fleet plan {plan_id!r} in {db_path}")
    return plan.iloc[0].to_dict(), legs, left
