"""One-pass screens in front of the vertex checks of :mod:`._layout` (private).

Each screen either proves that a check passes or says that the check's own numpy code must
decide; that code then runs unchanged and words the refusal. So the checks accept and refuse
exactly as without the screens, with the same messages: the screens only spare the curves that
pass the sorts and temporaries of the numpy code (at 10⁶ vertices most of its 0.5 s).
"""

from __future__ import annotations

import numba as nb
import numpy as np

# Slots probed for one row before :func:`equal_rows_possible` gives up and lets the sort
# decide: bounds its time on rows whose hashes crowd together.
_MAX_PROBES = 64
# Rows are numbered in int32 (the parts and their tables).
_MAX_ROWS = 2**31
# Rows per part of :func:`equal_rows_possible` (about): a part's table (at most 64 KB) stays in
# the core's own cache; one table for all 10^6 rows (16 MB) missed it at nearly every row,
# 0.09-0.12 s for both screens against 0.04 s.
_PART_ROWS = 4096
# The odd multipliers of the hash: the golden-ratio one and splitmix64's finalizer.
_K1 = np.uint64(0x9E3779B97F4A7C15)
_K2 = np.uint64(0xC2B2AE3D27D4EB4F)
_K3 = np.uint64(0x165667B19E3779F9)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S27, _S30, _S31 = np.uint64(27), np.uint64(30), np.uint64(31)


@nb.njit(cache=True)
def extent(X):
    """``(finite, span)`` of an ``(n, 3)`` array: whether every coordinate is finite, and
    (if so) ``max over columns of (column max / 2 − column min / 2)``, the half-range of
    :func:`._layout.unit_exponent` in one pass (max and min are exact in any order)."""
    n = X.shape[0]
    if n == 0:
        return True, 0.0
    lo0, lo1, lo2 = X[0, 0], X[0, 1], X[0, 2]
    hi0, hi1, hi2 = lo0, lo1, lo2
    nan = 0.0  # x − x is 0 for a finite x, NaN for NaN and ±inf: the sum says if all are finite
    for i in range(n):
        x, y, z = X[i, 0], X[i, 1], X[i, 2]
        nan += (x - x) + (y - y) + (z - z)
        lo0, lo1, lo2 = min(lo0, x), min(lo1, y), min(lo2, z)
        hi0, hi1, hi2 = max(hi0, x), max(hi1, y), max(hi2, z)
    if nan != 0.0:
        return False, 0.0
    return True, max(hi0 / 2 - lo0 / 2, max(hi1 / 2 - lo1 / 2, hi2 / 2 - lo2 / 2))


@nb.njit(cache=True)
def short_edge_possible(X, nxt, skip_dummy):
    """False if every edge ``(i, nxt[i])`` of an ``(n, 3)`` array is longer than
    :func:`._layout.check_distinct`'s bound ``1e-12 · max |X − mean|``; True: the check
    decides. Edges with ``nxt[i] == i`` are skipped with ``skip_dummy`` (open components).

    The bound is taken from above without the mean: the widest column range plus how far a
    rounded mean of ``n`` values may leave its range (``n · 2^-53 · max|X|``, taken four
    times), with a margin of 1e-6 for the order of the rounded sums of squares. Where the
    squares could under- or overflow, or a coordinate is not finite, True."""
    n = X.shape[0]
    if n == 0:
        return True
    lo0, lo1, lo2 = X[0, 0], X[0, 1], X[0, 2]
    hi0, hi1, hi2 = lo0, lo1, lo2
    nan = 0.0  # as in extent: NaN unless every coordinate is finite
    shortest = np.inf  # squared
    for i in range(n):
        x, y, z = X[i, 0], X[i, 1], X[i, 2]
        nan += (x - x) + (y - y) + (z - z)
        lo0, lo1, lo2 = min(lo0, x), min(lo1, y), min(lo2, z)
        hi0, hi1, hi2 = max(hi0, x), max(hi1, y), max(hi2, z)
        j = nxt[i]
        if skip_dummy and j == i:
            continue
        dx, dy, dz = X[j, 0] - x, X[j, 1] - y, X[j, 2] - z
        shortest = min(shortest, dx * dx + dy * dy + dz * dz)
    if nan != 0.0:
        return True
    big = max(max(-lo0, hi0), max(max(-lo1, hi1), max(-lo2, hi2)))
    if not big <= 1e300 / n:  # the sum of the mean may overflow: the check decides
        return True
    spread = max(hi0 - lo0, max(hi1 - lo1, hi2 - lo2))
    bound = 1e-12 * (spread + 2.0 * n * 2.0**-52 * big) * (1.0 + 1e-6)
    if not 1e-140 <= bound <= 1e140:
        return True
    return not shortest > bound * bound


@nb.njit(cache=True, inline="always")
def _row(X, nxt, midpoints, i):
    """Vertex ``i``, or (``midpoints``) the midpoint of its edge as numpy computes it."""
    if midpoints:
        j = nxt[i]
        return 0.5 * (X[i, 0] + X[j, 0]), 0.5 * (X[i, 1] + X[j, 1]), 0.5 * (X[i, 2] + X[j, 2])
    return X[i, 0], X[i, 1], X[i, 2]


@nb.njit(cache=True, inline="always")
def _hash(buf, bits, x, y, z):
    """64-bit hash of the bits of ``(x, y, z) + 0.0`` (``buf`` and its ``bits`` view: the
    scratch of the bit cast). ``+ 0.0`` turns -0.0 into 0.0: equal rows, equal bits."""
    buf[0] = x + 0.0
    buf[1] = y + 0.0
    buf[2] = z + 0.0
    h = (bits[0] * _K1) ^ (bits[1] * _K2) ^ (bits[2] * _K3)
    h ^= h >> _S30
    h *= _M1
    h ^= h >> _S27
    h *= _M2
    return h ^ (h >> _S31)


@nb.njit(cache=True)
def equal_rows_possible(X, nxt, midpoints, skip_dummy):
    """False if no two rows are equal (float equality: -0.0 equals 0.0) among the vertices of
    an ``(n, 3)`` array or (``midpoints``) the midpoints of its edges ``(i, nxt[i])``, without
    the edges with ``nxt[i] == i`` if ``skip_dummy``; True if two are, or if the screen gave
    up (:data:`_MAX_PROBES`): the sort of the check decides.

    The rows' hashes (:func:`_hash`) are counted and then sorted by their top bits into parts
    of about :data:`_PART_ROWS` rows; equal rows have equal hashes, so they meet in one part,
    whose open-addressing table compares hashes and, where two agree, the rows themselves.
    NaN never gets here (the checks run after :func:`._layout.check_finite`)."""
    n = X.shape[0]
    if n >= _MAX_ROWS:
        return True
    skip_dummy = skip_dummy and midpoints  # every vertex is a row
    b = 0
    while n >> b > _PART_ROWS:
        b += 1
    shift = np.uint64(63 - b)  # the part is h >> shift >> 1 (one shift of 64 is undefined)
    parts = 1 << b
    start = np.zeros(parts + 1, np.int64)
    H = np.empty(n, np.uint64)
    buf = np.empty(3, np.float64)
    bits = buf.view(np.uint64)
    for i in range(n):
        if skip_dummy and nxt[i] == i:
            continue
        x, y, z = _row(X, nxt, midpoints, i)
        H[i] = _hash(buf, bits, x, y, z)
        start[(np.int64(H[i] >> shift) >> 1) + 1] += 1
    for p in range(parts):
        start[p + 1] += start[p]
    fill = start[:parts].copy()
    PH = np.empty(start[parts], np.uint64)  # the hashes and rows, part after part
    PR = np.empty(start[parts], np.int32)
    for i in range(n):
        if skip_dummy and nxt[i] == i:
            continue
        p = np.int64(H[i] >> shift) >> 1
        PH[fill[p]] = H[i]
        PR[fill[p]] = i
        fill[p] += 1
    largest = 0
    for p in range(parts):
        largest = max(largest, start[p + 1] - start[p])
    size = 2
    while size < 2 * largest:
        size *= 2
    mask = np.uint64(size - 1)
    table = np.empty(size, np.int32)  # a part's rows, by their place in the part
    for p in range(parts):
        table[:] = -1
        first = start[p]
        for t in range(first, start[p + 1]):
            h = PH[t]
            slot = np.int64(h & mask)
            probes = 0
            while table[slot] != -1:
                s = first + table[slot]
                if PH[s] == h:
                    x, y, z = _row(X, nxt, midpoints, PR[s])
                    u, v, w = _row(X, nxt, midpoints, PR[t])
                    if x == u and y == v and z == w:
                        return True
                probes += 1
                if probes == _MAX_PROBES:
                    return True
                slot = (slot + 1) & (size - 1)
            table[slot] = t - first
    return False
