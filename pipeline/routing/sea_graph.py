"""The coarse global sea graph the global sea-route layer searches (global_routes.py): a 0.125° grid of sea cells.

A node is the centre of a 0.125° cell between the ice limits (`LAT_LIMITS_DEG`) that keeps the clearance from land
(land.py's distance field, the product's own mask). An edge joins a node to one of its 16 neighbours (the 8 around
it and the 8 a knight's move away, so paths need not zig-zag at 45°) when the great-circle leg between the centres
keeps the clearance at every point, checked at ≤ 0.1 NM (clearance.leg_is_clear_nb, the rule every plan is held
to). Columns wrap round the antimeridian. Edges are one bit each (a uint16 per node), about 6 MB in memory (2.1 million cells).

Building the edges for a clearance takes about 25 s on one core; the result is kept per process and on disk
(a temporary directory, keyed by the mask, the clearance and this module's `GRAPH_VERSION`), so a process pays
it at most once per machine and clearance.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
import threading
from pathlib import Path
from typing import NamedTuple

import numba
import numpy as np

from pipeline.routing.clearance import Clearance, leg_is_clear_nb
from pipeline.routing.land import distance_to_land_nb, land_grid
from pipeline.routing.land_mask import mask_key, mask_path

GRAPH_VERSION = 1
RES_DEG = 0.125
LAT_LIMITS_DEG = (-62.0, 72.0)  # ice limits: no route into the Antarctic pack or through the Arctic passages
N_COLS = int(round(360.0 / RES_DEG))
N_ROWS = int(round((LAT_LIMITS_DEG[1] - LAT_LIMITS_DEG[0]) / RES_DEG))
# the 16 moves (row, column): bit k of a node's edge word is move k
MOVES = np.array([(-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (-1, 1), (1, -1), (1, 1),
                  (-1, -2), (-1, 2), (1, -2), (1, 2), (-2, -1), (-2, 1), (2, -1), (2, 1)], np.int64)
OPPOSITE = np.array([1, 0, 3, 2, 7, 6, 5, 4, 11, 10, 9, 8, 15, 14, 13, 12], np.int64)


class SeaGraph(NamedTuple):
    """`edges[i, j]`: bit k set when the leg from cell (i, j) to cell (i + MOVES[k, 0], j + MOVES[k, 1]) (columns
    wrapped) keeps `clearance_nm`; a cell with no bits is not a node. Row 0 is the northernmost."""

    edges: np.ndarray  # (N_ROWS, N_COLS) uint16
    clearance_nm: float


@numba.njit(cache=True)
def cell_lat(i):
    return LAT_LIMITS_DEG[1] - (i + 0.5) * RES_DEG


@numba.njit(cache=True)
def cell_lon(j):
    return -180.0 + (j + 0.5) * RES_DEG


def open_sea_rule(clearance_nm: float) -> Clearance:
    """The clearance rule away from any port: `clearance_nm` everywhere (no approach: it is never inside one)."""
    return Clearance(float(clearance_nm), -1.0, 0.0, 0.0, 0.0, 0.0)


@numba.njit(cache=True)
def _build_edges(grid, rule, moves, opposite, edges):
    nr, nc = edges.shape
    node = np.zeros((nr, nc), np.bool_)
    need = rule.clearance_nm
    for i in range(nr):
        for j in range(nc):
            d = distance_to_land_nb(grid, cell_lat(i), cell_lon(j), need + 1.0)
            node[i, j] = d > 0.0 and d >= need
    lo, hi = LAT_LIMITS_DEG[0], LAT_LIMITS_DEG[1]
    for i in range(nr):
        for j in range(nc):
            if not node[i, j]:
                continue
            for k in range(moves.shape[0]):
                ii, jj = i + moves[k, 0], (j + moves[k, 1]) % nc
                if ii < 0 or ii >= nr or not node[ii, jj]:
                    continue
                if (edges[i, j] >> k) & 1:
                    continue  # set from the other end already
                if leg_is_clear_nb(grid, rule, cell_lat(i), cell_lon(j), cell_lat(ii), cell_lon(jj), lo, hi):
                    edges[i, j] |= np.uint16(1 << k)
                    edges[ii, jj] |= np.uint16(1 << opposite[k])
    return edges


def build_sea_graph(clearance_nm: float) -> SeaGraph:
    """The graph's edges for `clearance_nm`, built from the land grid (about 25 s)."""
    edges = np.zeros((N_ROWS, N_COLS), np.uint16)
    _build_edges(land_grid(), open_sea_rule(clearance_nm), MOVES, OPPOSITE, edges)
    return SeaGraph(edges=edges, clearance_nm=float(clearance_nm))


def _cache_path(clearance_nm: float) -> Path:
    key = f"{mask_key(mask_path())}|{clearance_nm:.6f}|{GRAPH_VERSION}|{RES_DEG}|{LAT_LIMITS_DEG}"
    digest = hashlib.sha256(key.encode()).hexdigest()[:16]
    return Path(tempfile.gettempdir()) / "jitroute-sea-graph" / f"sea_graph_{digest}.npz"


_GRAPHS: dict[float, SeaGraph] = {}
_LOCK = threading.Lock()


def sea_graph(clearance_nm: float) -> SeaGraph:
    """The process's graph for `clearance_nm`: from memory, else the disk cache, else built (and cached)."""
    key = round(float(clearance_nm), 6)
    g = _GRAPHS.get(key)
    if g is not None:
        return g
    with _LOCK:
        g = _GRAPHS.get(key)
        if g is None:
            path = _cache_path(key)
            if path.exists():
                with np.load(path) as z:
                    g = SeaGraph(edges=z["edges"], clearance_nm=key)
            else:
                g = build_sea_graph(key)
                path.parent.mkdir(parents=True, exist_ok=True)
                tmp = path.with_name(f"{path.stem}.{os.getpid()}.{threading.get_ident()}.tmp.npz")
                np.savez_compressed(tmp, edges=g.edges)
                tmp.replace(path)
            _GRAPHS[key] = g
    return g
