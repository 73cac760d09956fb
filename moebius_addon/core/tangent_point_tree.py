"""The tangent-point energy and its exact derivative by Barnes–Hut on the edge hierarchy (the tree
engine; docs/design.md, "Tangent-point energy"; docs/api.md, "Tangent-point energy").

The ordered pairs of edges are split as for the Möbius energy (:class:`.barnes_hut.Frame`:
the same hierarchy, the same dual traversal, the same near and far lists), and summed with
:func:`.energies.tangent_point.pair`:

* **near pairs** (leaves close to each other): every ordered pair of edges exactly, except an
  edge with itself and its neighbours along the curve;
* **far pairs** ``(A, B)`` (clusters apart, ``max(diam) ≤ θ · gap``): every *edge* ``I`` of
  ``A`` against the cluster ``B`` as one point, the pair kernel with ``l_J = L_B`` (total
  length) and ``m_J = c_B`` (length-weighted centre). The kernel depends on ``J`` only
  through ``l_J`` and ``m_J``, so this is the monopole of ``B`` and its first order vanishes
  (``Σ_J l_J (m_J − c_B) = 0``): the error is second order in ``diam B / |m_I − c_B|``. The
  target side is not expanded at all, so the tangents enter exactly for every ``α`` (no
  projector tensor is needed, and none could make ``|T × d|^α`` separable for ``α ≠ 2``).
  The price: the far field costs one kernel per edge of ``A`` rather than one per pair of
  clusters, O(N log N) rather than O(N); measured against the Möbius tree in
  docs/benchmarks.md.

The gradient is the exact derivative of this approximated sum for the fixed split: the far
field's derivatives in ``L_B`` and ``c_B`` go to ``B``'s edges by ``∂L_B/∂l_J = 1``,
``∂c_B/∂m_J = l_J/L_B``, ``∂c_B/∂l_J = (m_J − c_B)/L_B``. Every edge's own sums are
sequential; what a pair gives its second edge or source cluster goes to :data:`_FAR_CHUNKS`
fixed buffers (the leaves dealt to them in fixed ranges), added in a fixed order: the same
bits for every thread count.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from . import bvh
from ._far_field import _cluster_data
from ._layout import Layout
from ._near_field import _to_vertices
from .barnes_hut import Frame, _edge_arrays, check_theta
from .energies.tangent_point import (
    DEFAULT_ALPHA,
    DEFAULT_BETA,
    KIND_2,
    KIND_2_4,
    KIND_2_45,
    KIND_GENERAL,
    check_exponents,
    kind_of,
    pair,
)

#: Default admissibility of the tangent-point tree (see docs/benchmarks.md, "Tangent-point
#: energy": the relative errors measured at it).
THETA = 0.25
# Fixed pieces of the parallel loops over leaves: the per-edge sums are their own (any split,
# the same bits); what the pairs give their second edge (near) or source cluster (far) goes to
# one buffer per piece, so their number is fixed.
_FAR_CHUNKS = 16


@nb.njit(cache=True, inline="always")
def _kernel(dx, dy, dz, ax, ay, az, li, lj, r2, alpha, beta, kind):
    """:func:`pair` with ``kind`` made a constant at each call site (the branches inside fold
    away)."""
    if kind == KIND_2_4:
        return pair(dx, dy, dz, ax, ay, az, li, lj, r2, alpha, beta, KIND_2_4)
    if kind == KIND_2_45:
        return pair(dx, dy, dz, ax, ay, az, li, lj, r2, alpha, beta, KIND_2_45)
    if kind == KIND_2:
        return pair(dx, dy, dz, ax, ay, az, li, lj, r2, alpha, beta, KIND_2)
    return pair(dx, dy, dz, ax, ay, az, li, lj, r2, alpha, beta, KIND_GENERAL)


# The near field's lanes (the idea of ``_near_field``): up to this many edges ``I`` of a leaf
# against one partner edge ``J`` at a time. One work array per parallel piece: lane j's edge at
# W[_LANES k + j] (k: midpoint, edge vector, length, then its tree position and neighbours' as
# floats, position −1 past the leaf's end), its sums at W[_NW_SUMS + _LANES k + j] (f,
# ∂f/∂e_I, ∂f/∂d) and what its pair gives J at W[_NW_OUT + _LANES k + j] (−∂f/∂d, ∂f/∂l_J),
# added over the lanes in lane order. Constant offsets plus j: the lane loop vectorizes. No
# fast-math (see ``_near_field``).
_LANES = 8
_NW_ID = 7 * _LANES
_NW_SUMS = 10 * _LANES
_NW_OUT = 17 * _LANES
_NW_SIZE = 21 * _LANES


@nb.njit(cache=True, error_model="numpy", inline="always")
def _near_lanes(W, rx, ry, rz, lj, r, alpha, beta, kind, grad):
    """Partner edge ``r`` (midpoint, length, tree position as a float) against every lane's
    edge, added to the lane's sums; what each pair gives ``r`` in the lane's ``_NW_OUT``
    slots. The edge itself, its neighbours and the lanes past the leaf's end count zero: by a
    select (``|d|² = ∞``), no branch."""
    for j in range(_LANES):
        dx = W[j] - rx
        dy = W[_LANES + j] - ry
        dz = W[2 * _LANES + j] - rz
        q = W[_NW_ID + j]
        r2 = dx * dx + dy * dy + dz * dz
        skip = (r == q or r == W[_NW_ID + _LANES + j] or r == W[_NW_ID + 2 * _LANES + j]
                or q < 0.0)
        r2 = np.inf if skip else r2
        f, fax, fay, faz, fdx, fdy, fdz, fl = _kernel(
            dx, dy, dz, W[3 * _LANES + j], W[4 * _LANES + j], W[5 * _LANES + j],
            W[6 * _LANES + j], lj, r2, alpha, beta, kind)
        W[_NW_SUMS + j] += f
        if grad:
            W[_NW_SUMS + _LANES + j] += fax
            W[_NW_SUMS + 2 * _LANES + j] += fay
            W[_NW_SUMS + 3 * _LANES + j] += faz
            W[_NW_SUMS + 4 * _LANES + j] += fdx
            W[_NW_SUMS + 5 * _LANES + j] += fdy
            W[_NW_SUMS + 6 * _LANES + j] += fdz
            W[_NW_OUT + j] = fdx
            W[_NW_OUT + _LANES + j] = fdy
            W[_NW_OUT + 2 * _LANES + j] = fdz
            W[_NW_OUT + 3 * _LANES + j] = fl


@nb.njit(cache=True, inline="always")
def _near_partner(W, b4, M, ln, lo_b, hi_b, alpha, beta, kind, grad):
    """The lanes against every edge of one partner leaf, what the pairs give each of its edges
    added to ``b4`` (the lanes in order)."""
    for r in range(lo_b, hi_b):
        _near_lanes(W, M[r, 0], M[r, 1], M[r, 2], ln[r], float(r), alpha, beta, kind, grad)
        if grad:
            sx = sy = sz = sl = 0.0
            for j in range(_LANES):
                sx += W[_NW_OUT + j]
                sy += W[_NW_OUT + _LANES + j]
                sz += W[_NW_OUT + 2 * _LANES + j]
                sl += W[_NW_OUT + 3 * _LANES + j]
            b4[0, r] -= sx
            b4[1, r] -= sy
            b4[2, r] -= sz
            b4[3, r] += sl


@nb.njit(cache=True, parallel=True, error_model="numpy")
def _near(E, M, ln, lo, hi, leaves, noff, npart, nbr, alpha, beta, kind, grad):
    """Per edge (tree order): row 0 ``Σ_J f(I, J)`` over its near partners and, with ``grad``,
    the partials of every near pair it is part of (as ``I`` or as ``J``) in its edge vector
    (rows 1–3, without the length term), midpoint (4–6) and length (7). Each ordered pair is
    evaluated once, by the leaf of its ``I``: the leaf's edges are the lanes
    (:func:`_near_lanes`), the partners' edges go by one at a time; what a pair gives ``J``
    goes to one buffer per fixed piece of the leaves, added in piece order."""
    n = ln.shape[0]
    nl = leaves.shape[0]
    rows = np.zeros((8 if grad else 1, n))
    nchunks = min(nl, _FAR_CHUNKS)
    sb = np.zeros((nchunks, 4 if grad else 0, n))
    for cc in nb.prange(nchunks):
        ch = np.int64(cc)
        b4 = sb[ch]
        W = np.zeros(_NW_SIZE)
        for t in range(ch * nl // nchunks, (ch + 1) * nl // nchunks):
            a = leaves[t]
            for q0 in range(lo[a], hi[a], _LANES):
                count = min(_LANES, hi[a] - q0)
                for j in range(_LANES):
                    q = q0 + min(j, count - 1)  # lanes past the leaf's end: its last edge, off
                    W[j] = M[q, 0]
                    W[_LANES + j] = M[q, 1]
                    W[2 * _LANES + j] = M[q, 2]
                    W[3 * _LANES + j] = E[q, 0]
                    W[4 * _LANES + j] = E[q, 1]
                    W[5 * _LANES + j] = E[q, 2]
                    W[6 * _LANES + j] = ln[q]
                    W[_NW_ID + j] = q if j < count else -1.0
                    W[_NW_ID + _LANES + j] = nbr[q, 0]
                    W[_NW_ID + 2 * _LANES + j] = nbr[q, 1]
                W[_NW_SUMS:] = 0.0
                for p in range(noff[a], noff[a + 1]):
                    b = npart[p]
                    # kind and grad constants at each call (the branches fold away)
                    if grad:
                        if kind == KIND_2_4:
                            _near_partner(W, b4, M, ln, lo[b], hi[b], alpha, beta, KIND_2_4, True)
                        elif kind == KIND_2_45:
                            _near_partner(W, b4, M, ln, lo[b], hi[b], alpha, beta, KIND_2_45,
                                          True)
                        elif kind == KIND_2:
                            _near_partner(W, b4, M, ln, lo[b], hi[b], alpha, beta, KIND_2, True)
                        else:
                            _near_partner(W, b4, M, ln, lo[b], hi[b], alpha, beta, KIND_GENERAL,
                                          True)
                    else:
                        if kind == KIND_2_4:
                            _near_partner(W, b4, M, ln, lo[b], hi[b], alpha, beta, KIND_2_4,
                                          False)
                        elif kind == KIND_2_45:
                            _near_partner(W, b4, M, ln, lo[b], hi[b], alpha, beta, KIND_2_45,
                                          False)
                        elif kind == KIND_2:
                            _near_partner(W, b4, M, ln, lo[b], hi[b], alpha, beta, KIND_2, False)
                        else:
                            _near_partner(W, b4, M, ln, lo[b], hi[b], alpha, beta, KIND_GENERAL,
                                          False)
                for j in range(count):
                    q = q0 + j
                    rows[0, q] = W[_NW_SUMS + j]
                    if grad:
                        for k in range(1, 7):
                            rows[k, q] = W[_NW_SUMS + k * _LANES + j]
    if grad:
        for ch in range(nchunks):  # in piece order: the same bits for any thread count
            for k in range(4):
                for q in nb.prange(n):
                    rows[4 + k, q] += sb[ch, k, q]
    return rows


@nb.njit(cache=True, parallel=True, error_model="numpy")
def _far(E, M, ln, L, C, lo, hi, leaves, parent, foff, fpart, alpha, beta, kind, grad,
         rows):
    """Every edge against the far partners of its leaf and of the leaf's ancestors, each
    partner ``B`` as one point of weight ``L_B`` at ``c_B``: added to ``rows`` (row 0 the
    energy, 1–3 the edge vector, 4–6 the midpoint; :func:`_near`'s layout). Returns, per
    fixed piece of the leaves, the derivatives of the sum in every cluster's ``L`` (column
    0) and ``c`` (1–3)."""
    m = L.shape[0]
    nl = leaves.shape[0]
    nchunks = _FAR_CHUNKS
    gnode = np.zeros((nchunks, m if grad else 0, 4))
    for cc in nb.prange(nchunks):
        ch = np.int64(cc)
        g = gnode[ch]
        for t in range(ch * nl // nchunks, (ch + 1) * nl // nchunks):
            leaf = leaves[t]
            for q in range(lo[leaf], hi[leaf]):
                px, py, pz = M[q, 0], M[q, 1], M[q, 2]
                ax, ay, az, li = E[q, 0], E[q, 1], E[q, 2], ln[q]
                s = gax = gay = gaz = gmx = gmy = gmz = 0.0
                a = leaf
                while a >= 0:
                    for p in range(foff[a], foff[a + 1]):
                        b = fpart[p]
                        dx = px - C[b, 0]
                        dy = py - C[b, 1]
                        dz = pz - C[b, 2]
                        f, fax, fay, faz, fdx, fdy, fdz, fl = _kernel(
                            dx, dy, dz, ax, ay, az, li, L[b], dx * dx + dy * dy + dz * dz,
                            alpha, beta, kind)
                        s += f
                        if grad:
                            gax += fax
                            gay += fay
                            gaz += faz
                            gmx += fdx
                            gmy += fdy
                            gmz += fdz
                            g[b, 0] += fl
                            g[b, 1] -= fdx
                            g[b, 2] -= fdy
                            g[b, 3] -= fdz
                    a = parent[a]
                rows[0, q] += s
                if grad:
                    rows[1, q] += gax
                    rows[2, q] += gay
                    rows[3, q] += gaz
                    rows[4, q] += gmx
                    rows[5, q] += gmy
                    rows[6, q] += gmz
    return gnode


@nb.njit(cache=True, parallel=True)
def _far_sources(M, ln, L, C, lo, hi, leaves, parent, gnode, rows):
    """The clusters' derivatives ``gnode`` (in ``L``, ``c``) passed to their edges: per edge
    and every cluster holding it, ``∂/∂l += g_L + <g_c, m − c>/L`` (row 7) and
    ``∂/∂m += g_c l/L`` (rows 4–6)."""
    nl = leaves.shape[0]
    for tt in nb.prange(nl):
        leaf = leaves[np.int64(tt)]
        for q in range(lo[leaf], hi[leaf]):
            gl = gmx = gmy = gmz = 0.0
            b = leaf
            while b >= 0:
                il = 1.0 / L[b]
                gl += gnode[b, 0] + il * (gnode[b, 1] * (M[q, 0] - C[b, 0])
                                          + gnode[b, 2] * (M[q, 1] - C[b, 1])
                                          + gnode[b, 3] * (M[q, 2] - C[b, 2]))
                w = ln[q] * il
                gmx += gnode[b, 1] * w
                gmy += gnode[b, 2] * w
                gmz += gnode[b, 3] * w
                b = parent[b]
            rows[7, q] += gl
            rows[4, q] += gmx
            rows[5, q] += gmy
            rows[6, q] += gmz


class TangentPointFrame(Frame):
    """The hierarchy and far/near split of :class:`.barnes_hut.Frame` with the tangent-point
    energy's sums; reusable at nearby polygons (a line search sees one smooth function).

    Parameters
    ----------
    X : (N, 3) array
        Stacked vertices of closed components (see ``_layout``; open curves are refused by the
        public evaluators, as for the Möbius tree).
    layout : Layout
    alpha, beta : float
        The exponents (:func:`.energies.tangent_point.check_exponents`).
    theta : float
        Admissibility: clusters are far when ``max(diam) ≤ theta · gap`` of their boxes.
    leaf_size : int
        Edges per leaf at most.
    """

    def __init__(self, X: np.ndarray, layout: Layout, alpha: float = DEFAULT_ALPHA,
                 beta: float = DEFAULT_BETA,
                 theta: float = THETA, leaf_size: int = bvh.LEAF_SIZE):
        self.alpha, self.beta = check_exponents(alpha, beta)
        self.kind = kind_of(self.alpha, self.beta)
        super().__init__(X, layout, check_theta(theta), leaf_size)
        left, right = self.tree.left, self.tree.right
        parent = np.full(left.shape[0], -1, np.int64)
        inner = np.flatnonzero(left >= 0)
        parent[left[inner]] = inner
        parent[right[inner]] = inner
        self.parent = parent

    def _evaluate(self, X: np.ndarray, grad: bool):
        lay, tree = self.layout, self.tree
        X0, edges, clusters = self._own
        if not np.array_equal(X, X0):
            edges = _edge_arrays(X, lay.nxt, lay.comp, lay.starts, tree.perm)
            clusters = _cluster_data(*edges[:4], tree.lo, tree.hi, tree.left, tree.right)
        E, M, ln = edges[0], edges[1], edges[2]
        L, C = clusters[0], clusters[1]
        noff, npart, nbr = self._near_lists
        args = (self.alpha, self.beta, self.kind, grad)
        rows = _near(E, M, ln, tree.lo, tree.hi, self.leaves, noff, npart, nbr, *args)
        gnode = _far(E, M, ln, L, C, tree.lo, tree.hi, self.leaves, self.parent, self.foff,
                     self.fpart, *args, rows)
        energy = float(np.sum(rows[0]))
        if not grad:
            return energy, None
        _far_sources(M, ln, L, C, tree.lo, tree.hi, self.leaves, self.parent,
                     gnode.sum(axis=0), rows)
        rows[1:4] += rows[7] / ln * E.T  # ∂l/∂e = e/l
        return energy, _to_vertices(rows, lay.prv, self._at)


def tp_tree_energy(X: np.ndarray, layout: Layout, alpha: float = DEFAULT_ALPHA,
                   beta: float = DEFAULT_BETA,
                   theta: float = THETA) -> float:
    """Barnes–Hut tangent-point energy of the stacked vertex array, split built at ``X``."""
    return TangentPointFrame(X, layout, alpha, beta, theta).energy(X)


def tp_tree_energy_gradient(X: np.ndarray, layout: Layout, alpha: float = DEFAULT_ALPHA,
                            beta: float = DEFAULT_BETA, theta: float = THETA):
    """Barnes–Hut tangent-point energy and its exact gradient, split built at ``X``."""
    return TangentPointFrame(X, layout, alpha, beta, theta).energy_gradient(X)
