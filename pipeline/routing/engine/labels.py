"""How the label searches store and look up their labels (compiled): stores that grow, a prefix-minimum tree over
time bins, and time spans for the searches that keep a bounded number of labels per node."""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np


class LabelMode(NamedTuple):
    """How a label search keeps its labels (label_search.dp_exact_nb): every label that is not dominated (`EXACT`), or at most
    `buckets` per node (the line's candidate times cut into that many equal spans, a span keeping its label of least
    f − e·t + lam_t·t, lam_t in t/h: approximate, for local searches and for voyages too long for every label). With
    `skip_dropped` (exact mode only) a leg is not sailed when a label made already is sure to drop the one it would
    make. With `max_legs` > 0 the search gives up (no plan, cost inf) once it has sailed more legs than that: its
    work is paced by legs sailed, never by the clock."""

    buckets: int = 0
    lam_t: float = 0.0
    skip_dropped: bool = True
    max_legs: int = 0


EXACT = LabelMode()


def bucketed(buckets: int, lam_t: float) -> LabelMode:
    """At most `buckets` labels per node, a time span's label chosen at the time price lam_t (t/h); `EXACT` for 0."""
    return LabelMode(int(buckets), float(lam_t), True, 0)


@numba.njit(cache=True)
def grow(a, n):
    """`a` with room for at least n entries (doubling), its contents kept."""
    if n <= a.shape[0]:
        return a
    b = np.empty(max(n, 2 * a.shape[0]), a.dtype)
    b[: a.shape[0]] = a
    return b


@numba.njit(cache=True, inline="always")
def grow_store(n, a, b, c, d, e):
    """The five parallel arrays of a DP's label store (time or slot, fuel, parent, node, setting), each with room for
    at least n labels (`grow`)."""
    return grow(a, n), grow(b, n), grow(c, n), grow(d, n), grow(e, n)


@numba.njit(cache=True)
def prefix_min(tree, row, n):
    """The least value put at positions 1..n of the prefix-minimum (Fenwick) tree tree[row]."""
    best = np.inf
    while n > 0:
        best = min(best, tree[row, n])
        n -= n & -n
    return best


@numba.njit(cache=True)
def put_min(tree, row, n, val):
    """Put val at position n (1-based) of the prefix-minimum tree tree[row]."""
    while n < tree.shape[1]:
        tree[row, n] = min(tree[row, n], val)
        n += n & -n


@numba.njit(cache=True)
def time_span_nb(t, t_lo, t_span, buckets):
    """Which of `buckets` equal spans of [t_lo, t_lo + t_span] the time t falls in (the searches that keep at most
    that many labels per node)."""
    return min(int((t - t_lo) / t_span * buckets), buckets - 1) if t_span > 0.0 else 0
