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


def test_a_served_plan_fleet_reads_input_files_only_from_the_inbox(served, tmp_path):
    import flows.planning

    secret = tmp_path / "secret.csv"
    secret.write_text("code,cargo_type\nAWS_SECRET,hunter2\n")
    inbox = served / "inbox"
    inbox.mkdir(parents=True)
    (inbox / "link.csv").symlink_to(secret)  # a link out of the inbox is followed before the check
    for kwargs, refused in (({"contracts": str(secret)}, "contracts"), ({"contracts": "../../secret.csv"}, "contracts"),
                            ({"contracts": "link.csv"}, "contracts"), ({"contracts": "/etc/passwd"}, "contracts"),
                            ({"contracts": "c.csv", "availability": "/proc/self/environ"}, "availability"),
                            ({"contracts": "c.csv", "ports": str(secret)}, "ports")):
        with pytest.raises(SettingsError, match=f"parameter {refused}=.* refused: a served flow reads input files only "
                                                f"under {inbox}/"):
            flows.planning.plan_fleet.fn(**kwargs)
    with pytest.raises(SettingsError, match="parameter data_root=.* refused"):
        flows.planning.plan_fleet.fn("c.csv", data_root=str(tmp_path / "theirs"))
    for flow, name in ((flows.refit.import_noon_reports, "path"), (flows.refit.import_bunker_logs, "path"),
                       (flows.refit.import_fleet, "folder")):
        with pytest.raises(SettingsError, match=f"parameter {name}=.* refused"):
            flow.fn(str(secret))
    assert not (served / "warehouse.duckdb").exists() and not (tmp_path / "theirs").exists()


def test_a_served_plan_fleet_takes_a_file_of_the_inbox_by_name(served):
    from flows.settings import served_input_file

    (served / "inbox").mkdir(parents=True)
    (served / "inbox" / "contracts.csv").write_text("code\n")
    assert served_input_file("contracts", "contracts.csv") == str((served / "inbox" / "contracts.csv").resolve())
    assert served_input_file("contracts", str(served / "inbox" / "contracts.csv")).endswith("inbox/contracts.csv")
    assert served_input_file("contracts", None) is None


def test_input_files_are_the_operators_own_when_not_served(monkeypatch, tmp_path):
    from flows.settings import served_input_file

    monkeypatch.delenv(SERVED_ENV, raising=False)
    assert served_input_file("contracts", "/srv/plans/contracts.csv") == "/srv/plans/contracts.csv"
