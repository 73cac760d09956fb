"""The hs metric without a matrix: its product through a hierarchy of arcs (the tree engine's
metric for ``hs`` and ``hs_pure``; :mod:`.hs_solve` solves with it).

The metric of docs/design.md ("Metrics"; the paper's "Discrete inner product") is

    A = 2 Dᵀ(diag(W1) − W)D + 2 Mᵀ(diag(V1) − V)M + N b bᵀ / L^(2s+1)

with ``w_IJ = l_I l_J / |d|^(2s−1)`` and ``v_IJ = w_IJ (1/|d|² − 1/ρ²)`` over disjoint edge
pairs (``d = m_I − m_J``, ρ the arc length between the midpoints, 1/ρ² = 0 between
components), ``s`` the metric's order (3/2, the paper's: ``|d|²`` and ``L⁴``; :mod:`.metrics`
says why these powers). Here ``W`` and ``V`` are replaced by ``W̃``, ``Ṽ``:

* **near** pairs of edges (pairs of leaves of the hierarchy that are not admissible, which
  always includes pairs close in space and pairs close along the curve) keep their exact
  weights, computed once per iterate and stored;
* **far** pairs of clusters ``(A, B)`` take one weight per cluster pair from the clusters'
  length-weighted centres ``c`` and arc-length centres ``σ``: ``w = l_I l_J / |c_A −
  c_B|^(2s−1)`` and ``v = w (1/|c_A − c_B|² − 1/ρ(σ_A, σ_B)²)`` (kept ≥ 0).

The clusters are arcs (contiguous edges of one component, :func:`arc_tree`), so that ρ is
smooth over a cluster pair; a pair is admissible when both boxes are small against their gap,
``max(diam A, diam B) ≤ θ gap(A, B)``, and, on one component, both arcs are short against the
arc length between them, ``max(len A, len B) ≤ θ ρ(A, B)``. The weights stay symmetric and
non-negative, so ``Ã`` keeps the structure that makes ``A`` positive definite (graph Laplacians
of non-negative weights plus the barycenter term): the metric of the tree path is ``Ã`` itself,
a function of the polygon, the same in every product (docs/lab/tree-engine.md: its products against
the dense ``A``).

Products cost O(near pairs + far pairs + N): the near field as stored rows, the far field by an
upward pass (cluster sums of ``l f``), one weight per cluster pair, and a downward pass.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ..geometry.layout import Layout
from ..metrics.banded import EdgeParts
from ..metrics.gram import (
    _PURE_L2,
    PAPER_ORDER,
    banded_parts_of_lengths,
    barycenter_beta,
    check_order,
    kernel_exponent,
    length_power,
)
from ..metrics.hs_weight import hs_weight
from ..metrics.records import served_by
from . import bvh
from .moebius import _by_target

#: Admissibility of the metric's far field (its own, coarser than the energy's: the metric
#: is any positive definite matrix close to hs, while the energy must be accurate).
THETA = 0.5
#: Edges per leaf at most.
LEAF_SIZE = 8
# The split's walks (:func:`_split`): from ``_SPLIT_PARALLEL_FROM`` nodes on, (root, root)
# split into at least ``_SPLIT_TASKS`` pairs, their walks dealt in turn to ``_SPLIT_CHUNKS``
# chunks run in parallel; below, ``_SERIAL_TASKS`` walks one after the other (no parallel
# loop; a walk whose rows run out is walked again, not the whole split). 1 000 strands of 30
# edges, two threads: 555 ms as one walk, 280 ms in chunks (FHW at 10⁵ edges: 30 / 15 ms).
_SPLIT_TASKS = 1024
_SPLIT_CHUNKS = 32
_SPLIT_PARALLEL_FROM = 512
_SERIAL_TASKS = 64
#: ``HsOperator(single=None)`` stores its near weights in single precision from this many on
#: (two arrays of them; 320 MB in double): a dense crowd of strands stores about 2 000 per
#: vertex where a knot stores 33–39, and every Krylov step reads them all. 1 000 strands of 30
#: edges (62 million): 2.13–2.14 s per iteration in double, 1.94–1.96 s in single.
SINGLE_WEIGHTS_CELLS = 20_000_000
#: Pairs whose arc length exceeds this many times their distance are "folded" (strands that
#: come close again along the curve, or other components): the lower-order weights of those
#: pairs alone enter the preconditioner's diagonal (see :meth:`HsOperator.preconditioner_parts`).
FOLDED = 2.0
#: The metrics this module computes (``metrics.records``: those the tree solves by Krylov).
METRICS = served_by("krylov")


# ------------------------------------------------------------------------------------------------
# the hierarchy of arcs


@nb.njit(cache=True)
def _arc_tree(starts, leaf_size):
    """Binary tree over the edges in index order: a range spanning several components is split
    at the component boundary nearest its middle, a range of one component in halves, down to
    ``leaf_size`` edges. Parents come before their children."""
    n = starts[-1]
    k = starts.shape[0] - 1
    cap = 2 * (n // max(leaf_size // 2, 1) + k) + 2
    lo = np.empty(cap, np.int64)
    hi = np.empty(cap, np.int64)
    left = np.full(cap, -1, np.int64)
    right = np.full(cap, -1, np.int64)
    comp_of = np.empty(n, np.int64)
    for c in range(k):
        for i in range(starts[c], starts[c + 1]):
            comp_of[i] = c
    lo[0] = 0
    hi[0] = n
    count = 1
    stack = np.empty(128, np.int64)
    stack[0] = 0
    top = 1
    while top > 0:
        top -= 1
        node = stack[top]
        a, b = lo[node], hi[node]
        ca, cb = comp_of[a], comp_of[b - 1]
        if ca != cb:
            mid2 = a + b  # twice the middle
            m = starts[ca + 1]
            for c in range(ca + 2, cb + 1):
                if abs(2 * starts[c] - mid2) < abs(2 * m - mid2):
                    m = starts[c]
        elif b - a > leaf_size:
            m = (a + b) // 2
        else:
            continue
        for child in range(2):
            lo[count] = a if child == 0 else m
            hi[count] = m if child == 0 else b
            if child == 0:
                left[node] = count
            else:
                right[node] = count
            if top == stack.shape[0]:
                grown = np.empty(2 * top, np.int64)
                grown[:top] = stack
                stack = grown
            stack[top] = count
            top += 1
            count += 1
    perm = np.arange(n)
    return perm, lo[:count].copy(), hi[:count].copy(), left[:count].copy(), right[:count].copy()


def arc_tree(layout: Layout, leaf_size: int = LEAF_SIZE) -> bvh.Tree:
    """The hierarchy of arcs over the edges of ``layout`` (``perm`` is the identity)."""
    return bvh.Tree(*_arc_tree(layout.starts, int(leaf_size)))


@nb.njit(cache=True)
def _edge_data(X, nxt, starts):
    """Edge lengths, midpoints, the arc position of every midpoint along its component and
    the components' lengths."""
    n = X.shape[0]
    k = starts.shape[0] - 1
    ln = np.empty(n)
    mid = np.empty((n, 3))
    arc = np.empty(n)
    clen = np.empty(k)
    for c in range(k):
        s = 0.0
        for i in range(starts[c], starts[c + 1]):
            j = nxt[i]
            e2 = 0.0
            for d in range(3):
                e = X[j, d] - X[i, d]
                e2 += e * e
                mid[i, d] = 0.5 * (X[i, d] + X[j, d])
            ln[i] = np.sqrt(e2)
            arc[i] = s + 0.5 * ln[i]
            s += ln[i]
        clen[c] = s
    return ln, mid, arc, clen


@nb.njit(cache=True)
def _node_data(ln, mid, arc, starts, lo, hi, left, right):
    """Per node: component (−1 when it spans several), total length, length-weighted centre,
    arc-length start and end along its component."""
    m = lo.shape[0]
    nc = np.empty(m, np.int64)
    L = np.zeros(m)
    C = np.zeros((m, 3))
    s0 = np.empty(m)
    s1 = np.empty(m)
    for node in range(m - 1, -1, -1):
        a, b = lo[node], hi[node]
        c = 0
        while starts[c + 1] <= a:
            c += 1
        nc[node] = c if b <= starts[c + 1] else -1
        if left[node] < 0:
            for q in range(a, b):
                L[node] += ln[q]
                for d in range(3):
                    C[node, d] += ln[q] * mid[q, d]
            for d in range(3):
                C[node, d] /= L[node]
        else:
            c1, c2 = left[node], right[node]
            L[node] = L[c1] + L[c2]
            for d in range(3):
                C[node, d] = (L[c1] * C[c1, d] + L[c2] * C[c2, d]) / L[node]
        s0[node] = arc[a] - 0.5 * ln[a]
        s1[node] = arc[b - 1] + 0.5 * ln[b - 1]
    return nc, L, C, s0, s1


@nb.njit(cache=True, inline="always")
def _arc_gap(s0a, s1a, s0b, s1b, length):
    """Arc length between two disjoint arcs of a closed curve of ``length``."""
    f1 = (s0b - s1a) % length
    f2 = (s0a - s1b) % length
    return min(f1, f2)


@nb.njit(cache=True, inline="always")
def _admissible(a, b, bmin, bmax, diam2, nc, s0, s1, clen, closed, theta2):
    if nc[a] < 0 or nc[b] < 0:
        return False
    gap2 = bvh.box_gap2(bmin, bmax, a, b)
    if gap2 <= 0.0 or max(diam2[a], diam2[b]) > theta2 * gap2:
        return False
    if nc[a] != nc[b]:
        return True
    span = max(s1[a] - s0[a], s1[b] - s0[b])
    if closed[nc[a]]:
        rho = _arc_gap(s0[a], s1[a], s0[b], s1[b], clen[nc[a]])
    else:  # an open component: no way round its ends
        rho = max(s0[b] - s1[a], s0[a] - s1[b])
    return span * span <= theta2 * rho * rho


@nb.njit(cache=True, inline="always")
def _split_test(a, b, ctx, lists):
    """A pair of admissible clusters (``ctx``: :func:`_admissible`'s arrays) is far; every
    other pair, self pairs first of all, is split."""
    bmin, bmax, diam2, nc, s0, s1, clen, closed, theta2 = ctx
    if a != b and _admissible(a, b, bmin, bmax, diam2, nc, s0, s1, clen, closed, theta2):
        return bvh.ACCEPT
    return bvh.SPLIT


@nb.njit(cache=True, inline="always")
def _split_visit(a, b, far_pair, ctx, lists):
    """A far pair appended to the far list, a near pair of leaves to the near list
    (``lists``: both and their counts); stops the walk (False) where the list is full."""
    far, nf, near, nn = lists
    if far_pair:
        if nf == far.shape[0]:
            return False, lists
        far[nf, 0], far[nf, 1] = a, b
        return True, (far, nf + 1, near, nn)
    if nn == near.shape[0]:
        return False, lists
    near[nn, 0], near[nn, 1] = a, b
    return True, (far, nf, near, nn + 1)


@nb.njit(cache=True)
def _is_split(a, b, ctx):
    """:func:`_split_test`'s verdict SPLIT, as a call (not inlined: compiles once)."""
    return _split_test(a, b, ctx, None) == bvh.SPLIT


@nb.njit(cache=True)
def _split_tasks(left, right, diam2, ctx, want):
    """The pairs the parallel split starts from: (root, root) split level by level, each
    split pair replaced in place by its parts in the order the depth-first walk visits them
    (far pairs and pairs of leaves stay), until there are ``want``: the walks from these
    pairs, one after the other, visit every pair in the order of the one walk from the root."""
    cur = np.zeros((1, 2), np.int64)
    tmp = np.empty((4, 2), np.int64)
    while cur.shape[0] < want:
        nxt = np.empty((3 * cur.shape[0], 2), np.int64)
        count = 0
        grew = False
        for p in range(cur.shape[0]):
            a, b = cur[p, 0], cur[p, 1]
            if (left[a] >= 0 or left[b] >= 0) and _is_split(a, b, ctx):
                tmp, top = bvh.push_split(tmp, 0, a, b, left, right, diam2)
                for s in range(top - 1, -1, -1):  # the walk takes the last pushed first
                    nxt[count, 0], nxt[count, 1] = tmp[s, 0], tmp[s, 1]
                    count += 1
                grew = True
            else:
                nxt[count, 0], nxt[count, 1] = a, b
                count += 1
        cur = nxt[:count].copy()
        if not grew:
            break
    return cur


@nb.njit(cache=True)
def _split_chunk(tasks, t, nchunks, left, right, diam2, ctx, far, f, near, n, f0, fc, n0, ncnt):
    """One chunk of :func:`_split`: its walks ``t``, ``t + nchunks``, … into its rows ``far``
    (``f`` used) and ``near`` (``n`` used), each walk's first rows and counts recorded;
    returns the rows used, the next walk, and which rows ran out (that walk to run again)."""
    stack = np.empty((256, 2), np.int64)
    while t < tasks.shape[0]:
        stack, (_, f1, _, n1), done = bvh.dual_traversal(
            stack, tasks[t, 0], tasks[t, 1], left, right, diam2, _split_test, _split_visit,
            ctx, (far, f, near, n))
        if not done:  # this walk again once there is room
            return f, n, t, f1 == far.shape[0], n1 == near.shape[0]
        f0[t], fc[t], n0[t], ncnt[t] = f, f1 - f, n, n1 - n
        f, n = f1, n1
        t += nchunks
    return f, n, t, False, False


@nb.njit(cache=True, parallel=True)
def _split_round(tasks, nxt_t, left, right, diam2, ctx, fbuf, nf, nbuf, nn, f0, fc, n0, ncnt):
    """The chunks of :func:`_split` in parallel, each from its next walk (``nxt_t``) on, until
    its walks are done or its rows run out; which chunks ran out of far and of near rows.
    (A function of its own: a parallel loop inside :func:`_split`'s loop over the rounds kept
    the first round's buffers.)"""
    nchunks = nf.shape[0]
    full_f = np.zeros(nchunks, np.bool_)
    full_n = np.zeros(nchunks, np.bool_)
    for cc in nb.prange(nchunks):
        ch = np.int64(cc)
        nf[ch], nn[ch], nxt_t[ch], full_f[ch], full_n[ch] = _split_chunk(
            tasks, nxt_t[ch], nchunks, left, right, diam2, ctx, fbuf[ch], nf[ch], nbuf[ch],
            nn[ch], f0, fc, n0, ncnt)
    return full_f, full_n


def _split(left, right, bmin, bmax, nc, s0, s1, clen, closed, theta2, nchunks=None,
           want=None):
    """Dual traversal from (root, root) (:func:`bvh.dual_traversal`): unordered far pairs of
    admissible clusters and near pairs of leaves (self pairs included), in the order of the one
    depth-first walk whatever the thread count. The walks from the pairs of
    :func:`_split_tasks` are dealt to ``nchunks`` chunks in turn and run in parallel (one
    chunk: one after the other, no parallel loop), each chunk's pairs into its own rows; a
    chunk whose rows run out goes on from the walk it was in, with four times the room; the
    lists are then gathered walk by walk. ``nchunks``, ``want``: by default from the tree's
    size (:data:`_SPLIT_PARALLEL_FROM`). (Python between the kernels: as one kernel it
    compiled for 7 s more.)"""
    if nchunks is None:
        par = left.shape[0] >= _SPLIT_PARALLEL_FROM
        nchunks, want = (_SPLIT_CHUNKS, _SPLIT_TASKS) if par else (1, _SERIAL_TASKS)
    diam2 = bvh.node_diam2(bmin, bmax)
    ctx = (bmin, bmax, diam2, nc, s0, s1, clen, closed, theta2)
    tasks = _split_tasks(left, right, diam2, ctx, want)
    nt = tasks.shape[0]
    # per walk: its first row in its chunk's far and near rows, and how many it wrote
    f0, fc, n0, ncnt = (np.empty(nt, np.int64) for _ in range(4))
    nf = np.zeros(nchunks, np.int64)
    nn = np.zeros(nchunks, np.int64)
    nxt_t = np.arange(nchunks, dtype=np.int64)  # per chunk its next walk (t = ch, ch + nchunks, …)
    rows = max(64, 32 * left.shape[0] // nchunks)
    fbuf = np.empty((nchunks, rows, 2), np.int64)
    nbuf = np.empty((nchunks, rows, 2), np.int64)
    while True:
        if nchunks == 1:
            nf[0], nn[0], nxt_t[0], full_f, full_n = _split_chunk(
                tasks, nxt_t[0], 1, left, right, diam2, ctx, fbuf[0], nf[0], nbuf[0], nn[0],
                f0, fc, n0, ncnt)
        else:
            full_f, full_n = _split_round(tasks, nxt_t, left, right, diam2, ctx, fbuf, nf, nbuf,
                                          nn, f0, fc, n0, ncnt)
        if not (np.any(full_f) or np.any(full_n)):
            break
        if np.any(full_f):
            fbuf = _grown(fbuf, nf)
        if np.any(full_n):
            nbuf = _grown(nbuf, nn)
    return _gathered(fbuf, f0, fc, nchunks), _gathered(nbuf, n0, ncnt, nchunks)


def _grown(buf: np.ndarray, used: np.ndarray) -> np.ndarray:
    """``buf`` (chunks, r, 2) with four times the rows per chunk, the ``used`` rows of each kept."""
    out = np.empty((buf.shape[0], 4 * buf.shape[1], 2), np.int64)
    for ch in range(buf.shape[0]):
        out[ch, :used[ch]] = buf[ch, :used[ch]]
    return out


@nb.njit(cache=True)
def _gathered(buf, start, count, nchunks):
    """The walks' pairs (walk ``t`` in chunk ``t mod nchunks`` from row ``start[t]``, ``count[t]``
    of them) one after the other in walk order."""
    nt = start.shape[0]
    off = np.zeros(nt + 1, np.int64)
    for t in range(nt):
        off[t + 1] = off[t] + count[t]
    out = np.empty((off[nt], 2), np.int64)
    for t in range(nt):
        ch = t % nchunks
        for k in range(count[t]):
            out[off[t] + k, 0] = buf[ch, start[t] + k, 0]
            out[off[t] + k, 1] = buf[ch, start[t] + k, 1]
    return out


# ------------------------------------------------------------------------------------------------
# weights


@nb.njit(cache=True, inline="always")
def _pair_weight(ln, mid, q, r, expo):
    """:func:`hs_weight` of the edges ``q`` and ``r``: ``(w, 1/|d|²)``."""
    dx = mid[q, 0] - mid[r, 0]
    dy = mid[q, 1] - mid[r, 1]
    dz = mid[q, 2] - mid[r, 2]
    return hs_weight(ln[q], ln[r], dx * dx + dy * dy + dz * dz, expo)


@nb.njit(cache=True, parallel=True)
def _near_weights(ln, mid, arc, clen, closed, nxt, starts, comp, lo, hi, leaves, noff, npart,
                  rowoff, low, expo, cross2, w, v, w1, v1, x1):
    """Exact weights of every near pair, stored per target edge as one row over the edges of
    its leaf's partner leaves (in partner order), their row sums, and the row sums of ``v``
    over the folded pairs (other components, or ``ρ² ≥ cross2 · |d|²``). ``expo``:
    :func:`.metrics.kernel_exponent` (None at order 3/2, pruned at compile time). A leaf is an
    arc of one component (:func:`_arc_tree`), so a partner leaf's pairs are all of one kind:
    another component's take a loop without the arc length's tests (a crowd of strands has
    mostly such pairs)."""
    for kk in nb.prange(leaves.shape[0]):
        a = leaves[np.int64(kk)]
        width = 0
        for p in range(noff[a], noff[a + 1]):
            b = npart[p]
            width += hi[b] - lo[b]
        for q in range(lo[a], hi[a]):
            pos = rowoff[a] + (q - lo[a]) * width
            cq = comp[q]
            sq = starts[cq + 1] - starts[cq]
            sw = 0.0
            sv = 0.0
            sx = 0.0
            real_q = nxt[q] != q  # an open component's dummy edge (length 0) is no edge
            for p in range(noff[a], noff[a + 1]):
                b = npart[p]
                if comp[lo[b]] != cq:  # another component: every pair folded, no arc length
                    for r in range(lo[b], hi[b]):
                        wq = 0.0
                        vq = 0.0
                        if real_q and nxt[r] != r:
                            wq, inv = _pair_weight(ln, mid, q, r, expo)
                            vq = low * wq * inv
                        w[pos] = wq
                        v[pos] = vq
                        sw += wq
                        sv += vq
                        sx += vq
                        pos += 1
                    continue
                for r in range(lo[b], hi[b]):
                    wq = 0.0
                    vq = 0.0
                    if not closed[cq]:  # along an open polyline: no way round
                        gap = abs(r - q)
                    else:
                        # (r − q) mod sq without a division
                        gap = r - q if r >= q else r - q + sq
                        if gap == sq - 1:
                            gap = 1
                    if gap >= 2 and real_q and nxt[r] != r:
                        wq, inv = _pair_weight(ln, mid, q, r, expo)
                        fwd = abs(arc[r] - arc[q])
                        rho = min(fwd, clen[cq] - fwd) if closed[cq] else fwd
                        vq = low * wq * (inv - 1.0 / (rho * rho))
                        if rho * rho * inv >= cross2:
                            sx += vq
                    w[pos] = wq
                    v[pos] = vq
                    sw += wq
                    sv += vq
                    pos += 1
            w1[q] = sw
            v1[q] = sv
            x1[q] = sx


@nb.njit(cache=True, parallel=True)
def _far_weights(L, C, nc, s0, s1, clen, closed, foff, fpart, low, expo, cross2, fw, fv, rw, rv,
                 rx):
    """One weight pair per ordered far pair of clusters (per unit length of both: ``w`` and
    ``v`` divided by ``l_I l_J``), and per target cluster the sums ``Σ_B ω L_B`` (what its
    edges' row sums receive, times their own length), those of ``v`` over folded pairs (see
    :func:`_near_weights`) apart. ``expo`` as there."""
    m = L.shape[0]
    for aa in nb.prange(m):
        a = np.int64(aa)
        sw = 0.0
        sv = 0.0
        sx = 0.0
        for p in range(foff[a], foff[a + 1]):
            b = fpart[p]
            dx = C[a, 0] - C[b, 0]
            dy = C[a, 1] - C[b, 1]
            dz = C[a, 2] - C[b, 2]
            r2 = dx * dx + dy * dy + dz * dz
            ww, inv = hs_weight(1.0, 1.0, r2, expo)  # per unit length of both clusters
            if nc[a] == nc[b]:
                ca = 0.5 * (s0[a] + s1[a])
                cb = 0.5 * (s0[b] + s1[b])
                fwd = abs(ca - cb)
                rho = min(fwd, clen[nc[a]] - fwd) if closed[nc[a]] else fwd
                vv = low * ww * max(0.0, inv - 1.0 / (rho * rho))
                if rho * rho * inv >= cross2:
                    sx += vv * L[b]
            else:
                vv = low * ww * inv
                sx += vv * L[b]
            fw[p] = ww
            fv[p] = vv
            sw += ww * L[b]
            sv += vv * L[b]
        rw[a] = sw
        rv[a] = sv
        rx[a] = sx


@nb.njit(cache=True)
def _push_to_edges(acc, ln, lo, hi, left, right, out):
    """``out[q] += l_q Σ_{A ∋ q} acc[A]`` (acc per node, any number of columns)."""
    m = acc.shape[0]
    tot = acc.copy()
    for node in range(m):  # parents come first
        if left[node] >= 0:
            for c in (left[node], right[node]):
                for d in range(acc.shape[1]):
                    tot[c, d] += tot[node, d]
        else:
            for q in range(lo[node], hi[node]):
                for d in range(acc.shape[1]):
                    out[q, d] += ln[q] * tot[node, d]


# ------------------------------------------------------------------------------------------------
# the product


@nb.njit(cache=True, parallel=True)
def _edge_fields(U, nxt, ln, FG):
    """``(D U, M U)`` per edge: ``(U[nxt] − U) / l`` and ``(U + U[nxt]) / 2`` as the rows 0–2
    and 3–5 of one (6, N) array ``FG``, written (a coordinate's values contiguous: the near
    product's loads vectorize, 1.4–1.5× faster than from (N, 3) fields)."""
    n = U.shape[0]
    for ii in nb.prange(n):
        i = np.int64(ii)
        j = nxt[i]
        for d in range(3):
            # an open component's dummy edge (j = i, length 0) has no difference
            FG[d, i] = (U[j, d] - U[i, d]) / ln[i] if j != i else 0.0
            FG[3 + d, i] = 0.5 * (U[i, d] + U[j, d])


@nb.njit(cache=True, parallel=True, fastmath={"reassoc", "contract", "nsz", "arcp"})
def _near_product(FG, w, v, lo, hi, leaves, noff, npart, rowoff, Y):
    """``Y[q, :3] = Σ w_qr F[r]``, ``Y[q, 3:] = Σ v_qr G[r]`` over the stored near rows
    (``FG``: :func:`_edge_fields`)."""
    for kk in nb.prange(leaves.shape[0]):
        a = leaves[np.int64(kk)]
        width = 0
        for p in range(noff[a], noff[a + 1]):
            b = npart[p]
            width += hi[b] - lo[b]
        for q in range(lo[a], hi[a]):
            pos = rowoff[a] + (q - lo[a]) * width
            f0 = f1 = f2 = g0 = g1 = g2 = 0.0
            for p in range(noff[a], noff[a + 1]):
                b = npart[p]
                for r in range(np.uint64(lo[b]), np.uint64(hi[b])):  # unsigned: no wraparound
                    wq = w[np.uint64(pos)]
                    vq = v[np.uint64(pos)]
                    f0 += wq * FG[0, r]
                    f1 += wq * FG[1, r]
                    f2 += wq * FG[2, r]
                    g0 += vq * FG[3, r]
                    g1 += vq * FG[4, r]
                    g2 += vq * FG[5, r]
                    pos += 1
            Y[q, 0], Y[q, 1], Y[q, 2] = f0, f1, f2
            Y[q, 3], Y[q, 4], Y[q, 5] = g0, g1, g2


@nb.njit(cache=True, parallel=True)
def _assemble(U, FG, Y, w1, v1, ln, prv, comp, starts, beta, mass, out):
    """``2 Dᵀ(W̃1 ∘ F − Y_F) + 2 Mᵀ(Ṽ1 ∘ G − Y_G)`` per vertex, the barycenter term
    ``β (βᵀU)`` per component and ``mass`` times the P1 mass matrix applied to ``U``, written
    to ``out`` (N, 3)."""
    n = U.shape[0]
    k = starts.shape[0] - 1
    bu = np.zeros((k, 3))
    for c in range(k):
        for i in range(starts[c], starts[c + 1]):
            for d in range(3):
                bu[c, d] += beta[i] * U[i, d]
    for pp in nb.prange(n):
        p = np.int64(pp)
        q = prv[p]
        c = comp[p]
        for d in range(3):
            hp = 2.0 * (w1[p] * FG[d, p] - Y[p, d]) / ln[p] if ln[p] > 0.0 else 0.0
            hq = 2.0 * (w1[q] * FG[d, q] - Y[q, d]) / ln[q] if ln[q] > 0.0 else 0.0
            gp = 2.0 * (v1[p] * FG[3 + d, p] - Y[p, 3 + d])
            gq = 2.0 * (v1[q] * FG[3 + d, q] - Y[q, 3 + d])
            o = hq - hp + 0.5 * (gp + gq) + beta[p] * bu[c, d]
            if mass != 0.0:  # edges p and q: l/3 at this vertex, l/6 at the other end
                o += mass * (ln[p] * (U[p, d] / 3 + FG[d, p] * ln[p] / 6 + U[p, d] / 6)
                             + ln[q] * (U[p, d] / 3 + (U[p, d] - FG[d, q] * ln[q]) / 6))
            out[p, d] = o


@nb.njit(cache=True)
def _cluster_sums(FG, ln, lo, hi, left, right):
    """Per node ``(Σ l F, Σ l G)`` over its edges (6 columns), bottom-up."""
    m = lo.shape[0]
    S = np.zeros((m, 6))
    for node in range(m - 1, -1, -1):
        if left[node] < 0:
            for q in range(lo[node], hi[node]):
                for d in range(3):
                    S[node, d] += ln[q] * FG[d, q]
                    S[node, 3 + d] += ln[q] * FG[3 + d, q]
        else:
            for d in range(6):
                S[node, d] = S[left[node], d] + S[right[node], d]
    return S


@nb.njit(cache=True, parallel=True)
def _far_product(S, foff, fpart, fw, fv):
    """Per target node ``Σ_B (ω_W S_F[B], ω_V S_G[B])``."""
    m = S.shape[0]
    acc = np.zeros((m, 6))
    for aa in nb.prange(m):
        a = np.int64(aa)
        for p in range(foff[a], foff[a + 1]):
            b = fpart[p]
            for d in range(3):
                acc[a, d] += fw[p] * S[b, d]
                acc[a, 3 + d] += fv[p] * S[b, 3 + d]
    return acc


class HsOperator:
    """``Ã`` of the polygon ``X`` (stacked, see ``_layout``) for ``metric`` "hs" or "hs_pure":
    the hierarchy, the split and the weights, built once; :meth:`product` applies it.

    Parameters
    ----------
    X : (N, 3) array
    layout : Layout
    metric : {"hs", "hs_pure"}
    order : float in (1, 2)
        The metric's order s (3/2: the paper's; :func:`.metrics.gram_matrix`).
    theta : float
        Admissibility of the far field (see the module's text).
    leaf_size : int
    single : bool or None
        The near pairs' weights stored in single precision (the products still sum in
        double; the row sums, the diagonal and :meth:`preconditioner_parts` are the same):
        half of the operator's memory, 0.42 GB at 10⁶ vertices, for a change of the metric
        of the order of 1e-7 relative, far below the far field's. None: from
        :data:`SINGLE_WEIGHTS_CELLS` stored weights on.
    """

    def __init__(self, X: np.ndarray, layout: Layout, metric: str = "hs",
                 order: float = PAPER_ORDER, theta: float = THETA,
                 leaf_size: int = LEAF_SIZE, single: bool | None = False):
        if metric not in ("hs", "hs_pure"):
            raise ValueError(f"{metric!r} is not computed by the tree's metric (hs, hs_pure)")
        self.layout = layout
        self.metric = metric
        self._room = None  # the product's buffers (product)
        self.order = check_order(order)
        expo = kernel_exponent(self.order)
        self.low = 1.0 if metric == "hs" else 0.0
        lay = layout
        tree = arc_tree(lay, leaf_size)
        self.tree = tree
        ln, mid, arc, clen = _edge_data(X, lay.nxt, lay.starts)
        self.ln = ln
        self.total = float(ln.sum())
        nc, L, C, s0, s1 = _node_data(ln, mid, arc, lay.starts, tree.lo, tree.hi, tree.left,
                                      tree.right)
        bmin, bmax = bvh.segment_boxes(tree, X, lay)
        closed = np.ones(lay.k, np.bool_) if lay.closed is None else lay.closed
        far, near = _split(tree.left, tree.right, bmin, bmax, nc, s0, s1, clen, closed,
                           float(theta) ** 2)
        m = tree.size
        self.far_pairs, self.near_pairs = far.shape[0], near.shape[0]
        self.foff, self.fpart = _by_target(far, m)
        self.noff, self.npart = _by_target(near, m)
        self.leaves = np.flatnonzero(tree.left < 0).astype(np.int64)
        size = tree.hi - tree.lo
        # near row width of every leaf: the edges of its partner leaves
        owner = np.repeat(np.arange(m), np.diff(self.noff))
        width = np.bincount(owner, weights=size[self.npart], minlength=m).astype(np.int64)
        cells = np.where(tree.left < 0, size * width, 0)
        self.rowoff = np.concatenate(([0], np.cumsum(cells)[:-1])).astype(np.int64)
        total = int(cells.sum())
        if single is None:
            single = total >= SINGLE_WEIGHTS_CELLS
        self.w = np.empty(total, np.float32 if single else np.float64)
        self.v = np.empty(total, self.w.dtype)
        rows = np.empty((3, lay.n))
        cross2 = FOLDED**2
        _near_weights(ln, mid, arc, clen, closed, lay.nxt, lay.starts, lay.comp, tree.lo,
                      tree.hi, self.leaves,
                      self.noff, self.npart, self.rowoff, self.low, expo, cross2, self.w, self.v,
                      rows[0], rows[1], rows[2])
        self.fw = np.empty(self.fpart.shape[0])
        self.fv = np.empty(self.fpart.shape[0])
        rfar = np.empty((3, m))
        _far_weights(L, C, nc, s0, s1, clen, closed, self.foff, self.fpart, self.low, expo,
                     cross2,
                     self.fw, self.fv, rfar[0], rfar[1], rfar[2])
        rows = np.ascontiguousarray(rows.T)
        _push_to_edges(np.ascontiguousarray(rfar.T), ln, tree.lo, tree.hi, tree.left,
                       tree.right, rows)
        self.w1 = np.ascontiguousarray(rows[:, 0])
        self.v1 = np.ascontiguousarray(rows[:, 1])
        self.x1 = np.ascontiguousarray(rows[:, 2])  # v's row sums over folded pairs
        # the barycenter term N b bᵀ / L^(2s+1) as β βᵀ per component (as in metrics.gram_x)
        self.beta = barycenter_beta(ln, lay, self.total, self.order)
        # hs_pure's small L² term, scaled like the metric (metrics._gram_hs_pure)
        self._mass = (_PURE_L2 / self.total**length_power(self.order)
                      if metric == "hs_pure" else 0.0)
        if lay.has_open:  # and the L² term that keeps it definite on straight polylines
            self._mass += 1.0 / self.total**length_power(self.order)  # (metrics._hs_family)

    @property
    def nbytes(self) -> int:
        """Memory held by the stored weights."""
        return int(self.w.nbytes + self.v.nbytes + self.fw.nbytes + self.fv.nbytes)

    def product(self, U: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """``Ã U`` for a field ``U`` (N, 3), in ``out`` (C-contiguous float64) if given."""
        lay, ln, tree = self.layout, self.ln, self.tree
        U = np.ascontiguousarray(U, dtype=np.float64)
        # the edge fields and near sums in the same memory at every product: fresh, their
        # 96 MB at 10⁶ vertices came as new pages from the kernel each time
        # (docs/lab/repulsor.md, "Fewer fresh pages")
        if self._room is None:
            self._room = (np.empty((6, lay.n)), np.empty((lay.n, 6)))
        FG, Y = self._room
        _edge_fields(U, lay.nxt, ln, FG)
        _near_product(FG, self.w, self.v, tree.lo, tree.hi, self.leaves, self.noff,
                      self.npart, self.rowoff, Y)
        S = _cluster_sums(FG, ln, tree.lo, tree.hi, tree.left, tree.right)
        acc = _far_product(S, self.foff, self.fpart, self.fw, self.fv)
        _push_to_edges(acc, ln, tree.lo, tree.hi, tree.left, tree.right, Y)
        out = np.empty((lay.n, 3)) if out is None else out
        _assemble(U, FG, Y, self.w1, self.v1, ln, lay.prv, lay.comp, lay.starts, self.beta,
                  self._mass, out)
        return out

    def diagonal(self) -> np.ndarray:
        """The diagonal of ``Ã`` (N,): ``2 Σ_{I ∋ p} W̃1_I / l_I² + ½ Σ_{I ∋ p} Ṽ1_I + β_p²``
        (the off-diagonal parts vanish there: edges through one vertex are not disjoint)."""
        lay, ln = self.layout, self.ln
        # 0 at an open component's dummy edge (length 0)
        e = 2.0 * np.divide(self.w1, ln**2, out=np.zeros_like(ln), where=ln > 0) + 0.5 * self.v1
        d = e + e[lay.prv] + self.beta**2
        if self._mass != 0.0:
            d += self._mass * (ln + ln[lay.prv]) / 3
        return d

    def preconditioner_parts(self):
        """``H = s·h1 + 2 Mᵀ diag(Ṽ1) M`` as :func:`metrics.banded_parts` gives a banded
        metric: ``(rows, cols, vals, beta)`` (β: this metric's barycenter term), with ``s``
        the ratio of the traces of ``Ã``'s and h1's banded parts."""
        lay = self.layout
        rows, cols, vals, _ = banded_parts_of_lengths("h1", self.ln, lay)
        diag = rows == cols
        s = float((self.diagonal() - self.beta**2).sum() / vals[diag].sum())
        i = np.arange(lay.n)
        j = lay.nxt
        h = 0.5 * self.x1
        return (np.concatenate([rows, i, i, j, j]), np.concatenate([cols, i, j, i, j]),
                np.concatenate([s * vals, h, h, h, h]), self.beta)

    def preconditioner_edges(self):
        """The metric of :meth:`preconditioner_parts` as one 2 × 2 block per edge
        (:class:`.banded.EdgeParts`; closed components): no triplets to build, and the band is
        filled in parallel. FHW at 10⁶ edges, 2 threads, setup and one iteration: the triplets'
        build and fill took 3.6 s, the fill from edges 0.2 s (docs/lab/repulsor.md, "The band
        solver's correction without BLAS, its band filled in parallel")."""
        ln = self.ln
        total = float(ln.sum())
        m = ln / 3 * (1.0 / total**3)  # h1's mass and stiffness, as banded_parts_of_lengths
        k = (1.0 / ln) * (1.0 / total)
        s = float((self.diagonal() - self.beta**2).sum() / np.concatenate([m, m, k, k]).sum())
        h = 0.5 * self.x1
        mo = ln / 6 * (1.0 / total**3)
        return EdgeParts(s * m + s * k + h, s * mo - s * k + h, self.beta)
