"""The 00/12 UTC cycles' leads past 132 h (GSM FD0600…FD1100, GWM FD0600-1100): fetched and used whenever a cycle
lists them, never required, and a cycle without them ends at its own last step (no empty steps sailed as calm).

The end-to-end test uses short leads (0–12 h every 6 h, then 24 and 36 h) so that it writes and decodes few global
files; the code paths are those of 0–132 h and 144–264 h."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.routing import weather_field as wf
from pipeline.sources import gsm, gwm, rish
from pipeline.synthetic import weather
from pipeline.synthetic.mirror import gsm_name, gwm_name


def test_the_long_leads_are_those_jma_publishes_past_132_h():
    assert rish.long_gsm_leads(132, 264, 12) == list(range(144, 265, 12))
    assert len(rish.expected_gsm_leads(132, 6)) + len(rish.long_gsm_leads(132, 264, 12)) == 23 + 11
    assert rish.long_gsm_leads(132, None, 12) == rish.long_gsm_leads(132, 0, 12) == []


def test_long_lead_files_are_selected_when_listed_and_never_a_gap_when_not():
    c = np.datetime64("2020-12-01T00", "ns")
    base, extra = rish.expected_gsm_leads(12, 6), rish.long_gsm_leads(12, 36, 12)
    names = [gsm_name(c, h) for h in base] + [gwm_name(c, 0, 12, 0.5)]
    sel = gsm.select(names, c, base, extra)
    assert sel.n_expected == 3 and sel.gaps_h == [] and len(sel.names) == 3
    long_names = names + [gsm_name(c, 24), gsm_name(c, 36), gwm_name(c, 24, 36, 0.5)]
    sel = gsm.select(long_names, c, base, extra)
    assert sel.n_expected == 5 and sel.gaps_h == [] and gsm_name(c, 36) in sel.names
    waves = gwm.select(long_names, c, base, extra)
    assert waves.n_expected == gwm.FILES_PER_CYCLE + 1 and gwm_name(c, 24, 36, 0.5) in waves.names
    assert gsm.select(names[1:], c, base, extra).gaps_h == [0]  # a lead every cycle must have is still a gap


@pytest.fixture(scope="module")
def long_mirror(tmp_path_factory):
    from pipeline.synthetic.mirror import write_mirror

    out = tmp_path_factory.mktemp("long_mirror")
    write_mirror(out, "2020-12-01", "2020-12-01", cycles=(0, 6), seed=0, max_lead_h=12, long_lead_h=36)
    return out


def _settings_with(**extra):
    from flows.settings import load_settings

    def load(**overrides):
        return load_settings(**overrides).with_overrides(**{"sources.gsm_max_lead_h": 12, **extra})
    return load


def _ingest(monkeypatch, root, mirror, cycle, **extra):
    import flows.jobs.ingest as ingest
    from tests.conftest import mirror_urls

    monkeypatch.setattr(ingest, "load_settings", _settings_with(**extra))
    return ingest.ingest_cycle(cycle, data_root=str(root), **mirror_urls(mirror))


@pytest.mark.slow  # whole cycles written to a mirror and ingested, end to end
def test_a_00_utc_cycle_keeps_its_long_leads_and_a_06_utc_cycle_ends_at_its_own(long_mirror, tmp_path, monkeypatch):
    from storage import cube
    from storage.layout import DataLayout

    root = tmp_path / "data"
    r00 = _ingest(monkeypatch, root, long_mirror, "2020-12-01T00", **{"sources.gsm_long_lead_h": 36})
    r06 = _ingest(monkeypatch, root, long_mirror, "2020-12-01T06", **{"sources.gsm_long_lead_h": 36})
    assert r00["complete"] and r06["complete"]  # the 06 cycle lists no long leads: no gap either
    assert r00["n_ok"] == r00["n_expected"] and r06["n_ok"] == r06["n_expected"]
    assert r00["n_ok"] == r06["n_ok"] + 3  # GSM FD0100, FD0112 and GWM FD0100-0112
    store = DataLayout(root).cube_store
    assert cube.step_axis_h(store) == [0, 6, 12, 24, 36]
    f00 = wf.from_cycle(cube.load_cycle(DataLayout(root).weather_cube, "2020-12-01T00"))
    f06 = wf.from_cycle(cube.load_cycle(DataLayout(root).weather_cube, "2020-12-01T06"))
    assert list(f00.times_h) == [0, 6, 12, 24, 36] and list(f06.times_h) == [0, 6, 12]  # the 06 cycle's end
    assert np.isfinite(f06.cells).any(axis=(0, 1, 3)).all()
    from flows.jobs.weather_maps import steps_h  # the maps and animations show each cycle's own leads

    assert steps_h(store, "2020-12-01T06") == [0, 6, 12] and steps_h(store, "2020-12-01T00") == [0, 6, 12, 24, 36]
    # the 36 h lead is the analytic wind of that valid time, not a persisted 12 h
    t = weather.hours_since_epoch(np.datetime64("2020-12-01T00", "ns")) + 36.0
    u, v = weather.wind_uv(t, 20.0, 150.0)
    out = np.empty(wf.N_VARS)
    assert not wf.sample_nb(f00.kernel, 36.0, 20.0, 150.0, out)
    assert out[wf.U10] == pytest.approx(float(u), abs=0.05) and out[wf.V10] == pytest.approx(float(v), abs=0.05)
    assert wf.sample_nb(f06.kernel, 20.0, 20.0, 150.0, out)  # past the 06 cycle's 12 h: beyond, not a hole


@pytest.mark.slow  # whole cycles written to a mirror and ingested, end to end
def test_a_cube_made_with_shorter_leads_keeps_its_axis(long_mirror, tmp_path, monkeypatch, caplog):
    from storage import cube
    from storage.layout import DataLayout

    root = tmp_path / "data"
    assert _ingest(monkeypatch, root, long_mirror, "2020-12-01T06", **{"sources.gsm_long_lead_h": 0})["complete"]
    r00 = _ingest(monkeypatch, root, long_mirror, "2020-12-01T00", **{"sources.gsm_long_lead_h": 36})
    assert r00["complete"] and cube.step_axis_h(DataLayout(root).cube_store) == [0, 6, 12]
    assert "leads 24, 36 h are not kept" in caplog.text


@pytest.mark.slow  # whole cycles written to a mirror and ingested, end to end
def test_a_lagged_ensemble_reads_the_same_window_from_each_complete_cycle(long_mirror, tmp_path, monkeypatch):
    from flows.jobs.route_worker import lagged_members
    from pipeline.routing.problem import WeatherWindow
    from storage.layout import DataLayout

    root = tmp_path / "data"
    for c in ("2020-12-01T00", "2020-12-01T06"):
        assert _ingest(monkeypatch, root, long_mirror, c, **{"sources.gsm_long_lead_h": 36})["complete"]
    store = DataLayout(root).weather_cube_url
    window = WeatherWindow(np.datetime64("2020-12-01T08"), np.datetime64("2020-12-01T16"), (10.0, 30.0), (140.0, 160.0))
    members = lagged_members(store, None, "2020-12-01T06", window, 4)
    assert [m.cycle for m in members] == [np.datetime64("2020-12-01T06"), np.datetime64("2020-12-01T00")]
    assert members[0].horizon_utc == np.datetime64("2020-12-01T18") and members[1].horizon_utc == np.datetime64("2020-12-02T00")
    assert lagged_members(store, None, "2020-12-01T06", window, 1)[0].cycle == np.datetime64("2020-12-01T06")
    # a voyage routed by a fleet worker keeps its spread across both cycles in its routes row
    from flows.jobs.route_worker import route_one
    from pipeline.performance.model import reference_model
    from pipeline.routing.job import RouteJob
    from schemas.tables.routes import ROUTES

    voyage = {"voyage_id": "VENS", "imo": 9140607, "dep_lat": 20.0, "dep_lon": 150.0, "arr_lat": 20.0, "arr_lon": 151.5,
              "depart_utc": np.datetime64("2020-12-01T08"), "rta_utc": np.datetime64("2020-12-01T16"),
              "draft_m": 10.0, "trim_m": 0.0, "rpm_options": [70.0, 85.0, 100.0]}
    job = RouteJob(voyage=voyage, vessel={"imo": 9140607, "rpm_max": 100.0}, model=reference_model().to_json(),
                   run_id="r1", cycle="2020-12-01T06:00:00", exports=False)
    row = route_one(job, store)["route"]
    assert row["status"] == "ok", row["reason"]
    assert set(ROUTES.names) >= set(row) and row["ensemble_members"] == 2
    assert 0.0 <= row["p_on_time"] <= 1.0 and row["fuel_p10_t"] <= row["fuel_p50_t"] <= row["fuel_p90_t"]
    assert row["savings_p10_pct"] <= row["savings_p50_pct"] <= row["savings_p90_pct"]
    job0 = RouteJob(**{**job.__dict__, "options": job.options.__class__(ensemble_members=0)})
    assert route_one(job0, store)["route"]["ensemble_members"] is None
