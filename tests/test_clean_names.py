"""Names with control characters are refused at import (kept with their reason and raw text, nothing silently
dropped), and text shown in logs, terminals, Markdown tables and RTZ files is escaped there."""

from __future__ import annotations

import re

import duckdb
import pandas as pd
import pytest
from typer.testing import CliRunner

from cli.main import app
from pipeline.synthetic.fleet import generate_fleet, write_fleet
from pipeline.validate_ids import markdown_cell, printable

FORGED = "Tokyo Bay\n\x1b[31mERROR voyage V20002 lost"


@pytest.fixture(autouse=True)
def plain_cli(monkeypatch):
    monkeypatch.delenv("PREFECT_API_URL", raising=False)
    monkeypatch.setenv("COLUMNS", "400")


@pytest.mark.slow
def test_control_characters_in_vessel_and_port_names_are_refused_at_import_with_nothing_lost(tmp_path):
    folder = tmp_path / "fleet"
    write_fleet(generate_fleet("2020-12-01T00", n_vessels=4, days=30, seed=3), folder)
    vessels = pd.read_csv(folder / "vessels.csv", dtype=str, keep_default_na=False)
    voyages = pd.read_csv(folder / "voyages.csv", dtype=str, keep_default_na=False)
    vessels.loc[1, "name"] = "JIT\x07 BULKER"
    voyages.loc[0, "dep_name"] = FORGED
    voyages.loc[2, "arr_name"] = "Guam\u2028Apra"
    voyages.loc[3, "arr_name"] = "Naha | Okinawa"  # printable: kept
    assert len(voyages) == 4 and voyages.loc[1, "imo"] == vessels.loc[1, "imo"]  # V2's vessel is the refused one
    vessels.to_csv(folder / "vessels.csv", index=False)
    voyages.to_csv(folder / "voyages.csv", index=False)
    root = tmp_path / "data"
    result = CliRunner().invoke(app, ["fleet", "import", str(folder), "--data", str(root)])
    assert result.exit_code == 0, result.output
    assert "\x1b" not in result.output
    con = duckdb.connect(str(root / "warehouse.duckdb"), read_only=True)
    try:
        n_vessels, n_voyages = con.execute("SELECT (SELECT count(*) FROM vessels), (SELECT count(*) FROM voyages)").fetchone()
        rej_v = con.execute("SELECT reason, raw FROM vessels_rejected").fetchall()
        rej_y = con.execute("SELECT voyage_id, reason, raw FROM voyages_rejected ORDER BY voyage_id").fetchall()
        names = [r[0] for r in con.execute("SELECT dep_name || arr_name FROM voyages").fetchall()]
    finally:
        con.close()
    assert [r for r, _ in rej_v] == ["control characters or a line break in name"]
    assert "JIT\x07 BULKER" in rej_v[0][1]  # the raw row is kept as it was, to be fixed
    reasons = {r for _, r, _ in rej_y}
    assert {"control characters or a line break in dep_name", "control characters or a line break in arr_name"} <= reasons
    assert any(FORGED in raw for _, _, raw in rej_y)
    # nothing lost: every row of the files is stored or rejected
    assert n_vessels + len(rej_v) == len(vessels)
    assert n_voyages + len(rej_y) == len(voyages)
    assert any("Naha | Okinawa" in n for n in names)
    assert not any(re.search("[\x00-\x1f\x7f\u2028]", n) for n in names)


def test_markdown_table_cells_and_log_text_are_escaped():
    from flows.jobs.fleet import run_markdown

    md = run_markdown({"run_id": "r1", "cycle": "2020-12-01T00", "n": 1,
                       "problems": [{"voyage_id": "V1", "status": "failed", "reason": f"voyage V1: departure {FORGED} | x is on land"}],
                       "export_failures": []})
    rows = [line for line in md.splitlines() if line.startswith("| V1 ")]
    assert len(rows) == 1 and "\x1b" not in md
    assert rows[0].count(" | ") == 2 and "\\|" in rows[0] and "\\n\\x1b[31m" in rows[0]
    assert printable(FORGED) == "Tokyo Bay\\n\\x1b[31mERROR voyage V20002 lost"
    assert markdown_cell("a|b") == "a\\|b"


def test_the_attention_table_shows_names_as_text_not_markup_or_escapes():
    from rich.console import Console

    from cli.fleet import problems_table

    console = Console(width=300, record=True, color_system=None)
    console.print(problems_table({"problems": [{"voyage_id": "V1", "imo": 9140607, "status": "failed",
                                                "reason": "[bold red]port[/] " + FORGED}]}))
    text = console.export_text()
    assert "[bold red]port[/]" in text and "\\x1b[31m" in text and "\x1b" not in text


def test_an_rtz_with_a_control_character_in_a_stored_name_is_still_valid():
    from pipeline.export.rtz import route_to_rtz, validate_rtz

    route = {"voyage_id": "V1", "imo": 9140607, "vessel_name": "JIT\x07 BULKER", "dep_name": FORGED, "arr_name": "Guam",
             "solver": "gc", "depart_utc": "2020-12-01T00:00:00Z", "rta_utc": "2020-12-02T00:00:00Z"}
    legs = [{"leg": 0, "lat0": 30.0, "lon0": 140.0, "lat1": 31.0, "lon1": 141.0, "rpm": 80.0, "stw_kn": 12.0,
             "sog_kn": 12.0, "course_deg": 40.0, "etd_utc": "2020-12-01T00:00:00Z", "eta_utc": "2020-12-01T06:00:00Z",
             "fuel_t": 3.0, "hours": 6.0, "wind_kn": 10.0, "hs_m": 1.0}]
    xml = route_to_rtz(route, legs)
    validate_rtz(xml)
    assert b"JIT\\x07 BULKER" in xml
