"""Möbius energy and its exact derivative by Barnes–Hut on the edge hierarchy (the tree engine).

The energy of docs/design.md is a sum over ordered pairs of disjoint edges
(``moebius_dense.py`` sums all of them). Here the pairs are split by a dual traversal of the
hierarchy (:mod:`bvh`) into

* the **far field**: pairs of clusters ``(A, B)`` of one component each whose boxes are apart,
  ``max(diam A, diam B) ≤ θ · gap(A, B)``, summed by the expansion of the kernel to second
  order in the clusters' moments (:mod:`._far_field`). At the default θ the relative errors
  measured at most 8.2e-6 (energy) and 5.0e-4 (gradient) on 7_2, FHW, a link of three rings
  and a non-equilateral 7_2 of 5 000 and 20 000 edges (docs/lab/tree-engine.md); the gradient's
  falls about like θ³. Open components (docs/api.md, "Open curves"): their pairs take
  O'Hara's kernel ``l_I l_J/|d|²``, so clusters of open components only are far whatever
  components they hold (θ times :data:`OPEN_THETA` where they may share one); the arc-length
  part ``−l_I l_J/D²`` of O'Hara's regularized energy is :mod:`._arc_field`'s, with the arc
  terms that make the far field cancel on straight pieces as the exact sum does. Measured at
  the default θ on open cables, bundles and mixed layouts (tests/core/test_open_tree.py):
  energy within 1e-5; gradient within 1e-4 on bundles and mixed layouts, 1.5e-3 on single
  nearly straight cables (where the energy nearly cancels).
* the **near field**: every other pair (always the pairs close in space, and so those close
  along the curve: boxes of edges sharing a vertex touch), summed exactly with the kernel of
  ``moebius_dense.py`` (:mod:`._near_field`).

The gradient is the exact derivative of this approximated sum for the fixed split: each
cluster's derivative with respect to its moments is pushed down to its edges by the chain rule
(:func:`._far_field._push_down`). Both passes are parallel over targets (each target sums its
own ordered pairs, so nothing is shared between threads): the results are the same bits for
every thread count.

The split (the "frame": hierarchy and interaction lists) is a function of the polygon it was
built at. :class:`Frame` keeps it so that several polygons can be evaluated with one split (a
line search sees one smooth function); :func:`tree_energy` builds a fresh one.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ..energies.moebius import THETA  # the default θ: the energy's record
from ..geometry.layout import Layout
from . import bvh
from .arc_field import ArcField
from .far_field import _cluster_data, _far, _far_to_edges, _push_down
from .near_field import _NEAR_PIECES, _near, _near_schedule, _to_vertices

# Fixed split of the traversal into chunks (the same lists for every thread count).
_SPLIT_CHUNKS = 16


def check_theta(theta) -> float:
    """``theta`` as a float in (0, 2), else ValueError naming it."""
    try:
        t = float(theta)
    except (TypeError, ValueError):
        raise ValueError(f"theta must be a number in (0, 2), got {theta!r}") from None
    if not (0.0 < t < 2.0):
        raise ValueError(f"theta must be a number in (0, 2), got {theta!r}")
    return t


# ------------------------------------------------------------------------------------------------
# cluster data


@nb.njit(cache=True)
def _edge_arrays(X, nxt, comp, starts, perm):
    """Edge vectors, midpoints, lengths, components and positions along their component, in
    tree order."""
    n = perm.shape[0]
    E = np.empty((n, 3))
    M = np.empty((n, 3))
    ln = np.empty(n)
    cp = np.empty(n, np.int64)
    pos = np.empty(n, np.int64)
    size = np.empty(n, np.int64)
    for q in range(n):
        i = perm[q]
        j = nxt[i]
        s = 0.0
        for k in range(3):
            e = X[j, k] - X[i, k]
            E[q, k] = e
            M[q, k] = 0.5 * (X[i, k] + X[j, k])
            s += e * e
        ln[q] = np.sqrt(s)
        c = comp[i]
        cp[q] = c
        pos[q] = i - starts[c]
        size[q] = starts[c + 1] - starts[c]
    return E, M, ln, cp, pos, size


# ------------------------------------------------------------------------------------------------
# the split into far and near pairs


# The depth-first split's stack: a step pops one pair and pushes at most three whose depths
# (depth of a + depth of b) are larger by one or two, so the stack never holds more than
# 2 · (2 · tree depth) + 1 pairs; a tree whose splits halve the leaves, over fewer than 2^63
# edges, is less than 64 deep.
_STACK = 512


@nb.njit(cache=True)
def _node_table(bmin, bmax, nc):
    """Per node in one row (one cache line): box min (0–2), box max (3–5), squared diagonal
    (6) and component (7, −1 for several): what the split reads of a node."""
    m = bmin.shape[0]
    tab = np.empty((m, 8))
    for i in range(m):
        s = 0.0
        for k in range(3):
            tab[i, k] = bmin[i, k]
            tab[i, 3 + k] = bmax[i, k]
            d = bmax[i, k] - bmin[i, k]
            s += d * d
        tab[i, 6] = s
        tab[i, 7] = nc[i]
    return tab


#: Kinds of nodes (``nc`` of :func:`._far_field._cluster_data`): a closed component ``c ≥ 0``,
#: an open one ``OPEN_KIND − c`` (≤ −3), several open ones −2, any other mixture −1. Every pair
#: with an edge of an open component takes O'Hara's kernel ``l_I l_J/|d|²`` (its arc-length
#: part is :mod:`._arc_field`'s), so a node of open components only is far from any node whose
#: box is apart.
OPEN_KIND = -3
# Far pairs that may hold two edges of one open component take theta times this: there the
# 3-D sum and the arc-length part nearly cancel, and the far field's error (its gradient's
# falls like theta³) is measured against what is left (single cables of 1 000 to 2 000 edges,
# default theta, gradient relative to the exact one: 6e-3 at factor 1, 1.5e-3 to 2.9e-3 at
# 0.5, 7e-4 to 1.4e-3 at 0.4). Which pairs may share one is told by the nodes' masks of open
# components (open_masks): without them every pair of nodes holding several cables took it,
# and 100 cables of 200 edges had 2.0M near pairs of leaves instead of 1.25M (1.2M at 1).
OPEN_THETA = 0.4


@nb.njit(cache=True, inline="always")
def _kinds_admissible(ka, kb):
    """Clusters whose pairs take one kernel: both of closed components (one each), or one of
    open components only (kinds ≤ −2; −1: a node of several components, not all open)."""
    return (ka >= 0 and kb >= 0) or ka <= -2 or kb <= -2


@nb.njit(cache=True, inline="always")
def _may_share_open(ka, kb, masks, a, b):
    """Whether nodes ``a`` and ``b`` of kinds ``ka``, ``kb`` may hold edges of one open
    component: ``masks`` (nodes, 2) has bit ``c mod 128`` of every open component ``c`` a node
    holds (two nodes with no bit in common hold none in common; :func:`open_masks`)."""
    if ka >= 0 or kb >= 0:
        return False
    return (masks[a, 0] & masks[b, 0]) != 0 or (masks[a, 1] & masks[b, 1]) != 0


def open_masks(layout: Layout, tree: bvh.Tree) -> np.ndarray:
    """``(nodes, 2)`` uint64: bit ``c mod 128`` set for every open component ``c`` a node
    holds (all zero for closed layouts, without a pass: it took 5.8 ms at 10⁶ edges)."""
    if not layout.has_open:
        return np.zeros((tree.size, 2), np.uint64)
    bits = np.zeros((layout.n, 2), np.uint64)
    c = layout.comp
    on = ~layout.closed[c]
    w = (c % 128) // 64
    b = np.left_shift(np.uint64(1), (c % 64).astype(np.uint64))
    bits[np.flatnonzero(on & (w == 0)), 0] = b[on & (w == 0)]
    bits[np.flatnonzero(on & (w == 1)), 1] = b[on & (w == 1)]
    return _node_masks(bits, tree.perm, tree.lo, tree.hi, tree.left, tree.right)


@nb.njit(cache=True)
def _node_masks(bits, perm, lo, hi, left, right):
    """Per node the OR of its edges' ``bits`` (2 words), bottom-up (children come after their
    parents)."""
    m = lo.shape[0]
    masks = np.zeros((m, 2), np.uint64)
    for node in range(m - 1, -1, -1):
        for k in range(2):
            if left[node] < 0:
                for q in range(lo[node], hi[node]):
                    masks[node, k] |= bits[perm[q], k]
            else:
                masks[node, k] = masks[left[node], k] | masks[right[node], k]
    return masks


@nb.njit(cache=True, inline="always")
def _admissible_row(tab, a, b, theta2, masks):
    """Far pair: boxes apart, one component each, ``max(diam²) ≤ θ² gap²`` (rows of
    :func:`_node_table`)."""
    g = 0.0
    for k in range(3):
        x = max(tab[a, k] - tab[b, 3 + k], tab[b, k] - tab[a, 3 + k])
        if x > 0.0:
            g += x * x
    ka, kb = tab[a, 7], tab[b, 7]
    if g <= 0.0 or not _kinds_admissible(ka, kb):
        return False
    t2 = theta2 * (OPEN_THETA * OPEN_THETA) if _may_share_open(ka, kb, masks, a, b) else theta2
    return max(tab[a, 6], tab[b, 6]) <= t2 * g


@nb.njit(cache=True)
def _descend(a0, b0, left, right, tab, theta2, masks, stack, far, nfar, near, nnear):
    """Depth-first split of the pair (a0, b0): far pairs (admissible clusters) and near pairs of
    leaves written to ``far``/``near`` from ``nfar``/``nnear`` on; returns the new counts, or
    (−1, −1) when an array is full. The order of :func:`bvh.push_split`: a self pair's children
    with themselves, then with each other; else the larger node's halves, left first."""
    stack[0, 0] = a0
    stack[0, 1] = b0
    top = 1
    fcap = far.shape[0]
    ncap = near.shape[0]
    while top > 0:
        top -= 1
        a = stack[top, 0]
        b = stack[top, 1]
        la = left[a]
        if a == b:
            if la < 0:
                if nnear == ncap:
                    return -1, -1
                near[nnear, 0] = a
                near[nnear, 1] = b
                nnear += 1
            else:
                ra = right[a]
                stack[top, 0] = la
                stack[top, 1] = ra
                stack[top + 1, 0] = ra
                stack[top + 1, 1] = ra
                stack[top + 2, 0] = la
                stack[top + 2, 1] = la
                top += 3
            continue
        if _admissible_row(tab, a, b, theta2, masks):
            if nfar == fcap:
                return -1, -1
            far[nfar, 0] = a
            far[nfar, 1] = b
            nfar += 1
            continue
        lb = left[b]
        if la < 0 and lb < 0:
            if nnear == ncap:
                return -1, -1
            near[nnear, 0] = a
            near[nnear, 1] = b
            nnear += 1
        elif lb < 0 or (la >= 0 and tab[a, 6] >= tab[b, 6]):
            stack[top, 0] = right[a]
            stack[top, 1] = b
            stack[top + 1, 0] = la
            stack[top + 1, 1] = b
            top += 2
        else:
            stack[top, 0] = a
            stack[top, 1] = right[b]
            stack[top + 1, 0] = a
            stack[top + 1, 1] = lb
            top += 2
    return nfar, nnear


@nb.njit(cache=True, inline="always")
def _admissible(a, b, bmin, bmax, nc, diam2, theta2, masks):
    gap2 = bvh.box_gap2(bmin, bmax, a, b)
    if gap2 <= 0.0 or not _kinds_admissible(nc[a], nc[b]):
        return False
    t2 = (theta2 * (OPEN_THETA * OPEN_THETA) if _may_share_open(nc[a], nc[b], masks, a, b)
          else theta2)
    return max(diam2[a], diam2[b]) <= t2 * gap2


@nb.njit(cache=True)
def _tasks(left, right, bmin, bmax, nc, diam2, theta2, masks, want):
    """The pairs of nodes the depth-first split starts from: (root, root) expanded breadth
    first, as the split would (far and leaf pairs are final), until there are ``want``."""
    cur = np.zeros((1, 2), np.int64)
    while cur.shape[0] < want:
        nxt = np.empty((3 * cur.shape[0], 2), np.int64)
        count = 0
        grew = False
        for p in range(cur.shape[0]):
            a, b = cur[p, 0], cur[p, 1]
            if (left[a] >= 0 or left[b] >= 0) and (
                    a == b or not _admissible(a, b, bmin, bmax, nc, diam2, theta2, masks)):
                nxt, count = bvh.push_split(nxt, count, a, b, left, right, diam2)
                grew = True
            else:
                nxt[count, 0], nxt[count, 1] = a, b
                count += 1
        cur = nxt[:count].copy()
        if not grew:
            break
    return cur


@nb.njit(cache=True, parallel=True)
def _split(left, right, bmin, bmax, nc, theta2, masks, nchunks, want, cap):
    """Dual traversal from (root, root): unordered far pairs (admissible clusters) and near
    pairs of leaves (self pairs ``(A, A)`` included). The pairs of a frontier of ``want`` node
    pairs are split depth first in ``nchunks`` fixed chunks, each into a buffer of ``cap``
    pairs (all chunks again with twice the room while one runs out), and concatenated in
    chunk order: the same lists for every thread count."""
    diam2 = bvh.node_diam2(bmin, bmax)
    tasks = _tasks(left, right, bmin, bmax, nc, diam2, theta2, masks, want)
    tab = _node_table(bmin, bmax, nc)
    nf = np.zeros(nchunks, np.int64)
    nn = np.zeros(nchunks, np.int64)
    room = max(cap, 1)
    while True:
        # node indices in 32 bits: half these buffers' pages (a first call faults in each)
        fbuf = np.empty((nchunks, room, 2), np.int32)
        nbuf = np.empty((nchunks, room, 2), np.int32)
        for cc in nb.prange(nchunks):
            ch = np.int64(cc)
            stack = np.empty((_STACK, 2), np.int64)
            f, n = 0, 0
            for t in range(ch, tasks.shape[0], nchunks):
                f, n = _descend(tasks[t, 0], tasks[t, 1], left, right, tab, theta2, masks, stack,
                                fbuf[ch], f, nbuf[ch], n)
                if f < 0:
                    break
            nf[ch] = f
            nn[ch] = n
        if nf.min() >= 0:
            break
        room *= 2
    of = np.zeros(nchunks + 1, np.int64)
    on = np.zeros(nchunks + 1, np.int64)
    for ch in range(nchunks):
        of[ch + 1] = of[ch] + nf[ch]
        on[ch + 1] = on[ch] + nn[ch]
    # the chunks moved down to their place in the buffers themselves (never up: a chunk's place
    # is at or below its start), not copied: the pages of a second list are not touched
    far = _compact(fbuf.reshape(nchunks * room, 2), nf, of, room)
    near = _compact(nbuf.reshape(nchunks * room, 2), nn, on, room)
    return far, near


@nb.njit(cache=True, inline="always")
def _compact(flat, counts, offsets, room):
    """The pairs of every chunk (``counts[ch]`` at ``ch · room``) moved to ``offsets[ch]`` in
    chunk order, forward (an overlap lies above the place written); the first
    ``offsets[-1]`` rows."""
    for ch in range(1, counts.shape[0]):
        src = ch * room
        dst = offsets[ch]
        for k in range(counts[ch]):
            flat[dst + k, 0] = flat[src + k, 0]
            flat[dst + k, 1] = flat[src + k, 1]
    return flat[:offsets[counts.shape[0]]]


@nb.njit(cache=True)
def _by_target(pairs, m):
    """CSR lists ``(offsets, partners)`` of every node's ordered partners: each unordered pair
    ``(a, b)`` appears as a → b and b → a (once for a self pair)."""
    cnt = np.zeros(m + 1, np.int64)
    for p in range(pairs.shape[0]):
        a, b = pairs[p, 0], pairs[p, 1]
        cnt[a + 1] += 1
        if a != b:
            cnt[b + 1] += 1
    for k in range(m):
        cnt[k + 1] += cnt[k]
    fill = cnt[:m].copy()
    out = np.empty(cnt[m], np.int32)  # node indices (the offsets in 64 bits)
    for p in range(pairs.shape[0]):
        a, b = pairs[p, 0], pairs[p, 1]
        out[fill[a]] = b
        fill[a] += 1
        if a != b:
            out[fill[b]] = a
            fill[b] += 1
    return cnt, out


@nb.njit(cache=True)
def _neighbours(perm, nxt, prv):
    """Per tree position the tree positions of the previous and the next edge along the curve
    (always in a near partner: boxes of edges that share a vertex touch), and per edge its tree
    position (−1 for the dummy edges of open components, which are not in the tree: the ends
    of an open polyline have no neighbour there)."""
    n = perm.shape[0]
    at = np.full(nxt.shape[0], -1, np.int64)  # −1: a dummy edge of an open component
    for q in range(n):
        at[perm[q]] = q
    nbr = np.empty((n, 2), np.int64)
    for q in range(n):
        i = perm[q]
        nbr[q, 0] = at[prv[i]]
        nbr[q, 1] = at[nxt[i]]
    return nbr, at


@nb.njit(cache=True)
def _near_lists(leaves, pairs, m, perm, nxt, prv):
    """What the near field reads besides the edges: its schedule of the pairs of near leaves
    (:func:`._near_field._near_schedule`) and :func:`_neighbours`."""
    schedule = _near_schedule(leaves, pairs, m, min(leaves.shape[0], _NEAR_PIECES))
    nbr, at = _neighbours(perm, nxt, prv)
    return *schedule, nbr, at


# ------------------------------------------------------------------------------------------------
# public: a frame (hierarchy + split) and evaluations with it


class Frame:
    """The hierarchy and the far/near split built at one polygon, reusable at nearby ones.

    Parameters
    ----------
    X : (N, 3) array
        Stacked vertices (see ``_layout``).
    layout : Layout
    theta : float
        Admissibility: clusters are far when ``max(diam) ≤ theta · gap`` of their boxes.
    leaf_size : int
        Edges per leaf at most.
    keep_near : bool
        Keep the near pairs of leaves as :attr:`near` (for checks; the evaluations read only
        what :meth:`_near_setup` derives from them; 32-bit indices, 53 MB at 10⁶ edges).
    """

    #: Whether open components take O'Hara's arc-length part (:mod:`._arc_field`; the Möbius
    #: energy's).
    arc_part = True

    def __init__(self, X: np.ndarray, layout: Layout, theta: float = THETA,
                 leaf_size: int = bvh.LEAF_SIZE, keep_near: bool = False):
        self.layout = layout
        self.theta = check_theta(theta)
        # open components: their dummy edges (._layout) stay out of the tree
        tree = bvh.build(X, layout, leaf_size,
                         np.flatnonzero(layout.real) if layout.has_open else None)
        self.tree = tree
        self._closed_count = layout.k if layout.closed is None else int(layout.closed.sum())
        bmin, bmax = bvh.segment_boxes(tree, X, layout)
        edges = self._edges(X)
        # the near field's components: an open component's edges match no other edge (its
        # pairs take O'Hara's kernel, as edges of two components)
        self._near_cp = edges[3]
        #: every component open: the near and far fields' pairs take the length part alone
        self._all_open = bool(layout.has_open and not layout.closed.any())
        if layout.has_open:
            cp = layout.comp[tree.perm]
            self._near_cp = np.where(layout.closed[cp], cp, -2 - np.arange(cp.shape[0]))
        clusters = self._clusters(edges)
        # what an evaluation at the frame's own polygon reuses (the engine's next call)
        self._own = (X.copy(), edges, clusters)
        nc = clusters[-1]
        m = tree.size
        # a chunk's list held up to 8.5 m / (theta · chunks) pairs (FHW, trefoil and ring, 600 to
        # 40 000 edges, θ 0.25–0.5): room for 12, since a chunk that runs out has every chunk
        # split again (at 2 400 edges, θ 0.5, twice the time); untouched room costs no pages.
        # Never more than every pair of nodes (a tiny theta asked for petabytes here)
        cap = max(256, int(min(12 * m / self.theta, m * (m + 1) / 2) / _SPLIT_CHUNKS))
        far, near = _split(tree.left, tree.right, bmin, bmax, nc, self.theta**2,
                           open_masks(layout, tree), _SPLIT_CHUNKS,
                           64 * _SPLIT_CHUNKS, cap)
        self.far_pairs = far.shape[0]
        self.near_pairs = near.shape[0]
        self.foff, self.fpart = _by_target(far, m)
        del far
        self.near = near if keep_near else None
        self.leaves = np.flatnonzero(tree.left < 0).astype(np.int64)
        self._near_setup(near, m)
        del near
        #: The arc-length part of the open components' energy (None: all closed).
        self.arc = (ArcField(layout, X, tree, self.foff, self.fpart)
                    if layout.has_open and self.arc_part else None)

    def _clusters(self, edges):
        """Per node what the far field reads, the nodes' kinds (``nc``) last."""
        tree = self.tree
        return _cluster_data(*edges[:4], tree.lo, tree.hi, tree.left, tree.right)

    def _near_setup(self, near: np.ndarray, m: int):
        """What the near field reads besides the edges (:func:`_near_lists`)."""
        tree, layout = self.tree, self.layout
        *self._near_lists, self._at = _near_lists(self.leaves, near, m, tree.perm, layout.nxt,
                                                  layout.prv)

    def _edges(self, X: np.ndarray):
        """:func:`_edge_arrays` in tree order, an open component's edges of kind
        :data:`OPEN_KIND` (what the clusters' ``nc`` is built from)."""
        lay = self.layout
        edges = _edge_arrays(X, lay.nxt, lay.comp, lay.starts, self.tree.perm)
        if lay.has_open:
            cp = edges[3]
            edges = (*edges[:3], np.where(lay.closed[cp], cp, OPEN_KIND - cp), *edges[4:])
        return edges

    def _evaluate(self, X: np.ndarray, grad: bool):
        lay, tree = self.layout, self.tree
        X0, edges, clusters = self._own
        if not np.array_equal(X, X0):
            edges = self._edges(X)
            clusters = self._clusters(edges)
        E, M, ln = edges[:3]
        L, C, S, D, Q, T, nc = clusters
        eF, gL, gS, gC, gD, gQ, gT = _far(L, C, S, D, Q, T, nc, self.foff, self.fpart, grad,
                                          self._all_open)
        part = _near(E, M, ln, self._near_cp, tree.lo, tree.hi, *self._near_lists, grad,
                     self._all_open)
        energy = 4.0 * self._closed_count + float(np.sum(part[0])) + float(np.sum(eF))
        g1 = None
        if self.arc is not None:  # O'Hara's arc-length part: E = (3-D part) − E₁ (+ C)
            e1, g1 = self.arc.energy_gradient(X, grad)
            energy += e1
        if not grad:
            return energy, None
        acc = _push_down(L, C, S, D, gL, gS, gC, gD, gQ, gT, tree.left, tree.right)
        _far_to_edges(E, M, ln, C, tree.lo, tree.hi, self.leaves, acc, part)
        G = _to_vertices(part, lay.prv, self._at)
        return energy, (G if g1 is None else G + g1)

    def energy(self, X: np.ndarray) -> float:
        """The approximated energy at ``X`` with this frame's split (cluster data refitted)."""
        return self._evaluate(X, False)[0]

    def energy_gradient(self, X: np.ndarray) -> tuple[float, np.ndarray]:
        """The approximated energy at ``X`` and its exact gradient ``(N, 3)`` for this split."""
        return self._evaluate(X, True)


def tree_energy(X: np.ndarray, layout: Layout, theta: float = THETA) -> float:
    """Barnes–Hut energy of the stacked vertex array with a split built at ``X``."""
    return Frame(X, layout, theta).energy(X)


def tree_energy_gradient(X: np.ndarray, layout: Layout,
                         theta: float = THETA) -> tuple[float, np.ndarray]:
    """Barnes–Hut energy and its exact gradient with a split built at ``X``."""
    return Frame(X, layout, theta).energy_gradient(X)

