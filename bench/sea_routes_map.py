"""Draw the product's sea route and searoute's line for bench pairs on one map: bench/out/sea_route_<pair>.png.

    .venv/bin/python bench/sea_routes_map.py "Manila - Guam" "Hong Kong - Qingdao"    # pair keys as sea_routes.py prints

The land is the product's own mask (grey); the product's route red with its waypoints, searoute's line blue (its
ends joined to the given positions by dotted legs: the unsailed ends its length leaves out). Needs searoute installed
(`pip install searoute`, for the bench only) and matplotlib.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from sea_route_pairs import PAIRS, PORTS, key  # noqa: E402


def draw(pair: str) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import searoute as sr

    from pipeline.routing.global_routes import sea_route
    from pipeline.routing.land import is_sea

    a, b, avoid = next(p for p in PAIRS if key(*p) == pair)
    (la, lo), (lb, lob) = PORTS[a], PORTS[b]
    r = sea_route(PORTS[a], PORTS[b], avoid=set(avoid))
    f = sr.searoute([lo, la], [lob, lb], units="naut", restrictions=["northwest"] + [x for x in avoid if x in ("suez", "panama")])
    sx, sy = np.array(f["geometry"]["coordinates"]).T
    # unwrap longitudes round the first point so a route over the antimeridian draws as one line
    ref = lo
    rx = (r.lon - ref + 180.0) % 360.0 - 180.0 + ref
    sx = (sx - ref + 180.0) % 360.0 - 180.0 + ref
    lon0, lon1 = min(rx.min(), sx.min()) - 1.0, max(rx.max(), sx.max()) + 1.0
    lat0, lat1 = min(r.lat.min(), sy.min()) - 1.0, max(r.lat.max(), sy.max()) + 1.0
    step = max(lon1 - lon0, lat1 - lat0) / 600.0
    gx, gy = np.meshgrid(np.arange(lon0, lon1, step), np.arange(lat0, lat1, step))
    sea = is_sea(gy, (gx + 180.0) % 360.0 - 180.0)
    fig, ax = plt.subplots(figsize=(10, 10 * (lat1 - lat0) / (lon1 - lon0) / np.cos(np.radians(0.5 * (lat0 + lat1))) + 0.8))
    ax.pcolormesh(gx, gy, ~sea, cmap="Greys", vmin=0, vmax=3, shading="auto")
    ax.plot(rx, r.lat, "r.-", lw=1.2, ms=3, label=f"jitroute {r.dist_nm:,.0f} NM")
    ax.plot(sx, sy, "b-", lw=1.0, label=f"searoute {f['properties']['length']:,.0f} NM")
    ax.plot([lo, sx[0]], [la, sy[0]], "b:", lw=1.0)
    ax.plot([rx[-1], sx[-1]], [lb, sy[-1]], "b:", lw=1.0)
    ax.plot([lo, rx[-1]], [la, lb], "ko", ms=4)
    ax.set_aspect(1.0 / np.cos(np.radians(0.5 * (lat0 + lat1))))
    ax.set_title(pair)
    ax.legend(loc="best")
    out = ROOT / "bench" / "out" / f"sea_route_{pair.replace(' ', '_').replace('(', '').replace(')', '').replace('+', '_')}.png"
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=80, bbox_inches="tight")
    plt.close(fig)
    return out


if __name__ == "__main__":
    for pair in sys.argv[1:]:
        print(draw(pair))
