"""Safe random routes for the BFOA's initialisation and dispersal (numba): a random walk line by line
that drifts towards a drawn offset and bends back to the destination in time (see engine/swarm.py)."""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np


class Walk(NamedTuple):
    """How a random route walks (`random_walk_nb`): tries per node and overall, lines to back up on failure, the
    spread of its target offsets (nodes), and the chances per line of a new target and of a step towards it."""

    r_max: int
    k_max: int
    backup: int
    sigma: float
    p_new: float
    p_step: float


@numba.njit(cache=True)
def random_walk_nb(nodes, edge_ok, max_shift, walk, offset, rng):
    """Safe random route: a walk line by line whose step heads, one node at a time, for a target offset that
    is redrawn now and then (so random routes are smooth detours of every size, not zig-zags) and bends back
    to the destination in time. Each node: the preferred one first, then nodes ever farther from it (random
    side), R_max tries in all; on failure back up `backup` lines; give up after K_max tries overall.
    Offsets are drawn ~ N(0, sigma) nodes, the first one around `offset` instead of 0; a new target with
    probability p_new per line; a step towards it with probability p_step per line. With sigma 0, p_new 0 and
    p_step 1 the walk is the offset route: out to `offset` one node a line, along it, and back in time. The settings
    come as one `Walk`."""
    r_max, k_max, backup, sigma, p_new, p_step = walk
    L2 = nodes.shape[0]
    P = edge_ok.shape[1]
    c = P // 2
    L = L2 - 2
    nodes[0] = c
    nodes[L2 - 1] = c
    target = c + offset + int(np.round(rng.normal() * sigma))
    i, tries = 1, 0
    while i <= L:
        a = nodes[i - 1]
        left = L + 1 - i  # legs still to go after line i
        lo = max(0, a - max_shift, c - max_shift * left)
        hi = min(P - 1, a + max_shift, c + max_shift * left)
        if rng.random() < p_new:
            target = c + int(np.round(rng.normal() * sigma))
        tgt = min(max(target, c - (left - 1)), c + (left - 1))  # in reach of the destination, one node a line
        homing = abs(a - c) >= left - 1
        step = 0
        if tgt != a and (homing or rng.random() < p_step):
            step = 1 if tgt > a else -1
            if abs(a - c) > left:  # behind on the way back: larger steps
                step *= (abs(a - c) + left - 1) // left
        pref = min(max(a + step, lo), hi)
        placed = False
        if lo <= hi:
            for t in range(r_max):
                off = (t + 1) // 2
                b = pref + (off if rng.random() < 0.5 else -off)
                if b < lo or b > hi:
                    b = rng.integers(lo, hi + 1)
                if edge_ok[i - 1, a, b] and (i < L or edge_ok[L, b, c]):
                    nodes[i] = b
                    placed = True
                    break
        tries += 1
        if placed:
            i += 1
        else:
            i = max(1, i - backup)
        if tries > k_max:
            return False
    return True
