"""The tangent-point energy and its exact derivative by Barnes–Hut on the edge hierarchy (the tree
engine; docs/design.md, "Tangent-point energy"; docs/api.md, "Tangent-point energy").

The ordered pairs of edges are split as for the Möbius energy (:class:`.barnes_hut.Frame`:
the same hierarchy, the same dual traversal, the same near and far lists), and summed with
:func:`.energies.tangent_point.pair`:

* **near pairs** (leaves close to each other): every ordered pair of edges exactly, except an
  edge with itself and its neighbours along the curve, both orders of a pair at once;
* **far pairs** ``(A, B)`` (clusters apart, ``max(diam) ≤ θ · gap``), for ``α = 2``: **cluster
  against cluster**, one kernel per ordered pair of clusters (O(N) kernels). With ``α = 2``,
  ``f_IJ = l_I l_J dᵀ P_I d / |d|^β`` (``P_I = 1 − T_I T_Iᵀ``), so ``A`` enters through its
  moments ``G = Σ e eᵀ/l``, ``W = Σ (e eᵀ/l) ⊗ δ``, ``V = Σ (e eᵀ/l) ⊗ δ ⊗ δ`` and ``S = Σ l δ
  δᵀ`` (``δ = m − c_A``), ``B`` through ``L_B``, ``c_B`` and ``S_B``; the pair sum is
  expanded to second order on both sides around ``d = c_A − c_B``, error third order in
  ``diam / |d|`` (the formula in the block comment above :func:`_cc_node`).
* far pairs for other ``α`` (``|T × d|^α`` is no polynomial in ``T``, no moments make it
  separable): every *edge* ``I`` of ``A`` against ``B`` as one point, the pair kernel with
  ``l_J = L_B`` and ``m_J = c_B`` (the monopole of ``B``, its first order vanishes; the
  target side exact), one kernel per edge of ``A``, O(N log N).

Errors and times of both measured in docs/lab/tangent-point.md ("Tangent-point energy: cluster
against cluster", "Second order on both sides").

The gradient is the exact derivative of this approximated sum for the fixed split: the far
field's derivatives in the clusters' moments go to their edges by the chain rule
(``∂L/∂l_J = 1``, ``∂c/∂m_J = l_J/L``, ``∂c/∂l_J = (m_J − c)/L``, ``G``, ``W``, ``V`` through
``e eᵀ/l`` and ``δ``, ``S`` through ``l δ δᵀ``, ``∂W_abk/∂c_k = −G_ab``, ``∂V/∂c`` through
``W``): for ``α = 2`` summed down the tree once (:func:`_cc_push`), for other ``α`` each edge
walking up its ancestors. Every edge's and every target cluster's own sums are sequential;
what a pair gives its second edge or source cluster goes to rows of the same fixed piece of
the leaves or to fixed buffers per piece, added in a fixed order: the same bits for every
thread count.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ..energies.tangent_point import (
    DEFAULT_ALPHA,
    DEFAULT_BETA,
    KIND_2,
    KIND_2_4,
    KIND_2_45,
    KIND_GENERAL,
    THETA,
    check_exponents,
    kind_of,
    pair,
    pair_both_2,
    pair_radial,
    radial,
)
from ..geometry.layout import Layout
from .far_field import _kind, _levels
from .moebius import Frame, _edge_arrays, _neighbours, check_theta
from .near_field import _lane_store, _load_lanes, _to_vertices

#: Edges per leaf of the tangent-point tree (the near field's lanes, below).
LEAF_SIZE = 4
# Fixed pieces of the parallel loops over leaves: the per-edge sums are their own (any split,
# the same bits); what the pairs give their second edge (near) or source cluster (far) goes to
# one buffer per piece, so their number is fixed.
_FAR_CHUNKS = 16


# The near field's lanes (the idea of ``_near_field``): up to this many edges of a leaf against
# one partner edge at a time, both orders of each pair at once (the distance, |d|^−β and the
# masks are shared). One work array per parallel piece: lane j's edge at W[_LANES k + j] (k:
# midpoint, edge vector, length, then its tree position and neighbours' as floats, position −1
# past the leaf's end, then 1 / length), its sums at W[_NW_SUMS + _LANES k + j] (f, ∂/∂e,
# ∂/∂m, ∂/∂l) and what its pairs give the partner at W[_NW_OUT + _LANES k + j] (∂/∂e, ∂/∂m,
# ∂/∂l), added over the lanes in lane order. Constant offsets plus j: the lane loop
# vectorizes. The first ten rows as in ``_near_field``, by its _load_lanes.
# Of fast-math only "contract" (fused multiply–adds), here and in the far field's kernels
# (_cc_moments, _cc_far, _cc_to_edges): about 8 % off the sums. Only while the code compiled in
# a first process and the code numba's cache loads give the same bits
# (tests/core/test_shipped_cache.py); in the Möbius near and far fields they did not
# (docs/lab/repulsor.md, "Fused multiply–adds and symmetric moments in the tangent-point tree").
# For α = 2 the partner edges go two at a time: the radial parts of both (1 / |d|², |d|^−β,
# the masks) first, each in its own rows (_NW_INV, and _NW_INV + _LANES for the second;
# |d|^−β _NW_RB further on), so that their divisions overlap (one at a time, the pairs waited
# for each division: the near field's gradient pass at 10⁵ edges 43 → 37 ms, at the price of
# _near_leaves compiling in 35 s instead of 15 s; one loop over twice the lanes for both kept
# scalar divisions and gave nothing; docs/lab/repulsor.md, "The near field's divisions overlap, no
# reference counting in the loops, …").
# Four lanes on leaves of four edges (:data:`LEAF_SIZE`): the finer split leaves about half the
# near pairs, and the far field, cluster against cluster, is cheap per pair. The energy-only
# pass loops over ``lanes``, a run-time argument equal to _LANES: a constant trip count of four
# was unrolled fully and left scalar (times in docs/lab/repulsor.md, "The tangent-point tree on
# leaves of four edges").
_LANES = 4
_NW_ID = 7 * _LANES
_NW_IL = 10 * _LANES
_NW_SUMS = 11 * _LANES
_NW_OUT = 19 * _LANES
_NW_INV = 26 * _LANES
_NW_RB = 2 * _LANES
_NW_SIZE = 30 * _LANES


@nb.njit(cache=True, error_model="numpy", inline="always")
def _near_radial_k(W, ri, rx, ry, rz, r, lim, beta, kind, lanes):
    """Per lane ``1 / |d|²`` and ``|d|^−β`` (:func:`.energies.tangent_point.radial`) of the
    lane's edge and partner edge ``r`` (midpoint, tree position as a float), to rows ``ri``
    and ``ri + _NW_RB`` (``ri`` a constant at each call). The edge itself, its neighbours,
    the lanes past the leaf's end and lanes at positions ≥ ``lim`` (a leaf against itself:
    each pair once) count zero: ``|d|² = ∞`` by a select, no branch."""
    for j in range(lanes):
        dx = W[j] - rx
        dy = W[_LANES + j] - ry
        dz = W[2 * _LANES + j] - rz
        q = W[_NW_ID + j]
        r2 = dx * dx + dy * dy + dz * dz
        # one select per test: a compound condition branches, and the loop does not vectorize
        # (the energy alone took 2.6–3.2× the time at 10⁵ edges, docs/lab/tangent-point.md)
        r2 = np.inf if r == q else r2
        r2 = np.inf if r == W[_NW_ID + _LANES + j] else r2
        r2 = np.inf if r == W[_NW_ID + 2 * _LANES + j] else r2
        r2 = np.inf if q < 0.0 else r2
        r2 = np.inf if q >= lim else r2
        inv, rb = radial(r2, beta, kind)
        W[ri + j] = inv
        W[ri + _NW_RB + j] = rb


@nb.njit(cache=True, inline="always")
def _near_radial(W, ri, rx, ry, rz, r, lim, beta, kind, lanes):
    """:func:`_near_radial_k` with ``kind`` a constant in each branch."""
    if kind == KIND_2_4:
        _near_radial_k(W, ri, rx, ry, rz, r, lim, beta, KIND_2_4, lanes)
    elif kind == KIND_2_45:
        _near_radial_k(W, ri, rx, ry, rz, r, lim, beta, KIND_2_45, lanes)
    else:
        _near_radial_k(W, ri, rx, ry, rz, r, lim, beta, KIND_2, lanes)


@nb.njit(cache=True, error_model="numpy", inline="always")
def _near_lanes(W, ri, rx, ry, rz, sx, sy, sz, lr, ir, alpha, beta, grad, lanes):
    """Partner edge ``r`` (midpoint, edge vector, length and its inverse) against every lane's
    edge, both ordered pairs, with the lanes' :func:`_near_radial` in rows ``ri``: added to the
    lane's sums, what they give ``r`` in the lane's ``_NW_OUT`` slots. Any ``α``
    (:func:`_near_lanes_2` for ``α = 2``)."""
    for j in range(_LANES if grad else lanes):
        dx = W[j] - rx
        dy = W[_LANES + j] - ry
        dz = W[2 * _LANES + j] - rz
        inv = W[ri + j]
        rb = W[ri + _NW_RB + j]
        lq = W[6 * _LANES + j]
        # (I, J) = (lane, r) and (r, lane)
        f, fax, fay, faz, fdx, fdy, fdz, fl = pair_radial(
            dx, dy, dz, W[3 * _LANES + j], W[4 * _LANES + j], W[5 * _LANES + j],
            lq, W[_NW_IL + j], lr, inv, rb, alpha, beta, True)
        g, gax, gay, gaz, gdx, gdy, gdz, gl = pair_radial(
            -dx, -dy, -dz, sx, sy, sz, lr, ir, lq, inv, rb, alpha, beta, True)
        _lane_store(W, j, _NW_SUMS, _NW_OUT, _LANES, f + g, fax, fay, faz, gax, gay, gaz,
                    fdx - gdx, fdy - gdy, fdz - gdz, gl, fl, grad)


@nb.njit(cache=True, error_model="numpy", inline="always")
def _near_lanes_2(W, ri, rx, ry, rz, sx, sy, sz, lr, ir, beta, grad, lanes):
    """:func:`_near_lanes` for ``α = 2``: both orders of each pair at once
    (:func:`.energies.tangent_point.pair_both_2`)."""
    for j in range(_LANES if grad else lanes):
        (F, eix, eiy, eiz, ejx, ejy, ejz, mx, my, mz, gli, glj) = pair_both_2(
            W[j] - rx, W[_LANES + j] - ry, W[2 * _LANES + j] - rz,
            W[3 * _LANES + j], W[4 * _LANES + j], W[5 * _LANES + j],
            W[6 * _LANES + j], W[_NW_IL + j], sx, sy, sz, lr, ir,
            W[ri + j], W[ri + _NW_RB + j], beta)
        _lane_store(W, j, _NW_SUMS, _NW_OUT, _LANES, F, eix, eiy, eiz, ejx, ejy, ejz, mx, my, mz,
                    gli, glj, grad)


@nb.njit(cache=True, inline="always")
def _near_out(W, acc, row):
    """What the pairs gave the partner edge (the lanes' ``_NW_OUT`` slots, in lane order) added
    to its columns 1–7 of row ``row`` of ``acc``."""
    for k in range(7):
        t = 0.0
        for j in range(_LANES):
            t += W[_NW_OUT + k * _LANES + j]
        acc[row, 1 + k] += t


@nb.njit(cache=True, inline="always")
def _near_group(W, acc, n, E, M, ln, lo, hi, a, uoff, upart, uslot, width, alpha, beta, kind,
                general, grad, lanes):
    """The loaded lanes of leaf ``a`` against every edge ``r`` of the leaf itself (each pair
    once) and of its partners after it: what the pairs give ``r`` (edge vector, midpoint,
    length; the lanes in order) added to its columns 1–7 of ``acc``: its own row for a leaf of
    the same piece, else the partner's slot (rows ``n + width · slot …``). ``general`` and ``grad``
    constants at each call site, ``kind`` only in the small loop of :func:`_near_radial`: a
    copy of the pairs' loop per kind took minutes to compile."""
    for p in range(uoff[a] - 1, uoff[a + 1]):
        b = a if p < uoff[a] else upart[p]
        s = -1 if p < uoff[a] else uslot[p]
        # one array, not a choice of two: that counted a reference per partner, atomically
        off = 0 if s < 0 else n + width * s - lo[b]
        if general:  # one partner edge at a time (kind: the general power)
            for r in range(lo[b], hi[b]):
                fr = float(r)
                _near_radial_k(W, _NW_INV, M[r, 0], M[r, 1], M[r, 2], fr,
                               fr if b == a else np.inf, beta, KIND_2, lanes)
                _near_lanes(W, _NW_INV, M[r, 0], M[r, 1], M[r, 2], E[r, 0], E[r, 1], E[r, 2],
                            ln[r], 1.0 / ln[r], alpha, beta, grad, lanes)
                if grad:
                    _near_out(W, acc, r + off)
            continue
        # two partner edges at a time (see the lanes' comment). An odd last edge goes with
        # itself as the second, every lane off (lim −∞), and is not added to acc.
        for r in range(lo[b], hi[b], 2):
            r1 = min(r + 1, hi[b] - 1)
            fr = float(r)
            fr1 = float(r1)
            _near_radial(W, _NW_INV, M[r, 0], M[r, 1], M[r, 2], fr, fr if b == a else np.inf,
                         beta, kind, lanes)
            _near_radial(W, _NW_INV + _LANES, M[r1, 0], M[r1, 1], M[r1, 2], fr1,
                         -np.inf if r1 == r else (fr1 if b == a else np.inf), beta, kind,
                         lanes)
            _near_lanes_2(W, _NW_INV, M[r, 0], M[r, 1], M[r, 2], E[r, 0], E[r, 1], E[r, 2],
                          ln[r], 1.0 / ln[r], beta, grad, lanes)
            if grad:
                _near_out(W, acc, r + off)
            _near_lanes_2(W, _NW_INV + _LANES, M[r1, 0], M[r1, 1], M[r1, 2], E[r1, 0],
                          E[r1, 1], E[r1, 2], ln[r1], 1.0 / ln[r1], beta, grad, lanes)
            if grad and r1 != r:
                _near_out(W, acc, r1 + off)


@nb.njit(cache=True, error_model="numpy", fastmath={"contract"})
def _near_leaves(E, M, ln, lo, hi, leaves, t0, t1, uoff, upart, uslot, nbr, width, alpha,
                 beta, kind, grad, acc, n, lanes):
    """The leaves ``leaves[t0:t1]`` of :func:`_near` (one piece): the sums of their edges and
    what their pairs give other edges to ``acc`` (:func:`_near_group`). A function
    of its own, called from the parallel loop: in a copy of a variant, compiled without
    ``parallel``, the gradient pass took 0.28 s against 0.33 s inside the loop's body (10⁵
    edges); in place the difference was in the noise (docs/lab/repulsor.md, "Vectorized masking,
    faster band solves")."""
    W = np.zeros(_NW_SIZE)
    for t in range(t0, t1):
        a = leaves[t]
        for q0 in range(lo[a], hi[a], _LANES):
            count = min(_LANES, hi[a] - q0)
            _load_lanes(W, E, M, ln, nbr, q0, count, True, _LANES)  # past the leaf's end: off
            for j in range(_LANES):
                W[_NW_IL + j] = 1.0 / W[6 * _LANES + j]
            W[_NW_SUMS:_NW_INV] = 0.0
            # general and grad constants at each call (the branches fold away)
            if grad:
                if kind == KIND_GENERAL:
                    _near_group(W, acc, n, E, M, ln, lo, hi, a, uoff, upart, uslot, width,
                                alpha, beta, kind, True, True, lanes)
                else:
                    _near_group(W, acc, n, E, M, ln, lo, hi, a, uoff, upart, uslot, width,
                                alpha, beta, kind, False, True, lanes)
            else:
                if kind == KIND_GENERAL:
                    _near_group(W, acc, n, E, M, ln, lo, hi, a, uoff, upart, uslot, width,
                                alpha, beta, kind, True, False, lanes)
                else:
                    _near_group(W, acc, n, E, M, ln, lo, hi, a, uoff, upart, uslot, width,
                                alpha, beta, kind, False, False, lanes)
            for j in range(count):
                q = q0 + j
                acc[q, 0] += W[_NW_SUMS + j]
                if grad:
                    for k in range(1, 8):
                        acc[q, k] += W[_NW_SUMS + k * _LANES + j]


@nb.njit(cache=True)
def _near_pieces(leaves, pairs, m, nchunks):
    """Each unordered pair of near leaves (``pairs``, :func:`.barnes_hut._split`'s) once, by
    the first in tree order: per leaf its partners after it (CSR ``uoff``, ``upart``, in the
    order of ``pairs``) and the slot each takes in the buffer of what the pairs give partners
    beyond the leaf's piece (``uslot``, −1 for a partner in the same piece; one slot per piece
    and partner leaf, ``slot_leaf``), the pieces ``nchunks`` fixed ranges of ``leaves``."""
    nl = leaves.shape[0]
    pos = np.full(m, -1, np.int64)
    for t in range(nl):
        pos[leaves[t]] = t
    uoff = np.zeros(m + 1, np.int64)
    for p in range(pairs.shape[0]):
        if pairs[p, 0] != pairs[p, 1]:
            uoff[min(pairs[p, 0], pairs[p, 1]) + 1] += 1
    for k in range(m):
        uoff[k + 1] += uoff[k]
    upart = np.empty(uoff[m], np.int32)
    fill = uoff[:m].copy()
    for p in range(pairs.shape[0]):
        a, b = pairs[p, 0], pairs[p, 1]
        if a != b:
            lo_ = min(a, b)
            upart[fill[lo_]] = max(a, b)
            fill[lo_] += 1
    uslot = np.empty(uoff[m], np.int32)
    slot_leaf = np.empty(uoff[m], np.int64)
    stamp = np.full(m, -1, np.int64)
    slot = np.empty(m, np.int64)
    ns = 0
    for ch in range(nchunks):
        t1 = (ch + 1) * nl // nchunks
        for t in range(ch * nl // nchunks, t1):
            a = leaves[t]
            for k in range(uoff[a], uoff[a + 1]):
                b = upart[k]
                if pos[b] < t1:
                    uslot[k] = -1
                else:
                    if stamp[b] != ch:
                        stamp[b] = ch
                        slot[b] = ns
                        slot_leaf[ns] = b
                        ns += 1
                    uslot[k] = slot[b]
    return uoff, upart, uslot, slot_leaf[:ns].copy()


@nb.njit(cache=True, parallel=True)
def _lc_data(M, ln, cp, lo, hi, left, right):
    """Per node what the tangent-point far field and the split read: total length ``L``,
    length-weighted centre ``c`` and kind (:func:`._far_field._cluster_data`'s, without the
    Möbius energy's higher moments). One depth at a time from the deepest."""
    m = lo.shape[0]
    L = np.empty(m)
    C = np.empty((m, 3))
    nc = np.empty(m, np.int64)
    order, offsets = _levels(left, right)
    for d in range(offsets.shape[0] - 2, -1, -1):
        for tt in nb.prange(offsets[d], offsets[d + 1]):
            node = order[tt]
            a0, b0 = left[node], right[node]
            if a0 < 0:
                tot = cx = cy = cz = 0.0
                c0 = cp[lo[node]]
                for q in range(lo[node], hi[node]):
                    w = ln[q]
                    tot += w
                    cx += w * M[q, 0]
                    cy += w * M[q, 1]
                    cz += w * M[q, 2]
                    c0 = _kind(c0, cp[q])
                L[node] = tot
                C[node, 0] = cx / tot
                C[node, 1] = cy / tot
                C[node, 2] = cz / tot
                nc[node] = c0
            else:
                tot = L[a0] + L[b0]
                L[node] = tot
                for k in range(3):
                    C[node, k] = (L[a0] * C[a0, k] + L[b0] * C[b0, k]) / tot
                nc[node] = _kind(nc[a0], nc[b0])
    return L, C, nc


@nb.njit(cache=True, parallel=True, error_model="numpy")
def _near(E, M, ln, lo, hi, leaves, uoff, upart, uslot, slot_leaf, nbr, alpha, beta, kind, grad,
          lanes):
    """Per edge (tree order): row 0 ``Σ_J f(I, J)`` over its near partners and, with ``grad``,
    the partials of every near pair it is part of (as ``I`` or as ``J``) in its edge vector
    (rows 1–3, without the length term), midpoint (4–6) and length (7). Each unordered pair of
    edges is evaluated once, both orders (:func:`_near_lanes`), by the first leaf in tree order
    (:func:`_near_pieces`); the pieces of the leaves in parallel, each writing its own edges'
    rows, what its pairs give edges beyond it to their slots, added in slot order: the same
    bits for any thread count. ``lanes``: always :data:`_LANES`, passed at run time (see the
    lanes' comment above)."""
    n = ln.shape[0]
    nl = leaves.shape[0]
    width = np.int64(0)  # not a literal 0: typed Literal[int], _near_leaves compiled twice
    for t in range(nl):
        width = max(width, hi[leaves[t]] - lo[leaves[t]])
    slots = slot_leaf.shape[0] if grad else 0
    # an edge's sums in one cache line; the slots after the edges
    acc = np.zeros((n + width * slots, 8 if grad else 1))
    nchunks = min(nl, _FAR_CHUNKS)
    for cc in nb.prange(nchunks):
        ch = np.int64(cc)
        _near_leaves(E, M, ln, lo, hi, leaves, ch * nl // nchunks, (ch + 1) * nl // nchunks,
                     uoff, upart, uslot, nbr, width, alpha, beta, kind, grad, acc, n, lanes)
    for s in range(slots):  # in slot order: the same bits for any thread count
        b = slot_leaf[s]
        for i in range(hi[b] - lo[b]):
            for k in range(1, 8):
                acc[lo[b] + i, k] += acc[n + width * s + i, k]
    rows = np.empty((acc.shape[1], n))
    for qq in nb.prange(n):
        q = np.int64(qq)
        for k in range(acc.shape[1]):
            rows[k, q] = acc[q, k]
    return rows


@nb.njit(cache=True, parallel=True, error_model="numpy")
def _far(E, M, ln, L, C, lo, hi, leaves, parent, foff, fpart, alpha, beta, grad, rows):
    """For ``α ≠ 2`` (``α = 2`` takes :func:`_cc_far`): every edge against the far partners of
    its leaf and of the leaf's ancestors, each partner ``B`` as one point of weight ``L_B`` at
    ``c_B``: added to ``rows`` (row 0 the energy, 1–3 the edge vector, 4–6 the midpoint;
    :func:`_near`'s layout). Returns, per fixed piece of the leaves, the derivatives of the sum
    in every cluster's ``L`` (column 0) and ``c`` (1–3)."""
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
                il = 1.0 / li
                s = gax = gay = gaz = gmx = gmy = gmz = 0.0
                a = leaf
                while a >= 0:
                    for p in range(foff[a], foff[a + 1]):
                        b = fpart[p]
                        dx = px - C[b, 0]
                        dy = py - C[b, 1]
                        dz = pz - C[b, 2]
                        f, fax, fay, faz, fdx, fdy, fdz, fl = pair(
                            dx, dy, dz, ax, ay, az, li, il, L[b], dx * dx + dy * dy + dz * dz,
                            alpha, beta, KIND_GENERAL)
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
# a far pair through moments. Per node: L and c (as the Möbius tree), G = Σ e eᵀ/l (Σ l P =
# L·1 − G), W = Σ (e eᵀ/l) ⊗ δ, S = Σ l δ δᵀ and V = Σ (e eᵀ/l) ⊗ δ ⊗ δ (δ = m − c). A far
# pair (A, B) is Σ_IJ l_I l_J φ_I(d + δ_I − δ_J), d = c_A − c_B, φ_I(x) = xᵀ P_I x |x|^−β,
# expanded to second order on both sides. The first orders: B's vanishes (Σ l δ = 0), A's is
# −W; the mixed second order vanishes too. With ρ = |d|^−β, ρ₂ = ρ/|d|², ρ₄ = ρ₂/|d|²:
#
#   F = L_B [L_A |d|² ρ − ρ dᵀG_A d − 2ρ <v_A, d> + β ρ₂ W_A(d, d, d)]           (orders 0, 1)
#     + ½ L_B [κ_A ρ + ρ₂ dᵀR_A d − β(β+2) ρ₄ V_A(d, d, d, d)]                  (A's order 2)
#     + ρ Q_A:S_B − ½β ρ₂ [4 dᵀQ_A S_B d + tr S_B dᵀQ_A d] + ½β(β+2) ρ₄ dᵀQ_A d dᵀS_B d
#                                                                                (B's order 2)
#
# with v_a = Σ_b W_abb, Q_A = L_A·1 − G_A, κ = (2 − β) tr S − 2 Σ_ab V_abab and R = β(β − 2) S +
# β (2 (N + Nᵀ) + K), N_bl = Σ_a V_abal, K_ab = Σ_k V_abkk (:func:`_cc_coeffs`): one kernel per
# pair of clusters (O(N) kernels), error of third order in diam / |d| (the first order's terms
# of order two came to 1e-3–7e-3 of the energy at θ 0.25, the second order's are 1e-4 at most;
# docs/lab/tangent-point.md, "Second order on both sides").

# the pairs ab of a symmetric index pair, in the order 00, 01, 02, 11, 12, 22, and back
_PA = np.array([0, 0, 0, 1, 1, 2])
_PB = np.array([0, 1, 2, 1, 2, 2])
_PI = np.array([[0, 1, 2], [1, 3, 4], [2, 4, 5]])
# the fifteen monomials of degree four in d, x⁴, x³y, x³z, x²y², x²yz, x²z², xy³, xy²z, xyz²,
# xz³, y⁴, y³z, y²z², yz³, z⁴: the one of each index quadruple
_MONO = np.zeros((3, 3, 3, 3), np.int64)
for _i, _e in enumerate([(4, 0, 0), (3, 1, 0), (3, 0, 1), (2, 2, 0), (2, 1, 1), (2, 0, 2),
                         (1, 3, 0), (1, 2, 1), (1, 1, 2), (1, 0, 3), (0, 4, 0), (0, 3, 1),
                         (0, 2, 2), (0, 1, 3), (0, 0, 4)]):
    for _q in np.ndindex(3, 3, 3, 3):
        if tuple(sum(1 for t in _q if t == k) for k in range(3)) == _e:
            _MONO[_q] = _i
del _i, _e, _q
# the entries of V that make N_ij + N_ji (N_bl = Σ_a V_abal), per pair ij; the monomial of each
# entry (ab, kl) of V and how many index quadruples it stands for
_N_AT = np.array([[6 * _PI[a, i] + _PI[a, j] for a in range(3)]
                  + [6 * _PI[a, j] + _PI[a, i] for a in range(3)]
                  for i, j in zip(_PA, _PB, strict=True)])
_Q_AT = np.array([_MONO[_PA[p], _PB[p], _PA[s], _PB[s]] for p in range(6) for s in range(6)])
_Q_W = np.array([(1.0 if _PA[p] == _PB[p] else 2.0) * (1.0 if _PA[s] == _PB[s] else 2.0)
                 for p in range(6) for s in range(6)])


@nb.njit(cache=True, inline="always")
def _cc_shift(node, ch, L, C, G, Wm, Sm, V):
    """Child ``ch``'s ``G``, ``W``, ``S``, ``V`` moved to the centre of ``node`` (``u = c_ch −
    c``: ``W += G ⊗ u``, ``S += L u uᵀ``, ``V += W ⊗ u + u ⊗ W + G ⊗ u ⊗ u``), added to its
    rows."""
    u0 = C[ch, 0] - C[node, 0]
    u1 = C[ch, 1] - C[node, 1]
    u2 = C[ch, 2] - C[node, 2]
    uu0, uu1, uu2, uu3, uu4, uu5 = u0 * u0, u0 * u1, u0 * u2, u1 * u1, u1 * u2, u2 * u2
    lc = L[ch]
    Sm[node, 0] += lc * uu0
    Sm[node, 1] += lc * uu1
    Sm[node, 2] += lc * uu2
    Sm[node, 3] += lc * uu3
    Sm[node, 4] += lc * uu4
    Sm[node, 5] += lc * uu5
    for p in range(6):
        g = G[ch, p]
        w0, w1, w2 = Wm[ch, 3 * p], Wm[ch, 3 * p + 1], Wm[ch, 3 * p + 2]
        Wm[node, 3 * p] += g * u0
        Wm[node, 3 * p + 1] += g * u1
        Wm[node, 3 * p + 2] += g * u2
        k = 6 * p
        V[node, k] += 2.0 * w0 * u0 + g * uu0
        V[node, k + 1] += w0 * u1 + w1 * u0 + g * uu1
        V[node, k + 2] += w0 * u2 + w2 * u0 + g * uu2
        V[node, k + 3] += 2.0 * w1 * u1 + g * uu3
        V[node, k + 4] += w1 * u2 + w2 * u1 + g * uu4
        V[node, k + 5] += 2.0 * w2 * u2 + g * uu5


@nb.njit(cache=True, inline="always")
def _cc_node(node, E, M, ln, lo, hi, left, right, L, C, G, Wm, Sm, V):
    """``G``, ``W``, ``S`` and ``V`` of one node about its centre ``C[node]``, symmetric in
    their index pairs and stored by the pair (:data:`_SYM_W`): ``G`` and ``S`` six entries,
    ``W`` eighteen (index 3 ab + c), ``V`` 36 (index 6 ab + kl). A leaf from its edges (one
    pair ab at a time, its sums in registers), a parent from its children's moved to its
    centre (:func:`_cc_shift`), each entry written once before it is added to."""
    if left[node] < 0:
        c0, c1, c2 = C[node, 0], C[node, 1], C[node, 2]
        s0 = s1 = s2 = s3 = s4 = s5 = 0.0
        for q in range(lo[node], hi[node]):
            lq = ln[q]
            d0, d1, d2 = M[q, 0] - c0, M[q, 1] - c1, M[q, 2] - c2
            s0 += lq * d0 * d0
            s1 += lq * d0 * d1
            s2 += lq * d0 * d2
            s3 += lq * d1 * d1
            s4 += lq * d1 * d2
            s5 += lq * d2 * d2
        Sm[node, 0], Sm[node, 1], Sm[node, 2] = s0, s1, s2
        Sm[node, 3], Sm[node, 4], Sm[node, 5] = s3, s4, s5
        for p in range(6):
            i, j = _PA[p], _PB[p]
            g = w0 = w1 = w2 = v0 = v1 = v2 = v3 = v4 = v5 = 0.0
            for q in range(lo[node], hi[node]):
                t = E[q, i] * (E[q, j] * (1.0 / ln[q]))
                d0, d1, d2 = M[q, 0] - c0, M[q, 1] - c1, M[q, 2] - c2
                t0, t1, t2 = t * d0, t * d1, t * d2
                g += t
                w0 += t0
                w1 += t1
                w2 += t2
                v0 += t0 * d0
                v1 += t0 * d1
                v2 += t0 * d2
                v3 += t1 * d1
                v4 += t1 * d2
                v5 += t2 * d2
            G[node, p] = g
            Wm[node, 3 * p], Wm[node, 3 * p + 1], Wm[node, 3 * p + 2] = w0, w1, w2
            k = 6 * p
            V[node, k], V[node, k + 1], V[node, k + 2] = v0, v1, v2
            V[node, k + 3], V[node, k + 4], V[node, k + 5] = v3, v4, v5
    else:
        a0, b0 = left[node], right[node]
        for s in range(6):
            G[node, s] = G[a0, s] + G[b0, s]
            Sm[node, s] = Sm[a0, s] + Sm[b0, s]
        for k in range(18):
            Wm[node, k] = Wm[a0, k] + Wm[b0, k]
        for k in range(36):
            V[node, k] = V[a0, k] + V[b0, k]
        _cc_shift(node, a0, L, C, G, Wm, Sm, V)
        _cc_shift(node, b0, L, C, G, Wm, Sm, V)


@nb.njit(cache=True, parallel=True, fastmath={"contract"})
def _cc_moments(E, M, ln, lo, hi, left, right, L, C):
    """Per node ``G``, ``W``, ``S`` and ``V`` (:func:`_cc_node`), bottom-up one depth at a
    time (each node writes its own row)."""
    m = lo.shape[0]
    G = np.empty((m, 6))
    Wm = np.empty((m, 18))
    Sm = np.empty((m, 6))
    V = np.empty((m, 36))
    order, offsets = _levels(left, right)
    for d in range(offsets.shape[0] - 2, -1, -1):
        if offsets[d + 1] - offsets[d] >= 256:
            for t in nb.prange(offsets[d], offsets[d + 1]):
                _cc_node(order[t], E, M, ln, lo, hi, left, right, L, C, G, Wm, Sm, V)
        else:
            for t in range(offsets[d], offsets[d + 1]):
                _cc_node(order[t], E, M, ln, lo, hi, left, right, L, C, G, Wm, Sm, V)
    return G, Wm, Sm, V


@nb.njit(cache=True, parallel=True)
def _cc_coeffs(Sm, V, beta):
    """Per node what its second order as a target needs (the formula above): ``κ``, ``R``
    (six, by the pair) and the fifteen coefficients of ``V(d, d, d, d)`` (:data:`_MONO`), by
    the tables :data:`_N_AT`, :data:`_Q_AT` and :data:`_Q_W`."""
    m = Sm.shape[0]
    T = np.empty((m, 22))
    b2 = beta * (beta - 2.0)
    for nn in nb.prange(m):
        n = np.int64(nn)
        tr1 = V[n, 0] + V[n, 21] + V[n, 35] + 2.0 * (V[n, 7] + V[n, 14] + V[n, 28])
        T[n, 0] = (2.0 - beta) * (Sm[n, 0] + Sm[n, 3] + Sm[n, 5]) - 2.0 * tr1
        for s in range(6):
            nij = 0.0
            for t in range(6):
                nij += V[n, _N_AT[s, t]]
            kij = V[n, 6 * s] + V[n, 6 * s + 3] + V[n, 6 * s + 5]
            T[n, 1 + s] = b2 * Sm[n, s] + beta * (2.0 * nij + kij)
        for k in range(15):
            T[n, 7 + k] = 0.0
        for f in range(36):
            T[n, 7 + _Q_AT[f]] += _Q_W[f] * V[n, f]
    return T


# The cluster–cluster far field's lanes (the idea of ``_near_field``): up to this many partners
# of one target at a time. One work array per parallel piece: lane j's partner at W[_CL k + j]
# (k: L, c; |d|^−β at _CW_RHO; S, six, at _CW_S; 1 / |d|² at _CW_INV), its sums at
# W[_CW_SUMS + _CL k + j] (energy; ∂/∂L_A, ∂/∂c_A; −2 L ρ d; ∂/∂G_A, six; β L ρ₂ d ⊗ d ⊗ d,
# ten; L ρ; L ρ₂ d dᵀ, six; L ρ₄ d⁴, fifteen) and what the pair gives the partner at
# W[_CW_OUT + _CL k + j] (∂/∂L_B, ∂/∂c_B, ∂/∂S_B), added over the lanes in lane order. Lanes
# past the last partner repeat it with L = 0 and S = 0: every term is a multiple of one of them.
_CL = 4
_CW_RHO = 4 * _CL
_CW_S = 5 * _CL
_CW_INV = 11 * _CL
_CW_SUMS = 12 * _CL
_NSUMS = 46
_CW_OUT = _CW_SUMS + _NSUMS * _CL
_NOUT = 10
_CW_SIZE = _CW_OUT + _NOUT * _CL
# G, W, S, V and their derivatives are symmetric in their index pairs: stored by the pair ab
# in the order 00, 01, 02, 11, 12, 22 (six of nine entries, 18 of 27, 36 of 81); a sum over
# a, b takes the pairs off the diagonal twice (_SYM_W). The derivatives are those in the full
# tensor's entries (∂/∂G_ab = ∂/∂G_ba), so the sums over full indices use _SYM_W too.
_SYM_W = np.array([1.0, 2.0, 2.0, 1.0, 2.0, 1.0])


@nb.njit(cache=True, inline="always")
def _cc_radial_k(W, cax, cay, caz, beta, kind, lanes):
    """Per lane ``|d|^−β`` and ``1 / |d|²`` (:func:`.energies.tangent_point.radial`) to
    ``W[_CW_RHO + j]`` and ``W[_CW_INV + j]``."""
    for j in range(lanes):
        dx = cax - W[_CL + j]
        dy = cay - W[2 * _CL + j]
        dz = caz - W[3 * _CL + j]
        inv, rb = radial(dx * dx + dy * dy + dz * dz, beta, kind)
        W[_CW_RHO + j] = rb
        W[_CW_INV + j] = inv


@nb.njit(cache=True, inline="always")
def _cc_radial(W, cax, cay, caz, beta, kind, lanes):
    """:func:`_cc_radial_k` with ``kind`` a constant in each branch: the pairs' loop is one for
    every kind (a copy per kind took minutes to compile)."""
    if kind == KIND_2_4:
        _cc_radial_k(W, cax, cay, caz, beta, KIND_2_4, lanes)
    elif kind == KIND_2_45:
        _cc_radial_k(W, cax, cay, caz, beta, KIND_2_45, lanes)
    else:
        _cc_radial_k(W, cax, cay, caz, beta, KIND_2, lanes)


@nb.njit(cache=True)
def _cc_slots(foff, fpart, m, nchunks):
    """The far field's rows of what targets give their partners as sources: one row per piece
    (a fixed range of ``nchunks`` of the targets) and partner it meets, numbered piece by
    piece; ``fslot`` the row of each far pair (``fpart``'s order), ``soff``/``sidx`` per node
    its rows, in piece order (CSR). At 10⁵ edges (θ 0.7) 58 582 rows against 16 × 50 000 for
    a row per piece and node, whose scattered writes faulted in 25 MB of pages per evaluation
    (docs/lab/repulsor.md, "The Möbius near field takes each pair once, …")."""
    fslot = np.empty(fpart.shape[0], np.int32)
    stamp = np.full(m, -1, np.int64)
    slot = np.empty(m, np.int64)
    count = np.zeros(m + 1, np.int64)
    node = np.empty(fpart.shape[0], np.int64)  # the partner of each row (at most one per pair)
    ns = 0
    for ch in range(nchunks):
        for a in range(ch * m // nchunks, (ch + 1) * m // nchunks):
            for p in range(foff[a], foff[a + 1]):
                b = fpart[p]
                if stamp[b] != ch:
                    stamp[b] = ch
                    slot[b] = ns
                    node[ns] = b
                    count[b + 1] += 1
                    ns += 1
                fslot[p] = slot[b]
    soff = np.cumsum(count)
    sidx = np.empty(ns, np.int32)
    fill = soff[:m].copy()
    for r in range(ns):  # in row order, so in piece order per node
        b = node[r]
        sidx[fill[b]] = r
        fill[b] += 1
    return fslot, soff, sidx



@nb.njit(cache=True, error_model="numpy", inline="always")
def _cc_target(a, W, S, L, C, G, Wm, Sm, T2, foff, fpart, beta, kind, grad, gs, fslot, eF, gt,
               gG, gW, gS, gD, lanes):
    """Target ``a`` against its far partners, by lanes (see above); ``S`` scratch for the
    lanes' sums; ``gs[fslot[p]]`` the source row of pair ``p`` (:func:`_cc_slots`). Rows are
    indexed in place, not taken as views: a view per partner counted its reference up and
    down, atomically (docs/lab/repulsor.md, "The near field's divisions overlap, no reference
    counting in the loops, …")."""
    la = L[a]
    cax, cay, caz = C[a, 0], C[a, 1], C[a, 2]
    g00, g01, g02, g11, g12, g22 = G[a, 0], G[a, 1], G[a, 2], G[a, 3], G[a, 4], G[a, 5]
    a000, a001, a002 = Wm[a, 0], Wm[a, 1], Wm[a, 2]
    a010, a011, a012 = Wm[a, 3], Wm[a, 4], Wm[a, 5]
    a020, a021, a022 = Wm[a, 6], Wm[a, 7], Wm[a, 8]
    a110, a111, a112 = Wm[a, 9], Wm[a, 10], Wm[a, 11]
    a120, a121, a122 = Wm[a, 12], Wm[a, 13], Wm[a, 14]
    a220, a221, a222 = Wm[a, 15], Wm[a, 16], Wm[a, 17]
    v0 = a000 + a011 + a022
    v1 = a010 + a111 + a122
    v2 = a020 + a121 + a222
    kap = T2[a, 0]
    r00, r01, r02, r11, r12, r22 = T2[a, 1], T2[a, 2], T2[a, 3], T2[a, 4], T2[a, 5], T2[a, 6]
    q0, q1, q2, q3, q4 = T2[a, 7], T2[a, 8], T2[a, 9], T2[a, 10], T2[a, 11]
    q5, q6, q7, q8, q9 = T2[a, 12], T2[a, 13], T2[a, 14], T2[a, 15], T2[a, 16]
    q10, q11, q12, q13, q14 = T2[a, 17], T2[a, 18], T2[a, 19], T2[a, 20], T2[a, 21]
    b2 = beta + 2.0
    b4 = beta + 4.0
    bb2 = beta * b2
    W[_CW_SUMS:_CW_OUT] = 0.0
    p1 = foff[a + 1]
    for p0 in range(foff[a], p1, _CL):
        cnt = min(_CL, p1 - p0)
        for j in range(_CL):
            b = fpart[p0 + min(j, cnt - 1)]
            W[j] = L[b] if j < cnt else 0.0
            W[_CL + j] = C[b, 0]
            W[2 * _CL + j] = C[b, 1]
            W[3 * _CL + j] = C[b, 2]
            for k in range(6):
                W[_CW_S + k * _CL + j] = Sm[b, k] if j < cnt else 0.0
        _cc_radial(W, cax, cay, caz, beta, kind, lanes)
        # a run-time count for the energy alone (as the near field's: a constant was unrolled)
        for j in range(_CL if grad else lanes):
            lb = W[j]
            dx = cax - W[_CL + j]
            dy = cay - W[2 * _CL + j]
            dz = caz - W[3 * _CL + j]
            s00, s01, s02 = W[_CW_S + j], W[_CW_S + _CL + j], W[_CW_S + 2 * _CL + j]
            s11, s12, s22 = W[_CW_S + 3 * _CL + j], W[_CW_S + 4 * _CL + j], W[_CW_S + 5 * _CL + j]
            r2 = dx * dx + dy * dy + dz * dz
            rho = W[_CW_RHO + j]
            inv = W[_CW_INV + j]
            rho2 = rho * inv
            rho4 = rho2 * inv
            gdx = g00 * dx + g01 * dy + g02 * dz
            gdy = g01 * dx + g11 * dy + g12 * dz
            gdz = g02 * dx + g12 * dy + g22 * dz
            dgd = dx * gdx + dy * gdy + dz * gdz
            vd = v0 * dx + v1 * dy + v2 * dz
            # Wd_ab = Σ_c W_abc d_c; w_a = Σ_b Wd_ab d_b; s = dᵀ Wd d
            d00 = a000 * dx + a001 * dy + a002 * dz
            d01 = a010 * dx + a011 * dy + a012 * dz
            d02 = a020 * dx + a021 * dy + a022 * dz
            d11 = a110 * dx + a111 * dy + a112 * dz
            d12 = a120 * dx + a121 * dy + a122 * dz
            d22 = a220 * dx + a221 * dy + a222 * dz
            w0 = d00 * dx + d01 * dy + d02 * dz
            w1 = d01 * dx + d11 * dy + d12 * dz
            w2 = d02 * dx + d12 * dy + d22 * dz
            s = w0 * dx + w1 * dy + w2 * dz
            inner = la * r2 * rho - rho * dgd - 2.0 * rho * vd + beta * rho2 * s
            # A's second order: R d, and V(d, d, d, d) by its gradient (the cubic monomials)
            rx0 = r00 * dx + r01 * dy + r02 * dz
            rx1 = r01 * dx + r11 * dy + r12 * dz
            rx2 = r02 * dx + r12 * dy + r22 * dz
            xrx = dx * rx0 + dy * rx1 + dz * rx2
            xx = dx * dx
            yy = dy * dy
            zz = dz * dz
            m0, m1, m2, m3, m4 = xx * dx, xx * dy, xx * dz, dx * yy, dx * dy * dz
            m5, m6, m7, m8, m9 = dx * zz, yy * dy, yy * dz, dy * zz, zz * dz
            gv0 = (4.0 * q0 * m0 + 3.0 * q1 * m1 + 3.0 * q2 * m2 + 2.0 * q3 * m3 + 2.0 * q4 * m4
                   + 2.0 * q5 * m5 + q6 * m6 + q7 * m7 + q8 * m8 + q9 * m9)
            gv1 = (q1 * m0 + 2.0 * q3 * m1 + q4 * m2 + 3.0 * q6 * m3 + 2.0 * q7 * m4 + q8 * m5
                   + 4.0 * q10 * m6 + 3.0 * q11 * m7 + 2.0 * q12 * m8 + q13 * m9)
            gv2 = (q2 * m0 + q4 * m1 + 2.0 * q5 * m2 + q7 * m3 + 2.0 * q8 * m4 + 3.0 * q9 * m5
                   + q11 * m6 + 2.0 * q12 * m7 + 3.0 * q13 * m8 + 4.0 * q14 * m9)
            v4 = 0.25 * (dx * gv0 + dy * gv1 + dz * gv2)
            a2 = 0.5 * (rho * kap + rho2 * xrx - bb2 * rho4 * v4)
            # B's second order: S_B d, Q_A = L_A·1 − G_A
            sx0 = s00 * dx + s01 * dy + s02 * dz
            sx1 = s01 * dx + s11 * dy + s12 * dz
            sx2 = s02 * dx + s12 * dy + s22 * dz
            xsx = dx * sx0 + dy * sx1 + dz * sx2
            trs = s00 + s11 + s22
            qs = la * trs - (g00 * s00 + g11 * s11 + g22 * s22
                             + 2.0 * (g01 * s01 + g02 * s02 + g12 * s12))
            qx = la * r2 - dgd
            xqsx = la * xsx - (gdx * sx0 + gdy * sx1 + gdz * sx2)
            f2b = (rho * qs - 0.5 * beta * rho2 * (4.0 * xqsx + trs * qx)
                   + 0.5 * bb2 * rho4 * qx * xsx)
            W[_CW_SUMS + j] += lb * (inner + a2) + f2b
            if grad:
                # u_c = Σ_ab W_abc d_a d_b
                xy = 2.0 * dx * dy
                xz = 2.0 * dx * dz
                yz = 2.0 * dy * dz
                u0 = a000 * xx + a110 * yy + a220 * zz + a010 * xy + a020 * xz + a120 * yz
                u1 = a001 * xx + a111 * yy + a221 * zz + a011 * xy + a021 * xz + a121 * yz
                u2 = a002 * xx + a112 * yy + a222 * zz + a012 * xy + a022 * xz + a122 * yz
                rho6 = rho4 * inv
                # ∂/∂d of the orders 0 and 1, of A's second order and of B's
                c1 = (la * rho * (2.0 - beta) + beta * rho2 * dgd + 2.0 * beta * rho2 * vd
                      - beta * b2 * rho4 * s)
                ca = 0.5 * (-beta * rho2 * kap - b2 * rho4 * xrx + bb2 * b4 * rho6 * v4)
                qx0 = la * dx - gdx
                qx1 = la * dy - gdy
                qx2 = la * dz - gdz
                cb = (-beta * rho2 * qs + 0.5 * beta * b2 * rho4 * (4.0 * xqsx + trs * qx)
                      - 0.5 * bb2 * b4 * rho6 * qx * xsx)
                # (Q S + S Q) d = 2 L_A S d − G S d − S G d
                e0 = 2.0 * la * sx0 - (g00 * sx0 + g01 * sx1 + g02 * sx2) - (
                    s00 * gdx + s01 * gdy + s02 * gdz)
                e1 = 2.0 * la * sx1 - (g01 * sx0 + g11 * sx1 + g12 * sx2) - (
                    s01 * gdx + s11 * gdy + s12 * gdz)
                e2 = 2.0 * la * sx2 - (g02 * sx0 + g12 * sx1 + g22 * sx2) - (
                    s02 * gdx + s12 * gdy + s22 * gdz)
                kb = beta * rho2 * trs
                kq = bb2 * rho4 * xsx
                kr = bb2 * rho4 * qx
                hx = (lb * (c1 * dx - 2.0 * rho * gdx - 2.0 * rho * v0
                            + beta * rho2 * (2.0 * w0 + u0)
                            + ca * dx + rho2 * rx0 - 0.5 * bb2 * rho4 * gv0)
                      + cb * dx - 2.0 * beta * rho2 * e0 - kb * qx0 + kq * qx0 + kr * sx0)
                hy = (lb * (c1 * dy - 2.0 * rho * gdy - 2.0 * rho * v1
                            + beta * rho2 * (2.0 * w1 + u1)
                            + ca * dy + rho2 * rx1 - 0.5 * bb2 * rho4 * gv1)
                      + cb * dy - 2.0 * beta * rho2 * e1 - kb * qx1 + kq * qx1 + kr * sx1)
                hz = (lb * (c1 * dz - 2.0 * rho * gdz - 2.0 * rho * v2
                            + beta * rho2 * (2.0 * w2 + u2)
                            + ca * dz + rho2 * rx2 - 0.5 * bb2 * rho4 * gv2)
                      + cb * dz - 2.0 * beta * rho2 * e2 - kb * qx2 + kq * qx2 + kr * sx2)
                # ∂/∂Q_A of B's second order: ρ S_B − β ρ₂ (S_B d dᵀ + d dᵀ S_B) + ½ (β(β+2) ρ₄
                # dᵀS_B d − β ρ₂ tr S_B) d dᵀ; its trace to ∂/∂L_A, minus it to ∂/∂G_A
                br = beta * rho2
                hq = 0.5 * (kq - kb)
                dq00 = rho * s00 - 2.0 * br * sx0 * dx + hq * xx
                dq01 = rho * s01 - br * (sx0 * dy + dx * sx1) + hq * dx * dy
                dq02 = rho * s02 - br * (sx0 * dz + dx * sx2) + hq * dx * dz
                dq11 = rho * s11 - 2.0 * br * sx1 * dy + hq * yy
                dq12 = rho * s12 - br * (sx1 * dz + dy * sx2) + hq * dy * dz
                dq22 = rho * s22 - 2.0 * br * sx2 * dz + hq * zz
                k = -lb * rho
                k3 = beta * lb * rho2
                kx = k3 * xx
                ky = k3 * yy
                kz = k3 * zz
                W[_CW_SUMS + _CL + j] += lb * r2 * rho + dq00 + dq11 + dq22
                W[_CW_SUMS + 2 * _CL + j] += hx
                W[_CW_SUMS + 3 * _CL + j] += hy
                W[_CW_SUMS + 4 * _CL + j] += hz
                W[_CW_SUMS + 5 * _CL + j] += 2.0 * k * dx
                W[_CW_SUMS + 6 * _CL + j] += 2.0 * k * dy
                W[_CW_SUMS + 7 * _CL + j] += 2.0 * k * dz
                W[_CW_SUMS + 8 * _CL + j] += k * xx - dq00
                W[_CW_SUMS + 9 * _CL + j] += k * dx * dy - dq01
                W[_CW_SUMS + 10 * _CL + j] += k * dx * dz - dq02
                W[_CW_SUMS + 11 * _CL + j] += k * yy - dq11
                W[_CW_SUMS + 12 * _CL + j] += k * dy * dz - dq12
                W[_CW_SUMS + 13 * _CL + j] += k * zz - dq22
                W[_CW_SUMS + 14 * _CL + j] += kx * dx
                W[_CW_SUMS + 15 * _CL + j] += kx * dy
                W[_CW_SUMS + 16 * _CL + j] += kx * dz
                W[_CW_SUMS + 17 * _CL + j] += ky * dx
                W[_CW_SUMS + 18 * _CL + j] += k3 * dx * dy * dz
                W[_CW_SUMS + 19 * _CL + j] += kz * dx
                W[_CW_SUMS + 20 * _CL + j] += ky * dy
                W[_CW_SUMS + 21 * _CL + j] += ky * dz
                W[_CW_SUMS + 22 * _CL + j] += kz * dy
                W[_CW_SUMS + 23 * _CL + j] += kz * dz
                # for ∂/∂S_A and ∂/∂V_A (:func:`_cc_second`): L ρ, L ρ₂ d dᵀ, L ρ₄ d⁴
                l2 = lb * rho2
                l4 = lb * rho4
                W[_CW_SUMS + 24 * _CL + j] += lb * rho
                W[_CW_SUMS + 25 * _CL + j] += l2 * xx
                W[_CW_SUMS + 26 * _CL + j] += l2 * dx * dy
                W[_CW_SUMS + 27 * _CL + j] += l2 * dx * dz
                W[_CW_SUMS + 28 * _CL + j] += l2 * yy
                W[_CW_SUMS + 29 * _CL + j] += l2 * dy * dz
                W[_CW_SUMS + 30 * _CL + j] += l2 * zz
                W[_CW_SUMS + 31 * _CL + j] += l4 * dx * m0
                W[_CW_SUMS + 32 * _CL + j] += l4 * dx * m1
                W[_CW_SUMS + 33 * _CL + j] += l4 * dx * m2
                W[_CW_SUMS + 34 * _CL + j] += l4 * dx * m3
                W[_CW_SUMS + 35 * _CL + j] += l4 * dx * m4
                W[_CW_SUMS + 36 * _CL + j] += l4 * dx * m5
                W[_CW_SUMS + 37 * _CL + j] += l4 * dx * m6
                W[_CW_SUMS + 38 * _CL + j] += l4 * dx * m7
                W[_CW_SUMS + 39 * _CL + j] += l4 * dx * m8
                W[_CW_SUMS + 40 * _CL + j] += l4 * dx * m9
                W[_CW_SUMS + 41 * _CL + j] += l4 * dy * m6
                W[_CW_SUMS + 42 * _CL + j] += l4 * dy * m7
                W[_CW_SUMS + 43 * _CL + j] += l4 * dy * m8
                W[_CW_SUMS + 44 * _CL + j] += l4 * dy * m9
                W[_CW_SUMS + 45 * _CL + j] += l4 * dz * m9
                # to the partner: ∂/∂L_B, ∂/∂d (c_B's with the sign turned), ∂/∂S_B = ρ Q_A −
                # β ρ₂ (Q_A d dᵀ + d dᵀ Q_A) − ½ β ρ₂ dᵀQ_A d · 1 + ½ β(β+2) ρ₄ dᵀQ_A d · d dᵀ
                hs = 0.5 * kr
                ht = 0.5 * br * qx
                W[_CW_OUT + j] = inner + a2
                W[_CW_OUT + _CL + j] = hx
                W[_CW_OUT + 2 * _CL + j] = hy
                W[_CW_OUT + 3 * _CL + j] = hz
                W[_CW_OUT + 4 * _CL + j] = rho * (la - g00) - 2.0 * br * qx0 * dx + hs * xx - ht
                W[_CW_OUT + 5 * _CL + j] = -rho * g01 - br * (qx0 * dy + dx * qx1) + hs * dx * dy
                W[_CW_OUT + 6 * _CL + j] = -rho * g02 - br * (qx0 * dz + dx * qx2) + hs * dx * dz
                W[_CW_OUT + 7 * _CL + j] = rho * (la - g11) - 2.0 * br * qx1 * dy + hs * yy - ht
                W[_CW_OUT + 8 * _CL + j] = -rho * g12 - br * (qx1 * dz + dy * qx2) + hs * dy * dz
                W[_CW_OUT + 9 * _CL + j] = rho * (la - g22) - 2.0 * br * qx2 * dz + hs * zz - ht
        if grad:
            for j in range(cnt):
                r = fslot[p0 + j]
                gs[r, 0] += W[_CW_OUT + j]
                gs[r, 1] -= W[_CW_OUT + _CL + j]
                gs[r, 2] -= W[_CW_OUT + 2 * _CL + j]
                gs[r, 3] -= W[_CW_OUT + 3 * _CL + j]
                for k in range(4, _NOUT):
                    gs[r, k] += W[_CW_OUT + k * _CL + j]
    e = 0.0
    for j in range(_CL):
        e += W[_CW_SUMS + j]
    eF[a] = e
    if grad:
        for k in range(1, _NSUMS):
            t = 0.0
            for j in range(_CL):
                t += W[_CW_SUMS + k * _CL + j]
            S[k] = t
        for k in range(4):
            gt[a, k] = S[1 + k]
        for k in range(6):  # ∂/∂G_ab (= ∂/∂G_ba), by the pair ab
            gG[a, k] = S[8 + k]
        # ∂/∂W_abc, symmetric in a, b, by (ab, c): the entry of the sorted index triple (xxx …
        # zzz at S[14 …]), and of −2ρ<v, d> (v_a = Σ_b W_abb) −2ρ d_a δ_bc made symmetric,
        # ½ (d_a δ_bc + d_b δ_ac)
        h5, h6, h7 = 0.5 * S[5], 0.5 * S[6], 0.5 * S[7]
        gW[a, 0], gW[a, 1], gW[a, 2] = S[14] + S[5], S[15], S[16]
        gW[a, 3], gW[a, 4], gW[a, 5] = S[15] + h6, S[17] + h5, S[18]
        gW[a, 6], gW[a, 7], gW[a, 8] = S[16] + h7, S[18], S[19] + h5
        gW[a, 9], gW[a, 10], gW[a, 11] = S[17], S[20] + S[6], S[21]
        gW[a, 12], gW[a, 13], gW[a, 14] = S[18], S[21] + h7, S[22] + h6
        gW[a, 15], gW[a, 16], gW[a, 17] = S[19], S[22], S[23] + S[7]
        _cc_second(a, S, beta, gS, gD)


@nb.njit(cache=True, inline="always")
def _cc_second(a, S, beta, gS, gD):
    """∂/∂S_A and ∂/∂V_A of A's second order as a target, from the lanes' sums ``s₀ = Σ L_B
    ρ`` (``S[24]``), ``X = Σ L_B ρ₂ d dᵀ`` (``S[25 …]``, by the pair) and ``Σ L_B ρ₄ d⁴``
    (``S[31 …]``, :data:`_MONO`): ``½ Σ_B L_B ∂²(d_a d_b ρ)/∂d_k∂d_l`` is ``½ (s₀ (δ_ak δ_bl +
    δ_al δ_bk) − β (δ_ak X_bl + δ_bk X_al + δ_al X_bk + δ_bl X_ak + X_ab δ_kl) + β(β+2) X⁴_abkl)``;
    ``V`` enters with it turned, ``S`` with it summed over ``a = b``."""
    s0 = S[24]
    for s in range(6):
        k, q = _PA[s], _PB[s]
        gS[a, s] = 0.5 * ((2.0 - beta) * s0 * (1.0 if k == q else 0.0)
                          + beta * (beta - 2.0) * S[25 + s])
    for p in range(6):
        i, j = _PA[p], _PB[p]
        for s in range(6):
            k, q = _PA[s], _PB[s]
            c = s0 * ((1.0 if (i == k and j == q) else 0.0) + (1.0 if (i == q and j == k) else 0.0))
            t = 0.0
            if i == k:
                t += S[25 + _PI[j, q]]
            if j == k:
                t += S[25 + _PI[i, q]]
            if i == q:
                t += S[25 + _PI[j, k]]
            if j == q:
                t += S[25 + _PI[i, k]]
            if k == q:
                t += S[25 + p]
            gD[a, 6 * p + s] = -0.5 * (c - beta * t
                                       + beta * (beta + 2.0) * S[31 + _MONO[i, j, k, q]])


@nb.njit(cache=True, parallel=True, error_model="numpy", fastmath={"contract"})
def _cc_far(L, C, G, Wm, Sm, T2, foff, fpart, fslot, rows, beta, kind, grad, lanes, gD):
    """Every node ``A`` against its far partners ``B`` (:func:`_cc_node`'s moments, ``T2``
    :func:`_cc_coeffs`'): per node the energy of its pairs as target; with ``grad`` the
    derivatives of the sum in its own ``L`` (column 0 of ``gt``), ``c`` (1–3), ``G`` (``gG``),
    ``W`` (``gW``), ``S`` (``gS``) and ``V`` (``gD``) as a target, and, per fixed piece of the
    targets, in every partner's ``L``, ``c`` and ``S`` as a source (``gs``, ``rows`` rows of
    :func:`_cc_slots`, ``fslot`` the row of each pair). Each target's sums are its own: the
    same bits for any thread count. ``lanes``: always :data:`_CL`, passed at run time. ``gD``:
    an ``(m, 36)`` array (with ``grad``) whose rows are all overwritten."""
    m = L.shape[0]
    nchunks = min(m, _FAR_CHUNKS)
    # every row written below (a target's own, zeros where it has no partner): np.zeros
    # cleared the 16 MB of these at 10⁵ edges once more (docs/lab/repulsor.md, "The near field's
    # divisions overlap, no reference counting in the loops, …")
    eF = np.empty(m)
    mg = m if grad else 0
    gt = np.empty((mg, 4))
    gG = np.empty((mg, 6))
    gW = np.empty((mg, 18))
    gS = np.empty((mg, 6))
    gs = np.zeros((rows if grad else 0, _NOUT))
    for cc in nb.prange(nchunks):
        ch = np.int64(cc)
        W = np.zeros(_CW_SIZE)
        S = np.zeros(_NSUMS)
        for a in range(ch * m // nchunks, (ch + 1) * m // nchunks):
            if foff[a + 1] == foff[a]:
                eF[a] = 0.0
                if grad:
                    gt[a] = 0.0
                    gG[a] = 0.0
                    gW[a] = 0.0
                    gS[a] = 0.0
                    gD[a] = 0.0
                continue
            if grad:  # a constant at each call (the branches fold away)
                _cc_target(a, W, S, L, C, G, Wm, Sm, T2, foff, fpart, beta, kind, True, gs,
                           fslot, eF, gt, gG, gW, gS, gD, lanes)
            else:
                _cc_target(a, W, S, L, C, G, Wm, Sm, T2, foff, fpart, beta, kind, False, gs,
                           fslot, eF, gt, gG, gW, gS, gD, lanes)
    return eF, gt, gG, gW, gS, gD, gs


@nb.njit(cache=True, parallel=True)
def _cc_node_grad(L, G, Wm, gt, gs, soff, sidx, gG, gW, gS, gD):
    """Per node, the derivatives the edges need: ``∂/∂L`` (target and source parts),
    ``∂/∂c`` with ``W``'s and ``V``'s dependence on ``c`` folded in (``∂W_abk/∂c_j = −δ_jk
    G_ab``, ``∂V_abkl/∂c_j = −δ_jk W_abl − δ_jl W_abk``; ``S``'s vanishes, ``Σ l δ = 0``), and
    the source part of ``∂/∂S`` added to ``gS`` in place."""
    m = L.shape[0]
    out = np.empty((m, 4))  # every row written
    for bb in nb.prange(m):
        b = np.int64(bb)
        s0 = gt[b, 0]
        s1 = gt[b, 1]
        s2 = gt[b, 2]
        s3 = gt[b, 3]
        for k in range(soff[b], soff[b + 1]):  # in piece order: the same bits for any thread count
            r = sidx[k]
            s0 += gs[r, 0]
            s1 += gs[r, 1]
            s2 += gs[r, 2]
            s3 += gs[r, 3]
            for q in range(6):
                gS[b, q] += gs[r, 4 + q]
        for ab in range(6):  # Σ over a, b: the pairs off the diagonal twice
            w = G[b, ab] * _SYM_W[ab]
            s1 -= gW[b, 3 * ab] * w
            s2 -= gW[b, 3 * ab + 1] * w
            s3 -= gW[b, 3 * ab + 2] * w
            # −2 Σ_l D_ab,jl W_ab,l for j = 0, 1, 2
            w2 = 2.0 * _SYM_W[ab]
            t0 = t1 = t2 = 0.0
            for c in range(3):
                wl = Wm[b, 3 * ab + c]
                t0 += gD[b, 6 * ab + _PI[0, c]] * wl
                t1 += gD[b, 6 * ab + _PI[1, c]] * wl
                t2 += gD[b, 6 * ab + _PI[2, c]] * wl
            s1 -= w2 * t0
            s2 -= w2 * t1
            s3 -= w2 * t2
        out[b, 0] = s0
        out[b, 1] = s1
        out[b, 2] = s2
        out[b, 3] = s3
    return out


@nb.njit(cache=True)
def _cc_push(L, C, parent, gn, gG, gW, gS, gD):
    """The nodes' derivatives summed down to the leaves, in place, each node's sum about its
    own centre: the terms :func:`_cc_to_edges` adds per edge and ancestor are polynomials in
    the edge's midpoint (``L`` and ``c`` through ``m − c``, ``S`` through ``l δ δᵀ``, ``G``,
    ``W`` and ``V`` through ``δ = m − c``), so a parent's sum moves to a child's centre by
    ``h = c_child − c`` (``δ = δ_child + h``). After it, per node: ``gn`` column 0 the
    ``∂/∂l`` constant, 1–3 the coefficient of ``l δ``; ``gS`` of ``l δ δᵀ``; ``gG``, ``gW``
    and ``gD`` of ``e eᵀ/l``, ``e eᵀ/l ⊗ δ`` and ``e eᵀ/l ⊗ δ ⊗ δ``. Parents first (a
    parent's index is below its children's)."""
    for b in range(L.shape[0]):
        il = 1.0 / L[b]
        for k in range(1, 4):
            gn[b, k] *= il
        p = parent[b]
        if p < 0:
            continue
        h = (C[b, 0] - C[p, 0], C[b, 1] - C[p, 1], C[b, 2] - C[p, 2])
        hsh = 0.0
        for s in range(6):
            hsh += _SYM_W[s] * gS[p, s] * h[_PA[s]] * h[_PB[s]]
        gn[b, 0] += gn[p, 0] + gn[p, 1] * h[0] + gn[p, 2] * h[1] + gn[p, 3] * h[2] + hsh
        for k in range(3):
            sh = gS[p, _PI[k, 0]] * h[0] + gS[p, _PI[k, 1]] * h[1] + gS[p, _PI[k, 2]] * h[2]
            gn[b, 1 + k] += gn[p, 1 + k] + 2.0 * sh
        for s in range(6):
            gS[b, s] += gS[p, s]
        for ab in range(6):
            dh0 = gD[p, 6 * ab] * h[0] + gD[p, 6 * ab + 1] * h[1] + gD[p, 6 * ab + 2] * h[2]
            dh1 = gD[p, 6 * ab + 1] * h[0] + gD[p, 6 * ab + 3] * h[1] + gD[p, 6 * ab + 4] * h[2]
            dh2 = gD[p, 6 * ab + 2] * h[0] + gD[p, 6 * ab + 4] * h[1] + gD[p, 6 * ab + 5] * h[2]
            gG[b, ab] += (gG[p, ab] + gW[p, 3 * ab] * h[0] + gW[p, 3 * ab + 1] * h[1]
                          + gW[p, 3 * ab + 2] * h[2] + dh0 * h[0] + dh1 * h[1] + dh2 * h[2])
            gW[b, 3 * ab] += gW[p, 3 * ab] + 2.0 * dh0
            gW[b, 3 * ab + 1] += gW[p, 3 * ab + 1] + 2.0 * dh1
            gW[b, 3 * ab + 2] += gW[p, 3 * ab + 2] + 2.0 * dh2
        for k in range(36):
            gD[b, k] += gD[p, k]


@nb.njit(cache=True, inline="always")
def _cc_edge_pair(b, ab, gG, gW, gD, x0, x1, x2):
    """For the pair ``ab`` of leaf ``b`` at an edge's ``δ``: ``H_ab = gG + Σ_c (gW + Dδ)_c
    δ_c`` and ``(gW + 2 Dδ)_c``, c = 0, 1, 2 (``Dδ_c = Σ_l gD_ab,cl δ_l``)."""
    k0 = 6 * ab
    y0 = gD[b, k0] * x0 + gD[b, k0 + 1] * x1 + gD[b, k0 + 2] * x2
    y1 = gD[b, k0 + 1] * x0 + gD[b, k0 + 3] * x1 + gD[b, k0 + 4] * x2
    y2 = gD[b, k0 + 2] * x0 + gD[b, k0 + 4] * x1 + gD[b, k0 + 5] * x2
    w0 = gW[b, 3 * ab]
    w1 = gW[b, 3 * ab + 1]
    w2 = gW[b, 3 * ab + 2]
    h = gG[b, ab] + (w0 + y0) * x0 + (w1 + y1) * x1 + (w2 + y2) * x2
    return h, w0 + 2.0 * y0, w1 + 2.0 * y1, w2 + 2.0 * y2


@nb.njit(cache=True, parallel=True, fastmath={"contract"})
def _cc_to_edges(E, M, ln, C, lo, hi, leaves, gn, gG, gW, gS, gD, rows):
    """The nodes' derivatives, summed to the leaves (:func:`_cc_push`), passed to their edges:
    ``L`` and ``c`` as in :func:`_far_sources`, ``S`` through ``l δ δᵀ``; ``G``, ``W`` and
    ``V`` through ``e eᵀ / l`` (edge vector rows 1–3, length row 7) and ``δ = m − c``
    (midpoint rows 4–6). Last, the length row's part of the edge vector's rows (``∂l/∂e =
    e/l``): ``rows`` is then complete."""
    nl = leaves.shape[0]
    for tt in nb.prange(nl):
        b = leaves[np.int64(tt)]
        for q in range(lo[b], hi[b]):
            e0, e1, e2 = E[q, 0], E[q, 1], E[q, 2]
            il = 1.0 / ln[q]
            x0 = M[q, 0] - C[b, 0]
            x1 = M[q, 1] - C[b, 1]
            x2 = M[q, 2] - C[b, 2]
            # S: l δᵀ gS δ
            sx0 = gS[b, 0] * x0 + gS[b, 1] * x1 + gS[b, 2] * x2
            sx1 = gS[b, 1] * x0 + gS[b, 3] * x1 + gS[b, 4] * x2
            sx2 = gS[b, 2] * x0 + gS[b, 4] * x1 + gS[b, 5] * x2
            gl = (gn[b, 0] + gn[b, 1] * x0 + gn[b, 2] * x1 + gn[b, 3] * x2
                  + sx0 * x0 + sx1 * x1 + sx2 * x2)
            gm0 = (gn[b, 1] + 2.0 * sx0) * ln[q]
            gm1 = (gn[b, 2] + 2.0 * sx1) * ln[q]
            gm2 = (gn[b, 3] + 2.0 * sx2) * ln[q]
            # per pair ab, y_abc = gW_abc + Σ_l gD_ab,cl δ_l: H = gG + Σ_c (gW + Dδ)_c δ_c
            # (symmetric, by the pair ab); ∂(eᵀHe/l)/∂e = 2 H e / l, ∂/∂l = −eᵀHe/l²,
            # ∂/∂m_c = Σ_ab (gW + 2 Dδ)_abc e_a e_b / l
            t00 = e0 * e0 * il
            t01 = 2.0 * e0 * e1 * il
            t02 = 2.0 * e0 * e2 * il
            t11 = e1 * e1 * il
            t12 = 2.0 * e1 * e2 * il
            t22 = e2 * e2 * il
            h0, y00, y01, y02 = _cc_edge_pair(b, 0, gG, gW, gD, x0, x1, x2)
            h1, y10, y11, y12 = _cc_edge_pair(b, 1, gG, gW, gD, x0, x1, x2)
            h2, y20, y21, y22 = _cc_edge_pair(b, 2, gG, gW, gD, x0, x1, x2)
            h3, y30, y31, y32 = _cc_edge_pair(b, 3, gG, gW, gD, x0, x1, x2)
            h4, y40, y41, y42 = _cc_edge_pair(b, 4, gG, gW, gD, x0, x1, x2)
            h5, y50, y51, y52 = _cc_edge_pair(b, 5, gG, gW, gD, x0, x1, x2)
            gm0 += y00 * t00 + y10 * t01 + y20 * t02 + y30 * t11 + y40 * t12 + y50 * t22
            gm1 += y01 * t00 + y11 * t01 + y21 * t02 + y31 * t11 + y41 * t12 + y51 * t22
            gm2 += y02 * t00 + y12 * t01 + y22 * t02 + y32 * t11 + y42 * t12 + y52 * t22
            he0 = h0 * e0 + h1 * e1 + h2 * e2
            he1 = h1 * e0 + h3 * e1 + h4 * e2
            he2 = h2 * e0 + h4 * e1 + h5 * e2
            ehe = e0 * he0 + e1 * he1 + e2 * he2
            ga0 = 2.0 * he0 * il
            ga1 = 2.0 * he1 * il
            ga2 = 2.0 * he2 * il
            gl -= ehe * il * il
            rows[4, q] += gm0
            rows[5, q] += gm1
            rows[6, q] += gm2
            rows[7, q] += gl
            # and the length row's part of the edge vector's, ∂l/∂e = e/l (the last sums)
            t = rows[7, q] / ln[q]
            rows[1, q] = (rows[1, q] + ga0) + t * e0
            rows[2, q] = (rows[2, q] + ga1) + t * e1
            rows[3, q] = (rows[3, q] + ga2) + t * e2



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
    # edges, (2, 4): gradient error 1.1e-2 against 6.5e-2 with θ alone; docs/lab/tangent-point.md)
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
        self._cc_own = None
        m = left.shape[0]
        self._cc_slots = (_cc_slots(self.foff, self.fpart, m, min(m, _FAR_CHUNKS))
                          if self.kind != KIND_GENERAL else None)

    def _clusters(self, edges):
        tree = self.tree
        return _lc_data(edges[1], edges[2], edges[3], tree.lo, tree.hi, tree.left, tree.right)

    def _near_setup(self, near: np.ndarray, m: int):
        tree, layout = self.tree, self.layout
        self._nbr, self._at = _neighbours(tree.perm, layout.nxt, layout.prv)
        self._pieces = _near_pieces(self.leaves, near, m, min(self.leaves.shape[0], _FAR_CHUNKS))

    def _evaluate(self, X: np.ndarray, grad: bool):
        lay, tree = self.layout, self.tree
        X0, edges, clusters = self._own
        own = np.array_equal(X, X0)
        if not own:
            edges = _edge_arrays(X, lay.nxt, lay.comp, lay.starts, tree.perm)
            clusters = self._clusters(edges)
        E, M, ln = edges[0], edges[1], edges[2]
        L, C = clusters[0], clusters[1]
        args = (self.alpha, self.beta, self.kind, grad)
        rows = _near(E, M, ln, tree.lo, tree.hi, self.leaves, *self._pieces, self._nbr, *args,
                     _LANES)
        if self.kind == KIND_GENERAL:
            # |T × d|^α is no polynomial in T for α ≠ 2: every edge against the cluster
            gnode = _far(E, M, ln, L, C, tree.lo, tree.hi, self.leaves, self.parent, self.foff,
                         self.fpart, self.alpha, self.beta, grad, rows)
            energy = float(np.sum(rows[0]))
            if not grad:
                return energy, None
            _far_sources(M, ln, L, C, tree.lo, tree.hi, self.leaves, self.parent,
                         gnode.sum(axis=0), rows)
            rows[1:4] += rows[7] / ln * E.T  # ∂l/∂e = e/l
        else:
            if own and self._cc_own is not None:
                G, Wm, Sm, T2 = self._cc_own
                V = np.empty((L.shape[0] if grad else 0, 36))  # room for ∂/∂V
            else:
                # V is read by _cc_coeffs alone, so its rows take ∂/∂V below (fewer fresh
                # pages for a first call)
                G, Wm, Sm, V = _cc_moments(E, M, ln, tree.lo, tree.hi, tree.left, tree.right,
                                           L, C)
                T2 = _cc_coeffs(Sm, V, self.beta)
                if own:
                    self._cc_own = (G, Wm, Sm, T2)
            fslot, soff, sidx = self._cc_slots
            eF, gt, gG, gW, gS, gD, gs = _cc_far(L, C, G, Wm, Sm, T2, self.foff, self.fpart,
                                                 fslot, sidx.shape[0], self.beta, self.kind,
                                                 grad, _CL, V)
            energy = float(np.sum(rows[0])) + float(np.sum(eF))
            if not grad:
                return energy, None
            gn = _cc_node_grad(L, G, Wm, gt, gs, soff, sidx, gG, gW, gS, gD)
            _cc_push(L, C, self.parent, gn, gG, gW, gS, gD)
            # with ∂l/∂e = e/l of every sum (numpy's three temporaries took about 1 ms at 10⁵)
            _cc_to_edges(E, M, ln, C, tree.lo, tree.hi, self.leaves, gn, gG, gW, gS, gD, rows)
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
