"""The console's web application: HTML pages (one shell, drawn by static/console.js), a JSON API over the data
root (storage/console_reads.py reads, pipeline/export/console_data.py shapes) and the route files to download.

Read-only: the warehouse's snapshot is opened read-only per request, the cube through its published view. With a
token every request must carry it (`Authorization: Bearer <token>`, or `?token=<token>` once: the console then sets
a cookie); without one the command binds only the loopback interface.
"""

from __future__ import annotations

import contextlib
import hmac
import json
import logging
import threading
from collections import OrderedDict
from datetime import UTC, datetime
from pathlib import Path

import duckdb
import pandas as pd
from starlette.applications import Starlette
from starlette.middleware import Middleware
from starlette.middleware.base import BaseHTTPMiddleware
from starlette.requests import Request
from starlette.responses import (
    PlainTextResponse,
    RedirectResponse,
    Response,
)
from starlette.routing import Mount, Route
from starlette.staticfiles import StaticFiles

from pipeline.export import console_data
from storage import console_reads
from storage.layout import DataLayout

log = logging.getLogger("jitroute.console")
STATIC = Path(__file__).resolve().parent / "static"
KEEP_READY_S = 5.0  # how often the fleet answer is checked against the snapshot and the minute
TOKEN_COOKIE = "jitroute_console_token"
PAGES = ("fleet", "voyage", "plan", "runs")
# the browser may load nothing from elsewhere: every script, style, picture and request comes from this server
SECURITY_HEADERS = {
    "Content-Security-Policy": "default-src 'self'; img-src 'self' data: blob:; style-src 'self'; script-src 'self'; "
                               "connect-src 'self'; frame-ancestors 'none'",
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
}


class ApiError(Exception):
    def __init__(self, status: int, message: str):
        super().__init__(message)
        self.status = status


def _json(data, status: int = 200) -> Response:
    body = json.dumps(data, allow_nan=False, separators=(",", ":"))
    return Response(body, status_code=status, media_type="application/json")


def _parse_utc(text: str | None, what: str) -> datetime | None:
    if not text:
        return None
    try:
        t = pd.Timestamp(text)
    except ValueError:
        raise ApiError(400, f"{what}={text!r} is not a time; give ISO 8601 UTC, e.g. 2020-12-01T12:00Z") from None
    if t.tzinfo is not None:
        t = t.tz_convert("UTC").tz_localize(None)
    return t.to_pydatetime()


def _extent(request: Request) -> dict:
    try:
        box = {k: float(request.query_params[k]) for k in ("west", "east", "south", "north")}
    except (KeyError, ValueError):
        raise ApiError(400, "give the map's box as west, east, south, north in degrees") from None
    if not (box["east"] > box["west"] and box["north"] > box["south"] and box["east"] - box["west"] <= 720):
        raise ApiError(400, f"box {box} is empty or too wide: east must exceed west, north south")
    return box


class AnswerCache:
    """The last few answers by key (the warehouse snapshot's version is part of a key, so a new snapshot is a new
    answer); safe across the server's threads."""

    def __init__(self, size: int = 8):
        self.size = size
        self._items: OrderedDict = OrderedDict()
        self._lock = threading.Lock()

    def get(self, key):
        with self._lock:
            if key in self._items:
                self._items.move_to_end(key)
                return self._items[key]
            return None

    def put(self, key, value) -> None:
        with self._lock:
            self._items[key] = value
            self._items.move_to_end(key)
            while len(self._items) > self.size:
                self._items.popitem(last=False)


class TokenMiddleware(BaseHTTPMiddleware):
    def __init__(self, app, token: str):
        super().__init__(app)
        self.token = token

    async def dispatch(self, request: Request, call_next):
        given = request.query_params.get("token") or request.cookies.get(TOKEN_COOKIE) or ""
        auth = request.headers.get("authorization", "")
        if auth.lower().startswith("bearer "):
            given = auth[7:].strip()
        if not hmac.compare_digest(given.encode(), self.token.encode()):
            return PlainTextResponse("this console needs its token: open it as http://<host>:<port>/fleet?token=<token> "
                                     "(the token given to `jitroute console --token`)", status_code=401)
        response = await call_next(request)
        if request.query_params.get("token"):
            response.set_cookie(TOKEN_COOKIE, self.token, httponly=True, samesite="strict")
        return response


class SecurityHeaders(BaseHTTPMiddleware):
    async def dispatch(self, request: Request, call_next):
        response = await call_next(request)
        response.headers.update(SECURITY_HEADERS)
        return response


def create_app(layout: DataLayout, token: str | None = None, now=None, prepare: bool = True) -> Starlette:
    """The console over `layout`'s data root. `now()` gives the current UTC time (naive), default the clock.
    `prepare`: while the server runs, a thread keeps the fleet page's answer made (see keep_ready)."""
    clock = now or (lambda: datetime.now(UTC).replace(tzinfo=None))

    def api(fn):
        def endpoint(request: Request):
            try:
                return fn(request)
            except ApiError as exc:
                return _json({"error": str(exc)}, exc.status)
            except console_reads.NoWarehouseError as exc:
                return _json({"error": str(exc)}, 503)
        endpoint.__name__ = fn.__name__
        return endpoint

    def shell(request: Request):
        return Response((STATIC / "index.html").read_text(), media_type="text/html")

    fleet_answers = AnswerCache()
    fleet_making = threading.Lock()

    def fleet_answer(at: datetime | None) -> bytes:
        """The fleet's JSON, from the cache while the warehouse snapshot (and, for positions shown now, the minute)
        is the same."""
        now = clock().replace(second=0, microsecond=0)  # positions to the minute: an answer serves a minute
        key = (console_reads.warehouse_version(layout), at)
        cached = fleet_answers.get(key)
        if cached is not None and (cached[1] is None or cached[1] == now):  # shown at now: this minute's only
            return cached[0]
        with fleet_making:  # one making at a time: a request arriving meanwhile takes that answer
            cached = fleet_answers.get(key)
            if cached is not None and (cached[1] is None or cached[1] == now):
                return cached[0]
            return make_fleet_answer(key, at, now)

    def make_fleet_answer(key, at: datetime | None, now: datetime) -> bytes:
        with console_reads.reader(layout) as con:
            run = console_reads.latest_run(con)
            routes = console_reads.latest_routes(con)
            as_of, note = console_data.as_of_time(now, run, at)
            legs = console_reads.legs_of_latest(con)
            reports = console_reads.reports_sailed(con, as_of)
        view = console_data.fleet_view(routes, legs, reports, as_of, note, run)
        view["weather"] = _weather_times(run, as_of)
        body = _json(view).body
        fleet_answers.put(key, (body, now if note == "now" else None))
        return body

    def fleet(request: Request):
        return Response(fleet_answer(_parse_utc(request.query_params.get("at"), "at")), media_type="application/json")

    def keep_ready(stop: threading.Event) -> None:
        """Keep the fleet page's answer made (at start, when the snapshot is replaced, each minute for positions shown
        now) and the land mask loaded, so an operator opening the console does not wait for them."""
        from pipeline.routing.land_mask import is_sea

        land_loaded = False
        while not stop.is_set():
            try:
                fleet_answer(None)
            except (console_reads.NoWarehouseError, OSError, duckdb.Error) as exc:
                log.debug("console: fleet answer not prepared (%s)", exc)
            if not land_loaded:  # after the fleet answer: a page asks for the land once it has the fleet
                is_sea(0.0, 0.0)
                land_loaded = True
            stop.wait(KEEP_READY_S)

    def _weather_times(run: dict | None, when) -> dict | None:
        cycle = (run or {}).get("cycle")
        if cycle is None or pd.isna(cycle):
            cycle = console_reads.newest_cycle(layout)
        if cycle is None:
            return None
        steps = console_reads.cube_steps(layout, cycle)
        if steps is None:
            return None
        return {"cycle": console_data.plain(pd.Timestamp(cycle)), "times": console_data.valid_times(cycle, steps),
                "default_step_h": console_data.nearest_step(cycle, steps, when)}

    def weather(request: Request):
        box = _extent(request)
        var = request.query_params.get("var", "wind")
        if var not in console_data.UNITS:
            raise ApiError(400, f"unknown weather variable {var!r}; use one of {', '.join(console_data.UNITS)}")
        cycle = _parse_utc(request.query_params.get("cycle"), "cycle")
        if cycle is None:
            raise ApiError(400, "give the cycle (its init time, ISO UTC)")
        try:
            step_h = int(request.query_params.get("step_h", "0"))
        except ValueError:
            raise ApiError(400, "step_h must be a whole number of hours") from None
        try:
            lat, lon, fields = console_reads.weather_step(layout, cycle, step_h, (box["south"], box["north"]),
                                                          (box["west"], box["east"]))
        except FileNotFoundError as exc:
            raise ApiError(404, str(exc)) from None
        except KeyError as exc:
            raise ApiError(404, str(exc).strip("'\"")) from None
        from pipeline.routing.land_mask import is_sea

        return _json(console_data.weather_layer(lat, lon, fields, var, cycle, step_h, box, is_sea=is_sea))

    land_pictures = AnswerCache()

    def land(request: Request):
        from pipeline.routing.land_mask import is_sea

        box = _extent(request)
        try:
            px = int(request.query_params.get("px", "800"))
        except ValueError:
            raise ApiError(400, "px must be a whole number of pixels") from None
        png = land_pictures.get((tuple(box.values()), px))
        if png is None:
            png = console_data.land_png(box, px, is_sea)
            land_pictures.put((tuple(box.values()), px), png)
        return Response(png, media_type="image/png", headers={"Cache-Control": "max-age=86400"})

    def _voyage_parts(voyage_id: str):
        with console_reads.reader(layout) as con:
            voyage = console_reads.voyage_row(con, voyage_id)
            if voyage is None:
                raise ApiError(404, f"no voyage {voyage_id!r} in the warehouse of {layout.root}")
            route = console_reads.latest_route_row(con, voyage_id)
            plans = console_reads.voyage_routes(con, voyage_id)
            has_plan = route is not None and route.get("status") in ("ok", "late")
            legs = console_reads.legs_of(con, route["run_id"], voyage_id) if has_plan else pd.DataFrame()
            earlier = [r for r, s in zip(plans["run_id"], plans["status"]) if s in ("ok", "late")
                       and (route is None or r != route["run_id"])]
            tracks = console_reads.track_of_plans(con, voyage_id, earlier[:5])
            actual = console_reads.voyage_actual(con, voyage_id)
            run = console_reads.latest_run(con)
        return voyage, route, legs, plans, tracks, actual, run

    def voyage(request: Request):
        voyage_id = request.path_params["voyage_id"]
        voyage, route, legs, plans, tracks, actual, run = _voyage_parts(voyage_id)
        view = console_data.voyage_view(voyage, route, legs, plans, tracks, actual, run)
        mid = None
        if view["times"]:
            t = pd.to_datetime([view["times"][0], view["times"][-1]])
            mid = (t[0] + (t[1] - t[0]) / 2).tz_localize(None).to_pydatetime()
        cycle_run = {"cycle": route.get("cycle")} if route is not None else run
        view["weather"] = _weather_times(cycle_run, mid)
        return _json(view)

    def download(request: Request):
        from pipeline.export.geojson import route_to_geojson
        from pipeline.export.paths import export_name
        from pipeline.export.rtz import route_to_rtz

        voyage_id, kind = request.path_params["voyage_id"], request.path_params["kind"]
        if kind not in ("rtz", "geojson"):
            raise ApiError(404, f"no {kind!r} download; use rtz or geojson")
        _voyage, route, legs, *_ = _voyage_parts(voyage_id)
        if legs.empty:
            raise ApiError(404, f"voyage {voyage_id!r} has no plan to download ({(route or {}).get('status')})")
        route = {k: (None if v is pd.NA else v) for k, v in route.items()}
        leg_rows = legs.to_dict("records")
        if kind == "rtz":
            body, media = route_to_rtz(route, leg_rows), "application/xml"
        else:
            body = json.dumps(route_to_geojson(route, leg_rows), allow_nan=False).encode()
            media = "application/geo+json"
        name = export_name(voyage_id, "." + kind)
        return Response(body, media_type=media, headers={"Content-Disposition": f'attachment; filename="{name}"'})

    def plan(request: Request):
        with console_reads.reader(layout) as con:
            parts = console_reads.active_fleet_plan(con)
        return _json(console_data.plan_view(*parts))

    def runs(request: Request):
        with console_reads.reader(layout) as con:
            view = console_data.runs_view(console_reads.runs_history(con), console_reads.cycles_status(con),
                                          console_reads.ingest_failures(con))
        view["data_root"] = str(layout.root)
        return _json(view)

    routes = [
        Route("/", lambda request: RedirectResponse("/fleet")),
        Route("/fleet", shell), Route("/plan", shell), Route("/runs", shell), Route("/voyage/{voyage_id:path}", shell),
        Route("/api/fleet", api(fleet)),
        Route("/api/weather", api(weather)),
        Route("/api/land.png", api(land)),
        Route("/api/plan", api(plan)),
        Route("/api/runs", api(runs)),
        Route("/api/voyage/{voyage_id}/route.{kind}", api(download)),
        Route("/api/voyage/{voyage_id}", api(voyage)),
        Mount("/static", StaticFiles(directory=STATIC), name="static"),
    ]
    middleware = [Middleware(SecurityHeaders)]
    if token:
        middleware.insert(0, Middleware(TokenMiddleware, token=token))
    @contextlib.asynccontextmanager
    async def lifespan(app):
        stop = threading.Event()
        if prepare:
            threading.Thread(target=keep_ready, args=(stop,), name="console-keep-ready", daemon=True).start()
        try:
            yield
        finally:
            stop.set()

    return Starlette(routes=routes, middleware=middleware, lifespan=lifespan)
