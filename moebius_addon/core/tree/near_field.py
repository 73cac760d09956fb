"""The near field of the tree engine: every pair of edges in near pairs of leaves, summed exactly
with the energy's pair kernel (:func:`.energies.moebius.pair`, private; :mod:`barnes_hut`
splits the pairs).

Each unordered pair of edges is computed once (the kernel is symmetric): a leaf's edges are the
SIMD lanes, the partner edges go by one at a time, and what a pair gives the partner edge is
added to the partner's row at once. So that no two threads write one row, the unordered pairs
of leaves are scheduled in rounds (:func:`_near_schedule`): the leaves are cut into fixed
pieces, a task is all pairs between two pieces (or within one), and a round holds tasks of
disjoint pieces, run in parallel; rounds one after the other. Every row takes its terms in an
order fixed by the schedule alone: the same bits for any thread count.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ..energies.moebius import SPLIT, pair

# Pieces of the leaves (tree order) for the near field's schedule: tasks are the pairs of pieces,
# round r those {i, j} with i + j = r (mod pieces), no piece twice (a round-robin). 64: at 10⁵
# edges and θ 0.175 the rounds' largest tasks leave two threads 1.00 of the work, four 0.98,
# eight 0.86 (16 pieces: 0.98, 0.85, 0.48; a greedy schedule of the tasks' pair counts).
_NEAR_PIECES = 64


# The near field's lanes: up to this many edges of a leaf against one partner edge at a time,
# each pair once. One work array per task: lane j's edge at W[_LANES k + j] (k: midpoint, edge
# vector, length, then its tree position, its neighbours', its component as floats: exact
# below 2^53, then two bounds: a partner edge at a position at or below the bound is not paired
# with the lane — in the leaf itself the lane's own position, so each pair of the leaf is taken
# once, in another leaf −1; +∞ past the leaf's end), its sums at W[_NW_SUMS + _LANES k + j]
# (f, ∂f/∂e, ∂f/∂m, ∂f/∂l: the columns of :func:`_near`'s buffer) and what its pair gives the
# partner at W[_NW_OUT + _LANES k + j] (∂f/∂e, ∂f/∂m, ∂f/∂l), added over the lanes. One
# array, constant offsets plus j: the loop over lanes vectorizes (an index array beside it kept
# it scalar). No fast-math: a lane's sums are sequential, nothing to reassociate, and with
# "contract" alone the compiling process and numba's cache gave different last bits (the
# tangent-point near field has it: there they agree; docs/lab/repulsor.md, "Fused multiply–adds and
# symmetric moments in the tangent-point tree").
_LANES = 8
assert _LANES == 8  # _near_out's pairwise sum over the lanes is written out for eight
_NW_ID = 7 * _LANES
_NW_LIM = 11 * _LANES
_NW_SUMS = 13 * _LANES
_NW_OUT = 21 * _LANES
_NW_SIZE = 28 * _LANES


@nb.njit(cache=True, error_model="numpy", inline="always")
def _near_lanes(W, rx, ry, rz, bx0, by0, bz0, lj, r, cr, own, grad):
    """Partner edge ``r`` (midpoint, edge vector, length, tree position and component, the
    last two as floats) against every lane's edge: the pair's ``f`` added to the lane's sums
    and, with ``grad``, its partials in both edges' lengths, edge vectors (without their length
    terms) and midpoints, the lane's added to its sums, the partner's written to the lane's
    ``_NW_OUT`` slots. ``own``: ``r`` is of the lanes' leaf (which row of bounds, see above).
    The edge's neighbours count zero, an edge of another component its length part only (both
    edge vectors zero): by selects of loaded values, no branch (a load inside a select is a
    branch: the near field took about 0.7 s instead of 0.26 s at 10⁵ edges)."""
    for j in range(_LANES):
        px = W[j]
        py = W[_LANES + j]
        pz = W[2 * _LANES + j]
        li = W[6 * _LANES + j]
        dx = px - rx
        dy = py - ry
        dz = pz - rz
        r2 = dx * dx + dy * dy + dz * dz
        # 1/|d|² = 0: every term 0. One select per test, of values loaded before: a compound
        # condition, or a load inside a select, branches, and the lane loop does not vectorize
        bound0 = W[_NW_LIM + j]
        bound1 = W[_NW_LIM + _LANES + j]
        r2 = np.inf if r <= (bound0 if own else bound1) else r2
        r2 = np.inf if r == W[_NW_ID + _LANES + j] else r2
        r2 = np.inf if r == W[_NW_ID + 2 * _LANES + j] else r2
        same = cr == W[_NW_ID + 3 * _LANES + j]
        ax = W[3 * _LANES + j]
        ay = W[4 * _LANES + j]
        az = W[5 * _LANES + j]
        ax = ax if same else 0.0
        ay = ay if same else 0.0
        az = az if same else 0.0
        bx = bx0 if same else 0.0
        by = by0 if same else 0.0
        bz = bz0 if same else 0.0
        f, fax, fay, faz, fbx, fby, fbz, fdx, fdy, fdz, wi, wj = pair(
            dx, dy, dz, ax, ay, az, bx, by, bz, li, lj, r2, SPLIT)
        _lane_store(W, j, _NW_SUMS, _NW_OUT, _LANES, f, fax, fay, faz, fbx, fby, fbz, fdx, fdy,
                    fdz, wi, wj, grad)


@nb.njit(cache=True, error_model="numpy", inline="always")
def _near_lanes_open(W, rx, ry, rz, lj, r, own):
    """:func:`_near_lanes` where every edge is of an open component (cables): every pair takes
    the length part ``f = l_I l_J / |d|²`` alone, and its edge-vector partials are zero, so
    only ``f``, ``∂f/∂m`` and ``∂f/∂l`` are computed and stored — in the operations and order
    the full kernel makes of them with zero edge vectors: the same bits. Its first lines
    repeat :func:`_near_lanes`' own: as one inline helper of both, this kernel measured 262
    against 122 ms (100 cables × 200 edges, two threads; its lane loop no longer vectorized)."""
    for j in range(_LANES):
        px = W[j]
        py = W[_LANES + j]
        pz = W[2 * _LANES + j]
        li = W[6 * _LANES + j]
        dx = px - rx
        dy = py - ry
        dz = pz - rz
        r2 = dx * dx + dy * dy + dz * dz
        bound0 = W[_NW_LIM + j]
        bound1 = W[_NW_LIM + _LANES + j]
        r2 = np.inf if r <= (bound0 if own else bound1) else r2
        r2 = np.inf if r == W[_NW_ID + _LANES + j] else r2
        r2 = np.inf if r == W[_NW_ID + 2 * _LANES + j] else r2
        inv = 1.0 / r2
        sv = (li * lj) * inv
        cd = -2.0 * sv
        mx = (cd * dx) * inv
        my = (cd * dy) * inv
        mz = (cd * dz) * inv
        # the rows of _lane_store that are not zero here (its ∂f/∂e rows stay +0)
        W[_NW_SUMS + j] += sv
        W[_NW_SUMS + 4 * _LANES + j] += mx
        W[_NW_SUMS + 5 * _LANES + j] += my
        W[_NW_SUMS + 6 * _LANES + j] += mz
        W[_NW_SUMS + 7 * _LANES + j] += lj * inv
        W[_NW_OUT + 3 * _LANES + j] = -mx
        W[_NW_OUT + 4 * _LANES + j] = -my
        W[_NW_OUT + 5 * _LANES + j] = -mz
        W[_NW_OUT + 6 * _LANES + j] = li * inv


@nb.njit(cache=True, inline="always")
def _lane_store(W, j, sums, out, lanes, F, eix, eiy, eiz, ejx, ejy, ejz, mx, my, mz, gli, glj,
                grad):
    """Lane ``j``'s pair into a near field's work array ``W`` (rows of ``lanes`` from ``sums``
    and ``out``, constants of the caller's module): ``F`` and, with ``grad``, the lane edge's
    ``∂/∂e`` (``ei``), ``∂/∂m`` (``m = ∂/∂d``) and ``∂/∂l`` (``gli``) added to its sums, the
    partner's (``ej``, ``−m``, ``glj``) written to its ``out`` rows. Shared by the Möbius near
    field and the tangent-point one's (both in the columns of their buffers)."""
    W[sums + j] += F
    if grad:
        W[sums + lanes + j] += eix
        W[sums + 2 * lanes + j] += eiy
        W[sums + 3 * lanes + j] += eiz
        W[sums + 4 * lanes + j] += mx
        W[sums + 5 * lanes + j] += my
        W[sums + 6 * lanes + j] += mz
        W[sums + 7 * lanes + j] += gli
        W[out + j] = ejx
        W[out + lanes + j] = ejy
        W[out + 2 * lanes + j] = ejz
        W[out + 3 * lanes + j] = -mx
        W[out + 4 * lanes + j] = -my
        W[out + 5 * lanes + j] = -mz
        W[out + 6 * lanes + j] = glj


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


@nb.njit(cache=True, inline="always")
def _task_key(i, j, pieces):
    """The schedule's key of the task of pieces ``i ≤ j``: its round ``(i + j) mod pieces``
    times ``pieces``, plus ``i``."""
    r = i + j
    return (r - pieces if r >= pieces else r) * pieces + i


@nb.njit(cache=True)
def _near_schedule(leaves, pairs, m, pieces):
    """The near field's schedule (see the module's doc) from the unordered pairs of near leaves
    ``pairs`` (node ids, a self pair once): ``(lane, part)`` the pairs as (leaf whose edges
    are the lanes, partner leaf), the lane leaf the first in tree order, sorted by round, task
    and lane leaf; ``toff`` the tasks' ranges of them, ``roff`` the rounds' ranges of tasks.
    ``pieces`` fixed ranges of ``leaves``."""
    nl = leaves.shape[0]
    pos = np.full(m, -1, np.int64)
    piece = np.empty(nl, np.int64)
    for t in range(nl):
        pos[leaves[t]] = t
        piece[t] = t * pieces // nl
    npairs = pairs.shape[0]
    # by lane leaf (the first in tree order; counting sort), the partner's position in order
    cnt = np.zeros(nl + 1, np.int64)
    for p in range(npairs):
        cnt[min(pos[pairs[p, 0]], pos[pairs[p, 1]]) + 1] += 1
    for t in range(nl):
        cnt[t + 1] += cnt[t]
    other = np.empty(npairs, np.int32)  # positions and leaves in 32 bits (fewer pages)
    fill = cnt[:nl].copy()
    for p in range(npairs):
        ta, tb = pos[pairs[p, 0]], pos[pairs[p, 1]]
        t0 = min(ta, tb)
        other[fill[t0]] = max(ta, tb)
        fill[t0] += 1
    # then stably by task, key round · pieces + the task's lower piece: each task by lane leaf
    nk = pieces * pieces
    koff = np.zeros(nk + 1, np.int64)
    for t in range(nl):
        for k in range(cnt[t], cnt[t + 1]):
            koff[_task_key(piece[t], piece[other[k]], pieces) + 1] += 1
    for k in range(nk):
        koff[k + 1] += koff[k]
    lane = np.empty(npairs, np.int32)
    part = np.empty(npairs, np.int32)
    kfill = koff[:nk].copy()
    for t in range(nl):
        for k in range(cnt[t], cnt[t + 1]):
            key = _task_key(piece[t], piece[other[k]], pieces)
            lane[kfill[key]] = leaves[t]
            part[kfill[key]] = leaves[other[k]]
            kfill[key] += 1
    # the tasks that have pairs, round by round
    roff = np.zeros(pieces + 1, np.int64)
    for k in range(nk):
        roff[k // pieces + 1] += koff[k + 1] > koff[k]
    roff = np.cumsum(roff)
    toff = np.empty(roff[pieces] + 1, np.int64)
    t = 0
    for k in range(nk):
        if koff[k + 1] > koff[k]:
            toff[t] = koff[k]
            t += 1
    toff[t] = npairs
    return lane, part, toff, roff


@nb.njit(cache=True, inline="always")
def _near_out(W, acc, row, k0):
    """What the lanes' pairs gave the partner edge (``_NW_OUT``, summed over the lanes in a
    fixed pairwise order) added to its columns ``1 + k0`` … 7 of row ``row`` of ``acc``
    (``k0 = 3``: the open kernel's, whose ∂f/∂e rows are zero)."""
    for k in range(k0, 7):
        o = _NW_OUT + k * _LANES
        acc[row, 1 + k] += (((W[o] + W[o + 1]) + (W[o + 2] + W[o + 3]))
                            + ((W[o + 4] + W[o + 5]) + (W[o + 6] + W[o + 7])))


@nb.njit(cache=True, error_model="numpy")
def _near_task(E, M, ln, cp, lo, hi, lane, part, p0, p1, nbr, grad, opened, acc):
    """The pairs ``p0 … p1 − 1`` of the schedule (one task; by lane leaf): each lane leaf's
    edges against the edges of its partners, all terms added to ``acc`` (the lanes' to their
    rows, the partners' to theirs); ``opened``: every edge is of an open component
    (:func:`_near_lanes_open`). A function of its own, called from the parallel loop."""
    W = np.zeros(_NW_SIZE)
    p = p0
    while p < p1:
        a = lane[p]
        pe = p + 1
        while pe < p1 and lane[pe] == a:
            pe += 1
        for q0 in range(lo[a], hi[a], _LANES):
            count = min(_LANES, hi[a] - q0)
            _load_lanes(W, E, M, ln, nbr, q0, count, False, _LANES)
            for j in range(_LANES):
                W[_NW_ID + 3 * _LANES + j] = cp[q0 + min(j, count - 1)]
                W[_NW_LIM + j] = q0 + j if j < count else np.inf
                W[_NW_LIM + _LANES + j] = -1.0 if j < count else np.inf
            W[_NW_SUMS:_NW_OUT] = 0.0
            for pp in range(p, pe):
                b = part[pp]
                own = b == a
                for r in range(lo[b], hi[b]):
                    # grad a constant at each call (the branch folds away)
                    if grad and opened:
                        _near_lanes_open(W, M[r, 0], M[r, 1], M[r, 2], ln[r], float(r), own)
                        _near_out(W, acc, r, 3)
                    elif grad:
                        _near_lanes(W, M[r, 0], M[r, 1], M[r, 2], E[r, 0], E[r, 1], E[r, 2],
                                    ln[r], float(r), float(cp[r]), own, True)
                        _near_out(W, acc, r, 0)
                    else:
                        _near_lanes(W, M[r, 0], M[r, 1], M[r, 2], E[r, 0], E[r, 1], E[r, 2],
                                    ln[r], float(r), float(cp[r]), own, False)
            for j in range(count):
                q = q0 + j
                acc[q, 0] += W[_NW_SUMS + j]
                if grad:
                    for k in range(1, 8):
                        acc[q, k] += W[_NW_SUMS + k * _LANES + j]
        p = pe


@nb.njit(cache=True, parallel=True, error_model="numpy")
def _near(E, M, ln, cp, lo, hi, lane, part, toff, roff, nbr, grad, opened):
    """The near field: every edge of a leaf against every edge of the leaf's near partners,
    each unordered pair once (:func:`_near_schedule`), except an edge with itself and its
    neighbours along the curve, with the energy's pair kernel. Per edge (tree order), a column
    of the ``(8, N)`` result (``(1, N)`` without ``grad``; a transposed view): row 0 its share
    of the energy (twice the sum of ``f`` over its pairs as the lane side: the energy sums
    both orders of each pair, ``f`` symmetric) and, with ``grad``, rows 1–3 and 4–6 the
    energy's derivatives in its edge vector and midpoint. The rounds one after the other, a
    round's tasks (disjoint pieces of the leaves) in parallel: the same bits for any thread
    count. ``opened``: every edge is of an open component, whose pairs take the length part
    alone (:func:`_near_lanes_open` with ``grad``: the same bits in half the time; the energy
    alone measured slower that way, 124 against 82 ms, and keeps the full kernel)."""
    n = ln.shape[0]
    # per edge a row of one cache line: f, ∂f/∂e, ∂f/∂m, ∂f/∂l; turned into the rows asked for
    # in place (no second buffer: 56 MB at 10⁶ edges)
    acc = np.zeros((n, 8 if grad else 1))
    for r in range(roff.shape[0] - 1):
        for tt in nb.prange(roff[r], roff[r + 1]):
            t = np.int64(tt)
            _near_task(E, M, ln, cp, lo, hi, lane, part, toff[t], toff[t + 1], nbr, grad, opened,
                       acc)
    for qq in nb.prange(n):
        q = np.int64(qq)
        acc[q, 0] = 2.0 * acc[q, 0]
        if grad:
            # the length term of ∂f/∂e_I: ∂f/∂l_I · e_I / l_I
            w = acc[q, 7] / ln[q]
            for k in range(3):
                acc[q, 1 + k] = 2.0 * (acc[q, 1 + k] + w * E[q, k])
                acc[q, 4 + k] = 2.0 * acc[q, 4 + k]
    return acc.T  # rows 0–6 as above (row 7 what is left of ∂f/∂l)


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
