"""RTZ route files (IEC 61174 Annex S) for ECDIS exchange, and their validation against the XSD.

Layout of a written file (version 1.1 unless asked otherwise; 1.0 and 1.2 are also written):

- `routeInfo`: routeName (voyage id and ports, file-name safe; `rtz_file_name` gives the
  matching `<routeName>.rtz`), vesselName (IMO when the name is missing), vesselIMO,
  vesselVoyage, optimizationMethod (solver), routeStatus; voyage totals, the savings against the
  constant-speed baseline (total, speed profile, route) and what the engine-change limits cost in a jitroute
  extension.
- `waypoints`: ids 1..n+1 in order, positions to 6 decimals (longitude −180..<180). As RTZ
  keeps a leg's data on the waypoint the leg leads *to*, waypoint 1 has no `leg` and every later
  waypoint carries `geometryType="Orthodrome"` (our legs are great circles) and the leg's planned speed (SOG,
  knots) as both `speedMin` and `speedMax`.
- `schedules`: one calculated schedule. Waypoint 1 has the ETD; waypoint k > 1 has the ETA (and
  ETD when not last), the planned SOG of the leg leading to it as `speed`, its rpm rounded in
  `rpm`, leg fuel in tonnes, the wind/current met, and the unrounded rpm, STW, Hs… in a jitroute
  extension. Times are UTC to the second with a Z. RTZ 1.0 names the element `sheduleElement`
  and gives wind speed in m/s; its extensions hold our elements directly.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path

from lxml import etree

from pipeline.export.voyage import (finite_or_none, iso_utc, require_legs, vessel_label, voyage_id,
                                    waypoint_names, waypoints_deg)
from pipeline.routing.geodesy import KN_PER_MS
from pipeline.validate_ids import printable

RTZ_SCHEMA_DIR = Path(__file__).parent / "schemas"  # shipped as package data (CIRM RTZ 1.0-1.2)
RTZ_SCHEMA_ENV = "JITROUTE_RTZ_SCHEMAS"
JITROUTE_NS = "urn:jitroute:rtz-extension:1"
MANUFACTURER = "jitroute"


@dataclass(frozen=True)
class _Dialect:
    namespace: str
    schedule_element: str
    wind_per_kn: float  # multiply knots by this to get the version's wind-speed unit
    wrapped_extensions: bool  # 1.1+: extensions/extension[@manufacturer,@name]/<ours>


_DIALECTS = {
    "1.0": _Dialect("http://www.cirm.org/RTZ/1/0", "sheduleElement", 1.0 / KN_PER_MS, False),
    "1.1": _Dialect("http://www.cirm.org/RTZ/1/1", "scheduleElement", 1.0, True),
    "1.2": _Dialect("http://www.cirm.org/RTZ/1/2", "scheduleElement", 1.0, True),
}


def _dialect(version: str) -> _Dialect:
    if version not in _DIALECTS:
        raise ValueError(f"RTZ version {version!r} is not supported; use one of {', '.join(_DIALECTS)}")
    return _DIALECTS[version]


def route_name(route: dict) -> str:
    """`<voyage id>_<departure>-<arrival>`, reduced to characters safe in a file name."""
    def safe(s) -> str:
        return re.sub(r"[^A-Za-z0-9.]+", "_", str(s)).strip("_")

    ports = [safe(route[k]) for k in ("dep_name", "arr_name") if route.get(k)]
    return "_".join([safe(voyage_id(route))] + (["-".join(ports)] if ports else []))


def rtz_file_name(route: dict) -> str:
    """The file name ECDIS expects for this route: routeName plus `.rtz`."""
    return f"{route_name(route)}.rtz"


def _num(x, decimals: int) -> str | None:
    v = finite_or_none(x)
    return None if v is None else f"{v:.{decimals}f}"


def _speed(x, decimals: int = 2) -> str | None:
    v = finite_or_none(x)
    return None if v is None or v < 0 else f"{v:.{decimals}f}"


def _course(x) -> str | None:
    v = finite_or_none(x)
    if v is None:
        return None
    v = round(v % 360.0, 1)
    return f"{0.0 if v >= 360.0 else v:.1f}"


def _lon(x) -> str:
    v = round(float(x), 6)  # round first, so 179.9999996 becomes −180.000000, never 180.000000
    return f"{((v + 180.0) % 360.0) - 180.0:.6f}"


def _set(el, **attrs) -> None:
    for k, v in attrs.items():
        if v is not None:  # control characters (not allowed in XML) written as escapes, never failing the file
            el.set(k, printable(v))


def _extension(parent, d: _Dialect, name: str, **attrs) -> None:
    """Our values under `extensions`, in the jitroute namespace (where the schema allows it)."""
    exts = etree.SubElement(parent, f"{{{d.namespace}}}extensions")
    holder = exts
    if d.wrapped_extensions:
        holder = etree.SubElement(exts, f"{{{d.namespace}}}extension", manufacturer=MANUFACTURER, name=name,
                                  version="1")
    _set(etree.SubElement(holder, f"{{{JITROUTE_NS}}}{name}"), **attrs)


def route_to_rtz(route: dict, legs: list[dict], version: str = "1.1") -> bytes:
    """The voyage as an RTZ document (UTF-8 bytes with an XML declaration)."""
    require_legs(route, legs, "an RTZ route")
    d = _dialect(version)
    ns = d.namespace
    root = etree.Element(f"{{{ns}}}route", nsmap={None: ns, "jr": JITROUTE_NS}, version=version)

    info = etree.SubElement(root, f"{{{ns}}}routeInfo")
    imo = route.get("imo")
    _set(info, routeName=route_name(route), vesselName=vessel_label(route),
         vesselIMO=int(imo) if finite_or_none(imo) is not None and int(imo) >= 0 else None,
         vesselMMSI=int(route["mmsi"]) if finite_or_none(route.get("mmsi")) is not None else None,
         vesselVoyage=voyage_id(route), routeStatus=route.get("status"),
         optimizationMethod=f"jitroute {route['solver']}" if route.get("solver") else None)
    _extension(info, d, "voyage", status=route.get("status"), reason=route.get("reason"),
               departUtc=iso_utc(route.get("depart_utc")), etaUtc=iso_utc(route.get("eta_utc")),
               rtaUtc=iso_utc(route.get("rta_utc")), hours=_num(route.get("hours"), 3),
               fuelT=_num(route.get("fuel_t"), 3), baselineFuelT=_num(route.get("baseline_fuel_t"), 3),
               savingsPct=_num(route.get("savings_pct"), 2), distanceNm=_num(route.get("distance_nm"), 2),
               savingsTotalPct=_num(route.get("savings_total_pct"), 2),
               savingsSpeedProfilePct=_num(route.get("savings_speed_profile_pct"), 2),
               savingsRoutePct=_num(route.get("savings_route_pct"), 2),
               minEngineHoldH=_num(route.get("min_engine_hold_h"), 2), limitsFuelT=_num(route.get("limits_fuel_t"), 3))

    lat, lon = waypoints_deg(legs)
    names = waypoint_names(route, len(lat))
    wps = etree.SubElement(root, f"{{{ns}}}waypoints")
    for i, (la, lo, name) in enumerate(zip(lat, lon, names)):
        wp = etree.SubElement(wps, f"{{{ns}}}waypoint", id=str(i + 1), revision="0", name=printable(name))
        etree.SubElement(wp, f"{{{ns}}}position", lat=f"{la:.6f}", lon=_lon(lo))
        if i > 0:  # the planned speed of the leg as both its limits: the plan holds one speed per leg
            speed = _speed(legs[i - 1].get("sog_kn"))
            _set(etree.SubElement(wp, f"{{{ns}}}leg", geometryType="Orthodrome"), speedMin=speed, speedMax=speed)

    schedules = etree.SubElement(root, f"{{{ns}}}schedules")
    schedule = etree.SubElement(schedules, f"{{{ns}}}schedule", id="1",
                                name=f"jitroute {route.get('solver') or 'plan'}")
    calculated = etree.SubElement(schedule, f"{{{ns}}}calculated")
    for i in range(len(lat)):
        el = etree.SubElement(calculated, f"{{{ns}}}{d.schedule_element}", waypointId=str(i + 1))
        leg = legs[i - 1] if i > 0 else None  # the leg leading to this waypoint
        _set(el, eta=iso_utc(leg.get("eta_utc")) if leg else None,
             etd=iso_utc(legs[i].get("etd_utc")) if i < len(legs) else None)
        if leg is None:
            continue
        rpm = finite_or_none(leg.get("rpm"))
        wind = finite_or_none(leg.get("wind_kn"))
        _set(el, speed=_speed(leg.get("sog_kn")),
             rpm=round(rpm) if rpm is not None and rpm >= 0 else None, fuel=_num(leg.get("fuel_t"), 3),
             windSpeed=_speed(None if wind is None else wind * d.wind_per_kn, 1),
             windDirection=_course(leg.get("wind_dir_deg")), currentSpeed=_speed(leg.get("current_kn")))
        _extension(el, d, "leg", leg=leg.get("leg", i - 1), rpm=_num(rpm, 2), stwKn=_num(leg.get("stw_kn"), 3),
                   sogKn=_num(leg.get("sog_kn"), 3), distNm=_num(leg.get("dist_nm"), 3),
                   hours=_num(leg.get("hours"), 4), fuelT=_num(leg.get("fuel_t"), 4),
                   windKn=_num(wind, 2), hsM=_num(leg.get("hs_m"), 2), waveDirDeg=_course(leg.get("wave_dir_deg")),
                   beyondForecast=str(bool(leg.get("beyond_forecast"))).lower())
    return etree.tostring(root, xml_declaration=True, encoding="UTF-8", pretty_print=True)


def schema_dir() -> Path:
    """Where the rtz-<version>.xsd files are: $JITROUTE_RTZ_SCHEMAS, else RTZ_SCHEMA_DIR."""
    return Path(os.environ.get(RTZ_SCHEMA_ENV) or RTZ_SCHEMA_DIR)


def validate_rtz(xml_bytes: bytes, version: str = "1.1", schema_path: Path | None = None) -> None:
    """Raise ValueError listing every schema error (line: message) unless the document is valid RTZ.

    Also checks what the schema cannot: waypoint ids are unique and every schedule element
    refers to an existing waypoint.
    """
    d = _dialect(version)
    xsd = Path(schema_path) if schema_path else schema_dir() / f"rtz-{version}.xsd"
    if not xsd.is_file():
        raise FileNotFoundError(f"RTZ schema {xsd} not found; set {RTZ_SCHEMA_ENV} to the folder holding "
                                f"rtz-{version}.xsd")
    try:
        doc = etree.fromstring(xml_bytes, etree.XMLParser(resolve_entities=False, no_network=True))
    except etree.XMLSyntaxError as e:
        raise ValueError(f"RTZ document is not well-formed XML: {e}") from None
    name = doc.find(f"{{{d.namespace}}}routeInfo")
    label = f"RTZ route {name.get('routeName')!r}" if name is not None else "RTZ document"
    schema = etree.XMLSchema(etree.parse(str(xsd)))  # ~1 ms; not shared, as validators keep per-call state
    if not schema.validate(doc):
        errors = "; ".join(f"line {e.line}: {e.message}" for e in schema.error_log)
        raise ValueError(f"{label} is not valid against {xsd.name}: {errors}")
    ids = [w.get("id") for w in doc.iter(f"{{{d.namespace}}}waypoint")]
    dupes = sorted({i for i in ids if ids.count(i) > 1}, key=int)
    if dupes:
        raise ValueError(f"{label}: waypoint ids must be unique, repeated: {', '.join(dupes)}")
    unknown = sorted({e.get("waypointId") for e in doc.iter(f"{{{d.namespace}}}{d.schedule_element}")}
                     - set(ids), key=int)
    if unknown:
        raise ValueError(f"{label}: schedule refers to waypoint ids that do not exist: {', '.join(unknown)}")
