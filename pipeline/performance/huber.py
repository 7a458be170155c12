"""Huber weights for the robust refit, with the medians they need found by selection (numba).

The median and MAD of a vessel's residuals change little from one re-weighting pass to the next, so
`median_near` first selects among the values near the previous guess and falls back to a full
quickselect only when the guess was off; the result always equals `np.median`.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def huber_weights(r, m, huber_k, med_guess, s_guess, buf, w):
    """Huber weights of residuals r[:m] into w[:m]: scale s = 1.4826 · MAD (1e-9 when the MAD is 0).

    Returns (median, s); the previous ones, if known (else NaN), are guesses that make the medians
    cheap. buf: (3, ≥ m) scratch.
    """
    if not (np.isfinite(med_guess) and np.isfinite(s_guess)):  # guess from the mean and standard deviation
        mean, sq = 0.0, 0.0
        for q in range(m):
            mean += r[q]
        mean /= m
        for q in range(m):
            sq += (r[q] - mean) * (r[q] - mean)
        med_guess, s_guess = mean, np.sqrt(sq / m)
    med = median_near(r, m, med_guess, 0.1 * s_guess, buf)
    for q in range(m):
        w[q] = abs(r[q] - med)  # w is scratch until the weights go in
    s = 1.4826 * median_near(w, m, s_guess / 1.4826, 0.1 * s_guess, buf)
    if s == 0.0:
        s = 1e-9
    c = huber_k * s
    for q in range(m):
        u = abs(r[q]) / c
        w[q] = 1.0 if u <= 1.0 else 1.0 / u  # a residual of exactly 0 (a fit through its few rows) weighs 1
    return med, s


@numba.njit(cache=True)
def median_near(a, m, guess, width, buf):
    """np.median of a[:m] (a is only read; buf: (3, ≥ m) scratch).

    If guess ± width brackets the middle order statistics, only the values inside the bracket are
    selected among (few, when the guess is good); otherwise all of them.
    """
    half = m // 2
    low, high = guess - width, guess + width
    below, inside = 0, 0
    near = buf[2]
    for q in range(m):
        v = a[q]
        below += v < low
        near[inside] = v
        inside += (v >= low) & (v <= high)
    if below <= half - 1 + m % 2 and half < below + inside:
        return _middle(near, inside, half - below, m % 2 == 0, buf[0], buf[1])
    return _middle(a, m, half, m % 2 == 0, buf[0], buf[1])


@numba.njit(cache=True)
def _middle(a, n, kth, even, s0, s1):
    """The kth smallest of a[:n], or with `even` the mean of the (kth − 1)th and kth (a is only read)."""
    upper = _kth(a, n, kth, s0, s1)
    if not even:
        return upper
    less, lower = 0, -np.inf  # how many are below `upper`, and the largest of them
    for q in range(n):
        v = a[q]
        less += v < upper
        lower = max(lower, v if v < upper else -np.inf)
    return ((lower if less == kth else upper) + upper) / 2


@numba.njit(cache=True)
def _kth(a, n, kth, s0, s1):
    """The kth smallest of a[:n] (a is only read; s0, s1: scratch of length ≥ n).

    Quickselect with a branch-free partition (values ping-pong between s0 and s1), which does not
    stall on unpredictable comparisons the way swapping in place does.
    """
    src, dst = a, s0
    lo, hi = 0, n
    while hi - lo > 24:
        x, y, z = src[lo], src[(lo + hi) // 2], src[hi - 1]
        pivot = max(min(x, y), min(max(x, y), z))  # median of three
        left, right = lo, hi - 1
        for q in range(lo, hi):  # smaller than the pivot to the left, the others to the right
            v = src[q]
            c = v < pivot
            dst[left] = v
            dst[right] = v
            left += c
            right -= 1 - c
        if kth < left:
            hi = left
        elif left > lo:
            lo = left
        else:  # nothing below the pivot (many equal values): finish with the swapping quickselect
            for q in range(lo, hi):
                s1[q] = dst[q]
            return _select(s1, lo, hi - 1, kth)
        src, dst = dst, (s1 if dst is s0 else s0)
    if src is a:
        for q in range(lo, hi):
            s0[q] = a[q]
        src = s0
    for i in range(lo + 1, hi):  # insertion sort of the few left
        v = src[i]
        j = i - 1
        while j >= lo and src[j] > v:
            src[j + 1] = src[j]
            j -= 1
        src[j + 1] = v
    return src[kth]


@numba.njit(cache=True)
def _select(a, left, right, kth):
    """Quickselect: reorder a[left:right+1] so a[kth] is in sorted position, smaller-or-equal before it."""
    while right > left:
        mid = (left + right) // 2  # median of three as pivot
        if a[mid] < a[left]:
            a[mid], a[left] = a[left], a[mid]
        if a[right] < a[left]:
            a[right], a[left] = a[left], a[right]
        if a[right] < a[mid]:
            a[right], a[mid] = a[mid], a[right]
        pivot = a[mid]
        i, j = left, right
        while i <= j:
            while a[i] < pivot:
                i += 1
            while a[j] > pivot:
                j -= 1
            if i <= j:
                a[i], a[j] = a[j], a[i]
                i += 1
                j -= 1
        if kth <= j:
            right = j
        elif kth >= i:
            left = i
        else:
            break
    return a[kth]
