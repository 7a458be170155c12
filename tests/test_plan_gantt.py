"""The fleet plan's Gantt picture: every vessel of the fleet has a row (an idle one says so), port calls are named."""

from __future__ import annotations

import pandas as pd

from pipeline.export.plan_gantt import plan_gantt_figure, plan_gantt_png


def _legs() -> pd.DataFrame:
    t = pd.Timestamp("2020-12-01T00:00Z")
    rows = [
        {"imo": 9100001, "seq": 0, "kind": "ballast", "contract_code": None, "from_port": "Singapore",
         "to_port": "Port Hedland", "depart_utc": t, "arrive_utc": t + pd.Timedelta(hours=120)},
        {"imo": 9100001, "seq": 1, "kind": "laden", "contract_code": "K001", "from_port": "Port Hedland",
         "to_port": "Qingdao", "depart_utc": t + pd.Timedelta(hours=150), "arrive_utc": t + pd.Timedelta(hours=400)},
    ]
    return pd.DataFrame(rows)


PLAN = {"plan_id": "plan-20201201T0000-abc123", "as_of_utc": "2020-12-01T00:00Z", "n_assigned": 1,
        "n_contracts": 2, "total_cost": 123456.0, "solve_status": "optimal"}


def _texts(fig) -> list[str]:
    ax = fig.axes[0]
    return [t.get_text() for t in ax.texts] + [t.get_text() for t in ax.get_yticklabels()]


def test_idle_vessels_get_a_row_that_says_so():
    fig = plan_gantt_figure(PLAN, _legs(), names={9100001: "ALPHA", 9100002: "BRAVO"},
                            fleet=[9100001, 9100002])
    texts = _texts(fig)
    assert "BRAVO 9100002" in texts and "ALPHA 9100001" in texts
    assert any(t.startswith("idle") for t in texts)
    assert "on 1 of 2 vessels" in fig.axes[0].get_title()


def test_without_the_fleet_only_busy_vessels_are_drawn():
    texts = _texts(plan_gantt_figure(PLAN, _legs(), names={9100001: "ALPHA"}))
    assert not any(t.startswith("idle") for t in texts)
    assert "ALPHA 9100001" in texts


def test_port_calls_are_named_on_the_bar(tmp_path):
    fig = plan_gantt_figure(PLAN, _legs(), fleet=[9100001])
    assert "Port Hedland" in _texts(fig)  # the call between the ballast arrival and the laden departure
    png = plan_gantt_png(tmp_path / "p.png", PLAN, _legs(), fleet=[9100001, 9100002])
    assert png.stat().st_size > 10_000
