"""The near field of the tree engine: every pair of edges in near pairs of leaves, summed exactly
with the energy's pair kernel (:func:`.energies.moebius.pair`, private; :mod:`barnes_hut`
splits the pairs).

The sum is ordered: each edge of a leaf sums over the edges of the leaf's near partners (itself
included), so every pair is computed once per side and no edge's sums depend on another's (the
same bits for any thread count; no buffers shared between threads). A leaf's edges are the SIMD
lanes; the partner edges go by one at a time.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .energies.moebius import SPLIT, pair

# Pieces of the near field's parallel loop over leaves (each edge's sums are its own: any split
# gives the same bits); a piece reuses one work array.
_NEAR_CHUNKS = 256


# The near field's lanes: up to this many edges of a leaf against one partner edge at a time.
# One work array per parallel piece: lane j's edge at W[_LANES k + j] (k: midpoint, edge
# vector, length, then its tree position, its neighbours' and its component, as floats: exact
# below 2^53) and its sums at W[_NW_SUMS + _LANES k + j]. One array, constant offsets plus j:
# the loop over lanes vectorizes (an index array beside it kept it scalar). No fast-math: a
# lane's sums are sequential, nothing to reassociate (an earlier near field with "reassoc" and
# "contract" gave the compiling process and numba's cache different last bits).
_LANES = 8
_NW_ID = 7 * _LANES
_NW_SUMS = 11 * _LANES
_NW_SIZE = 19 * _LANES


@nb.njit(cache=True, error_model="numpy", inline="always")
def _near_lanes(W, rx, ry, rz, bx0, by0, bz0, lj, r, cr, grad):
    """Partner edge ``r`` (midpoint, edge vector, length, tree position and component, the
    last two as floats) against every lane's edge, added to the lane's sums: ``f`` and, with
    ``grad``, ``l_J/|d|²`` and the partial ``∂f/∂e_I`` (without its length term) and
    ``∂f/∂m_I``. The edge itself and its neighbours count zero, an edge of another component
    its length part only: by selects, no branch."""
    for j in range(_LANES):
        px = W[j]
        py = W[_LANES + j]
        pz = W[2 * _LANES + j]
        ax = W[3 * _LANES + j]
        ay = W[4 * _LANES + j]
        az = W[5 * _LANES + j]
        li = W[6 * _LANES + j]
        dx = px - rx
        dy = py - ry
        dz = pz - rz
        r2 = dx * dx + dy * dy + dz * dz
        skip = r == W[_NW_ID + j] or r == W[_NW_ID + _LANES + j] or r == W[_NW_ID + 2 * _LANES + j]
        r2 = np.inf if skip else r2  # 1/|d|² = 0: every term 0
        same = cr == W[_NW_ID + 3 * _LANES + j]
        bx = bx0 if same else 0.0
        by = by0 if same else 0.0
        bz = bz0 if same else 0.0
        f, fax, fay, faz, _, _, _, fdx, fdy, fdz, wi, _ = pair(
            dx, dy, dz, ax, ay, az, bx, by, bz, li, lj, r2, SPLIT)
        W[_NW_SUMS + j] += f
        if grad:
            W[_NW_SUMS + _LANES + j] += wi
            W[_NW_SUMS + 2 * _LANES + j] += fax
            W[_NW_SUMS + 3 * _LANES + j] += fay
            W[_NW_SUMS + 4 * _LANES + j] += faz
            W[_NW_SUMS + 5 * _LANES + j] += fdx
            W[_NW_SUMS + 6 * _LANES + j] += fdy
            W[_NW_SUMS + 7 * _LANES + j] += fdz


@nb.njit(cache=True, parallel=True, error_model="numpy")
def _near_ordered(E, M, ln, cp, lo, hi, leaves, noff, npart, nbr, grad):
    """The near field as an ordered sum: every edge of a leaf against every edge of the leaf's
    near partners (itself included), except itself and its neighbours along the curve, with
    the energy's pair kernel. Per edge (tree order): ``rows[0]`` its share ``Σ_J f(I, J)``
    of the energy and, with ``grad``, rows 1–3 and 4–6 the derivatives of the ordered sum
    (``2 Σ_J ∂f(I, J)``, ``f`` symmetric) in its edge vector and midpoint. A leaf's edges
    are the lanes (:func:`_near_lanes`), the partners' edges go by one at a time; every pair is
    summed twice (once per side), and nothing is shared between edges: the same bits for any
    thread count and any split of the leaves."""
    n = ln.shape[0]
    nl = leaves.shape[0]
    rows = np.empty((7 if grad else 1, n))
    nchunks = min(nl, _NEAR_CHUNKS)
    for cc in nb.prange(nchunks):
        ch = np.int64(cc)
        W = np.zeros(_NW_SIZE)
        for t in range(ch * nl // nchunks, (ch + 1) * nl // nchunks):
            a = leaves[t]
            for q0 in range(lo[a], hi[a], _LANES):
                count = min(_LANES, hi[a] - q0)
                for j in range(_LANES):
                    q = q0 + min(j, count - 1)  # lanes past the leaf's end repeat its last edge
                    W[j] = M[q, 0]
                    W[_LANES + j] = M[q, 1]
                    W[2 * _LANES + j] = M[q, 2]
                    W[3 * _LANES + j] = E[q, 0]
                    W[4 * _LANES + j] = E[q, 1]
                    W[5 * _LANES + j] = E[q, 2]
                    W[6 * _LANES + j] = ln[q]
                    W[_NW_ID + j] = q
                    W[_NW_ID + _LANES + j] = nbr[q, 0]
                    W[_NW_ID + 2 * _LANES + j] = nbr[q, 1]
                    W[_NW_ID + 3 * _LANES + j] = cp[q]
                W[_NW_SUMS:] = 0.0
                for p in range(noff[a], noff[a + 1]):
                    b = npart[p]
                    for r in range(lo[b], hi[b]):
                        if grad:
                            _near_lanes(W, M[r, 0], M[r, 1], M[r, 2], E[r, 0], E[r, 1], E[r, 2],
                                        ln[r], float(r), float(cp[r]), True)
                        else:
                            _near_lanes(W, M[r, 0], M[r, 1], M[r, 2], E[r, 0], E[r, 1], E[r, 2],
                                        ln[r], float(r), float(cp[r]), False)
                for j in range(count):
                    q = q0 + j
                    rows[0, q] = W[_NW_SUMS + j]
                    if grad:
                        # the length term of ∂f/∂e_I: (l_J/l_I) e_I/|d|²
                        w = W[_NW_SUMS + _LANES + j] / ln[q]
                        for k in range(3):
                            ga = W[_NW_SUMS + (2 + k) * _LANES + j]
                            rows[1 + k, q] = 2.0 * (ga + w * E[q, k])
                            rows[4 + k, q] = 2.0 * W[_NW_SUMS + (5 + k) * _LANES + j]
    return rows


# ------------------------------------------------------------------------------------------------
# the symmetric near field: each unordered pair of edges once


# Slots (near pairs of leaves) per round of :func:`_near`: the partner side's sums of a round's
# pairs wait in a buffer of this many slots × edges per leaf × 7 floats (15 MB at leaves of 8)
# until the round's reduction adds them to the partner's edges.
_ROUND_SLOTS = 1 << 15
# Pieces of a round's parallel loop, each a fixed interleaved subset of its leaves (leaves
# have unequal numbers of partners; neighbouring ones similar numbers).
_PIECES = 64

# The work array of :func:`_near`'s blocks (one per leaf): the owner leaf's group of up to
# _LANES edges in lanes (fields of _LANES: midpoint, edge vector, length, tree position, its
# neighbours', component, 1 for a real lane), the partner's group twice over (fields of
# 2 _LANES: midpoint, edge vector, length, tree position, component, real), so that a shift s
# pairs lane j with partner lane s + j by contiguous loads; then the owner's sums (8 fields of
# _LANES) and the partner's (8 fields of 2 _LANES: partner edge i sums at i and i + _LANES).
_A_ID = 7 * _LANES
_A_OK = 11 * _LANES
_B = 12 * _LANES
_B2 = 2 * _LANES
_B_ID = _B + 7 * _B2
_B_CP = _B + 8 * _B2
_B_OK = _B + 9 * _B2
_SA = _B + 10 * _B2
_SB = _SA + 8 * _LANES
_W_SIZE = _SB + 8 * _B2


@nb.njit(cache=True, error_model="numpy", inline="always")
def _shift(W, s, both, grad):
    """Lane ``j`` of the owner's group against lane ``s + j`` of the partner's (doubled) group,
    for every ``j``: the pair kernel once, its value and partials added to the owner lane's
    sums and, with ``both``, to the partner edge's. Masked pairs (the edge itself, its
    neighbours, lanes past a group's end) take ``|d|² = inf``: every term 0. Two edges of
    different components count their length part only (both edge vectors 0 for the kernel)."""
    for j in range(_LANES):
        t = s + j
        ax0 = W[3 * _LANES + j]
        ay0 = W[4 * _LANES + j]
        az0 = W[5 * _LANES + j]
        bx0 = W[_B + 3 * _B2 + t]
        by0 = W[_B + 4 * _B2 + t]
        bz0 = W[_B + 5 * _B2 + t]
        dx = W[j] - W[_B + t]
        dy = W[_LANES + j] - W[_B + _B2 + t]
        dz = W[2 * _LANES + j] - W[_B + 2 * _B2 + t]
        r2 = dx * dx + dy * dy + dz * dz
        rid = W[_B_ID + t]
        skip = (rid == W[_A_ID + j] or rid == W[_A_ID + _LANES + j]
                or rid == W[_A_ID + 2 * _LANES + j] or W[_A_OK + j] == 0.0
                or W[_B_OK + t] == 0.0)
        r2 = np.inf if skip else r2  # 1/|d|² = 0: every term 0
        same = W[_A_ID + 3 * _LANES + j] == W[_B_CP + t]
        ax = ax0 if same else 0.0
        ay = ay0 if same else 0.0
        az = az0 if same else 0.0
        bx = bx0 if same else 0.0
        by = by0 if same else 0.0
        bz = bz0 if same else 0.0
        f, fax, fay, faz, fbx, fby, fbz, fdx, fdy, fdz, wi, wj = pair(
            dx, dy, dz, ax, ay, az, bx, by, bz, W[6 * _LANES + j], W[_B + 6 * _B2 + t], r2,
            SPLIT)
        W[_SA + j] += f
        if grad:
            W[_SA + _LANES + j] += wi
            W[_SA + 2 * _LANES + j] += fax
            W[_SA + 3 * _LANES + j] += fay
            W[_SA + 4 * _LANES + j] += faz
            W[_SA + 5 * _LANES + j] += fdx
            W[_SA + 6 * _LANES + j] += fdy
            W[_SA + 7 * _LANES + j] += fdz
        if both:
            W[_SB + t] += f
            if grad:
                W[_SB + _B2 + t] += wj
                W[_SB + 2 * _B2 + t] += fbx
                W[_SB + 3 * _B2 + t] += fby
                W[_SB + 4 * _B2 + t] += fbz
                W[_SB + 5 * _B2 + t] += fdx
                W[_SB + 6 * _B2 + t] += fdy
                W[_SB + 7 * _B2 + t] += fdz


@nb.njit(cache=True, inline="always")
def _load_owner(W, E, M, ln, cp, nbr, q0, count):
    """The owner's group ``q0 … q0 + count − 1`` into the lanes (lanes past its end repeat
    its last edge, marked not real)."""
    for j in range(_LANES):
        q = q0 + min(j, count - 1)
        W[j] = M[q, 0]
        W[_LANES + j] = M[q, 1]
        W[2 * _LANES + j] = M[q, 2]
        W[3 * _LANES + j] = E[q, 0]
        W[4 * _LANES + j] = E[q, 1]
        W[5 * _LANES + j] = E[q, 2]
        W[6 * _LANES + j] = ln[q]
        W[_A_ID + j] = q
        W[_A_ID + _LANES + j] = nbr[q, 0]
        W[_A_ID + 2 * _LANES + j] = nbr[q, 1]
        W[_A_ID + 3 * _LANES + j] = cp[q]
        W[_A_OK + j] = 1.0 if j < count else 0.0


@nb.njit(cache=True, inline="always")
def _load_partner(W, E, M, ln, cp, r0, count):
    """The partner's group ``r0 … r0 + count − 1`` into its lanes, twice over."""
    for i in range(_B2):
        jj = i % _LANES
        r = r0 + min(jj, count - 1)
        W[_B + i] = M[r, 0]
        W[_B + _B2 + i] = M[r, 1]
        W[_B + 2 * _B2 + i] = M[r, 2]
        W[_B + 3 * _B2 + i] = E[r, 0]
        W[_B + 4 * _B2 + i] = E[r, 1]
        W[_B + 5 * _B2 + i] = E[r, 2]
        W[_B + 6 * _B2 + i] = ln[r]
        W[_B_ID + i] = r
        W[_B_CP + i] = cp[r]
        W[_B_OK + i] = 1.0 if jj < count else 0.0


@nb.njit(cache=True, error_model="numpy", inline="always")
def _own_leaf(W, a, E, M, ln, cp, lo, hi, uoff, upart, nbr, buf, s0, rows, grad):
    """Leaf ``a``'s share of :func:`_near`: its edges' sums over its slots (into ``rows``) and
    the partners' sums of each slot ``p`` (into ``buf[p − s0]``)."""
    for q0 in range(lo[a], hi[a], _LANES):
        count = min(_LANES, hi[a] - q0)
        first = q0 == lo[a]
        _load_owner(W, E, M, ln, cp, nbr, q0, count)
        W[_SA:_SB] = 0.0
        for p in range(uoff[a], uoff[a + 1]):
            b = upart[p]
            for r0 in range(lo[b], hi[b], _LANES):
                cb = min(_LANES, hi[b] - r0)
                _load_partner(W, E, M, ln, cp, r0, cb)
                if b == a:  # the self pair, ordered: every pair of its edges from both sides
                    for s in range(_LANES):
                        if grad:
                            _shift(W, s, False, True)
                        else:
                            _shift(W, s, False, False)
                    continue
                W[_SB:] = 0.0
                for s in range(_LANES):
                    if grad:
                        _shift(W, s, True, True)
                    else:
                        _shift(W, s, True, False)
                slot = p - s0
                for i in range(cb):
                    r = r0 + i
                    at = r - lo[b]
                    # partner edge i's sums: at i (shifts s ≤ i) and i + _LANES (s > i)
                    v = W[_SB + i] + W[_SB + _LANES + i]
                    buf[slot, at, 0] = v if first else buf[slot, at, 0] + v
                    if grad:
                        # the length term of ∂f/∂e_J: (l_I/l_J) e_J/|d|²
                        w = (W[_SB + _B2 + i] + W[_SB + _B2 + _LANES + i]) / ln[r]
                        for c in range(3):
                            ge = W[_SB + (2 + c) * _B2 + i] + W[_SB + (2 + c) * _B2 + _LANES + i]
                            gd = W[_SB + (5 + c) * _B2 + i] + W[_SB + (5 + c) * _B2 + _LANES + i]
                            ve = 2.0 * (ge + w * E[r, c])
                            vm = -2.0 * gd  # d = m_I − m_J
                            buf[slot, at, 1 + c] = ve if first else buf[slot, at, 1 + c] + ve
                            buf[slot, at, 4 + c] = vm if first else buf[slot, at, 4 + c] + vm
        for j in range(count):
            q = q0 + j
            rows[0, q] += W[_SA + j]
            if grad:
                # the length term of ∂f/∂e_I: (l_J/l_I) e_I/|d|²
                w = W[_SA + _LANES + j] / ln[q]
                for c in range(3):
                    ga = W[_SA + (2 + c) * _LANES + j]
                    rows[1 + c, q] += 2.0 * (ga + w * E[q, c])
                    rows[4 + c, q] += 2.0 * W[_SA + (5 + c) * _LANES + j]


@nb.njit(cache=True, parallel=True, error_model="numpy")
def _near(E, M, ln, cp, lo, hi, leaves, uoff, upart, toff, tslot, rounds, nbr, grad):
    """The near field, each unordered pair of edges once: per edge (tree order) ``rows[0]``
    its share ``Σ_J f(I, J)`` of the ordered sum and, with ``grad``, rows 1–3 and 4–6 the
    derivatives of the ordered sum (``2 Σ_J ∂f(I, J)``, ``f`` symmetric) in its edge vector
    and midpoint; every pair of disjoint edges in near leaves, except an edge's neighbours
    along the curve, with the energy's pair kernel.

    Every near pair of leaves has an owner (``uoff``, ``upart``: CSR of the owner's partners,
    its self pair included; :func:`.barnes_hut._near_lists`). The owner sums a block of the
    pair's edges once (:func:`_shift`): its own side in its lanes, the partner's into the
    pair's slot of a buffer. The leaves go by ``rounds`` (ranges of ``leaves`` whose slots fit
    the buffer); after each, every leaf adds the slots it is the partner of (``toff``,
    ``tslot``: ascending) to its edges. Each leaf's sums and each slot are one thread's, and
    the reduction goes in the slots' order: the same bits for any thread count."""
    n = ln.shape[0]
    nl = leaves.shape[0]
    nv = 7 if grad else 1
    rows = np.zeros((nv, n))
    room = 1
    width = 1
    for k in range(rounds.shape[0] - 1):
        room = max(room, uoff[leaves[rounds[k + 1] - 1] + 1] - uoff[leaves[rounds[k]]])
    for t in range(nl):
        width = max(width, hi[leaves[t]] - lo[leaves[t]])
    buf = np.empty((room, width, nv))
    ptr = toff[:-1].copy()
    for k in range(rounds.shape[0] - 1):
        t0, t1 = rounds[k], rounds[k + 1]
        s0 = uoff[leaves[t0]]
        s1 = uoff[leaves[t1 - 1] + 1]
        npiece = min(t1 - t0, _PIECES)
        for cc in nb.prange(npiece):
            W = np.empty(_W_SIZE)
            for t in range(t0 + np.int64(cc), t1, npiece):
                _own_leaf(W, leaves[t], E, M, ln, cp, lo, hi, uoff, upart, nbr, buf, s0, rows,
                          grad)
        for tt in nb.prange(nl):
            b = leaves[np.int64(tt)]
            u = ptr[b]
            while u < toff[b + 1] and tslot[u] < s1:
                slot = tslot[u] - s0
                for i in range(hi[b] - lo[b]):
                    for c in range(nv):
                        rows[c, lo[b] + i] += buf[slot, i, c]
                u += 1
            ptr[b] = u
    return rows


@nb.njit(cache=True, parallel=True)
def _to_vertices(part, prv, at):
    """The gradient ``(N, 3)`` from the derivatives in the edge vectors (rows 1–3 of ``part``)
    and midpoints (rows 4–6) in tree order: ``e_I = P[nxt I] − P[I]`` and
    ``m_I = (P[I] + P[nxt I]) / 2``, so vertex ``v`` takes ``½ ∂m − ∂e`` of the edge it starts
    and ``∂e + ½ ∂m`` of the edge ``prv[v]`` it ends (none at the ends of an open polyline,
    whose dummy edges have tree position −1). Per vertex, in parallel."""
    n = at.shape[0]
    G = np.empty((n, 3))
    for vv in nb.prange(n):
        v = np.int64(vv)
        q = at[v]
        p = at[prv[v]]
        for k in range(3):
            a = (0.5 * part[4 + k, q] - part[1 + k, q]) if q >= 0 else 0.0
            b = (part[1 + k, p] + 0.5 * part[4 + k, p]) if p >= 0 else 0.0
            G[v, k] = a + b
    return G
