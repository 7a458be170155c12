"""Validation of the planning files: `ports.csv`, vessel availability (`availability.csv`) and `contracts.csv`.

As for vessels and voyages (`pipeline.fleet_validate`): rows come in as text, good rows leave typed, a refused row
keeps its raw text and the first failing check as its reason; a file missing a required column is refused whole
(`FleetFileError`). Times ISO 8601 (values without an offset are UTC).

ports.csv:        port, lat, lon (the pilot station: at sea)
availability.csv: imo, from_utc, from_port, [until_utc, until_port, port_hours, daily_cost, ports, cargo_types,
                  laden_speed_kn, ballast_speed_kn, laden_draft_m, ballast_draft_m]; `ports` and `cargo_types`
                  are lists separated by `;` (empty: any)
contracts.csv:    code, cargo_type, min_t, max_t, load_port, discharge_port, early_utc, late_utc, [penalty]

Besides each file's own checks, a row is refused for: a name (port, cargo type, a `;` list of them) holding a control
character or starting like a spreadsheet formula (=, +, -, @); the text `nan` in a number (an empty cell is the
default, `nan` is a mistake); a number above its LIMITS (a penalty or daily cost above 1e12, a speed above 40 kn, …);
a laden draft below the ballast draft; a contract window opening more than MAX_AHEAD_DAYS after the planning time.
"""

from __future__ import annotations

import pandas as pd

from pipeline.fleet_validate import FleetFileError, _integer_imo, _is_empty, _numbers, _Reasons, _split, raw_rows
from pipeline.planning.fuel import DEFAULT_BALLAST_DRAFT_M, DEFAULT_LADEN_DRAFT_M
from pipeline.timestamps import parse_iso_column
from pipeline.validate_ids import is_valid_imo, name_problem, voyage_id_problem

PORT_REQUIRED = ("port", "lat", "lon")
AVAILABILITY_REQUIRED = ("imo", "from_utc", "from_port")
AVAILABILITY_NUMERIC = ("port_hours", "daily_cost", "laden_speed_kn", "ballast_speed_kn", "laden_draft_m",
                        "ballast_draft_m")
CONTRACT_REQUIRED = ("code", "cargo_type", "min_t", "max_t", "load_port", "discharge_port", "early_utc", "late_utc")
# Bounds that keep every cost of a plan a number the LP solves exactly (HiGHS treats 1e20 as infinite; a penalty of
# 1e308 overflows its sums) and refuse values no ship or market has.
MAX_MONEY = 1e12  # a penalty, a daily cost (currency of the fuel price)
MAX_FUEL_PRICE = 1e6  # per tonne
LIMITS = {"penalty": MAX_MONEY, "daily_cost": MAX_MONEY, "port_hours": 24 * 60.0, "laden_speed_kn": 40.0,
          "ballast_speed_kn": 40.0, "laden_draft_m": 30.0, "ballast_draft_m": 30.0, "min_t": 1e6, "max_t": 1e6}
MAX_AHEAD_DAYS = 2 * 366  # a contract window opening later than this after the planning time is a typo in its year


def _require(raw: pd.DataFrame, cols, what: str, source: str) -> None:
    absent = [c for c in cols if c not in raw.columns]
    if absent:
        raise FleetFileError(f"{source or what}: required columns missing: {', '.join(absent)}")


def _text(df: pd.DataFrame, col: str) -> pd.Series:
    """Stripped text; None where empty."""
    empty = _is_empty(df[col])
    return pd.Series([None if e else str(x).strip() for x, e in zip(df[col], empty)], index=df.index, dtype=object)


def _checked_numbers(df: pd.DataFrame, cols, r: _Reasons) -> None:
    """`_numbers`, and the text `nan` (which the file's reader keeps as text and `_is_empty` takes as an empty cell,
    i.e. the default) refused, and each value above its LIMITS refused."""
    for c in cols:
        if c in df.columns:
            literal = df[c].map(lambda x: isinstance(x, str) and x.strip().lower() in ("nan", "-nan", "+nan"))
            r.flag(literal, f"not a number in {c} (NaN; leave the cell empty for the default)")
    _numbers(df, cols, r)
    for c in cols:
        if c in LIMITS:
            r.flag(df[c] > LIMITS[c], f"{c} above {LIMITS[c]:g}")


def _names(df: pd.DataFrame, cols, r: _Reasons) -> None:
    """Names (and `;` lists of names) that would forge log lines or run as spreadsheet formulas are refused."""
    for c in cols:
        if c in df.columns:
            why = [next((p for p in map(name_problem, x.split(";")) if p), None) if isinstance(x, str) else None
                   for x in df[c]]
            r.flag_each(pd.Series([f"{w} in {c}" if w else pd.NA for w in why], index=df.index, dtype=object))


def split_list(value) -> frozenset[str] | None:
    """'a;b' → {'a', 'b'}; empty → None (any)."""
    if value is None or (isinstance(value, float) and value != value) or not str(value).strip():
        return None
    return frozenset(x.strip() for x in str(value).split(";") if x.strip()) or None


def validate_ports(raw: pd.DataFrame, source: str = "", *, check_land: bool = True) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(good ports: port, lat, lon; refused rows with `raw`, `reason`). A port on land (global land mask) is refused:
    give the pilot station's position. So is a port at sea that touches land (0 NM from a land cell, e.g. exactly on
    a cell's corner), which no route can leave; the reason suggests a position a little further out."""
    _require(raw, PORT_REQUIRED, "ports file", source)
    df = raw.copy()
    r = _Reasons(df.index)
    for c in PORT_REQUIRED:
        r.flag(_is_empty(df[c]), f"missing {c}")
    _names(df, ("port",), r)
    df["port"] = _text(df, "port")
    _checked_numbers(df, ("lat", "lon"), r)
    r.flag(df["lat"].abs() > 90, "out of range lat")
    r.flag((df["lon"] < -180) | (df["lon"] > 360), "out of range lon")
    if check_land:
        from pipeline.routing.land import is_sea  # the routing land mask: a port routing cannot leave is useless

        ok = r.reason.isna()
        if ok.any():
            sea = pd.Series(True, index=df.index)
            sea[ok] = [bool(is_sea(la, lo)) for la, lo in zip(df.loc[ok, "lat"], df.loc[ok, "lon"])]
            r.flag(~sea, "on land (global land mask): give the position of the pilot station, at sea")
            ok = r.reason.isna()
            for i in df.index[ok]:
                why = _touches_land(float(df.at[i, "lat"]), float(df.at[i, "lon"]))
                if why:
                    r.flag(df.index == i, why)
    r.flag(df["port"].duplicated(keep="first") & r.reason.isna(), "duplicate port in file")
    return _split(df, r, raw_rows(raw), source)


def _touches_land(lat: float, lon: float) -> str | None:
    """Why a port at sea per the mask still cannot be sailed from: 0 NM from land (on the edge or corner of a land
    cell), where routing's leg check refuses every leg leaving it, even inside the port approach."""
    import numpy as np

    from pipeline.routing.geodesy import destination
    from pipeline.routing.land import distance_to_land_nm

    if float(distance_to_land_nm(lat, lon, 1.0)) > 0.0:
        return None
    for r_nm in np.arange(0.1, 2.01, 0.1):  # the nearest point at least 0.2 NM from land, as a suggestion
        pts = [destination(lat, lon, float(b), float(r_nm)) for b in range(0, 360, 15)]
        d = distance_to_land_nm(np.array([p[0] for p in pts]), np.array([p[1] for p in pts]), 1.0)
        if d.max() >= 0.2:
            la, lo = pts[int(np.argmax(d))]
            return (f"touches land in the land mask (0 NM from a land cell's edge): no route can leave it; "
                    f"move it out to sea, e.g. {la:.4f},{lo:.4f} ({r_nm:.1f} NM off)")
    return "touches land in the land mask (0 NM from a land cell's edge): no route can leave it; move it out to sea"


def validate_availability(raw: pd.DataFrame, *, known_imos: set[int] | None = None, ports: set[str] | None = None,
                          source: str = "") -> tuple[pd.DataFrame, pd.DataFrame]:
    """(good availability rows, typed; refused rows). `ports`: the known port names (None: not checked)."""
    _require(raw, AVAILABILITY_REQUIRED, "availability file", source)
    df = raw.copy()
    r = _Reasons(df.index)
    for c in AVAILABILITY_REQUIRED:
        r.flag(_is_empty(df[c]), f"missing {c}")
    df["imo"] = _integer_imo(df, r)
    r.flag(~df["imo"].map(lambda i: 0 < i <= 9_999_999 and is_valid_imo(i)), "IMO number fails its check digit")
    if known_imos is not None:
        r.flag(~df["imo"].isin(list(known_imos)), "unknown vessel (import it with vessels.csv first)")
    for c in ("from_utc", "until_utc"):
        if c not in df.columns:
            df[c] = None
        ts, why = parse_iso_column(df[c].where(~_is_empty(df[c]), "2000-01-01"))
        r.flag_each(why.where(~_is_empty(df[c]), pd.NA), prefix=f"{c}: ")
        df[c] = ts.where(~_is_empty(df[c]))
    _names(df, ("from_port", "until_port", "ports", "cargo_types"), r)
    for c in ("from_port", "until_port", "ports", "cargo_types"):
        df[c] = _text(df, c) if c in df.columns else None
    if ports is not None:
        for c in ("from_port", "until_port"):
            r.flag(df[c].notna() & ~df[c].isin(list(ports)), f"unknown {c} (not in the ports file)")
        unknown = df["ports"].map(lambda x: sorted((split_list(x) or set()) - set(ports)))
        r.flag_each(unknown.map(lambda u: f"unknown port(s) in ports: {', '.join(u)}" if u else pd.NA))
    r.flag(df["until_port"].notna() & df["until_utc"].isna(), "until_port given without until_utc")
    r.flag(df["until_utc"].notna() & (df["until_utc"] <= df["from_utc"]),
           "available nowhere: until_utc is not after from_utc")
    _checked_numbers(df, AVAILABILITY_NUMERIC, r)
    for c in AVAILABILITY_NUMERIC:
        r.flag(df[c] < 0, f"negative {c}")
    for c in ("laden_speed_kn", "ballast_speed_kn", "laden_draft_m", "ballast_draft_m"):
        r.flag(df[c] == 0, f"zero {c}")
    laden, ballast = df["laden_draft_m"].fillna(DEFAULT_LADEN_DRAFT_M), df["ballast_draft_m"].fillna(DEFAULT_BALLAST_DRAFT_M)
    r.flag(laden < ballast, f"laden_draft_m below ballast_draft_m (empty: {DEFAULT_LADEN_DRAFT_M:g} and "
                            f"{DEFAULT_BALLAST_DRAFT_M:g} m): a loaded ship floats deeper")
    allowed = df["ports"].map(split_list)
    r.flag(df["from_port"].notna() & allowed.notna() &
           pd.Series([a is not None and p not in a for a, p in zip(allowed, df["from_port"])], index=df.index),
           "from_port is not among the vessel's allowed ports")
    r.flag(df["imo"].duplicated(keep="first") & r.reason.isna(), "duplicate imo in file")
    return _split(df, r, raw_rows(raw), source)


def validate_contracts(raw: pd.DataFrame, *, as_of: pd.Timestamp | None = None, ports: set[str] | None = None,
                       max_dwt_t: float | None = None, cargo_types: set[str] | None = None,
                       source: str = "") -> tuple[pd.DataFrame, pd.DataFrame]:
    """(good contracts, typed; refused rows). A contract is refused when: a field is missing or malformed, the
    code is not a plain name or repeats, min_t > max_t, the window has zero length or closed before `as_of`, a
    port is unknown (not in `ports`) or both ports are the same, its minimum weight is above every deadweight
    (`max_dwt_t`), or no vessel may carry its cargo type (`cargo_types`: what the vessels may carry, None: any)."""
    _require(raw, CONTRACT_REQUIRED, "contracts file", source)
    df = raw.copy()
    r = _Reasons(df.index)
    problems = [voyage_id_problem(x) for x in df["code"]]  # a code names voyages and files: a plain name
    r.flag_each(pd.Series([p.replace("voyage_id", "code") if p else pd.NA for p in problems], index=df.index,
                          dtype=object))
    for c in CONTRACT_REQUIRED:
        r.flag(_is_empty(df[c]), f"missing {c}")
    _names(df, ("cargo_type", "load_port", "discharge_port"), r)
    for c in ("code", "cargo_type", "load_port", "discharge_port"):
        df[c] = _text(df, c)
    for c in ("early_utc", "late_utc"):
        ts, why = parse_iso_column(df[c])
        r.flag_each(why.where(~_is_empty(df[c]), pd.NA), prefix=f"{c}: ")
        df[c] = ts
    if "penalty" not in df.columns:
        df["penalty"] = None
    _checked_numbers(df, ("min_t", "max_t", "penalty"), r)
    for c in ("min_t", "max_t", "penalty"):
        r.flag(df[c] < 0, f"negative {c}")
    r.flag(df["max_t"] == 0, "max_t is zero")
    r.flag(df["min_t"] > df["max_t"], "min_t above max_t")
    r.flag(df["late_utc"] <= df["early_utc"], "window of zero length: late_utc is not after early_utc")
    if as_of is not None:
        r.flag(df["late_utc"] < pd.Timestamp(as_of), f"window closed before the planning time {pd.Timestamp(as_of)}")
        r.flag(df["early_utc"] > pd.Timestamp(as_of) + pd.Timedelta(days=MAX_AHEAD_DAYS),
               f"window opens more than {MAX_AHEAD_DAYS} days after the planning time {pd.Timestamp(as_of)} "
               "(check its year)")
    if ports is not None:
        for c in ("load_port", "discharge_port"):
            r.flag(df[c].notna() & ~df[c].isin(list(ports)), f"unknown {c} (not in the ports file)")
    r.flag(df["load_port"] == df["discharge_port"], "load_port and discharge_port are the same")
    if max_dwt_t is not None:
        r.flag(df["min_t"] > max_dwt_t, f"min_t above every vessel's deadweight ({max_dwt_t:.0f} t at most)")
    if cargo_types is not None:
        r.flag(df["cargo_type"].notna() & ~df["cargo_type"].isin(list(cargo_types)), "no vessel may carry this cargo type")
    r.flag(df["code"].duplicated(keep=False) & r.reason.isna(), "duplicate code in file (every row with it refused)")
    return _split(df, r, raw_rows(raw), source)
