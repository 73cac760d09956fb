"""Exact contact queries through the edge hierarchy (:mod:`bvh`): the first contact along a
motion and the closest pairs, with the same answers as the all-pairs searches of
:mod:`collision` in O(N log N) typical time (private; ``collision`` dispatches here).

Nothing is approximated: a pair of nodes is skipped only where no pair of their edges can
matter (the boxes of the edges' swept spheres do not meet, or the boxes are farther apart than
the best distance so far), every other pair of edges gets the all-pairs code's own test
(:func:`_pairs.pair_time`, :func:`_pairs.segment_distance2`). The contact time of a pair
depends on the pair alone, so the minimum is the same bits as the all-pairs search's.

Work is split into a fixed number of chunks of node pairs (a frontier of the dual traversal),
each searched depth first with its own running best; the minimum over chunks is exact, ties of
the closest pairs are broken by the smaller indices: the same result for any thread count. The
contact search's chunks also prune with each other's bests so far (see
:func:`_contact_search`).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ..geometry.edge_pairs import SLACK, edge_motion, pair_time, segment_distance2, tested
from ..geometry.layout import Layout
from . import bvh

_CHUNKS = 16
_TASKS = 8 * _CHUNKS  # node pairs in the frontier before the parallel search
#: The contact search's frontier: small tasks, so that a chunk soon reads what the others found.
_CONTACT_TASKS = 64 * _CHUNKS


@nb.njit(cache=True)
def _frontier(left, right, bmin, bmax, diam2, overlap, want, umin, umax, T, eps):
    """Node pairs (self pairs included) that hold every pair of edges a search must test,
    expanded breadth first from (root, root) until there are ``want`` of them or only leaf
    pairs are left; with ``overlap``, pairs that cannot come within ``eps`` before ``T``
    (:func:`_may_meet`) are dropped."""
    cur = np.zeros((1, 2), np.int64)
    while cur.shape[0] < want:
        nxt = np.empty((3 * cur.shape[0], 2), np.int64)
        count = 0
        grew = False
        for p in range(cur.shape[0]):
            a, b = cur[p, 0], cur[p, 1]
            if overlap and a != b and not _may_meet(bmin, bmax, umin, umax, a, b, T, eps):
                continue
            if left[a] >= 0 or left[b] >= 0:
                nxt, count = bvh.push_split(nxt, count, a, b, left, right, diam2)
                grew = True
            else:
                nxt[count, 0], nxt[count, 1] = a, b
                count += 1
        cur = nxt[:count].copy()
        if not grew:
            break
    return cur


# ------------------------------------------------------------------------------------------------
# first contact along a motion


@nb.njit(cache=True)
def _motion_boxes(X, U, nxt, perm, lo, hi, left, right, pad):
    """Per node the box of its edges' endpoints (padded by ``pad``) and the box of their
    velocities, bottom-up: at ``τ`` every point of the node's edges lies in the box swept
    back by ``τ`` times a velocity of the velocity box."""
    m = lo.shape[0]
    bmin = np.empty((m, 3))
    bmax = np.empty((m, 3))
    umin = np.empty((m, 3))
    umax = np.empty((m, 3))
    for node in range(m - 1, -1, -1):
        if left[node] < 0:
            for k in range(3):
                bmin[node, k] = np.inf
                bmax[node, k] = -np.inf
                umin[node, k] = np.inf
                umax[node, k] = -np.inf
            for q in range(lo[node], hi[node]):
                i = perm[q]
                for v in (i, nxt[i]):
                    for k in range(3):
                        bmin[node, k] = min(bmin[node, k], X[v, k] - pad)
                        bmax[node, k] = max(bmax[node, k], X[v, k] + pad)
                        umin[node, k] = min(umin[node, k], U[v, k])
                        umax[node, k] = max(umax[node, k], U[v, k])
        else:
            a, b = left[node], right[node]
            for k in range(3):
                bmin[node, k] = min(bmin[a, k], bmin[b, k])
                bmax[node, k] = max(bmax[a, k], bmax[b, k])
                umin[node, k] = min(umin[a, k], umin[b, k])
                umax[node, k] = max(umax[a, k], umax[b, k])
    return bmin, bmax, umin, umax


@nb.njit(cache=True, inline="always")
def _may_meet(bmin, bmax, umin, umax, a, b, T, eps):
    """Whether a point of node ``a``'s edges and one of node ``b``'s can come within ``eps``
    of each other at one time ``τ ∈ [0, T]`` (points ``x − τu``). False only where, on some
    axis, one node stays more than ``eps`` below the other at every such τ: the gap on an axis
    is bounded below by a linear function of τ, so checking both ends suffices. Two nodes
    moving alike keep their gap, however far they move (boxes swept over the whole motion
    would meet)."""
    for k in range(3):
        g = bmin[b, k] - bmax[a, k]  # a below b
        if g > eps and g - T * (umax[b, k] - umin[a, k]) > eps:
            return False
        g = bmin[a, k] - bmax[b, k]  # b below a
        if g > eps and g - T * (umax[a, k] - umin[b, k]) > eps:
            return False
    return True


@nb.njit(cache=True, parallel=True)
def _contact_search(X, U, nxt, starts, comp, closed, near, perm, lo, hi, left, right,
                    tau_max, eps, nchunks, want):
    """The first contact before ``tau_max``. A chunk publishes its best in ``best`` and starts
    each task from the least of all chunks' (read while they write: a stale value only prunes
    less, every value read is a pair's contact time or ``tau_max``, so every pair that can
    beat the answer is still tested and the answer is the same bits; only the work depends on
    the timing). Without it a chunk with no early contact of its own searched every pair that
    could meet before ``tau_max``: FHW at 10⁶ edges, a contact at 1.97 of 6, 1.29 against
    0.46 s."""
    mid, vel, spread, half, vmax = edge_motion(X, U, nxt)
    scale = 0.0
    for i in range(X.shape[0]):
        for k in range(3):
            scale = max(scale, abs(mid[i, k]) + tau_max * abs(vel[i, k]))
        scale = max(scale, half[i] + tau_max * spread[i])
    pad = 1e-12 * scale  # rounding of the pair test's arithmetic
    bmin, bmax, umin, umax = _motion_boxes(X, U, nxt, perm, lo, hi, left, right, pad)
    diam2 = bvh.node_diam2(bmin, bmax)
    reach = SLACK * eps  # what the pair test calls a contact
    tasks = _frontier(left, right, bmin, bmax, diam2, True, want, umin, umax, tau_max, reach)
    best = np.full(nchunks, tau_max)
    for cc in nb.prange(nchunks):
        ch = np.int64(cc)
        tb = tau_max
        stack = np.empty((128, 2), np.int64)
        for t in range(ch, tasks.shape[0], nchunks):
            tb = min(tb, best.min())  # the other chunks' bests so far
            stack[0, 0] = tasks[t, 0]
            stack[0, 1] = tasks[t, 1]
            top = 1
            while top > 0:
                top -= 1
                a, b = stack[top, 0], stack[top, 1]
                # only contacts before the best so far can change the answer
                if a != b and not _may_meet(bmin, bmax, umin, umax, a, b, tb, reach):
                    continue
                if left[a] < 0 and left[b] < 0:
                    before = tb
                    for q in range(lo[a], hi[a]):
                        for r in range(q + 1 if a == b else lo[b], hi[b]):
                            i, j = perm[q], perm[r]
                            if i > j:
                                i, j = j, i
                            if tested(i, j, starts, comp, closed, near):
                                tb = pair_time(X, U, nxt, i, j, mid, vel, spread, half, vmax,
                                               eps, tb)
                    if tb < before:
                        best[ch] = tb
                else:
                    stack, top = bvh.push_split(stack, top, a, b, left, right, diam2)
        best[ch] = tb
    return best.min()


def contact_time_tree(X: np.ndarray, U: np.ndarray, layout: Layout, tau_max: float,
                      eps: float, near=None, tree=None) -> float:
    """:func:`collision.contact_time_x` through the hierarchy (the same value; ``near`` as
    there; ``tree``: ``X``'s, built here if None): one search up to ``tau_max``. (Searching
    shorter horizons first, which paid while each chunk pruned with its own best alone, cost
    2–4× this: FHW, 10⁵ edges, 36–140 ms against 19–38 ms per search of a flow's step.)"""
    if tree is None:
        tree = bvh.build(X, layout)
    near = np.ones(layout.k, np.int64) if near is None else near
    return float(_contact_search(X, np.ascontiguousarray(U), layout.nxt, layout.starts,
                                 layout.comp, layout.closed_flags, near, *tree, float(tau_max),
                                 float(eps), _CHUNKS, _CONTACT_TASKS))


# ------------------------------------------------------------------------------------------------
# closest pairs


@nb.njit(cache=True, inline="always")
def _better(d2, i, j, best, bi, bj):
    return d2 < best or (d2 == best and (i < bi or (i == bi and j < bj)))


@nb.njit(cache=True, parallel=True)
def _closest_search(X, nxt, starts, comp, closed, perm, lo, hi, left, right, bmin, bmax,
                    min_gap, nchunks, want, edges):
    """Per chunk its closest pair of vertices (``min_gap`` apart along a component) and, with
    ``edges``, of edges. As in :func:`_contact_search` a chunk prunes with the least of all
    chunks' bests so far, read while they write (a stale one prunes less; a box pair is
    dropped only when strictly farther, so ties still reach :func:`_least`): the same pairs."""
    diam2 = bvh.node_diam2(bmin, bmax)
    tasks = _frontier(left, right, bmin, bmax, diam2, False, want, bmin, bmax, 0.0, 0.0)
    big = np.iinfo(np.int64).max
    vbest = np.full(nchunks, np.inf)
    vidx = np.full((nchunks, 2), big, np.int64)
    ebest = np.full(nchunks, np.inf)
    eidx = np.full((nchunks, 2), big, np.int64)
    epar = np.zeros((nchunks, 2))
    for cc in nb.prange(nchunks):
        ch = np.int64(cc)
        vb, vi0, vj0 = np.inf, big, big
        # without the edges, their bound never keeps a box pair (−∞)
        eb, ei0, ej0, es, et = np.inf if edges else -np.inf, big, big, 0.0, 0.0
        stack = np.empty((128, 2), np.int64)
        for t in range(ch, tasks.shape[0], nchunks):
            # the other chunks' bests so far, without their pairs: a pair of this chunk at
            # the same distance still counts (its indices beat ``big``)
            sv = vbest.min()
            if sv < vb:
                vb, vi0, vj0 = sv, big, big
            se = ebest.min()  # without the edges every eb is −∞: nothing taken
            if se < eb:
                eb, ei0, ej0 = se, big, big
            stack[0, 0] = tasks[t, 0]
            stack[0, 1] = tasks[t, 1]
            top = 1
            while top > 0:
                top -= 1
                a, b = stack[top, 0], stack[top, 1]
                if a != b:
                    g = bvh.box_gap2(bmin, bmax, a, b)
                    if g > vb and g > eb:
                        continue
                if left[a] < 0 and left[b] < 0:
                    for q in range(lo[a], hi[a]):
                        for r in range(q + 1 if a == b else lo[b], hi[b]):
                            i, j = perm[q], perm[r]
                            if i > j:
                                i, j = j, i
                            c = comp[i]
                            same = comp[j] == c
                            size = starts[c + 1] - starts[c]
                            gap = j - i
                            if same and closed[c]:  # an open one: no way round the ends
                                gap = min(gap, size - gap)
                            if (not same) or gap >= min_gap:
                                d2 = (X[i, 0] - X[j, 0]) ** 2 + (X[i, 1] - X[j, 1]) ** 2 + (
                                    X[i, 2] - X[j, 2]
                                ) ** 2
                                if _better(d2, i, j, vb, vi0, vj0):
                                    vb, vi0, vj0 = d2, i, j
                            i1, j1 = nxt[i], nxt[j]
                            # an open component's dummy edge (a point) is no edge here
                            if edges and ((not same) or gap >= 2) and i1 != i and j1 != j:
                                d2, s, u = segment_distance2(
                                    X[i, 0], X[i, 1], X[i, 2], X[i1, 0], X[i1, 1], X[i1, 2],
                                    X[j, 0], X[j, 1], X[j, 2], X[j1, 0], X[j1, 1], X[j1, 2],
                                )
                                if _better(d2, i, j, eb, ei0, ej0):
                                    eb, ei0, ej0, es, et = d2, i, j, s, u
                    vbest[ch] = vb  # published for the other chunks (their pairs at the end)
                    ebest[ch] = eb
                else:
                    stack, top = bvh.push_split(stack, top, a, b, left, right, diam2)
        vbest[ch], vidx[ch, 0], vidx[ch, 1] = vb, vi0, vj0
        ebest[ch], eidx[ch, 0], eidx[ch, 1] = eb, ei0, ej0
        epar[ch, 0], epar[ch, 1] = es, et
    return vbest, vidx, ebest, eidx, epar


def closest_pairs_tree(X: np.ndarray, layout: Layout, min_gap: int = 4):
    """:func:`collision.closest_pairs` through the hierarchy (the same distances; of several
    pairs at the same distance, the one with the smallest indices)."""
    vb, vi, eb, ei, ep = _closest(X, layout, min_gap, True)
    a, b = _least(vb, vi), _least(eb, ei)
    return (
        (float(np.sqrt(vb[a])), (int(vi[a, 0]), int(vi[a, 1]))),
        (float(np.sqrt(eb[b])), (int(ei[b, 0]), int(ei[b, 1])), (float(ep[b, 0]),
                                                                 float(ep[b, 1]))),
    )


def closest_vertices_tree(X: np.ndarray, layout: Layout, min_gap: int = 4):
    """The first half of :func:`closest_pairs_tree`, ``(distance, (i, j))``, without the
    edges' distances: the same vertices (of pairs at one distance, the smallest indices),
    searched in boxes of the vertices alone. FHW, one thread, best of 7 with the hierarchy's
    build: 9.7 against 20.4 ms for both halves at 25 000 edges, 41 against 103 ms at 100 000
    (the hs preconditioner asks it at every level of every iterate)."""
    vb, vi, *_ = _closest(X, layout, min_gap, False)
    a = _least(vb, vi)
    return float(np.sqrt(vb[a])), (int(vi[a, 0]), int(vi[a, 1]))


def _closest(X, layout, min_gap, edges: bool):
    """:func:`_closest_search` on a fresh hierarchy: its boxes the segments' with ``edges``,
    the vertices' alone without."""
    tree = bvh.build(X, layout)
    bmin, bmax = bvh.segment_boxes(tree, X, layout) if edges else bvh.vertex_boxes(tree, X)
    closed = np.ones(layout.k, np.bool_) if layout.closed is None else layout.closed
    return _closest_search(X, layout.nxt, layout.starts, layout.comp, closed, *tree, bmin,
                           bmax, int(min_gap), _CHUNKS, _TASKS, edges)


def _least(best, idx) -> int:
    """The chunk with the least distance, of equal ones the smallest indices."""
    return min(range(len(best)), key=lambda c: (best[c], idx[c, 0], idx[c, 1]))
