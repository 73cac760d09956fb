"""The tangent-point energy and its exact derivative by Barnes–Hut on the edge hierarchy (the tree
engine; docs/design.md, "Tangent-point energy"; docs/api.md, "Tangent-point energy").

The ordered pairs of edges are split as for the Möbius energy (:class:`.barnes_hut.Frame`:
the same hierarchy, the same dual traversal, the same near and far lists), and summed with
:func:`.energies.tangent_point.pair`:

* **near pairs** (leaves close to each other): every ordered pair of edges exactly, except an
  edge with itself and its neighbours along the curve;
* **far pairs** ``(A, B)`` (clusters apart, ``max(diam) ≤ θ · gap``), for ``α = 2``: **cluster
  against cluster**, one kernel per ordered pair of clusters (O(N) kernels). With ``α = 2``,
  ``f_IJ = l_I l_J dᵀ P_I d / |d|^β`` (``P_I = 1 − T_I T_Iᵀ``), so ``A`` enters through its
  projector moments ``G = Σ e eᵀ/l`` and ``W = Σ (e eᵀ/l) ⊗ δ`` (``δ = m − c_A``), ``B`` through
  ``L_B``, ``c_B``; the pair sum is expanded to first order on both sides around ``d = c_A −
  c_B`` (B's first order vanishes), error second order in ``diam / |d|`` on both sides (the
  formula in the block comment above :func:`_cc_node`).
* far pairs for other ``α`` (``|T × d|^α`` is no polynomial in ``T``, no moments make it
  separable): every *edge* ``I`` of ``A`` against ``B`` as one point, the pair kernel with
  ``l_J = L_B`` and ``m_J = c_B`` (the monopole of ``B``, its first order vanishes; the
  target side exact), one kernel per edge of ``A``, O(N log N).

Errors and times of both measured in docs/benchmarks.md ("Tangent-point energy: cluster
against cluster").

The gradient is the exact derivative of this approximated sum for the fixed split: the far
field's derivatives in the clusters' moments go to their edges by the chain rule
(``∂L/∂l_J = 1``, ``∂c/∂m_J = l_J/L``, ``∂c/∂l_J = (m_J − c)/L``, ``G`` and ``W`` through
``e eᵀ/l`` and ``δ``, ``∂W_abk/∂c_k = −G_ab``), each edge walking up its ancestors. Every
edge's and every target cluster's own sums are sequential; what a pair gives its second edge
or source cluster goes to fixed buffers per fixed piece of the leaves or nodes, added in a
fixed order: the same bits for every thread count.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ._far_field import _cluster_data, _levels
from ._layout import Layout
from ._near_field import _load_lanes, _to_vertices
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

#: Default admissibility of the tangent-point tree (with leaves of :data:`LEAF_SIZE` edges):
#: relative errors (energy / gradient) at most 1.4e-3 / 2.5e-2 on FHW at 2 400–10 000 edges,
#: about 6–7× / 24–40× below Repulsor's at its default. With leaves of four edges, 0.3 gave
#: errors 0.9–2.5× those of 0.3 with leaves of eight; 0.25 gives about the same
#: (docs/benchmarks.md, "Tangent-point energy: cluster against cluster" and session 13).
THETA = 0.25
#: Edges per leaf of the tangent-point tree (the near field's lanes, below).
LEAF_SIZE = 4
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
# fast-math (see ``_near_field``). The first ten rows as in ``_near_field``, by its _load_lanes.
# Four lanes on leaves of four edges (:data:`LEAF_SIZE`): the finer split leaves about half the
# near pairs, and the far field, cluster against cluster, is cheap per pair. The energy-only
# pass loops over ``lanes``, a run-time argument equal to _LANES: a constant trip count of four
# was unrolled fully and left scalar (times in docs/benchmarks.md, session 13).
_LANES = 4
_NW_ID = 7 * _LANES
_NW_SUMS = 10 * _LANES
_NW_OUT = 17 * _LANES
_NW_SIZE = 21 * _LANES


@nb.njit(cache=True, error_model="numpy", inline="always")
def _near_lanes(W, rx, ry, rz, lj, r, alpha, beta, kind, grad, lanes):
    """Partner edge ``r`` (midpoint, length, tree position as a float) against every lane's
    edge, added to the lane's sums; what each pair gives ``r`` in the lane's ``_NW_OUT``
    slots. The edge itself, its neighbours and the lanes past the leaf's end count zero: by a
    select (``|d|² = ∞``), no branch."""
    for j in range(_LANES if grad else lanes):
        dx = W[j] - rx
        dy = W[_LANES + j] - ry
        dz = W[2 * _LANES + j] - rz
        q = W[_NW_ID + j]
        r2 = dx * dx + dy * dy + dz * dz
        # one select per test: a compound condition branches, and the loop does not vectorize
        # (the energy alone took 2.6–3.2× the time at 10⁵ edges, docs/benchmarks.md)
        r2 = np.inf if r == q else r2
        r2 = np.inf if r == W[_NW_ID + _LANES + j] else r2
        r2 = np.inf if r == W[_NW_ID + 2 * _LANES + j] else r2
        r2 = np.inf if q < 0.0 else r2
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
def _near_partner(W, b4, M, ln, lo_b, hi_b, alpha, beta, kind, grad, lanes):
    """The lanes against every edge of one partner leaf, what the pairs give each of its edges
    added to ``b4`` (the lanes in order)."""
    for r in range(lo_b, hi_b):
        _near_lanes(W, M[r, 0], M[r, 1], M[r, 2], ln[r], float(r), alpha, beta, kind, grad,
                    lanes)
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


@nb.njit(cache=True, error_model="numpy")
def _near_leaves(E, M, ln, lo, hi, leaves, t0, t1, noff, npart, nbr, alpha, beta, kind, grad,
                 rows, b4, lanes):
    """The leaves ``leaves[t0:t1]`` of :func:`_near`: their edges' own sums to ``rows``, what
    their pairs give partner edges to ``b4``. A function of its own, called from the parallel
    loop: in a copy of a variant, compiled without ``parallel``, the gradient pass took 0.28 s
    against 0.33 s inside the loop's body (10⁵ edges); in place the difference was in the
    noise (docs/benchmarks.md, session 11)."""
    W = np.zeros(_NW_SIZE)
    for t in range(t0, t1):
        a = leaves[t]
        for q0 in range(lo[a], hi[a], _LANES):
            count = min(_LANES, hi[a] - q0)
            _load_lanes(W, E, M, ln, nbr, q0, count, True, _LANES)  # past the leaf's end: off
            W[_NW_SUMS:] = 0.0
            for p in range(noff[a], noff[a + 1]):
                b = npart[p]
                # kind and grad constants at each call (the branches fold away)
                if grad:
                    if kind == KIND_2_4:
                        _near_partner(W, b4, M, ln, lo[b], hi[b], alpha, beta,
                                      KIND_2_4, True, lanes)
                    elif kind == KIND_2_45:
                        _near_partner(W, b4, M, ln, lo[b], hi[b], alpha, beta, KIND_2_45,
                                      True, lanes)
                    elif kind == KIND_2:
                        _near_partner(W, b4, M, ln, lo[b], hi[b], alpha, beta, KIND_2, True, lanes)
                    else:
                        _near_partner(W, b4, M, ln, lo[b], hi[b], alpha, beta, KIND_GENERAL,
                                      True, lanes)
                else:
                    if kind == KIND_2_4:
                        _near_partner(W, b4, M, ln, lo[b], hi[b], alpha, beta, KIND_2_4,
                                      False, lanes)
                    elif kind == KIND_2_45:
                        _near_partner(W, b4, M, ln, lo[b], hi[b], alpha, beta, KIND_2_45,
                                      False, lanes)
                    elif kind == KIND_2:
                        _near_partner(W, b4, M, ln, lo[b], hi[b], alpha, beta, KIND_2, False, lanes)
                    else:
                        _near_partner(W, b4, M, ln, lo[b], hi[b], alpha, beta, KIND_GENERAL,
                                      False, lanes)
            for j in range(count):
                q = q0 + j
                rows[0, q] = W[_NW_SUMS + j]
                if grad:
                    for k in range(1, 7):
                        rows[k, q] = W[_NW_SUMS + k * _LANES + j]


@nb.njit(cache=True, parallel=True, error_model="numpy")
def _near(E, M, ln, lo, hi, leaves, noff, npart, nbr, alpha, beta, kind, grad, lanes):
    """Per edge (tree order): row 0 ``Σ_J f(I, J)`` over its near partners and, with ``grad``,
    the partials of every near pair it is part of (as ``I`` or as ``J``) in its edge vector
    (rows 1–3, without the length term), midpoint (4–6) and length (7). Each ordered pair is
    evaluated once, by the leaf of its ``I``: the leaf's edges are the lanes
    (:func:`_near_lanes`), the partners' edges go by one at a time; what a pair gives ``J``
    goes to one buffer per fixed piece of the leaves, added in piece order. ``lanes``: always
    :data:`_LANES`, passed at run time (see the lanes' comment above)."""
    n = ln.shape[0]
    nl = leaves.shape[0]
    rows = np.zeros((8 if grad else 1, n))
    nchunks = min(nl, _FAR_CHUNKS)
    sb = np.zeros((nchunks, 4 if grad else 0, n))
    for cc in nb.prange(nchunks):
        ch = np.int64(cc)
        _near_leaves(E, M, ln, lo, hi, leaves, ch * nl // nchunks, (ch + 1) * nl // nchunks,
                     noff, npart, nbr, alpha, beta, kind, grad, rows, sb[ch], lanes)
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


# ------------------------------------------------------------------------------------------------
# the cluster–cluster far field (α = 2)
#
# For α = 2, f_IJ = l_I l_J dᵀ P_I d / |d|^β with P_I = 1 − T_I T_Iᵀ, so a cluster's edges enter
# a far pair through projector moments. Per node: L and c (as the Möbius tree), G = Σ e eᵀ/l
# (Σ l P = L·1 − G) and the first projector moment W = Σ (e eᵀ/l) ⊗ δ (δ = m − c). A far pair
# (A, B) is Σ_IJ l_I l_J φ_I(d + δ_I − δ_J), d = c_A − c_B, expanded to first order on both
# sides; B's first order vanishes (Σ l δ = 0), A's is −W (Σ l P ⊗ δ = −W):
#
#   F(A, B) = L_B [L_A |d|^(2−β) − |d|^−β dᵀG_A d − 2 |d|^−β <v_A, d> + β |d|^(−β−2) W_A(d, d, d)]
#
# with v_a = Σ_b W_abb: one kernel per pair of clusters (O(N) kernels, not one per edge and
# cluster), error of second order in diam / |d| on both sides (docs/benchmarks.md,
# "Tangent-point energy: cluster against cluster").


@nb.njit(cache=True, inline="always")
def _cc_node(node, E, M, ln, lo, hi, left, right, C, G, Wm):
    """``G`` (9, row-major) and ``W`` (27, index 9a + 3b + c) of one node about its centre
    ``C[node]``: a leaf from its edges, a parent from its children's moved to its centre
    (``W += G_child ⊗ (c_child − c)``)."""
    for k in range(9):
        G[node, k] = 0.0
    for k in range(27):
        Wm[node, k] = 0.0
    if left[node] < 0:
        for q in range(lo[node], hi[node]):
            il = 1.0 / ln[q]
            for a in range(3):
                for b in range(3):
                    g = E[q, a] * E[q, b] * il
                    G[node, 3 * a + b] += g
                    for c in range(3):
                        Wm[node, 9 * a + 3 * b + c] += g * (M[q, c] - C[node, c])
    else:
        for ch in (left[node], right[node]):
            for a in range(3):
                for b in range(3):
                    g = G[ch, 3 * a + b]
                    G[node, 3 * a + b] += g
                    for c in range(3):
                        Wm[node, 9 * a + 3 * b + c] += (Wm[ch, 9 * a + 3 * b + c]
                                                        + g * (C[ch, c] - C[node, c]))


@nb.njit(cache=True, parallel=True)
def _cc_moments(E, M, ln, lo, hi, left, right, C):
    """Per node ``G`` and ``W`` (:func:`_cc_node`), bottom-up one depth at a time (each node
    writes its own row)."""
    m = lo.shape[0]
    G = np.empty((m, 9))
    Wm = np.empty((m, 27))
    order, offsets = _levels(left, right)
    for d in range(offsets.shape[0] - 2, -1, -1):
        if offsets[d + 1] - offsets[d] >= 256:
            for t in nb.prange(offsets[d], offsets[d + 1]):
                _cc_node(order[t], E, M, ln, lo, hi, left, right, C, G, Wm)
        else:
            for t in range(offsets[d], offsets[d + 1]):
                _cc_node(order[t], E, M, ln, lo, hi, left, right, C, G, Wm)
    return G, Wm


@nb.njit(cache=True, inline="always")
def _inv_beta(r2, beta, kind):
    """``|d|^−β`` from ``r2 = |d|²`` (no ``pow`` for β = 4 and 4.5)."""
    inv = 1.0 / r2
    if kind == KIND_2_4:
        return inv * inv
    if kind == KIND_2_45:
        return inv * inv * math.sqrt(math.sqrt(inv))
    return r2 ** (-0.5 * beta)


@nb.njit(cache=True, parallel=True, error_model="numpy")
def _cc_far(L, C, G, Wm, foff, fpart, beta, kind, grad):
    """Every node ``A`` against its far partners ``B`` (:func:`_cc_node`'s moments): per node
    the energy of its pairs as target; with ``grad`` the derivatives of the sum in its own
    ``L`` (column 0 of ``gt``), ``c`` (1–3), ``G`` (``gG``) and ``W`` (``gW``) as a target,
    and, per fixed piece of the targets, in every partner's ``L`` and ``c`` as a source
    (``gs``). Each target's sums are its own: the same bits for any thread count."""
    m = L.shape[0]
    nchunks = min(m, _FAR_CHUNKS)
    eF = np.zeros(m)
    gt = np.zeros((m if grad else 0, 4))
    gG = np.zeros((m if grad else 0, 9))
    gW = np.zeros((m if grad else 0, 27))
    gs = np.zeros((nchunks, m if grad else 0, 4))
    for cc in nb.prange(nchunks):
        ch = np.int64(cc)
        for a in range(ch * m // nchunks, (ch + 1) * m // nchunks):
            if foff[a + 1] == foff[a]:
                continue
            la = L[a]
            g0, g1, g2, g3, g4, g5, g6, g7, g8 = G[a, 0], G[a, 1], G[a, 2], G[a, 3], G[a, 4], \
                G[a, 5], G[a, 6], G[a, 7], G[a, 8]
            v0 = Wm[a, 0] + Wm[a, 4] + Wm[a, 8]
            v1 = Wm[a, 9] + Wm[a, 13] + Wm[a, 17]
            v2 = Wm[a, 18] + Wm[a, 22] + Wm[a, 26]
            e = sla = scx = scy = scz = 0.0
            p0 = p1 = p2 = 0.0  # Σ −2 L_B ρ d (∂/∂v)
            o00 = o01 = o02 = o11 = o12 = o22 = 0.0  # Σ −L_B ρ d dᵀ (∂/∂G)
            t = np.zeros(27) if grad else np.zeros(0)  # Σ β L_B ρ₂ d ⊗ d ⊗ d (∂/∂W)
            for p in range(foff[a], foff[a + 1]):
                b = fpart[p]
                lb = L[b]
                dx = C[a, 0] - C[b, 0]
                dy = C[a, 1] - C[b, 1]
                dz = C[a, 2] - C[b, 2]
                r2 = dx * dx + dy * dy + dz * dz
                rho = _inv_beta(r2, beta, kind)
                rho2 = rho / r2
                gdx = g0 * dx + g1 * dy + g2 * dz
                gdy = g3 * dx + g4 * dy + g5 * dz
                gdz = g6 * dx + g7 * dy + g8 * dz
                dgd = dx * gdx + dy * gdy + dz * gdz
                vd = v0 * dx + v1 * dy + v2 * dz
                # Wd_ab = Σ_c W_abc d_c; s = dᵀ Wd d; u_k = Σ_ab W_abk d_a d_b
                s = 0.0
                w0 = w1 = w2 = 0.0  # Σ_b Wd_kb d_b
                u0 = u1 = u2 = 0.0
                for i in range(3):
                    di = dx if i == 0 else (dy if i == 1 else dz)
                    for j in range(3):
                        dj = dx if j == 0 else (dy if j == 1 else dz)
                        base = 9 * i + 3 * j
                        wd = Wm[a, base] * dx + Wm[a, base + 1] * dy + Wm[a, base + 2] * dz
                        if i == 0:
                            w0 += wd * dj
                        elif i == 1:
                            w1 += wd * dj
                        else:
                            w2 += wd * dj
                        dd = di * dj
                        u0 += Wm[a, base] * dd
                        u1 += Wm[a, base + 1] * dd
                        u2 += Wm[a, base + 2] * dd
                s = w0 * dx + w1 * dy + w2 * dz
                inner = la * r2 * rho - rho * dgd - 2.0 * rho * vd + beta * rho2 * s
                e += lb * inner
                if grad:
                    # ∂/∂d of inner (docs: the derivation beside this kernel)
                    c1 = (la * rho * (2.0 - beta) + beta * rho2 * dgd + 2.0 * beta * rho2 * vd
                          - beta * (beta + 2.0) * rho2 / r2 * s)
                    hx = lb * (c1 * dx - 2.0 * rho * gdx - 2.0 * rho * v0
                               + beta * rho2 * (2.0 * w0 + u0))
                    hy = lb * (c1 * dy - 2.0 * rho * gdy - 2.0 * rho * v1
                               + beta * rho2 * (2.0 * w1 + u1))
                    hz = lb * (c1 * dz - 2.0 * rho * gdz - 2.0 * rho * v2
                               + beta * rho2 * (2.0 * w2 + u2))
                    sla += lb * r2 * rho
                    scx += hx
                    scy += hy
                    scz += hz
                    k = -lb * rho
                    o00 += k * dx * dx
                    o01 += k * dx * dy
                    o02 += k * dx * dz
                    o11 += k * dy * dy
                    o12 += k * dy * dz
                    o22 += k * dz * dz
                    p0 += 2.0 * k * dx
                    p1 += 2.0 * k * dy
                    p2 += 2.0 * k * dz
                    k3 = beta * lb * rho2
                    for i in range(3):
                        di = dx if i == 0 else (dy if i == 1 else dz)
                        for j in range(3):
                            dj = dx if j == 0 else (dy if j == 1 else dz)
                            kij = k3 * di * dj
                            t[9 * i + 3 * j] += kij * dx
                            t[9 * i + 3 * j + 1] += kij * dy
                            t[9 * i + 3 * j + 2] += kij * dz
                    gsb = gs[ch, b]
                    gsb[0] += inner
                    gsb[1] -= hx
                    gsb[2] -= hy
                    gsb[3] -= hz
            eF[a] = e
            if grad:
                gt[a, 0] = sla
                gt[a, 1] = scx
                gt[a, 2] = scy
                gt[a, 3] = scz
                gG[a, 0] = o00
                gG[a, 1] = o01
                gG[a, 2] = o02
                gG[a, 3] = o01
                gG[a, 4] = o11
                gG[a, 5] = o12
                gG[a, 6] = o02
                gG[a, 7] = o12
                gG[a, 8] = o22
                for k in range(27):
                    gW[a, k] = t[k]
                # ∂/∂W_abc of −2ρ<v, d> is −2ρ d_a δ_bc
                for i in range(3):
                    pi = p0 if i == 0 else (p1 if i == 1 else p2)
                    for j in range(3):
                        gW[a, 9 * i + 4 * j] += pi
    return eF, gt, gG, gW, gs


@nb.njit(cache=True, parallel=True)
def _cc_node_grad(L, G, gt, gs, gG, gW):
    """Per node, the derivatives the edges need: ``∂/∂L`` (target and source parts) and
    ``∂/∂c`` with ``W``'s dependence on ``c`` (``∂W_abk/∂c_k = −G_ab``) folded in."""
    m = L.shape[0]
    out = np.zeros((m, 4))
    nchunks = gs.shape[0]
    for bb in nb.prange(m):
        b = np.int64(bb)
        s0 = gt[b, 0]
        s1 = gt[b, 1]
        s2 = gt[b, 2]
        s3 = gt[b, 3]
        for ch in range(nchunks):  # in piece order: the same bits for any thread count
            s0 += gs[ch, b, 0]
            s1 += gs[ch, b, 1]
            s2 += gs[ch, b, 2]
            s3 += gs[ch, b, 3]
        for ab in range(9):
            s1 -= gW[b, 3 * ab] * G[b, ab]
            s2 -= gW[b, 3 * ab + 1] * G[b, ab]
            s3 -= gW[b, 3 * ab + 2] * G[b, ab]
        out[b, 0] = s0
        out[b, 1] = s1
        out[b, 2] = s2
        out[b, 3] = s3
    return out


@nb.njit(cache=True, parallel=True)
def _cc_to_edges(E, M, ln, L, C, lo, hi, leaves, parent, hasfar, gn, gG, gW, rows):
    """The nodes' derivatives passed to their edges (every node holding the edge that has far
    pairs): ``L`` and ``c`` as in :func:`_far_sources`; ``G`` and ``W`` through
    ``e eᵀ / l`` (edge vector rows 1–3 without the length term, length row 7) and ``δ = m − c``
    (midpoint rows 4–6)."""
    nl = leaves.shape[0]
    for tt in nb.prange(nl):
        leaf = leaves[np.int64(tt)]
        for q in range(lo[leaf], hi[leaf]):
            e0, e1, e2 = E[q, 0], E[q, 1], E[q, 2]
            il = 1.0 / ln[q]
            gl = ga0 = ga1 = ga2 = gm0 = gm1 = gm2 = 0.0
            b = leaf
            while b >= 0:
                if hasfar[b]:
                    iL = 1.0 / L[b]
                    x0 = M[q, 0] - C[b, 0]
                    x1 = M[q, 1] - C[b, 1]
                    x2 = M[q, 2] - C[b, 2]
                    gl += gn[b, 0] + iL * (gn[b, 1] * x0 + gn[b, 2] * x1 + gn[b, 3] * x2)
                    w = ln[q] * iL
                    gm0 += gn[b, 1] * w
                    gm1 += gn[b, 2] * w
                    gm2 += gn[b, 3] * w
                    # H = gG + gW·δ; ∂(eᵀHe/l)/∂e = (H + Hᵀ) e / l, ∂/∂l = −eᵀHe/l²
                    ehe = 0.0
                    for i in range(3):
                        ei = e0 if i == 0 else (e1 if i == 1 else e2)
                        hr = hc = 0.0  # (H e)_i, (Hᵀ e)_i
                        for j in range(3):
                            ej = e0 if j == 0 else (e1 if j == 1 else e2)
                            hij = (gG[b, 3 * i + j] + gW[b, 9 * i + 3 * j] * x0
                                   + gW[b, 9 * i + 3 * j + 1] * x1 + gW[b, 9 * i + 3 * j + 2] * x2)
                            hji = (gG[b, 3 * j + i] + gW[b, 9 * j + 3 * i] * x0
                                   + gW[b, 9 * j + 3 * i + 1] * x1 + gW[b, 9 * j + 3 * i + 2] * x2)
                            hr += hij * ej
                            hc += hji * ej
                            # ∂/∂m_c of Σ gW_ijc e_i e_j / l
                            eij = ei * ej * il
                            gm0 += gW[b, 9 * i + 3 * j] * eij
                            gm1 += gW[b, 9 * i + 3 * j + 1] * eij
                            gm2 += gW[b, 9 * i + 3 * j + 2] * eij
                        ehe += ei * hr
                        g = (hr + hc) * il
                        if i == 0:
                            ga0 += g
                        elif i == 1:
                            ga1 += g
                        else:
                            ga2 += g
                    gl -= ehe * il * il
                b = parent[b]
            rows[1, q] += ga0
            rows[2, q] += ga1
            rows[3, q] += ga2
            rows[4, q] += gm0
            rows[5, q] += gm1
            rows[6, q] += gm2
            rows[7, q] += gl


class TangentPointFrame(Frame):
    """The hierarchy and far/near split of :class:`.barnes_hut.Frame` with the tangent-point
    energy's sums; reusable at nearby polygons (a line search sees one smooth function).

    Parameters
    ----------
    X : (N, 3) array
        Stacked vertices of closed and open components (see ``_layout``).
    layout : Layout
    alpha, beta : float
        The exponents (:func:`.energies.tangent_point.check_exponents`).
    theta : float
        Admissibility: clusters are far when ``max(diam) ≤ theta · gap`` of their boxes.
    leaf_size : int
        Edges per leaf at most.
    """

    # open components: the same kernel as closed ones (pairs of neighbours along the curve left
    # out; the first and last edge are none) and no arc-length part; pairs of clusters that may
    # share one take θ · OPEN_THETA as for the Möbius energy (a single bent cable of 2 000
    # edges, (2, 4): gradient error 1.1e-2 against 6.5e-2 with θ alone; docs/benchmarks.md)
    arc_part = False

    def __init__(self, X: np.ndarray, layout: Layout, alpha: float = DEFAULT_ALPHA,
                 beta: float = DEFAULT_BETA,
                 theta: float = THETA, leaf_size: int = LEAF_SIZE):
        self.alpha, self.beta = check_exponents(alpha, beta)
        self.kind = kind_of(self.alpha, self.beta)
        super().__init__(X, layout, check_theta(theta), leaf_size)
        left, right = self.tree.left, self.tree.right
        parent = np.full(left.shape[0], -1, np.int64)
        inner = np.flatnonzero(left >= 0)
        parent[left[inner]] = inner
        parent[right[inner]] = inner
        self.parent = parent
        self._hasfar = np.diff(self.foff) > 0
        self._cc_own = None

    def _evaluate(self, X: np.ndarray, grad: bool):
        lay, tree = self.layout, self.tree
        X0, edges, clusters = self._own
        own = np.array_equal(X, X0)
        if not own:
            edges = _edge_arrays(X, lay.nxt, lay.comp, lay.starts, tree.perm)
            clusters = _cluster_data(*edges[:4], tree.lo, tree.hi, tree.left, tree.right)
        E, M, ln = edges[0], edges[1], edges[2]
        L, C = clusters[0], clusters[1]
        noff, npart, nbr = self._near_lists
        args = (self.alpha, self.beta, self.kind, grad)
        rows = _near(E, M, ln, tree.lo, tree.hi, self.leaves, noff, npart, nbr, *args, _LANES)
        if self.kind == KIND_GENERAL:
            # |T × d|^α is no polynomial in T for α ≠ 2: every edge against the cluster
            gnode = _far(E, M, ln, L, C, tree.lo, tree.hi, self.leaves, self.parent, self.foff,
                         self.fpart, *args, rows)
            energy = float(np.sum(rows[0]))
            if not grad:
                return energy, None
            _far_sources(M, ln, L, C, tree.lo, tree.hi, self.leaves, self.parent,
                         gnode.sum(axis=0), rows)
        else:
            if own and self._cc_own is not None:
                G, Wm = self._cc_own
            else:
                G, Wm = _cc_moments(E, M, ln, tree.lo, tree.hi, tree.left, tree.right, C)
                if own:
                    self._cc_own = (G, Wm)
            eF, gt, gG, gW, gs = _cc_far(L, C, G, Wm, self.foff, self.fpart, self.beta,
                                         self.kind, grad)
            energy = float(np.sum(rows[0])) + float(np.sum(eF))
            if not grad:
                return energy, None
            gn = _cc_node_grad(L, G, gt, gs, gG, gW)
            _cc_to_edges(E, M, ln, L, C, tree.lo, tree.hi, self.leaves, self.parent,
                         self._hasfar, gn, gG, gW, rows)
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
