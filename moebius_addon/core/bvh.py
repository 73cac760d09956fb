"""Bounding-volume hierarchy over the edges of a knot or link (private; the tree engine's and
the contact search's shared structure).

A binary tree built by median splits of the edge midpoints along the longest side of their
bounding box, ``O(N log N)``. Nodes are stored in arrays in creation order, so a parent always
comes before its children: a pass in reverse index order is bottom-up (refit), one in index
order top-down. Each node owns the contiguous range ``perm[lo:hi]`` of edge indices; a leaf
holds at most ``leaf_size`` edges.

The topology depends only on the midpoints at build time. ``refit`` recomputes the bounds for
moved vertices in ``O(N)``: the tree stays valid (every bound is exact for its edges), only
less tight, so a refitted tree gives the same exact answers as a fresh one.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from ._layout import Layout

LEAF_SIZE = 8


class Tree(NamedTuple):
    """Topology of the hierarchy: ``perm`` (N,) edge order; per node ``lo``, ``hi`` (range in
    ``perm``) and ``left``, ``right`` (child nodes, −1 at a leaf)."""

    perm: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    left: np.ndarray
    right: np.ndarray

    @property
    def size(self) -> int:
        return int(self.lo.shape[0])


@nb.njit(cache=True)
def _build(mid, leaf_size):
    n = mid.shape[0]
    perm = np.arange(n)
    cap = 2 * (n // max(leaf_size // 2, 1) + 1) + 1
    lo = np.empty(cap, np.int64)
    hi = np.empty(cap, np.int64)
    left = np.full(cap, -1, np.int64)
    right = np.full(cap, -1, np.int64)
    lo[0] = 0
    hi[0] = n
    count = 1
    stack = np.empty(64, np.int64)
    stack[0] = 0
    top = 1
    key = np.empty(n)
    while top > 0:
        top -= 1
        node = stack[top]
        a, b = lo[node], hi[node]
        if b - a <= leaf_size:
            continue
        # longest side of the midpoints' box
        axis = 0
        ext = -1.0
        for k in range(3):
            mn = np.inf
            mx = -np.inf
            for q in range(a, b):
                v = mid[perm[q], k]
                mn = min(mn, v)
                mx = max(mx, v)
            if mx - mn > ext:
                ext = mx - mn
                axis = k
        for q in range(a, b):
            key[q] = mid[perm[q], axis]
        # stable: ties keep their order, so the tree is a function of the input alone
        order = np.argsort(key[a:b], kind="mergesort")
        seg = perm[a:b].copy()
        for q in range(b - a):
            perm[a + q] = seg[order[q]]
        m = (a + b) // 2
        for child, (ca, cb) in enumerate(((a, m), (m, b))):
            lo[count] = ca
            hi[count] = cb
            if child == 0:
                left[node] = count
            else:
                right[node] = count
            stack[top] = count
            top += 1
            count += 1
    return perm, lo[:count].copy(), hi[:count].copy(), left[:count].copy(), right[:count].copy()


def build(X: np.ndarray, layout: Layout, leaf_size: int = LEAF_SIZE) -> Tree:
    """Hierarchy over the edges ``(X[I], X[nxt[I]])`` split at their midpoints' medians."""
    mid = np.ascontiguousarray(0.5 * (X + X[layout.nxt]))
    return Tree(*_build(mid, int(leaf_size)))


@nb.njit(cache=True)
def _segment_boxes(X, nxt, perm, lo, hi, left, right):
    """Per node the box ``(min xyz, max xyz)`` of its edges' endpoints, bottom-up."""
    m = lo.shape[0]
    bmin = np.empty((m, 3))
    bmax = np.empty((m, 3))
    for node in range(m - 1, -1, -1):
        if left[node] < 0:
            for k in range(3):
                bmin[node, k] = np.inf
                bmax[node, k] = -np.inf
            for q in range(lo[node], hi[node]):
                i = perm[q]
                j = nxt[i]
                for k in range(3):
                    a = X[i, k]
                    b = X[j, k]
                    bmin[node, k] = min(bmin[node, k], min(a, b))
                    bmax[node, k] = max(bmax[node, k], max(a, b))
        else:
            c1, c2 = left[node], right[node]
            for k in range(3):
                bmin[node, k] = min(bmin[c1, k], bmin[c2, k])
                bmax[node, k] = max(bmax[c1, k], bmax[c2, k])
    return bmin, bmax


def segment_boxes(tree: Tree, X: np.ndarray, layout: Layout):
    """Axis-aligned boxes ``(bmin, bmax)``, each ``(nodes, 3)``, of every node's edges (whole
    segments, not only midpoints): the refit for moved vertices, ``O(N)``."""
    return _segment_boxes(X, layout.nxt, *tree)


@nb.njit(cache=True, inline="always")
def box_gap2(bmin, bmax, a, b):
    """Squared distance between the boxes of nodes ``a`` and ``b`` (0 where they overlap)."""
    s = 0.0
    for k in range(3):
        g = max(bmin[a, k] - bmax[b, k], bmin[b, k] - bmax[a, k])
        if g > 0.0:
            s += g * g
    return s


@nb.njit(cache=True, inline="always")
def box_diam2(bmin, bmax, a):
    """Squared diagonal of node ``a``'s box."""
    s = 0.0
    for k in range(3):
        d = bmax[a, k] - bmin[a, k]
        s += d * d
    return s


@nb.njit(cache=True)
def node_diam2(bmin, bmax):
    """Squared box diagonal of every node."""
    m = bmin.shape[0]
    d = np.empty(m)
    for node in range(m):
        d[node] = box_diam2(bmin, bmax, node)
    return d


@nb.njit(cache=True, inline="always")
def push_split(stack, top, a, b, left, right, diam2):
    """Push onto ``stack`` (pairs of nodes, ``top`` used) the pairs that split ``(a, b)``
    in a dual traversal: for a self pair the two children with themselves and with each other,
    else the larger node's halves against the other (a leaf is never split). Returns the
    stack (grown when full) and the new top."""
    if top + 3 > stack.shape[0]:
        grown = np.empty((2 * stack.shape[0], 2), np.int64)
        grown[:top] = stack[:top]
        stack = grown
    if a == b:
        la, ra = left[a], right[a]
        stack[top, 0], stack[top, 1] = la, ra
        stack[top + 1, 0], stack[top + 1, 1] = ra, ra
        stack[top + 2, 0], stack[top + 2, 1] = la, la
        return stack, top + 3
    if left[b] < 0 or (left[a] >= 0 and diam2[a] >= diam2[b]):
        stack[top, 0], stack[top, 1] = right[a], b
        stack[top + 1, 0], stack[top + 1, 1] = left[a], b
    else:
        stack[top, 0], stack[top, 1] = a, right[b]
        stack[top + 1, 0], stack[top + 1, 1] = a, left[b]
    return stack, top + 2
