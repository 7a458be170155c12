"""How fast the console's fleet page loads as the fleet grows: 100 and 1,000 voyages (target: 1,000 in ≤ 2 s).

Set-up (not timed): a demo data root under bench/out/console/base — the generated mirror's 2020-12-01T00 cycle
ingested, a 12-vessel demo fleet imported, refitted and routed (`gc`) as `jitroute demo` does — then for each size a
copy of it with one more routing run of N voyages stored through the product's own writer
(route_store.begin_run / write_batch / finish_run): the demo's real plans repeated, each copy moved by up to ±1.6°
so the map is not one line drawn N times, with their voyages imported (fleet_store.import_voyages).

Timed, against `jitroute console --data <root>` started as a user starts it (a fresh server for each timing; the
server makes the fleet answer as it starts and keeps it until the warehouse snapshot changes):
- the fleet's data (`GET /api/fleet`): the first request, sent the moment the server listens (it waits for, or
  races, the server's own first answer: DuckDB, the cube and the land grid opened for the first time), and the
  median of 5 more (warm), with the answer's size;
- the whole page in headless Chromium (Debian's `/usr/bin/chromium` through Playwright; skipped when absent): from
  `goto /fleet` to every voyage drawn on the map, the voyages' table (its first 200 rows, those needing attention
  first; the rest on request) and the weather layer drawn, each time in a fresh browser context (no browser cache):
  the first load, sent the moment the server listens, and the median of 5 more.
It prints the figures per size, the ratio 1,000 / 100 and the 1,000-voyage page against the 2 s target.

    .venv/bin/python bench/console.py [--sizes 100,1000] [--repeat 5]
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
OUT = REPO / "bench" / "out" / "console"
CHROMIUM = Path("/usr/bin/chromium")
TARGET_S = 2.0


def base_root() -> Path:
    """The routed demo root every size starts from (made once, kept under bench/out/console/base)."""
    from cli.fleet import DEMO_AT_SEA, _import_fleet
    from flows.jobs.fleet import route_fleet_job
    from flows.jobs.ingest import ingest_cycle
    from flows.jobs.refit import refit_job
    from pipeline.synthetic.fleet import generate_fleet, write_fleet
    from pipeline.synthetic.mirror import write_mirror

    base = OUT / "base"
    root = base / "data"
    if (base / ".complete").exists():
        return root
    shutil.rmtree(base, ignore_errors=True)
    mirror = base / "mirror"
    write_mirror(mirror, "2020-12-01", "2020-12-01", cycles=(0,), seed=0)
    urls = {"rish_url": (mirror / "rish").as_uri() + "/", "oscar_url": (mirror / "oscar").as_uri() + "/"}
    assert ingest_cycle("2020-12-01T00", data_root=str(root), **urls)["complete"]
    write_fleet(generate_fleet("2020-12-01T00", n_vessels=12, days=120, seed=7, at_sea=DEMO_AT_SEA), base / "fleet")
    _import_fleet(base / "fleet", root)
    refit_job(data_root=str(root))
    os.environ["JITROUTE_DASK_WORKERS"] = "1"
    route_fleet_job(cycle="2020-12-01T00", data_root=str(root), solver="gc", exports=False, nominal_utc="2020-12-01T06")
    (base / ".complete").write_text("ok\n")
    return root


def sized_root(base: Path, n: int) -> Path:
    """A copy of the base root with a routing run of `n` voyages made of the base's plans."""
    import duckdb
    import pandas as pd

    from storage import fleet_store, route_store

    root = OUT / f"n{n}" / "data"
    shutil.rmtree(root.parent, ignore_errors=True)
    shutil.copytree(base, root)
    db = root / "warehouse.duckdb"
    with duckdb.connect(str(db), read_only=True) as con:
        routes = con.execute("SELECT * EXCLUDE (run_id) FROM routes WHERE status IN ('ok', 'late') ORDER BY voyage_id").fetchdf()
        legs = con.execute("SELECT l.* EXCLUDE (run_id) FROM route_legs l JOIN latest_routes r USING (run_id, voyage_id) "
                           "ORDER BY voyage_id, leg").fetchdf()
        voyages = con.execute("SELECT * FROM voyages").fetchdf().set_index("voyage_id")
        cycle = con.execute("SELECT cycle FROM route_runs").fetchone()[0]
    legs_of = {v: g for v, g in legs.groupby("voyage_id")}
    new_voyages, route_rows, leg_rows = [], [], []
    for i in range(n):
        src = routes.iloc[i % len(routes)]
        k = i // len(routes)
        dlat, dlon = 0.4 * ((k % 9) - 4), 0.4 * (((k // 9) % 9) - 4)
        vid = f"B{i:05d}"
        v = voyages.loc[src.voyage_id].copy()
        v["dep_lat"], v["dep_lon"], v["arr_lat"], v["arr_lon"] = (v["dep_lat"] + dlat, v["dep_lon"] + dlon,
                                                                  v["arr_lat"] + dlat, v["arr_lon"] + dlon)
        new_voyages.append({**v.to_dict(), "voyage_id": vid})
        route_rows.append({**{c: (None if _missing(x) else x) for c, x in src.items()}, "voyage_id": vid, "run_id": None,
                           "voyage_fingerprint": None})
        g = legs_of[src.voyage_id].copy()
        g["voyage_id"] = vid
        for c in ("lat0", "lat1"):
            g[c] = g[c] + dlat
        for c in ("lon0", "lon1"):
            g[c] = g[c] + dlon
        leg_rows += [{**{c: (None if _missing(x) else x) for c, x in r.items()}, "run_id": None}
                     for r in g.to_dict("records")]
    vdf = pd.DataFrame(new_voyages)
    vdf["rpm_options"] = [list(map(float, r)) if r is not None and not _missing(r) else None for r in vdf["rpm_options"]]
    fleet_store.import_voyages(db, vdf)
    run_id = f"bench-{n}"
    route_store.begin_run(db, run_id, cycle=cycle, solver="gc", trigger="manual", n_voyages=n,
                          nominal_utc="2020-12-01T06", cycle_age_h=6.0)
    per_voyage = {}
    for r in leg_rows:
        per_voyage.setdefault(r["voyage_id"], []).append(r)
    for b in range(0, n, 200):
        batch = route_rows[b:b + 200]
        route_store.write_batch(db, root / "exports", run_id, batch, [leg for r in batch for leg in per_voyage[r["voyage_id"]]])
    route_store.finish_run(db, root / "exports", run_id)
    with duckdb.connect(str(root / "warehouse.snapshot.duckdb"), read_only=True) as con:
        got = con.execute("SELECT count(*), sum(n_legs) FROM latest_routes WHERE run_id = $1", [run_id]).fetchone()
        n_legs = con.execute("SELECT count(*) FROM route_legs WHERE run_id = $1", [run_id]).fetchone()[0]
    assert got[0] == n and n_legs == got[1], (got, n_legs)
    return root


def _missing(x) -> bool:
    try:
        return x is None or bool(x != x)
    except (TypeError, ValueError):  # a list (rpm options)
        return False


def serve(root: Path):
    import socket
    import subprocess

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    log = open(root.parent / "console.log", "w")
    proc = subprocess.Popen([str(Path(sys.executable).parent / "jitroute"), "console", "--data", str(root), "--port",
                             str(port)], stdout=log, stderr=subprocess.STDOUT, env={**os.environ, "PYTHONPATH": str(REPO)})
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return proc, f"http://127.0.0.1:{port}"
        assert proc.poll() is None, (root.parent / "console.log").read_text()
        time.sleep(0.1)
    raise RuntimeError("the console did not start")


def time_api(url: str, repeat: int) -> dict:
    import httpx

    times = []
    for _ in range(repeat + 1):
        t0 = time.perf_counter()
        r = httpx.get(url + "/api/fleet", timeout=60)
        times.append(time.perf_counter() - t0)
        assert r.status_code == 200, r.text
    return {"api_cold_s": times[0], "api_warm_s": statistics.median(times[1:]), "api_kb": len(r.content) / 1024,
            "n_voyages": len(r.json()["voyages"])}


def time_page(root: Path, repeat: int, n: int) -> dict:
    """The page in a browser launched before the server starts: the first load goes out the moment the server
    listens (its own preparation of the fleet answer still running: the worst an operator meets), then `repeat`
    more, each in a fresh browser context."""
    if not CHROMIUM.exists():
        return {}
    from playwright.sync_api import sync_playwright

    times = []
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=["--no-sandbox", "--disable-dev-shm-usage"])
        proc, url = serve(root)
        try:
            for _ in range(repeat + 1):
                ctx = browser.new_context(viewport={"width": 1400, "height": 1000})
                page = ctx.new_page()
                t0 = time.perf_counter()
                page.goto(url + "/fleet")
                page.wait_for_selector("body[data-ready]", timeout=60_000)
                page.wait_for_selector("#map .layer-weather[data-valid] image", timeout=60_000)
                times.append(time.perf_counter() - t0)
                drawn = page.eval_on_selector_all("#map circle.ship, #map circle.voyage-start", "els => els.length")
                rows = page.eval_on_selector_all("#voyages tbody tr", "els => els.length")
                assert rows == min(n, 200) and drawn == n, (rows, drawn)  # the table shows 200 until asked
                if len(times) == 1:
                    page.screenshot(path=str(OUT / f"fleet_{n}.png"))
                ctx.close()
        finally:
            browser.close()
            proc.terminate()
            proc.wait(timeout=30)
    return {"page_cold_s": times[0], "page_warm_s": statistics.median(times[1:])}


def main() -> None:
    import duckdb

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="100,1000")
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    sizes = [int(x) for x in args.sizes.split(",")]
    OUT.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    base = base_root()
    print(f"set-up: base demo root {time.perf_counter() - t0:.0f} s ({base})")
    results = {}
    for n in sizes:
        t0 = time.perf_counter()
        root = sized_root(base, n)
        print(f"set-up: {n} voyages stored in {time.perf_counter() - t0:.0f} s")
        with duckdb.connect(str(root / "warehouse.snapshot.duckdb"), read_only=True) as con:
            shown = con.execute("SELECT count(*) FROM latest_routes").fetchone()[0]  # n and the base's own (a dozen)
        results[n] = time_page(root, args.repeat, shown)
        proc, url = serve(root)  # a fresh server: the first request races its own preparation
        try:
            results[n].update(time_api(url, args.repeat))
        finally:
            proc.terminate()
            proc.wait(timeout=30)
    load = os.getloadavg()
    print(f"\nfleet page, {os.cpu_count()} CPUs, load average {load[0]:.1f} / {load[1]:.1f} (1 / 5 min); "
          f"warm = median of {args.repeat}, each page in a fresh browser context")
    print(f"{'voyages':>8} {'shown':>6} {'api cold s':>11} {'api warm s':>11} {'api KB':>8} "
          f"{'page cold s':>12} {'page warm s':>12}")
    for n, r in results.items():
        page = (f"{r['page_cold_s']:>12.2f} {r['page_warm_s']:>12.2f}" if "page_cold_s" in r
                else f"{'no chromium':>12} {'':>12}")
        print(f"{n:>8} {r['n_voyages']:>6} {r['api_cold_s']:>11.2f} {r['api_warm_s']:>11.2f} {r['api_kb']:>8.0f} {page}")
    if len(results) >= 2:
        lo, hi = min(results), max(results)
        key = "page_warm_s" if "page_warm_s" in results[hi] else "api_warm_s"
        print(f"ratio {hi} / {lo} voyages ({key}): {results[hi][key] / results[lo][key]:.2f}x")
    big = results[max(results)]
    if "page_cold_s" in big:
        worst = max(big["page_cold_s"], big["page_warm_s"])
        print(f"{max(results)} voyages: page {worst:.2f} s at worst (cold or warm) = {worst / TARGET_S:.2f} of the "
              f"{TARGET_S:.0f} s target: {'met' if worst <= TARGET_S else 'MISSED'}")


if __name__ == "__main__":
    main()
