"""Bounding-volume hierarchy over the edges of a knot or link (private; the tree engine's and
the contact search's shared structure).

A binary tree built by splits of the edge midpoints along the longest side of their bounding
box at the quantile that leaves every leaf but one full, ``O(N log N)``. Nodes are stored in
preorder, so a parent always comes before its children: a pass in reverse index order is
bottom-up (refit), one in index order top-down. Each node owns the contiguous range
``perm[lo:hi]`` of edge indices; a leaf holds at most ``leaf_size`` edges.

The topology depends only on the midpoints at build time. ``refit`` recomputes the bounds for
moved vertices in ``O(N)``: the tree stays valid (every bound is exact for its edges), only
less tight, so a refitted tree gives the same exact answers as a fresh one.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from ..geometry.layout import Layout

# Edges per leaf: the near field's SIMD width (``_near_field._LANES``); leaves of 4, 12 and 16
# edges measured slower (docs/lab/tree-engine.md, "Where the time goes now").
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


@nb.njit(cache=True, inline="always")
def _before(key, perm, p, q):
    """Position ``p`` sorts before ``q``: by key, ties by edge index (a total order)."""
    return key[p] < key[q] or (key[p] == key[q] and perm[p] < perm[q])


@nb.njit(cache=True, inline="always")
def _swap(key, perm, p, q):
    key[p], key[q] = key[q], key[p]
    perm[p], perm[q] = perm[q], perm[p]


@nb.njit(cache=True)
def _select(key, perm, a, b, k):
    """Reorder ``key[a:b]``, ``perm[a:b]`` so that the ``k − a`` smallest (key, edge index)
    come first: quickselect with pivots at pseudo-random positions (a hash of the range, so
    the same every time; median-of-three pivots went quadratic on a circle, whose coordinates
    along an axis rise and fall), and after 64 rounds a sort of what is left (O(n log n) at
    worst)."""
    lo, hi = a, b - 1
    state = np.uint64(0x9E3779B97F4A7C15) ^ np.uint64(a) ^ (np.uint64(b) << np.uint64(32))
    rounds = 0
    while hi > lo:
        rounds += 1
        if rounds > 64:
            _sort_range(key, perm, lo, hi + 1)
            return
        # xorshift64*
        state ^= state >> np.uint64(12)
        state ^= state << np.uint64(25)
        state ^= state >> np.uint64(27)
        r = state * np.uint64(0x2545F4914F6CDD1D)
        _swap(key, perm, lo + np.int64(r % np.uint64(hi - lo + 1)), hi)
        store = lo
        for q in range(lo, hi):
            if _before(key, perm, q, hi):
                _swap(key, perm, q, store)
                store += 1
        _swap(key, perm, store, hi)
        if store == k:
            return
        if store < k:
            lo = store + 1
        else:
            hi = store - 1


@nb.njit(cache=True)
def _sort_range(key, perm, a, b):
    """Sort ``key[a:b]``, ``perm[a:b]`` by (key, edge index): by index, then stably by key."""
    order = np.argsort(perm[a:b], kind="mergesort")
    k1 = key[a:b][order]
    p1 = perm[a:b][order]
    order = np.argsort(k1, kind="mergesort")
    key[a:b] = k1[order]
    perm[a:b] = p1[order]


@nb.njit(cache=True, inline="always")
def _leaves(count, leaf_size):
    return (count + leaf_size - 1) // leaf_size


@nb.njit(cache=True, parallel=True)
def _build(mid, leaf_size):
    """Nodes in preorder (a node, its left subtree, its right subtree): a node of ``k`` leaves
    splits into ``⌈k/2⌉`` full leaves' worth of edges on the left and the rest on the right,
    at that quantile of the midpoints along the longest side of their box; so every leaf but
    the last is full and a subtree of ``k`` leaves has ``2k − 1`` nodes. Built level by level,
    each level's nodes in parallel (each reorders its own range): the same tree for every
    thread count."""
    n = mid.shape[0]
    m = 2 * _leaves(n, leaf_size) - 1
    perm = np.arange(n)
    key = np.empty(n)
    lo = np.empty(m, np.int64)
    hi = np.empty(m, np.int64)
    left = np.full(m, -1, np.int64)
    right = np.full(m, -1, np.int64)
    lo[0] = 0
    hi[0] = n
    level = np.zeros(1, np.int64)
    while level.shape[0] > 0:
        nxt = np.full(2 * level.shape[0], -1, np.int64)
        for t in nb.prange(level.shape[0]):
            node = level[t]
            a, b = lo[node], hi[node]
            k = _leaves(b - a, leaf_size)
            if k <= 1:
                continue
            # longest side of the midpoints' box (the first of equal sides), one pass over the
            # edges: a gather of a row, not three of one coordinate (the build 0.83–0.85 of
            # the time, 2 400 to 10⁵ edges)
            mn0 = mn1 = mn2 = np.inf
            mx0 = mx1 = mx2 = -np.inf
            for q in range(a, b):
                p = perm[q]
                v0, v1, v2 = mid[p, 0], mid[p, 1], mid[p, 2]
                mn0, mx0 = min(mn0, v0), max(mx0, v0)
                mn1, mx1 = min(mn1, v1), max(mx1, v1)
                mn2, mx2 = min(mn2, v2), max(mx2, v2)
            axis = 0
            ext = mx0 - mn0
            if mx1 - mn1 > ext:
                ext = mx1 - mn1
                axis = 1
            if mx2 - mn2 > ext:
                axis = 2
            for q in range(a, b):
                key[q] = mid[perm[q], axis]
            kl = (k + 1) // 2
            cut = a + leaf_size * kl
            _select(key, perm, a, b, cut)
            c1 = node + 1
            c2 = node + 2 * kl
            left[node] = c1
            right[node] = c2
            lo[c1], hi[c1] = a, cut
            lo[c2], hi[c2] = cut, b
            nxt[2 * t] = c1
            nxt[2 * t + 1] = c2
        count = 0
        for t in range(nxt.shape[0]):
            if nxt[t] >= 0:
                nxt[count] = nxt[t]
                count += 1
        level = nxt[:count].copy()
    return perm, lo, hi, left, right


def build(X: np.ndarray, layout: Layout, leaf_size: int = LEAF_SIZE,
          edges: np.ndarray | None = None) -> Tree:
    """Hierarchy over the edges ``(X[I], X[nxt[I]])`` split at their midpoints' quantiles;
    ``edges`` (sorted edge indices, default all) restricts it to those (the real edges of a
    layout with open components, whose dummy edges hold no segment)."""
    mid = 0.5 * (X + X[layout.nxt])
    if edges is None:
        return Tree(*_build(np.ascontiguousarray(mid), int(leaf_size)))
    perm, lo, hi, left, right = _build(np.ascontiguousarray(mid[edges]), int(leaf_size))
    return Tree(np.ascontiguousarray(edges[perm]), lo, hi, left, right)


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


def vertex_boxes(tree: Tree, X: np.ndarray):
    """Axis-aligned boxes ``(bmin, bmax)`` of every node's first vertices (the edges' own
    ``X[I]``, without their ends ``X[nxt[I]]``): boxes for questions about vertices."""
    return _segment_boxes(X, np.arange(X.shape[0]), *tree)


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


# ------------------------------------------------------------------------------------------------
# the dual traversal: one walk, parameterized by its test and what it does with a pair

#: Verdicts of a traversal's ``test`` on a pair of nodes: nothing in it matters (dropped), it is
#: taken whole (a far pair, given to ``visit``), or it is split (a pair of leaves: ``visit``).
PRUNE = 0
ACCEPT = 1
SPLIT = 2


@nb.njit(cache=True, inline="always")
def dual_traversal(stack, a0, b0, left, right, diam2, test, visit, ctx, state):
    """Depth-first dual traversal from the pair of nodes ``(a0, b0)``: ``test(a, b, ctx,
    state)`` gives each pair's verdict (:data:`PRUNE`, :data:`ACCEPT`, :data:`SPLIT`); an
    accepted pair and every pair of leaves to split go to ``visit(a, b, accepted, ctx, state)``,
    which returns ``(go on, state)``; other pairs are split by :func:`push_split`, the last
    pushed visited first. Returns the stack (grown when full), the state, and whether the walk
    ran to its end.

    Inlined into its caller (``inline="always"``), it is compiled with the caller's ``test``
    and ``visit`` as direct calls and the caller stays cacheable (a jitted function passed to a
    kernel compiled apart makes its callers uncacheable). The hs metric's split uses it; the
    energy's split and the contact searches keep their own loops, measured up to 2× faster
    (docs/lab/tree-engine.md, "One dual traversal")."""
    stack[0, 0] = a0
    stack[0, 1] = b0
    top = 1
    while top > 0:
        top -= 1
        a = stack[top, 0]
        b = stack[top, 1]
        verdict = test(a, b, ctx, state)
        if verdict == PRUNE:
            continue
        if verdict == SPLIT and (left[a] >= 0 or left[b] >= 0):
            stack, top = push_split(stack, top, a, b, left, right, diam2)
            continue
        go, state = visit(a, b, verdict == ACCEPT, ctx, state)
        if not go:
            return stack, state, False
    return stack, state, True
