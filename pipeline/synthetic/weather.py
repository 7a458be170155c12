"""Analytic, physically plausible weather for demo data and tests.

Every field is a closed-form function of (valid time, lat, lon) so tests can compare decoded,
regridded and sampled values against the truth at any point:
- wind: easterly trades (|lat| < 30), westerlies (30..60), plus a cyclonic mid-latitude storm
  that travels east across the North Pacific (or, `track="south-indian"`, one that travels east across the
  southern Indian Ocean, turning clockwise as a southern-hemisphere cyclone does);
- waves: significant wave height from the local wind (fully developed sea, capped), coming from
  where the wind comes from, period from height;
- currents: a Kuroshio-like western-boundary jet off Japan, a weak equatorial counter-current.

Units: wind and currents m/s (u east, v north; currents are going-to), swh m, mwd degrees
coming-from, mwp s. `t_h` is hours since `EPOCH`.
"""

from __future__ import annotations

import numpy as np

EPOCH = np.datetime64("2020-01-01T00:00", "ns")


def hours_since_epoch(t) -> np.ndarray:
    return (np.asarray(t, dtype="datetime64[ns]") - EPOCH) / np.timedelta64(1, "h")


def _wrap_dlon(dlon):
    return (np.asarray(dlon) + 180.0) % 360.0 - 180.0


# storm track → (hemisphere: +1 north, −1 south; first longitude east; first latitude from the equator)
STORM_TRACKS = {"north-pacific": (1.0, 140.0, 38.0),  # leaves Japan
                "south-indian": (-1.0, 10.0, 40.0)}  # leaves the Cape of Good Hope's longitudes


def storm_centre(t_h, seed: int = 0, track: str = "north-pacific"):
    """Storm centre (lat, lon east 0..360): starts where its track (STORM_TRACKS) begins, moves east ~25 kn, with a
    slow wobble."""
    hemisphere, first_lon, first_lat = STORM_TRACKS[track]
    rng = np.random.default_rng(seed)
    lon0 = first_lon + 5.0 * rng.random()
    lat0 = hemisphere * (first_lat + 4.0 * rng.random())
    period_h = 24.0 * 12.0  # a new storm leaves every 12 days
    phase = np.mod(np.asarray(t_h, dtype=float), period_h)
    lon = (lon0 + 0.6 * phase) % 360.0
    lat = lat0 + hemisphere * 4.0 * np.sin(phase / 48.0)
    return lat, lon


def wind_uv(t_h, lat, lon, seed: int = 0, track: str = "north-pacific"):
    """10 m wind (u, v) in m/s, the storm on `track` (STORM_TRACKS)."""
    lat = np.asarray(lat, dtype=float)
    lon = np.asarray(lon, dtype=float)
    t_h = np.asarray(t_h, dtype=float)
    # zonal background: trades (from the east) and westerlies
    u = -7.0 * np.cos(np.radians(lat) * 3.0) * (np.abs(lat) < 30) + 10.0 * np.sin(np.radians(np.abs(lat) - 30.0) * 6.0) * (
        (np.abs(lat) >= 30) & (np.abs(lat) <= 60)
    )
    v = 2.0 * np.sin(np.radians(lon) * 2.0 + t_h / 24.0) * np.cos(np.radians(lat))
    # cyclonic storm (counter-clockwise in the northern hemisphere, clockwise in the southern)
    hemisphere = STORM_TRACKS[track][0]
    clat, clon = storm_centre(t_h, seed, track)
    dy = (lat - clat) * 60.0  # NM
    dx = _wrap_dlon(lon - clon) * 60.0 * np.cos(np.radians(lat))
    r = np.hypot(dx, dy)
    r_max = 150.0
    speed = 22.0 * (r / r_max) * np.exp(1.0 - r / r_max)
    with np.errstate(invalid="ignore", divide="ignore"):
        ux = np.where(r > 0, -hemisphere * dy / r, 0.0)
        vy = np.where(r > 0, hemisphere * dx / r, 0.0)
    return u + speed * ux, v + speed * vy


def wind_dir_from_deg(u, v):
    """Meteorological direction the wind comes FROM, degrees clockwise from north."""
    return (np.degrees(np.arctan2(-np.asarray(u), -np.asarray(v))) + 360.0) % 360.0


def waves(t_h, lat, lon, seed: int = 0, track: str = "north-pacific"):
    """(swh_m, mwd_deg_from, mwp_s) consistent with the local wind."""
    u, v = wind_uv(t_h, lat, lon, seed, track)
    w = np.hypot(u, v)
    swh = np.minimum(0.5 + 0.022 * w**2, 14.0)
    mwd = wind_dir_from_deg(u, v)
    mwp = 3.5 * np.sqrt(swh) + 2.0
    return swh, mwd, mwp


def currents_uv(t_h, lat, lon):
    """Surface current (u, v) in m/s, going-to. Slowly varying in time."""
    lat = np.asarray(lat, dtype=float)
    lon = np.asarray(lon, dtype=float)
    t_h = np.asarray(t_h, dtype=float)
    # Kuroshio-like jet: flows north-east along Japan's south coast, ~1.5 m/s core
    axis_lat = 30.0 + 0.5 * (lon - 130.0)
    d = lat - axis_lat
    band = np.exp(-(d / 1.2) ** 2) * ((lon > 122.0) & (lon < 150.0))
    core = 1.5 * (1.0 + 0.1 * np.sin(t_h / 240.0))
    u = core * band * np.cos(np.radians(27.0))
    v = core * band * np.sin(np.radians(27.0))
    # equatorial counter-current, eastward at ~6N
    u = u + 0.4 * np.exp(-((lat - 6.0) / 2.0) ** 2)
    return u, v
