"""A hole in the wind is never passed off as calm weather: the legs sailed through it are counted and the plan
says so (`forecast_flag` 'weather missing', the reason naming the legs); a field without holes gives no flag."""

from __future__ import annotations

import numpy as np

from pipeline.performance.model import reference_model
from pipeline.routing import weather_field as wf
from pipeline.routing.solve import RoutingProblem
from routing_cases import solve

MODEL = reference_model(14.0, 100.0, 1.5)


def _problem():
    return RoutingProblem(dep=(34.85, 139.85), arr=(30.0, 147.0), depart_utc="2020-12-01T06", rta_utc="2020-12-03T06",
                          model=MODEL, rpm_options=(70, 85, 100), n_lines=6, n_points=7, voyage_id="VHOLE")


def _field(hole: bool):
    lat = np.arange(20.0, 45.01, 0.5)
    lon = np.arange(130.0, 160.01, 0.5)
    times = np.datetime64("2020-12-01T00") + np.arange(0, 120, 6).astype("timedelta64[h]")
    shape = (len(times), len(lat), len(lon))
    u = np.full(shape, 8.0)
    if hole:  # the wind missing at every lead over 31..34N 141..145E, across the route
        u[:, ((lat >= 31) & (lat <= 34))[:, None] & ((lon >= 141) & (lon <= 145))[None, :]] = np.nan
    return wf.from_arrays(lat, lon, times, u10=u, v10=np.zeros(shape), swh=np.full(shape, 1.0),
                          mwd_deg=np.full(shape, 90.0), uo=np.zeros(shape), vo=np.zeros(shape))


def test_a_route_through_a_hole_in_the_wind_is_flagged_with_its_legs():
    plan = solve(_problem(), _field(hole=True), solver="gc", seed=1)
    assert plan.status == "ok", plan.reason
    holed = [leg for leg in plan.legs if leg["hours_without_wind"] > 0]
    assert holed, [(leg["lat0"], leg["lon0"]) for leg in plan.legs]
    assert "weather missing" in plan.forecast_flag
    legs = ", ".join(str(leg["leg"]) for leg in holed)
    hours = sum(leg["hours_without_wind"] for leg in holed)
    assert f"no wind data for {hours:.1f} h on leg{'s' if len(holed) != 1 else ''} {legs}" in plan.reason
    assert plan.route_row()["forecast_flag"] == plan.forecast_flag


def test_the_same_route_without_the_hole_has_no_flag():
    plan = solve(_problem(), _field(hole=False), solver="gc", seed=1)
    assert plan.status == "ok"
    assert all(leg["hours_without_wind"] == 0.0 for leg in plan.legs)
    assert plan.forecast_flag is None and "weather missing" not in (plan.reason or "")
