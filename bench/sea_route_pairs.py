"""The sea-route bench's port pairs: each port as a position at sea near its pilot station or anchorage, the pairs
(with the passages searoute avoids, so the product is compared avoiding the same), the land clearance they are
routed with, and the key a pair is named by (bench/sea_routes.py, sea_routes_reference.py, sea_routes_map.py)."""

from __future__ import annotations

CLEARANCE_NM = 2.0

# (lat, lon) at sea, at or just off the pilot station / outer anchorage
PORTS = {
    "Shanghai": (31.0, 122.7), "Ningbo": (29.95, 122.55), "Qingdao": (35.95, 120.45), "Busan": (35.0, 129.1),
    "Tokyo Bay": (35.2, 139.8), "Nagoya": (34.55, 136.85), "Hong Kong": (22.1, 114.25), "Kaohsiung": (22.55, 120.2),
    "Manila": (14.33, 120.55), "Singapore": (1.15, 103.75), "Port Klang": (2.95, 101.2), "Jakarta": (-6.0, 106.85),
    "Colombo": (6.95, 79.8), "Mumbai": (18.85, 72.75), "Jebel Ali": (25.1, 54.9), "Jeddah": (21.45, 39.05),
    "Port Said": (31.4, 32.35), "Piraeus": (37.9, 23.55), "Istanbul": (40.96, 28.9), "Constanta": (44.1, 28.8),
    "Genoa": (44.35, 8.9), "Algeciras": (36.1, -5.35), "Valencia": (39.4, -0.25), "Marseille": (43.25, 5.25),
    "Naples": (40.75, 14.25), "Rotterdam": (52.0, 3.7), "Antwerp": (51.4, 3.05), "Hamburg": (54.0, 8.1),
    "Gdansk": (54.5, 18.8), "Gothenburg": (57.6, 11.6), "Le Havre": (49.55, 0.0), "Lisbon": (38.6, -9.3),
    "Dakar": (14.65, -17.45), "Lagos": (6.35, 3.35), "Cape Town": (-33.9, 18.35), "Durban": (-29.9, 31.1),
    "Mombasa": (-4.1, 39.75), "Santos": (-24.05, -46.3), "Rio de Janeiro": (-23.05, -43.15),
    "Buenos Aires": (-35.15, -56.25), "Valparaiso": (-33.0, -71.7), "Callao": (-12.05, -77.25),
    "Balboa": (8.85, -79.5), "Colon": (9.42, -79.93), "Kingston": (17.9, -76.8), "Houston": (29.3, -94.65),
    "New Orleans": (28.9, -89.45), "Miami": (25.75, -80.05), "New York": (40.45, -73.8), "Halifax": (44.5, -63.5),
    "Los Angeles": (33.65, -118.3), "Vancouver": (48.45, -124.8), "Honolulu": (21.25, -157.9), "Guam": (13.45, 144.6),
    "Sydney": (-33.85, 151.35), "Melbourne": (-38.4, 144.6), "Brisbane": (-27.2, 153.3),
    "Port Hedland": (-20.0, 118.55), "Auckland": (-36.6, 174.9), "Davao": (6.8, 125.75), "Cebu": (10.2, 123.85),
}

# (from, to, passages searoute cannot take: the product is compared avoiding them too)
PAIRS = [
    ("Shanghai", "Rotterdam", ()), ("Singapore", "Rotterdam", ()), ("Singapore", "Piraeus", ()),
    ("Mumbai", "Genoa", ()), ("Jeddah", "Rotterdam", ()), ("Jebel Ali", "Rotterdam", ()), ("Colombo", "Marseille", ()),
    ("Hong Kong", "Algeciras", ()), ("Port Said", "Singapore", ()),
    ("New York", "Los Angeles", ()), ("Houston", "Tokyo Bay", ()), ("Rotterdam", "Callao", ()),
    ("New Orleans", "Valparaiso", ()), ("Colon", "Balboa", ()), ("Miami", "Vancouver", ()), ("Kingston", "Honolulu", ()),
    ("Hamburg", "Gdansk", ("kiel",)), ("Rotterdam", "Gdansk", ("kiel",)), ("Antwerp", "Gothenburg", ()),
    ("Singapore", "Shanghai", ()), ("Port Klang", "Hong Kong", ()), ("Singapore", "Los Angeles", ()),
    ("Colombo", "Singapore", ()), ("Jakarta", "Singapore", ()), ("Port Klang", "Jebel Ali", ()),
    ("Piraeus", "Constanta", ()), ("Istanbul", "Genoa", ()), ("Rotterdam", "Piraeus", ()), ("Rotterdam", "Algeciras", ()),
    ("Algeciras", "Piraeus", ()), ("Genoa", "Piraeus", ()), ("Le Havre", "Valencia", ()), ("Naples", "Piraeus", ()),
    ("Marseille", "Port Said", ()), ("Lisbon", "Rotterdam", ()),
    ("Brisbane", "Singapore", ()), ("Sydney", "Port Hedland", ()), ("Port Hedland", "Qingdao", ()),
    ("Melbourne", "Auckland", ()),
    ("Manila", "Guam", ()), ("Hong Kong", "Manila", ()), ("Singapore", "Manila", ()), ("Manila", "Cebu", ()),
    ("Davao", "Hong Kong", ()), ("Busan", "Tokyo Bay", ()), ("Busan", "Nagoya", ()), ("Qingdao", "Tokyo Bay", ()),
    ("Hong Kong", "Qingdao", ()), ("Kaohsiung", "Ningbo", ()), ("Guam", "Manila", ()),
    ("Tokyo Bay", "Los Angeles", ()), ("Shanghai", "Vancouver", ()), ("Busan", "Vancouver", ()),
    ("Sydney", "Los Angeles", ()), ("Auckland", "Honolulu", ()), ("Valparaiso", "Sydney", ()),
    ("Cape Town", "Rotterdam", ()), ("Durban", "Singapore", ()), ("Mombasa", "Mumbai", ()), ("Santos", "Rotterdam", ()),
    ("Rio de Janeiro", "Lagos", ()), ("Buenos Aires", "Cape Town", ()), ("Dakar", "New York", ()),
    ("Halifax", "Rotterdam", ()), ("New York", "Rotterdam", ()), ("Santos", "Shanghai", ()),
    ("Shanghai", "Rotterdam", ("suez",)), ("Singapore", "Rotterdam", ("suez", "panama")),
]


def key(a, b, avoid) -> str:
    return f"{a} - {b}" + (f" (avoid {'+'.join(avoid)})" if avoid else "")
