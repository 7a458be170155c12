"""How the label searches store and look up their labels (compiled): stores that grow, a prefix-minimum tree over
time bins, and time spans for the searches that keep a bounded number of labels per node."""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def grow(a, n):
    """`a` with room for at least n entries (doubling), its contents kept."""
    if n <= a.shape[0]:
        return a
    b = np.empty(max(n, 2 * a.shape[0]), a.dtype)
    b[: a.shape[0]] = a
    return b


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
