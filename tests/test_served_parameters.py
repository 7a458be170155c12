"""On a served deployment, flow-run parameters cannot steer where data goes or where the Earthdata token is sent;
the token never travels in clear text across a network."""

from __future__ import annotations

import secrets

import pytest

import flows.fleet
import flows.ingest
import flows.refit
from flows.jobs.ingest import _opts
from flows.settings import SERVED_ENV, SettingsError, load_settings, pin_for_serving, refuse_served_overrides
from pipeline.sources.fetch import token_may_go_to
from tests.http_mirror import serve

TOKEN = "edl-" + secrets.token_hex(20)


@pytest.fixture
def served(tmp_path, monkeypatch):
    """This process as `jitroute serve` leaves it for its flow runs: data root and OSCAR origin pinned, token in env."""
    for var in ("JITROUTE_DATA", "JITROUTE_RISH_URL", "JITROUTE_OSCAR_URL", SERVED_ENV):
        monkeypatch.setenv(var, "")  # so the test's end restores each as it was, after pin_for_serving set it
    monkeypatch.setenv("JITROUTE_EARTHDATA_TOKEN", TOKEN)
    pinned = tmp_path / "pinned"
    pin_for_serving(str(pinned), "https://rish.example/arch/", "https://oscar.example/oscar/")
    return pinned


def test_a_served_ingest_refuses_a_callers_data_root_and_oscar_url_before_sending_or_writing_anything(served, tmp_path):
    theirs = tmp_path / "theirs"
    with serve(tmp_path) as (listener, handler):
        for kwargs, refused in (({"data_root": str(theirs)}, "data_root"),
                                ({"oscar_url": listener + "oscar/"}, "oscar_url"),
                                ({"rish_url": listener + "rish/"}, "rish_url")):
            with pytest.raises(SettingsError, match=f"parameter {refused}=.* refused: a served deployment"):
                flows.ingest.ingest_weather.fn("2020-12-01T00", **kwargs)
        with pytest.raises(SettingsError, match="parameter oscar_url=.* refused"):
            flows.fleet.nightly.fn("2020-12-01", oscar_url=listener + "oscar/")
        with pytest.raises(SettingsError, match="parameter data_root=.* refused"):
            flows.ingest.backfill.fn("2020-12-01", "2020-12-01", data_root=str(theirs))
        with pytest.raises(SettingsError, match="parameter data_root=.* refused"):
            flows.fleet.route_fleet.fn(data_root=str(theirs))
        with pytest.raises(SettingsError, match="parameter data_root=.* refused"):
            flows.refit.refit_performance.fn(data_root=str(theirs))
    assert handler.requests == []  # no request (so no token) reached the caller's listener
    assert not theirs.exists() and not served.exists()  # nothing written anywhere


def test_the_serve_process_s_own_values_pass(served):
    refuse_served_overrides(data_root=str(served), rish_url="https://rish.example/arch", oscar_url=None)
    s = load_settings()
    assert s.data_root == served and s.sources.oscar_url == "https://oscar.example/oscar/"


def test_parameters_pass_when_not_served(monkeypatch, tmp_path):
    monkeypatch.delenv(SERVED_ENV, raising=False)
    refuse_served_overrides(data_root=str(tmp_path / "anywhere"), oscar_url="http://127.0.0.1:9/oscar/")


@pytest.mark.parametrize("url, sent", [("https://podaac.example/oscar/", True), ("http://podaac.example/oscar/", False),
                                       ("http://10.1.2.3/oscar/", False), ("file:///srv/oscar/", False),
                                       ("http://127.0.0.1:8080/oscar/", True), ("http://localhost/oscar/", True),
                                       ("http://[::1]:8080/oscar/", True)])
def test_the_earthdata_token_goes_only_over_https_or_to_this_machine(monkeypatch, url, sent):
    monkeypatch.setenv("JITROUTE_EARTHDATA_TOKEN", TOKEN)
    s = load_settings(**{"sources.oscar_url": url})
    assert token_may_go_to(url) is sent
    assert (_opts(s, "OSCAR", TOKEN).token == TOKEN) is sent
    assert _opts(s, "GSM", TOKEN).token is None  # RISH never gets it
