"""Passages: the canals and narrow straits a sea route may sail through, each a fixed fairway.

A `Passage` is sailed along its fairway polyline, nothing else: the global sea-route layer (global_routes.py) joins
the fairway's two ends to its open-water graph, and a route that uses the passage keeps every fairway vertex as a
waypoint (the corridor along the route holds them as fixed gates). Inside a fairway the route is not held to the
voyage's land clearance but to the passage's own `clearance_nm` (None: the mask closes it, as for the canals, which
are land on the mask, and the Bosporus, narrower than its cells; such a fairway is drawn from charts and not checked).
A `gate` is a line from coast to coast across a strait the open-water graph could otherwise sail through (Dover,
Gibraltar): no leg outside the fairway may cross it, so every route through the strait is reported as using it and
`avoid` closes it.

Canals carry a transit time (`transit_h`, the fairway sailed at the canal's speed, locks and convoys included) and a
waiting allowance (`wait_h`) that the planner adds to a voyage through them; straits have neither (sailed at the
plan's own speed). Sources of the canal figures:
- Suez: 193 km (104 NM) from Port Said to Port Tewfik, transit 11–16 h in convoy (Suez Canal Authority, "Navigation
  rules" and transit statistics); 14 h taken, plus 12 h waiting for the daily convoy on average.
- Panama: 80 km (44 NM) from Cristóbal to Balboa, 8–10 h through the locks (Panama Canal Authority); 10 h taken,
  plus 24 h waiting without a booked slot (ACP "Canal Waters Time" runs about one day for unbooked ships).
- Corinth: 6.4 km, about 1 h through with a tug, one way at a time (Corinth Canal S.A.); 2 h waiting taken.
- Kiel: 98 km (53 NM) from Brunsbüttel to Kiel-Holtenau, about 7–9 h including the locks (WSA Nord-Ostsee-Kanal);
  8 h taken, plus 2 h at the locks.
Fairway coordinates: canals and the Bosporus drawn from the charts' channel axis, the Kanmon Strait (closed on the
mask) from Eurostat's marine network (as the `searoute` package ships it), the Inland Sea beyond it at 0.2 NM on the
mask; the straits' fairways are the
shortest path at their clearance on the product's land mask (fine-grid search, then string-pulled), which lies along
the traffic separation schemes within a mile or two.

Traffic separation schemes (kind "tss") off a headland where the open-water graph would round it 2 NM off, inside the
scheme's inshore traffic zone, which through traffic must leave alone (COLREG rule 10(d)): each scheme is two
one-way lanes (`one_way`: sailed only in the fairway's order, the lane's direction of traffic) and a gate from the
land out across the inshore zone and both lanes, so a route round the headland either sails the lane for its
direction or passes outside the whole scheme. A scheme is compulsory: `avoid` refuses its names (`check_avoid`).
The lanes' positions are approximate, taken from the schemes' charts as adopted by IMO (Off Ushant 2003, Off
Casquets, Off Finisterre 2004, Off Cabo de São Vicente 2005) and stated in round figures: the centre of each lane within about
3 NM, the distance off the headland (what sets the route's length) within about 2 NM. They are not for navigation.
The Strait of Dover's scheme is the `dover` strait's fairway and gate above.

Areas to avoid (`AREAS_TO_AVOID`): water the mask holds as sea that a route keeps out of, each an outline whose sides
are gates, with its source named: the Jiangsu shoals (the mask has no depths) and the Berlengas. Not avoidable.
"""

from __future__ import annotations

from dataclasses import dataclass


def _chain(*points: tuple[float, float]) -> tuple[tuple[tuple[float, float], tuple[float, float]], ...]:
    """The gate lines along a polyline of (lat, lon) points: a closed outline of a traffic separation scheme."""
    return tuple(zip(points[:-1], points[1:]))


@dataclass(frozen=True)
class Passage:
    name: str  # the `avoid` name, lower case
    kind: str  # "canal" | "strait" | "tss" (a traffic separation scheme's lane: compulsory, one way)
    fairway: tuple[tuple[float, float], ...]  # (lat, lon) degrees, in either direction of travel
    clearance_nm: float | None  # clearance inside the fairway; None: closed on the mask, drawn from charts
    transit_h: float | None = None  # canals: time to sail the fairway
    wait_h: float = 0.0  # canals: waiting allowance before the transit
    gates: tuple[tuple[tuple[float, float], tuple[float, float]], ...] = ()  # coast-to-coast lines, (lat, lon) ends
    title: str = ""
    one_way: bool = False  # a traffic lane: sailed only from the fairway's first vertex to its last


PASSAGES: tuple[Passage, ...] = (
    Passage("suez", "canal", (
        (31.45, 32.36), (31.3, 32.33), (31.23, 32.31), (30.85, 32.32), (30.6, 32.3), (30.55, 32.31),
        (30.42, 32.35), (30.33, 32.39), (30.22, 32.46), (30.12, 32.55), (29.95, 32.57), (29.9, 32.56),
        (29.78, 32.56),
    ), None, transit_h=14.0, wait_h=12.0,
            title="Suez Canal"),
    Passage("panama", "canal", (
        (9.42, -79.91), (9.35, -79.92), (9.27, -79.92), (9.22, -79.88), (9.15, -79.83), (9.12, -79.74),
        (9.1, -79.69), (9.05, -79.67), (9.02, -79.62), (9.0, -79.6), (8.95, -79.57), (8.88, -79.53), (8.83, -79.5),
    ), None, transit_h=10.0, wait_h=24.0,
            title="Panama Canal"),
    Passage("kiel", "canal", (
        (54.02, 8.2), (53.93, 8.55), (53.89, 8.75), (53.88, 9.0), (53.89, 9.14), (54.0, 9.3), (54.1, 9.45),
        (54.3, 9.67), (54.33, 9.85), (54.36, 10.05), (54.37, 10.15), (54.43, 10.19), (54.52, 10.28),
    ), None, transit_h=8.0, wait_h=2.0,
            title="Kiel Canal (Nord-Ostsee-Kanal), with the Elbe approach"),
    Passage("corinth", "canal", (
        (38.02, 22.86), (37.97, 22.92), (37.94, 22.955), (37.915, 23.01), (37.905, 23.03), (37.87, 23.06),
        (37.85, 23.25),
    ), None, transit_h=1.0, wait_h=2.0,
            title="Corinth Canal (beam under about 17 m)"),
    Passage("rion", "strait", (
        (37.95, 20.55), (38.055, 20.82), (38.08, 20.83), (38.1, 20.84), (38.22, 20.95), (38.25, 21.45),
        (38.295, 21.525), (38.305, 21.545), (38.32, 21.575), (38.33, 21.78), (38.345, 21.845), (38.345, 22.155),
        (38.2, 22.3),
    ), 0.2,
            title="Rion–Antirrion Strait (from between Zakynthos and Kefalonia through the Gulf of Patras to "
                  "the Gulf of Corinth)"),
    Passage("gibraltar", "strait", (
        (35.93, -6.1), (35.98, -5.56), (36.04, -5.41), (36.05, -5.15),
    ), 1.0, gates=(((36.2, -5.6), (35.7, -5.6)),),
            title="Strait of Gibraltar"),
    Passage("dover", "strait", (
        (50.75, 1.15), (51.25, 1.85),
    ), 1.0, gates=(((51.13, 1.33), (50.88, 1.58)),),
            title="Strait of Dover"),
    Passage("messina", "strait", (
        (38.35, 15.55), (38.275, 15.665), (38.26, 15.665), (38.255, 15.66), (38.235, 15.62), (38.185, 15.59),
        (38.18, 15.585), (38.175, 15.58), (38.15, 15.56), (37.95, 15.55),
    ), 0.1,
            title="Strait of Messina"),
    Passage("dardanelles", "strait", (
        (39.95, 26.05), (40.045, 26.235), (40.05, 26.24), (40.06, 26.26), (40.07, 26.28), (40.08, 26.3),
        (40.085, 26.31), (40.105, 26.34), (40.135, 26.385), (40.14, 26.39), (40.2, 26.4), (40.215, 26.415),
        (40.22, 26.43), (40.225, 26.45), (40.24, 26.475), (40.31, 26.58), (40.32, 26.595), (40.35, 26.635),
        (40.495, 26.82), (40.505, 26.85), (40.51, 26.87), (40.52, 26.885), (40.525, 26.89), (40.545, 26.955),
        (40.55, 26.995), (40.58, 27.03), (40.605, 27.075), (40.61, 27.135), (40.62, 27.17), (40.63, 27.19),
        (40.64, 27.2),
    ), 0.2,
            title="Dardanelles"),
    Passage("bosporus", "strait", (
        (40.96, 28.98), (41.0, 29.0), (41.03, 29.01), (41.07, 29.05), (41.11, 29.06), (41.15, 29.08),
        (41.2, 29.11), (41.27, 29.15),
    ), None,
            title="Bosporus"),
    Passage("singapore", "strait", (
        (1.9, 102.3), (1.83, 102.77), (1.28, 103.41), (1.24, 103.55), (1.14, 103.74), (1.23, 103.91),
        (1.33, 104.25), (1.35, 104.34), (1.45, 104.7),
    ), 0.5,
            title="Singapore Strait and southern Malacca Strait"),
    Passage("bab_el_mandeb", "strait", (
        (13.0, 43.0), (12.6, 43.41), (12.3, 43.9),
    ), 1.0,
            title="Bab-el-Mandeb (the channel east of Perim)"),
    Passage("great_belt", "strait", (
        (57.31, 10.9), (57.25, 10.84), (56.42, 10.98), (56.29, 10.91), (55.72, 10.87), (55.12, 10.98),
        (54.8, 10.93), (54.6, 11.0),
    ), 0.5,
            title="Kattegat and the Great Belt (route T)"),
    Passage("san_bernardino", "strait", (
        (12.45, 123.95), (12.51, 124.11), (12.75, 124.385), (12.75, 124.55),
    ), 0.4,
            title="San Bernardino Strait (Sibuyan and Samar Seas to the Pacific)"),
    Passage("verde_island", "strait", (
        (13.65, 120.6), (13.615, 120.895), (13.605, 121.16), (13.58, 121.27), (13.45, 121.5),
    ), 0.5,
            title="Verde Island Passage (Manila to the Sibuyan Sea)"),
    Passage("visayan", "strait", (
        (13.45, 121.5), (13.265, 121.875), (13.255, 121.895), (12.035, 123.12), (11.935, 123.125), (11.91, 123.14),
        (11.89, 123.155), (11.295, 124.07), (11.24, 124.1), (10.45, 124.1), (10.26, 124.085), (10.225, 124.065),
        (10.22, 124.05), (10.225, 124.045), (10.225, 123.875),
    ), 0.4,
            title="Sibuyan and Visayan Seas, the Camotes Sea round Mactan (the Verde Island Passage to Cebu)"),
    Passage("surigao", "strait", (
        (9.85, 125.35), (10.6, 125.45),
    ), 1.0,
            title="Surigao Strait (Mindanao Sea to Leyte Gulf)"),
    Passage("oresund", "strait", (
        (56.15, 12.35), (56.055, 12.625), (55.84, 12.805), (55.385, 12.805), (55.38, 12.81), (55.25, 12.85),
    ), 0.2,
            title="Øresund (The Sound; Drogden's 8 m limits the draught)"),
    Passage("bangka", "strait", (
        (-3.05, 106.2), (-2.825, 105.93), (-2.82, 105.925), (-2.39, 105.62), (-2.38, 105.61), (-2.095, 105.105),
        (-2.05, 105.08), (-2.02, 105.08), (-1.955, 105.1), (-1.95, 105.105), (-1.55, 105.2),
    ), 0.4,
            title="Bangka Strait (Java Sea to Singapore along Sumatra)"),
    Passage("durian", "strait", (
        (-0.9, 104.75), (-0.7, 104.34), (-0.48, 104.125), (0.655, 104.115), (0.92, 103.85), (0.915, 103.755),
        (0.925, 103.75), (1.045, 103.73), (1.12, 103.79), (1.12, 103.8),
    ), 0.4,
            title="Durian Strait (the Riau archipelago to the Singapore Strait)"),
    Passage("inland_sea", "strait", (
        (33.991, 130.691), (33.958, 130.837), (33.93, 130.9), (33.957, 130.957), (33.96, 131.0), (33.92, 131.05),
        (33.91, 131.25), (33.795, 132.01), (33.76, 132.045), (33.76, 132.06), (33.825, 132.16), (33.835, 132.38),
        (33.905, 132.48), (33.91, 132.545), (33.92, 132.56), (33.925, 132.565), (33.935, 132.67),
        (33.955, 132.705), (34.15, 132.93), (34.145, 132.98), (34.115, 133.01), (34.1, 133.01), (34.095, 133.015),
        (34.09, 133.04), (34.14, 133.1), (34.16, 133.13), (34.24, 133.235), (34.315, 133.535), (34.32, 133.655),
        (34.325, 133.66), (34.33, 133.665), (34.335, 133.71), (34.345, 133.795), (34.375, 133.835),
        (34.43, 134.025), (34.485, 134.035), (34.58, 134.155), (34.58, 134.9), (34.615, 134.99), (34.615, 135.035),
        (34.5, 135.15), (34.25, 134.96), (33.85, 134.95),
    ), None,
            title="Kanmon Strait and the Seto Inland Sea, out by the Akashi and Kitan Straits"),
    Passage("naruto", "strait", (
        (34.41, 134.0), (34.41, 134.08), (34.425, 134.135), (34.4, 134.245), (34.245, 134.65), (33.85, 134.95),
    ), 0.2,
            title="Naruto Strait (the Inland Sea's short way out to the Kii Channel; strong tidal streams)"),
    Passage("torres", "strait", (
        (-9.2, 144.0), (-10.49, 142.68), (-10.5, 141.2),
    ), 0.5, gates=(((-10.68, 142.55), (-9.15, 142.55)),),
            title="Torres Strait (Great North East and Prince of Wales channels)"),
    # Off Ushant: the scheme lies west and north-west of Ushant (Créac'h light 48.46 N 5.13 W), its lanes running
    # north past the island and bending north-east towards the Channel: the north-east-bound lane inside, about
    # 23 NM off at its nearest, the south-west-bound lane outside, about 32 NM off, the inshore traffic zone between
    # the island and the scheme. The gates run from the Breton mainland due west (across the Chenal du Four and the
    # island) past the south-west-bound lane, round the scheme's seaward side and back to the mainland.
    Passage("ushant_ne", "tss", (
        (48.25, -5.7), (48.72, -5.7), (49.07, -4.68),
    ), 2.0, gates=_chain((48.47, -4.55), (48.46, -6.02), (48.9, -6.02), (49.22, -4.9), (48.55, -4.5)), one_way=True,
            title="Off Ushant traffic separation scheme, north-east-bound lane"),
    Passage("ushant_sw", "tss", (
        (49.2, -4.7), (48.84, -5.93), (48.25, -5.93),
    ), 2.0, one_way=True,
            title="Off Ushant traffic separation scheme, south-west-bound lane"),
    # Off Casquets: the lanes run east-north-east and west-south-west north of the Casquets (49.72 N 2.38 W) and
    # Cap de la Hague: the eastbound lane on the south side, about 8 NM north of the Casquets, the westbound lane
    # on the north side, about 16 NM north (traffic keeps to starboard, as in the Strait of Dover). The gates close
    # the scheme and its inshore zone: north from the Cotentin, round the lanes, back by the Casquets and Alderney.
    Passage("casquets_e", "tss", (
        (49.8, -3.1), (49.91, -1.8),
    ), 2.0, gates=_chain((49.62, -1.85), (50.1, -1.87), (50.03, -3.05), (49.74, -3.05), (49.72, -2.38),
                         (49.62, -1.85)), one_way=True,
            title="Off Casquets traffic separation scheme, eastbound lane"),
    Passage("casquets_w", "tss", (
        (50.04, -1.8), (49.96, -3.1),
    ), 2.0, one_way=True,
            title="Off Casquets traffic separation scheme, westbound lane"),
    # Off Finisterre: the lanes run north-south 25-33 NM west of the cape (42.88 N 9.27 W) and bend north-east
    # towards the Bay of Biscay north of 43.2 N: the northbound lane inside, the southbound lane outside (the lanes
    # for ships carrying dangerous goods in bulk, further out, are left out). The gates run from Galicia due west
    # past the southbound lane, round the scheme's seaward side and back to the coast south of A Coruña.
    Passage("finisterre_n", "tss", (
        (42.6, -9.84), (43.2, -9.84), (43.66, -9.28),
    ), 2.0, gates=_chain((42.93, -9.0), (42.93, -10.15), (43.38, -10.2), (43.78, -9.6), (43.2, -8.8)), one_way=True,
            title="Off Finisterre traffic separation scheme, northbound lane"),
    Passage("finisterre_s", "tss", (
        (43.84, -9.45), (43.3, -10.02), (42.6, -10.02),
    ), 2.0, one_way=True,
            title="Off Finisterre traffic separation scheme, southbound lane"),
    # Off Cabo de São Vicente: the lanes wrap round the cape (37.02 N 8.99 W) from its south-east to its north-west,
    # the lane for traffic bound west and north inside, about 15-16 NM off, the lane bound south and east outside,
    # about 23-24 NM off. The gates run from the Algarve south past the outer lane, round the scheme's seaward side
    # 30 NM off the cape, and back to the Alentejo coast.
    Passage("sao_vicente_nw", "tss", (
        (36.83, -8.62), (36.75, -8.99), (36.83, -9.23), (37.02, -9.32), (37.21, -9.23), (37.45, -9.2),
    ), 2.0, gates=_chain((37.15, -8.7), (36.5, -8.7), (36.67, -9.43), (37.4, -9.58), (37.4, -8.75)), one_way=True,
            title="Off Cabo de São Vicente traffic separation scheme, lane bound west and north"),
    Passage("sao_vicente_se", "tss", (
        (37.45, -9.42), (37.02, -9.49), (36.74, -9.34), (36.62, -8.99), (36.7, -8.62),
    ), 2.0, one_way=True,
            title="Off Cabo de São Vicente traffic separation scheme, lane bound south and east"),
)


@dataclass(frozen=True)
class AreaToAvoid:
    """Water a route keeps out of although the land mask holds it as sea (shoals, routeing measures): its outline's
    sides are gates (no leg crosses them), so a route passes outside. The outline may run over land to close it."""

    name: str
    outline: tuple[tuple[float, float], ...]  # (lat, lon) degrees, a closed polygon (the last vertex joins the first)
    title: str
    source: str

    @property
    def gates(self) -> tuple[tuple[tuple[float, float], tuple[float, float]], ...]:
        return _chain(*self.outline, self.outline[0])


# Both outlines are approximate, drawn in round figures round what their sources describe; not for navigation.
AREAS_TO_AVOID: tuple[AreaToAvoid, ...] = (
    AreaToAvoid("jiangsu_shoals", (
        (31.7, 121.7), (31.95, 122.45), (32.6, 122.55), (33.5, 122.2), (34.3, 121.2), (34.6, 120.45), (34.3, 119.9),
        (32.0, 120.8),
    ), title="Jiangsu shoals (the Subei radial sand ridges off the Jiangsu coast, from the Yangtze's north bank to "
             "Haizhou Bay)",
        source="the radial sand ridge field of the southern Yellow Sea, fanning out about 100 km from Jianggang "
               "(32.7 N 120.9 E) with a few metres over the ridges at low water: deep-draught traffic between the "
               "Yangtze and Qingdao keeps east of it; the outline is its rough extent (32-35 N, 120.5-122.5 E) "
               "closed on the coast, not charted limits"),
    AreaToAvoid("berlengas", (
        (39.36, -9.36), (39.3, -9.48), (39.35, -9.66), (39.52, -9.68), (39.56, -9.5), (39.47, -9.16),
    ), title="Berlengas (the Berlengas and Farilhões islands and the channel inside them off Cabo Carvoeiro)",
        source="the routeing measures adopted by IMO off the Berlengas (a traffic separation scheme with an area to "
               "be avoided round the islands, which keeps through traffic outside them); drawn round the islands "
               "(Berlenga Grande 39.41 N 9.51 W, Farilhões 39.47 N 9.54 W) about 5 NM to seaward and closed on the "
               "coast at Peniche, not from the adopted coordinates"),
)


def area_gates() -> tuple[tuple[tuple[float, float], tuple[float, float]], ...]:
    """Every side of every area to avoid, as gates."""
    return tuple(g for a in AREAS_TO_AVOID for g in a.gates)


def check_avoid(names) -> frozenset[str]:
    """`names` as a set of passages a route may keep out of (lower case); ValueError for a name that is no passage,
    or that of a traffic separation scheme's lane (compulsory: a route sails its lane or passes outside the scheme)."""
    avoid = frozenset(str(a).strip().lower() for a in names if str(a).strip())
    unknown = sorted(avoid - {p.name for p in PASSAGES})
    if unknown:
        raise ValueError(f"unknown passage(s) to avoid: {', '.join(unknown)}; known: "
                         f"{', '.join(p.name for p in PASSAGES if p.kind != 'tss')}")
    compulsory = sorted(p.name for p in PASSAGES if p.name in avoid and p.kind == "tss")
    if compulsory:
        raise ValueError(f"cannot avoid {', '.join(compulsory)}: a traffic separation scheme's lanes are compulsory for "
                         f"through traffic (COLREG rule 10); the route sails the lane or passes outside the scheme")
    return avoid


def passage(name: str) -> Passage:
    for p in PASSAGES:
        if p.name == name:
            return p
    raise KeyError(f"no passage {name!r}; known: {', '.join(p.name for p in PASSAGES)}")


__all__ = ["AREAS_TO_AVOID", "PASSAGES", "AreaToAvoid", "Passage", "area_gates", "check_avoid", "passage"]
