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
        # 1/|d|² = 0: every term 0. One select per test: a compound condition branches, and
        # the lane loop does not vectorize
        r2 = np.inf if r == W[_NW_ID + j] else r2
        r2 = np.inf if r == W[_NW_ID + _LANES + j] else r2
        r2 = np.inf if r == W[_NW_ID + 2 * _LANES + j] else r2
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


@nb.njit(cache=True, inline="always")
def _load_lanes(W, E, M, ln, nbr, q0, count, off_past, lanes):
    """Edges ``q0 … q0 + count − 1`` of a leaf into the rows of ``W`` of a near field with
    ``lanes`` lanes (midpoint, edge vector, length, tree position, the neighbours' positions;
    row k at ``lanes · k``); lanes past the leaf's end repeat its last edge, with position −1
    when ``off_past`` (the tangent-point near field masks them so), else its own."""
    for j in range(lanes):
        q = q0 + min(j, count - 1)
        W[j] = M[q, 0]
        W[lanes + j] = M[q, 1]
        W[2 * lanes + j] = M[q, 2]
        W[3 * lanes + j] = E[q, 0]
        W[4 * lanes + j] = E[q, 1]
        W[5 * lanes + j] = E[q, 2]
        W[6 * lanes + j] = ln[q]
        W[7 * lanes + j] = -1.0 if off_past and j >= count else q
        W[8 * lanes + j] = nbr[q, 0]
        W[9 * lanes + j] = nbr[q, 1]


@nb.njit(cache=True, error_model="numpy")
def _near_leaves(E, M, ln, cp, lo, hi, leaves, t0, t1, noff, npart, nbr, grad, rows):
    """The leaves ``leaves[t0:t1]`` of :func:`_near`, their edges' sums to ``rows``. A function
    of its own, called from the parallel loop, as in the tangent-point near field (here no
    difference was measured; the same bits)."""
    W = np.zeros(_NW_SIZE)
    for t in range(t0, t1):
        a = leaves[t]
        for q0 in range(lo[a], hi[a], _LANES):
            count = min(_LANES, hi[a] - q0)
            _load_lanes(W, E, M, ln, nbr, q0, count, False, _LANES)
            for j in range(_LANES):
                W[_NW_ID + 3 * _LANES + j] = cp[q0 + min(j, count - 1)]
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


@nb.njit(cache=True, parallel=True, error_model="numpy")
def _near(E, M, ln, cp, lo, hi, leaves, noff, npart, nbr, grad):
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
        _near_leaves(E, M, ln, cp, lo, hi, leaves, ch * nl // nchunks,
                     (ch + 1) * nl // nchunks, noff, npart, nbr, grad, rows)
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
