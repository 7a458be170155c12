"""The operator's console in a real browser: `jitroute console` serves a routed demo data root and Debian's headless
Chromium (driven by Playwright, `executable_path=/usr/bin/chromium`; no browser download) opens each page.

Screenshots of every page are written under the session's pytest tmp folder (`console_screenshots*`, the path is
printed; `JITROUTE_CONSOLE_SHOTS=<folder>` writes them there instead) for a person to look at.
"""

from __future__ import annotations

import os
from datetime import datetime, timedelta
from pathlib import Path
from urllib.parse import urlparse

import duckdb
import httpx
import pytest

CHROMIUM = Path("/usr/bin/chromium")
SHOTS_VAR = "JITROUTE_CONSOLE_SHOTS"


def _browser_or_skip() -> None:
    if not CHROMIUM.exists():
        pytest.skip(f"machine capability: BROWSER TESTS SKIPPED, {CHROMIUM} is missing; install Debian's chromium "
                    "(`apt-get install -y chromium`, as .ci/run does as root) to run the console's browser tests")
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:  # a package of the test extras, not a capability of the machine: an incomplete install fails
        pytest.fail("the playwright package is missing; install the test extras (`pip install -c constraints.txt -e "
                    "'.[test]'`)")


@pytest.fixture(scope="module")
def demo_root(tmp_path_factory, demo_mirror) -> Path:
    """The demo's data root, made as `jitroute demo` makes it (cycle ingested, demo fleet with two ships at sea
    imported and refitted, demo contracts planned, the fleet routed), with the fast `gc` solver."""
    _browser_or_skip()
    from cli.fleet import DEMO_AT_SEA, _import_fleet
    from flows.jobs.ingest import ingest_cycle
    from flows.jobs.planning import plan_fleet_job
    from flows.jobs.refit import refit_job
    from pipeline.synthetic.contracts import write_demo_planning
    from pipeline.synthetic.fleet import generate_fleet, write_fleet
    from tests.conftest import mirror_urls, route_demo_cycle

    base = tmp_path_factory.mktemp("console")
    root = base / "data"
    assert ingest_cycle("2020-12-01T00", data_root=str(root), **mirror_urls(demo_mirror))["complete"]
    fleet = generate_fleet("2020-12-01T00", n_vessels=8, days=120, seed=7, at_sea=DEMO_AT_SEA)
    write_fleet(fleet, base / "fleet")
    _import_fleet(base / "fleet", root)
    refit_job(data_root=str(root))
    files = write_demo_planning(fleet.vessels, "2020-12-01T00", base / "planning")
    plan_fleet_job(contracts=files["contracts"], availability=files["availability"], ports=files["ports"],
                   as_of="2020-12-01T00:00Z", data_root=str(root))
    route_demo_cycle(root)
    return root


def _q(root: Path, sql: str) -> list[tuple]:
    with duckdb.connect(str(root / "warehouse.snapshot.duckdb"), read_only=True) as con:
        return con.execute(sql).fetchall()


@pytest.fixture(scope="module")
def console_url(demo_root, tmp_path_factory):
    """`jitroute console --data <demo root>` on a free loopback port, as a user starts it; stopped at the end."""
    from tests.processes import VENV_BIN, describe, free_port, new_tag, poll, port_open, start, stop, tagged_env

    tag, port = new_tag(), free_port()
    log = tmp_path_factory.mktemp("console_log") / "console.log"
    server = start([str(VENV_BIN / "jitroute"), "console", "--data", str(demo_root), "--port", str(port)],
                   tagged_env(tag), log)
    try:
        poll("the console", lambda: port_open(port, server, log), 60, 0.2)
        yield f"http://127.0.0.1:{port}"
    finally:
        left = stop([server], tag)
        assert not left, describe(left)


@pytest.fixture(scope="module")
def shots(tmp_path_factory) -> Path:
    folder = Path(os.environ[SHOTS_VAR]) if os.environ.get(SHOTS_VAR) else tmp_path_factory.mktemp("console_screenshots")
    folder.mkdir(parents=True, exist_ok=True)
    print(f"console screenshots: {folder}")
    return folder


@pytest.fixture(scope="module")
def browser():
    _browser_or_skip()
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=str(CHROMIUM), args=["--no-sandbox", "--disable-dev-shm-usage"])
        try:
            yield b
        finally:
            b.close()


class Visit:
    """A browser page that records every request it makes and every script error."""

    def __init__(self, browser, base: str):
        self.context = browser.new_context(viewport={"width": 1400, "height": 1000})
        self.page = self.context.new_page()
        self.base = base
        self.requests: list[str] = []
        self.errors: list[str] = []
        self.context.on("request", lambda r: self.requests.append(r.url))
        self.page.on("pageerror", lambda e: self.errors.append(str(e)))
        self.page.on("console", lambda m: self.errors.append(m.text) if m.type == "error" else None)

    def open(self, path: str) -> None:
        self.page.goto(self.base + path)
        self.page.wait_for_selector("body[data-ready]", timeout=30_000)
        assert not self.page.query_selector("#main .error"), self.page.inner_text("#main .error")

    def left_loopback(self) -> list[str]:
        """Requests to anywhere but this machine's loopback (data: URLs of pictures drawn in the page are local)."""
        return [u for u in self.requests if urlparse(u).scheme not in ("data", "blob")
                and urlparse(u).hostname != "127.0.0.1"]

    def close(self) -> None:
        self.context.close()


@pytest.fixture
def visit(browser, console_url):
    v = Visit(browser, console_url)
    yield v
    v.close()
    assert v.requests, "the page made no request at all"
    assert not v.left_loopback(), f"requests left 127.0.0.1: {v.left_loopback()}"
    assert not v.errors, f"script errors in the page: {v.errors}"


def _shot(visit: Visit, shots: Path, name: str) -> None:
    path = shots / f"{name}.png"
    visit.page.screenshot(path=str(path), full_page=True)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and path.stat().st_size > 10_000


def _weather_drawn(visit: Visit) -> str:
    visit.page.wait_for_selector("#map .layer-weather[data-valid] image", timeout=30_000)
    return visit.page.get_attribute("#map .layer-weather", "data-valid")


def test_the_fleet_map_draws_every_demo_voyage_where_its_ship_is(visit, demo_root, shots):
    visit.open("/fleet")
    routes = _q(demo_root, "SELECT voyage_id, status FROM latest_routes")
    ships = visit.page.eval_on_selector_all("#map circle.ship", "els => els.map(e => [e.dataset.voyage, e.dataset.phase])")
    starts = visit.page.eval_on_selector_all("#map circle.voyage-start", "els => els.map(e => e.dataset.voyage)")
    assert sorted([v for v, _ in ships] + starts) == sorted(v for v, _ in routes)  # every voyage drawn once
    # one ship marker per vessel: a ship is in one place, its other voyages are drawn as plans from their start
    assert len(ships) == _q(demo_root, "SELECT count(DISTINCT imo) FROM latest_routes")[0][0]
    planned = {v for v, s in routes if s in ("ok", "late")}
    ahead = visit.page.eval_on_selector_all("#map path.track-ahead", "els => els.map(e => e.dataset.voyage)")
    assert set(ahead) <= planned and len(ahead) >= len(planned) - 2  # ships at their arrival have nothing ahead
    # the ships re-planned at sea (of the demo's two, those with a plan) are at sea at the run's time, with their
    # track behind them
    at_sea = {v for v, in _q(demo_root, "SELECT voyage_id FROM latest_routes WHERE start_kind <> 'port' "
                                        "AND status IN ('ok', 'late')")}
    assert at_sea
    assert {v for v, phase in ships if phase == "at sea"} >= at_sea
    behind = set(visit.page.eval_on_selector_all("#map path.track-behind", "els => els.map(e => e.dataset.voyage)"))
    assert at_sea <= behind
    # positions are shown at the run's time (the demo is years old), and the page says so
    assert "2020-12-01 06:00Z" in visit.page.inner_text("#fleet-summary")
    rows = visit.page.eval_on_selector_all("#voyages tbody tr", "els => els.map(e => e.dataset.voyage)")
    assert sorted(rows) == sorted(v for v, _ in routes)
    late = [v for v, s in routes if s == "late"]
    for v in late:  # a late voyage says by how much
        assert "late: ETA" in visit.page.inner_text(f'#voyages tr[data-voyage="{v}"]')
    # the table's filter keeps one vessel's voyages
    vessel, n_voyages = _q(demo_root, "SELECT vessel_name, count(*) FROM latest_routes GROUP BY 1 ORDER BY 2 DESC, 1 LIMIT 1")[0]
    visit.page.fill("#voyage-filter", vessel.lower())
    shown = visit.page.eval_on_selector_all("#voyages tbody tr td:first-child", "els => els.map(e => e.innerText)")
    assert shown == [vessel] * n_voyages
    visit.page.fill("#voyage-filter", "")
    _weather_drawn(visit)
    _shot(visit, shots, "fleet")


def test_the_slider_changes_the_valid_time_shown(visit, shots):
    visit.open("/fleet")
    first = _weather_drawn(visit)
    label = visit.page.inner_text("#valid-time")
    arrows = visit.page.inner_html("#map .layer-arrows")
    assert first.startswith("2020-12-01T06:00") and "valid 2020-12-01 06:00Z" in label  # the step at the run's time
    visit.page.focus("#valid-slider")
    visit.page.keyboard.press("ArrowRight")
    visit.page.wait_for_function("(was) => document.querySelector('#map .layer-weather').dataset.valid !== was",
                                 arg=first, timeout=30_000)
    second = visit.page.get_attribute("#map .layer-weather", "data-valid")
    step = datetime.fromisoformat(second.rstrip("Z")) - datetime.fromisoformat(first.rstrip("Z"))
    assert step == timedelta(hours=6)  # the cube's next lead time
    assert visit.page.inner_text("#valid-time") != label and "valid 2020-12-01 12:00Z" in visit.page.inner_text("#valid-time")
    assert visit.page.inner_html("#map .layer-arrows") != arrows  # the field drawn is the new step's
    assert "[kn]" in visit.page.inner_text("#weather-legend")
    visit.page.select_option("#weather-var", "waves")
    visit.page.wait_for_function("() => document.querySelector('#map .layer-weather').dataset.var === 'waves'",
                                 timeout=30_000)
    assert "[m]" in visit.page.inner_text("#weather-legend")
    _shot(visit, shots, "fleet_waves_next_step")


def test_a_voyage_page_lists_its_legs_and_gives_its_route_files(visit, demo_root, console_url, shots):
    from pipeline.export.rtz import validate_rtz

    vid, n_legs, run_id = _q(demo_root, "SELECT voyage_id, n_legs, run_id FROM latest_routes WHERE status = 'ok' "
                                        "ORDER BY n_legs DESC LIMIT 1")[0]
    legs = _q(demo_root, f"SELECT etd_utc, rpm, fuel_t FROM route_legs WHERE run_id = '{run_id}' AND voyage_id = '{vid}' "
                         "ORDER BY leg")
    visit.open(f"/voyage/{vid}")
    rows = visit.page.eval_on_selector_all("#legs tbody tr", "els => els.map(e => [...e.cells].map(c => c.innerText))")
    assert len(rows) == n_legs == len(legs)
    for row, (etd, rpm, fuel) in zip(rows, legs):
        assert row[1] == etd.strftime("%Y-%m-%d %H:%MZ")
        assert float(row[5]) == pytest.approx(rpm, abs=0.05)
    assert sum(float(r[-1]) for r in rows) == pytest.approx(sum(f for *_, f in legs), abs=0.01 * len(rows))
    assert visit.page.query_selector("#map path.track-plan") and visit.page.query_selector("#profile")
    _weather_drawn(visit)
    assert visit.page.get_attribute("#ship-at-time", "visibility") == "visible"
    href = visit.page.get_attribute("#download-rtz", "href")
    rtz = httpx.get(console_url + href)
    assert rtz.status_code == 200 and f'filename="{vid}.rtz"' in rtz.headers["content-disposition"]
    validate_rtz(rtz.content)
    gj = httpx.get(console_url + visit.page.get_attribute("#download-geojson", "href")).json()
    assert gj["features"][0]["geometry"]["type"] in ("LineString", "MultiLineString")
    assert len(gj["features"]) == n_legs + 2  # the route, then its n + 1 waypoints
    _shot(visit, shots, "voyage")


def test_the_fleet_plan_page_shows_every_vessel_and_the_contracts_left(visit, demo_root, shots):
    visit.open("/plan")
    (plan_id,), = _q(demo_root, "SELECT plan_id FROM fleet_plans WHERE status = 'active'")
    n_legs = _q(demo_root, f"SELECT count(*) FROM fleet_plan_legs WHERE plan_id = '{plan_id}'")[0][0]
    left = _q(demo_root, f"SELECT contract_code FROM fleet_plan_unassigned WHERE plan_id = '{plan_id}'")
    n_vessels = _q(demo_root, "SELECT count(*) FROM vessels")[0][0]
    assert plan_id in visit.page.inner_text("h1")
    assert len(visit.page.query_selector_all("#gantt rect.gantt-bar")) == n_legs
    assert len(visit.page.query_selector_all("#plan-legs tbody tr")) == n_legs
    names = visit.page.eval_on_selector_all("#gantt > text", "els => els.map(e => e.textContent)")
    assert sum(1 for n in names if n.startswith("JIT ")) == n_vessels  # idle vessels too
    if left:
        codes = visit.page.eval_on_selector_all("#unassigned tbody tr td:first-child", "els => els.map(e => e.innerText)")
        assert sorted(codes) == sorted(c for c, in left)
    _shot(visit, shots, "plan")


def test_the_runs_page_lists_the_runs_and_cycles(visit, demo_root, shots):
    visit.open("/runs")
    runs = _q(demo_root, "SELECT run_id FROM route_runs")
    assert len(visit.page.query_selector_all("#runs tbody tr")) == len(runs)
    assert runs[0][0] in visit.page.inner_text("#runs")
    header = visit.page.eval_on_selector_all("#runs thead th", "els => els.map(e => e.innerText.trim())")
    assert {"in forecast %", "P10–P90 %", "Verified", "claimed %", "realised %"} <= set(header)
    verified = _q(demo_root, "SELECT count(*) FROM plan_verification")[0][0]  # one cycle: nothing to verify with
    column = header.index("Verified")
    cells = visit.page.eval_on_selector_all(f"#runs tbody tr td:nth-child({column + 1})", "els => els.map(e => e.innerText)")
    assert cells == ["–"] * len(runs) if verified == 0 else any(c != "–" for c in cells)
    assert len(visit.page.query_selector_all("#cycles tbody tr")) == _q(demo_root, "SELECT count(*) FROM cycles")[0][0]
    _shot(visit, shots, "runs")
