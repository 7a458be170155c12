"""The Earthdata token: sent as a bearer header to the OSCAR host only, never after a redirect to another
host, and never found in logs, output, exceptions, DuckDB tables, files or paths under the data root,
or anything the Prefect API holds (flow/task runs, parameters, states, logs, artifacts, its database)."""

from __future__ import annotations

import logging
import secrets
import traceback
from pathlib import Path
from uuid import UUID

import duckdb
import pytest

import flows.ingest
import flows.jobs.ingest
from flows.settings import load_settings
from pipeline.sources.fetch import FetchOptions
from storage.layout import DataLayout
from tests.http_mirror import serve
from tests.reliability.conftest import CYCLE, gsm_file, oscar_files
from tests.reliability.ingest_child import load_settings_with

TOKEN = "edl-" + secrets.token_hex(20)


def _run(root: Path, rish_url: str, oscar_url: str):
    """The real flow; returns (report or exception, flow run id)."""
    state = flows.ingest.ingest_weather(CYCLE, data_root=str(root), rish_url=rish_url, oscar_url=oscar_url, force=True,
                                        return_state=True)
    return state.result(raise_on_failure=False), state.state_details.flow_run_id


def _warehouse_text(db: Path) -> str:
    con = duckdb.connect(str(db), read_only=True)
    tables = [r[0] for r in con.execute("SELECT table_name FROM information_schema.tables WHERE table_schema = 'main'").fetchall()]
    text = "\n".join(f"{t}: {con.execute(f'SELECT * FROM {t}').fetchall()!r}" for t in tables)
    con.close()
    assert "ingest_log" in tables and "cycles" in tables
    return text


def _prefect_text(run_ids: list[UUID]) -> str:
    """Everything the Prefect API returns about these flow runs, as JSON text."""
    from prefect.client.orchestration import get_client
    from prefect.client.schemas.filters import (ArtifactFilter, FlowRunFilter, FlowRunFilterId, LogFilter, LogFilterFlowRunId,
                                                TaskRunFilter)
    from prefect.client.schemas.sorting import ArtifactSort, LogSort, TaskRunSort
    from prefect.logging.handlers import APILogHandler

    APILogHandler().flush()  # the run logs are sent in the background; wait for them
    runs = FlowRunFilter(id=FlowRunFilterId(any_=run_ids))
    with get_client(sync_client=True) as client:
        parts = [client.read_flow_run(i).model_dump_json() for i in run_ids]
        tasks = client.read_task_runs(flow_run_filter=runs, limit=200, sort=TaskRunSort.EXPECTED_START_TIME_ASC)
        parts += [t.model_dump_json() for t in tasks]
        logs = client.read_logs(log_filter=LogFilter(flow_run_id=LogFilterFlowRunId(any_=run_ids)), limit=200, offset=0, sort=LogSort.TIMESTAMP_ASC)
        parts += [log.model_dump_json() for log in logs]
        parts += [a.model_dump_json() for a in client.read_artifacts(
            artifact_filter=ArtifactFilter(), flow_run_filter=runs, task_run_filter=TaskRunFilter(), limit=200, offset=0,
            sort=ArtifactSort.ID_DESC)]
    assert logs and len(tasks) == 4 + 4 + 4, "the API returned too little for the search to prove anything"
    return "\n".join(parts)


def _prefect_files_text() -> str:
    """The Prefect API's database file and the local Prefect home (result storage), as raw bytes."""
    import prefect.settings

    db = Path(str(prefect.settings.PREFECT_SERVER_DATABASE_CONNECTION_URL.value()).split("///", 1)[1])
    home = Path(prefect.settings.PREFECT_HOME.value())
    files = [p for p in (db, db.with_name(db.name + "-wal")) if p.exists()] + [p for p in home.rglob("*") if p.is_file()]
    assert db.exists()
    return "\n".join(p.read_bytes().decode("latin-1") for p in files)


def test_token_is_sent_to_the_oscar_host_only_and_never_stored_or_shown(mirror, tmp_path, monkeypatch, fast_settings,
                                                                        prefect_harness, capfd, caplog):
    monkeypatch.setenv("JITROUTE_EARTHDATA_TOKEN", TOKEN)
    monkeypatch.setattr(flows.jobs.ingest, "load_settings", load_settings_with(**{"sources.allowed_redirect_hosts": ("localhost",)}))
    oscar = oscar_files(mirror)[1]
    roots = [tmp_path / f"data{k}" for k in range(3)]  # one per run: a fetched file would be skipped next time
    outcomes = []
    with caplog.at_level(logging.DEBUG), serve(mirror) as (other_url, other):
        moved = f"http://localhost:{other_url.rsplit(':', 1)[1].strip('/')}/oscar/{oscar.name}"
        with serve(mirror, {gsm_file(mirror, 6).name: "500"}) as (rish_url, rish), \
                serve(mirror, {oscar.name: f"redirect:{moved}"}) as (oscar_url, osc):
            # 1. OSCAR file redirected to an allowed other host; one RISH file fails (error path)
            outcomes.append(_run(roots[0], rish_url + "rish/", oscar_url + "oscar/"))
        with serve(mirror, {oscar.name: "500"}) as (oscar_url, osc_failing):
            # 2. the OSCAR download itself fails after retries
            outcomes.append(_run(roots[1], f"file://{mirror}/rish/", oscar_url + "oscar/"))
        with serve(mirror, {"oscar/": "redirect:http://127.0.0.9:9/oscar/"}) as (oscar_url, _):
            # 3. the OSCAR index redirects to a host that is not allowed: the listing is unreachable, the cycle incomplete
            outcomes.append(_run(roots[2], f"file://{mirror}/rish/", oscar_url + "oscar/"))
    (r1, _), (r2, _), (r3, _) = outcomes
    run_ids = [i for _, i in outcomes]
    assert not r1["complete"] and f"GSM {gsm_file(mirror, 6).name}: missing" in r1["missing"]
    assert f"OSCAR {oscar.name}: missing" in r2["missing"]
    assert not r3["complete"] and any(m.startswith("OSCAR listing unreachable") and "refused" in m for m in r3["missing"]), r3

    # the header went to the OSCAR host, on every request there, and nowhere else
    assert [p for p, _ in osc.requests] == ["/oscar/", f"/oscar/{oscar.name}"]
    assert all(h.get("Authorization") == f"Bearer {TOKEN}" for _, h in osc.requests + osc_failing.requests)
    assert [p for p, _ in other.requests] == [f"/oscar/{oscar.name}"]  # the redirect was followed...
    assert not any("Authorization" in h for _, h in other.requests)  # ...without the token
    assert rish.requests and not any("Authorization" in h for _, h in rish.requests)

    # and the token is nowhere
    captured = capfd.readouterr()
    places = {
        "stdout/stderr": captured.out + captured.err,
        "log records": "\n".join(f"{r.getMessage()} {r.exc_text or ''}" for r in caplog.records),
        "reports": repr(outcomes),
        "warehouse": "\n".join(_warehouse_text(DataLayout(r).warehouse) for r in roots),
        "snapshot": "\n".join(_warehouse_text(DataLayout(r).warehouse_snapshot) for r in roots),
        "data root paths": "\n".join(str(p) for r in roots for p in r.rglob("*")),
        "data root files": "\n".join(p.read_bytes().decode("latin-1") for r in roots for p in r.rglob("*") if p.is_file()),
        "prefect api": _prefect_text(run_ids),
        "prefect files": _prefect_files_text(),
        "reprs": repr(load_settings()) + repr(FetchOptions(token=TOKEN)),
    }
    assert "refused" in places["prefect api"] and oscar.name in places["warehouse"]  # the searches see real content
    leaks = [where for where, text in places.items() if TOKEN in text or TOKEN[4:20] in text]
    assert leaks == []


def test_token_comes_from_the_environment_and_is_absent_without_it(monkeypatch):
    monkeypatch.delenv("JITROUTE_EARTHDATA_TOKEN", raising=False)
    assert load_settings().sources.earthdata_token is None
    monkeypatch.setenv("JITROUTE_EARTHDATA_TOKEN", TOKEN)
    s = load_settings()
    assert s.sources.earthdata_token == TOKEN
    assert flows.jobs.ingest._opts(s, "OSCAR").token == TOKEN
    assert flows.jobs.ingest._opts(s, "GSM").token is None and flows.jobs.ingest._opts(s, "GWM").token is None
    assert TOKEN not in repr(s) and TOKEN not in repr(flows.jobs.ingest._opts(s, "OSCAR"))


@pytest.mark.parametrize("status", ["404", "500"])
def test_failed_oscar_fetch_messages_carry_no_token(tmp_path, status):
    from pipeline.sources.fetch import fetch, read_text

    (tmp_path / "srv").mkdir()
    opts = FetchOptions(timeout_s=2, retries=1, backoff_s=0.01, token=TOKEN)
    with serve(tmp_path / "srv", {"a.nc": status, "srv/": status}) as (url, handler):
        r = fetch(url + "a.nc", tmp_path / "out" / "a.nc", opts)
        with pytest.raises((FileNotFoundError, ConnectionError)) as info:
            read_text(url + "srv/", opts)
    assert r.status == "missing" and TOKEN not in (r.error or "") and TOKEN not in repr(r)
    assert TOKEN not in "".join(traceback.format_exception(info.value))
    assert all(h["Authorization"] == f"Bearer {TOKEN}" for _, h in handler.requests)


def test_token_falls_back_to_a_prefect_secret_block(monkeypatch, prefect_harness):
    from prefect.blocks.system import Secret

    other = "edl-" + secrets.token_hex(20)  # not TOKEN: the database search above must not meet a stored block
    monkeypatch.delenv("JITROUTE_EARTHDATA_TOKEN", raising=False)
    s = load_settings(**{"sources.earthdata_secret_block": "jitroute-test-earthdata"})
    assert flows.jobs.ingest.earthdata_token(s) is None  # no block yet: OSCAR is fetched without a token
    Secret(value=other).save("jitroute-test-earthdata", overwrite=True)
    assert flows.jobs.ingest.earthdata_token(s) == other
    assert flows.jobs.ingest._opts(s, "OSCAR", other).token == other and flows.jobs.ingest._opts(s, "GSM", other).token is None
    monkeypatch.setenv("JITROUTE_EARTHDATA_TOKEN", TOKEN)  # the environment wins over the block
    assert flows.jobs.ingest.earthdata_token(load_settings(**{"sources.earthdata_secret_block": "jitroute-test-earthdata"})) == TOKEN


def test_redirect_hosts_come_from_the_environment(monkeypatch):
    monkeypatch.setenv("JITROUTE_ALLOWED_REDIRECT_HOSTS", "mirror.example.org, cdn.example.org")
    assert flows.jobs.ingest._opts(load_settings(), "GSM").allowed_redirect_hosts == ("mirror.example.org", "cdn.example.org")
    monkeypatch.delenv("JITROUTE_ALLOWED_REDIRECT_HOSTS")
    assert load_settings().sources.allowed_redirect_hosts == ()
