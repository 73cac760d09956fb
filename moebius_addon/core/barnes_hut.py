"""Möbius energy and its exact derivative by Barnes–Hut on the edge hierarchy (the tree engine).

The energy of docs/design.md is a sum over ordered pairs of disjoint edges (``energy.py`` sums
all of them). Here the pairs are split by a dual traversal of the hierarchy (:mod:`bvh`) into

* the **far field**: pairs of clusters ``(A, B)`` of one component each whose boxes are apart,
  ``max(diam A, diam B) ≤ θ · gap(A, B)``. The pair sum ``Σ_IJ l_I l_J k + e_Iᵀ H e_J`` (``k =
  1/|d|²``, ``H = ∇² log|d|``) is replaced by its Taylor expansion to second order in the
  offsets ``δ_I = m_I − c`` from the clusters' length-weighted centres, ``d = c_A − c_B``,
  written with the clusters' moments: total length ``L``, summed edge vector ``S``, tangent
  dipole ``D = Σ e δᵀ``, length quadrupole ``Q = Σ l δ δᵀ`` and tangent quadrupole
  ``T = Σ e ⊗ δ ⊗ δ``:

      F(A, B) = L_A L_B k + ½ ∇²k : (L_B Q_A + L_A Q_B) + S_Aᵀ H S_B + T(D_A, S_B) − T(D_B, S_A)
                + ½ K4 : (T_A ⊗ S_B) − K4 : (D_A ⊗ D_B) + ½ K4 : (S_A ⊗ T_B)

  with ``T`` the first-order term (:func:`_dipole`) and ``K4 = ∇⁴ log|d|`` contracted through
  traces and projections of the moments (:func:`_quadrupole`, :func:`_dipole_pair`); between
  components the length part ``L_A L_B k + ½ ∇²k : (…)`` alone, the O'Hara kernel of
  ``energy.py``. Both parts to the same order: for two pieces of one straight line they
  cancel (the exact F is 0), and expanding the length part alone further measured larger
  errors. At the default θ the relative errors measured at most 1e-5 (energy) and 6.3e-4
  (gradient) on 7_2, FHW and a non-equilateral trefoil of 5 000 and 20 000 edges, the first
  order's 1.7e-3 and 6.7e-3; the gradient's falls about like θ³.
* the **near field**: every other pair (always the pairs close in space, and so those close
  along the curve: boxes of edges sharing a vertex touch), summed exactly with the kernel of
  ``energy.py``.

The gradient is the exact derivative of this approximated sum for the fixed split: each
cluster's derivative with respect to ``(L, c, S, D, Q, T)`` is pushed down to its edges by the
chain rule (:func:`_push_down`). Both passes are parallel over targets (each target sums its
own ordered pairs, so nothing is shared between threads): the results are the same bits for
every thread count.

The split (the "frame": hierarchy and interaction lists) is a function of the polygon it was
built at. :class:`Frame` keeps it so that several polygons can be evaluated with one split (a
line search sees one smooth function); :func:`tree_energy` builds a fresh one.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from . import bvh
from ._layout import Layout

# Default admissibility: the largest of 0.15, 0.175, 0.2, 0.25 whose relative errors stay, with
# a margin, below 1e-4 (energy) and 1e-3 (gradient) on 7_2, FHW and a non-equilateral trefoil at
# 3 000 to 20 000 edges (worst measured: 9.8e-6 and 6.3e-4, FHW's gradient; 0.2 gave 9.5e-4).
THETA = 0.175
# The near field's fast-math: reassociation lets its sums vectorize; no "contract": with it (and
# reassoc), the code compiled in a first process and the code numba's cache gave later ones
# different last bits in the gradient (each of the two flags alone did not).
_NEAR_FASTMATH = {"reassoc", "nsz", "arcp"}
# Fixed split of the traversal into chunks (the same lists for every thread count).
_SPLIT_CHUNKS = 16
# Pieces of the near field's parallel loop over leaves (each edge's sums are its own: any split
# gives the same bits); a piece stages its leaves' partners in one scratch array.
_NEAR_CHUNKS = 256


ENGINE_NAMES = ("auto", "exact", "tree")
# From this many edges on, "auto" takes the tree: at the default theta its energy+gradient
# (frame included, 7_2) measured 1.1x the exact speed at 2 000 edges, 1.5x at 3 000, 2.4x at
# 5 000, 5.3x at 10 000, 11.9x at 20 000 (docs/benchmarks.md, "Tree engine").
TREE_FROM = 5000


def uses_tree(engine: str, n: int) -> bool:
    """Whether ``engine`` ("exact", "tree" or "auto": the tree from ``TREE_FROM`` edges on)
    evaluates a polygon of ``n`` edges with the tree; ValueError for another name."""
    if engine not in ENGINE_NAMES:
        raise ValueError(f"unknown engine {engine!r}; choose one of {', '.join(ENGINE_NAMES)}")
    return engine == "tree" or (engine == "auto" and n >= TREE_FROM)


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


@nb.njit(cache=True)
def _cluster_data(E, M, ln, cp, lo, hi, left, right):
    """Per node, bottom-up: total length ``L``, length-weighted centre ``c``, summed edge vector
    ``S``, tangent dipole ``D = Σ e_I δ_Iᵀ``, length quadrupole ``Q = Σ l_I δ_I δ_Iᵀ``, tangent
    quadrupole ``T_acd = Σ e_I,a δ_I,c δ_I,d`` (``δ_I = m_I − c``) and the node's component (−1
    for a node holding edges of several components). A parent takes its children's moments
    moved to its centre (``δ = δ_child + h``, ``h = c_child − c``; ``Σ l δ_child = 0``)."""
    m = lo.shape[0]
    L = np.empty(m)
    C = np.empty((m, 3))
    S = np.empty((m, 3))
    D = np.zeros((m, 3, 3))
    Q = np.zeros((m, 3, 3))
    T = np.zeros((m, 3, 3, 3))
    nc = np.empty(m, np.int64)
    dl = np.empty(3)
    for node in range(m - 1, -1, -1):
        if left[node] < 0:
            tot = 0.0
            cx = cy = cz = sx = sy = sz = 0.0
            c0 = cp[lo[node]]
            for q in range(lo[node], hi[node]):
                w = ln[q]
                tot += w
                cx += w * M[q, 0]
                cy += w * M[q, 1]
                cz += w * M[q, 2]
                sx += E[q, 0]
                sy += E[q, 1]
                sz += E[q, 2]
                if cp[q] != c0:
                    c0 = -1
            L[node] = tot
            C[node, 0] = cx / tot
            C[node, 1] = cy / tot
            C[node, 2] = cz / tot
            S[node, 0] = sx
            S[node, 1] = sy
            S[node, 2] = sz
            nc[node] = c0
            for q in range(lo[node], hi[node]):
                for k in range(3):
                    dl[k] = M[q, k] - C[node, k]
                for a in range(3):
                    for b in range(3):
                        D[node, a, b] += E[q, a] * dl[b]
                        Q[node, a, b] += ln[q] * dl[a] * dl[b]
                        for c in range(3):
                            T[node, a, b, c] += E[q, a] * dl[b] * dl[c]
        else:
            a0, b0 = left[node], right[node]
            tot = L[a0] + L[b0]
            L[node] = tot
            for k in range(3):
                C[node, k] = (L[a0] * C[a0, k] + L[b0] * C[b0, k]) / tot
                S[node, k] = S[a0, k] + S[b0, k]
            for ch in (a0, b0):
                for k in range(3):
                    dl[k] = C[ch, k] - C[node, k]
                for a in range(3):
                    for b in range(3):
                        D[node, a, b] += D[ch, a, b] + S[ch, a] * dl[b]
                        Q[node, a, b] += Q[ch, a, b] + L[ch] * dl[a] * dl[b]
                        for c in range(3):
                            T[node, a, b, c] += (T[ch, a, b, c] + D[ch, a, b] * dl[c]
                                                 + D[ch, a, c] * dl[b]
                                                 + S[ch, a] * dl[b] * dl[c])
            nc[node] = nc[a0] if nc[a0] == nc[b0] else -1
    return L, C, S, D, Q, T, nc


# ------------------------------------------------------------------------------------------------
# the split into far and near pairs


# The depth-first split's stack: a step pops one pair and pushes at most three whose depths
# (depth of a + depth of b) are larger by one or two, so the stack never holds more than
# 2 · (2 · tree depth) + 1 pairs; a median-split tree over fewer than 2^63 edges is less than
# 64 deep.
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


@nb.njit(cache=True, inline="always")
def _admissible_row(tab, a, b, theta2):
    """Far pair: boxes apart, one component each, ``max(diam²) ≤ θ² gap²`` (rows of
    :func:`_node_table`)."""
    g = 0.0
    for k in range(3):
        x = max(tab[a, k] - tab[b, 3 + k], tab[b, k] - tab[a, 3 + k])
        if x > 0.0:
            g += x * x
    return (g > 0.0 and tab[a, 7] >= 0.0 and tab[b, 7] >= 0.0
            and max(tab[a, 6], tab[b, 6]) <= theta2 * g)


@nb.njit(cache=True)
def _descend(a0, b0, left, right, tab, theta2, stack, far, nfar, near, nnear):
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
        if _admissible_row(tab, a, b, theta2):
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
def _admissible(a, b, bmin, bmax, nc, diam2, theta2):
    gap2 = bvh.box_gap2(bmin, bmax, a, b)
    return gap2 > 0.0 and nc[a] >= 0 and nc[b] >= 0 and max(diam2[a], diam2[b]) <= theta2 * gap2


@nb.njit(cache=True)
def _tasks(left, right, bmin, bmax, nc, diam2, theta2, want):
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
                    a == b or not _admissible(a, b, bmin, bmax, nc, diam2, theta2)):
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
def _split(left, right, bmin, bmax, nc, theta2, nchunks, want, cap):
    """Dual traversal from (root, root): unordered far pairs (admissible clusters) and near
    pairs of leaves (self pairs ``(A, A)`` included). The pairs of a frontier of ``want`` node
    pairs are split depth first in ``nchunks`` fixed chunks, each into a buffer of ``cap``
    pairs (all chunks again with twice the room while one runs out), and concatenated in
    chunk order: the same lists for every thread count."""
    diam2 = bvh.node_diam2(bmin, bmax)
    tasks = _tasks(left, right, bmin, bmax, nc, diam2, theta2, want)
    tab = _node_table(bmin, bmax, nc)
    nf = np.zeros(nchunks, np.int64)
    nn = np.zeros(nchunks, np.int64)
    room = max(cap, 1)
    while True:
        fbuf = np.empty((nchunks, room, 2), np.int64)
        nbuf = np.empty((nchunks, room, 2), np.int64)
        for cc in nb.prange(nchunks):
            ch = np.int64(cc)
            stack = np.empty((_STACK, 2), np.int64)
            f, n = 0, 0
            for t in range(ch, tasks.shape[0], nchunks):
                f, n = _descend(tasks[t, 0], tasks[t, 1], left, right, tab, theta2, stack,
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
    far = np.empty((of[nchunks], 2), np.int64)
    near = np.empty((on[nchunks], 2), np.int64)
    for cc in nb.prange(nchunks):
        ch = np.int64(cc)
        far[of[ch]:of[ch + 1]] = fbuf[ch, :nf[ch]]
        near[on[ch]:on[ch + 1]] = nbuf[ch, :nn[ch]]
    return far, near


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
    out = np.empty(cnt[m], np.int64)
    for p in range(pairs.shape[0]):
        a, b = pairs[p, 0], pairs[p, 1]
        out[fill[a]] = b
        fill[a] += 1
        if a != b:
            out[fill[b]] = a
            fill[b] += 1
    return cnt, out


# ------------------------------------------------------------------------------------------------
# far field


@nb.njit(cache=True, inline="always")
def _dipole(X, s0, s1, s2, d0, d1, d2, inv, w, grad_s, grad_x, gs, gX, gd):
    """First-order tangent term ``T(X, s) = Σ_abc ∂_c H_ab(d) X_ac s_b`` of the expansion of
    ``Σ e_Iᵀ H(m_I − m_J) e_J`` (``H = ∇² log|d|``, the tangent kernel of the energy) around
    the clusters' centres; adds ``w`` times its derivatives in ``s`` (with ``grad_s``) and in
    ``X`` (with ``grad_x``) to ``gs``, ``gX``, and in ``d`` (with either) to ``gd``. Returns
    ``T``."""
    w4 = inv * inv
    w6 = w4 * inv
    xd0 = X[0, 0] * d0 + X[0, 1] * d1 + X[0, 2] * d2
    xd1 = X[1, 0] * d0 + X[1, 1] * d1 + X[1, 2] * d2
    xd2 = X[2, 0] * d0 + X[2, 1] * d1 + X[2, 2] * d2
    xt0 = X[0, 0] * d0 + X[1, 0] * d1 + X[2, 0] * d2
    xt1 = X[0, 1] * d0 + X[1, 1] * d1 + X[2, 1] * d2
    xt2 = X[0, 2] * d0 + X[1, 2] * d1 + X[2, 2] * d2
    tr = X[0, 0] + X[1, 1] + X[2, 2]
    ds = d0 * s0 + d1 * s1 + d2 * s2
    dxd = d0 * xd0 + d1 * xd1 + d2 * xd2
    bb = s0 * (xd0 + xt0) + s1 * (xd1 + xt1) + s2 * (xd2 + xt2) + tr * ds
    t = -2.0 * w4 * bb + 8.0 * w6 * dxd * ds
    if grad_s or grad_x:
        a4 = -2.0 * w4 * w
        a6 = 8.0 * w6 * w
        if grad_s:
            gs[0] += a4 * (xd0 + xt0 + tr * d0) + a6 * dxd * d0
            gs[1] += a4 * (xd1 + xt1 + tr * d1) + a6 * dxd * d1
            gs[2] += a4 * (xd2 + xt2 + tr * d2) + a6 * dxd * d2
        if grad_x:
            dd = (d0, d1, d2)
            ss = (s0, s1, s2)
            for a in range(3):
                for b in range(3):
                    v = a4 * (ss[a] * dd[b] + dd[a] * ss[b]) + a6 * ds * dd[a] * dd[b]
                    if a == b:
                        v += a4 * ds
                    gX[a, b] += v
        xs0 = X[0, 0] * s0 + X[0, 1] * s1 + X[0, 2] * s2
        xs1 = X[1, 0] * s0 + X[1, 1] * s1 + X[1, 2] * s2
        xs2 = X[2, 0] * s0 + X[2, 1] * s1 + X[2, 2] * s2
        ts0 = X[0, 0] * s0 + X[1, 0] * s1 + X[2, 0] * s2
        ts1 = X[0, 1] * s0 + X[1, 1] * s1 + X[2, 1] * s2
        ts2 = X[0, 2] * s0 + X[1, 2] * s1 + X[2, 2] * s2
        c1 = w * (8.0 * w6 * bb - 48.0 * w6 * inv * dxd * ds)
        gd[0] += c1 * d0 + a4 * (ts0 + tr * s0 + xs0) + a6 * ((xd0 + xt0) * ds + dxd * s0)
        gd[1] += c1 * d1 + a4 * (ts1 + tr * s1 + xs1) + a6 * ((xd1 + xt1) * ds + dxd * s1)
        gd[2] += c1 * d2 + a4 * (ts2 + tr * s2 + xs2) + a6 * ((xd2 + xt2) * ds + dxd * s2)
    return t


@nb.njit(cache=True, inline="always")
def _quadrupole(T, s, x, w, wt, grad_t, grad_s, grad_x, gal, gbe, gs, gx, v, Tx):
    """Second-order tangent term ``K4 : (T ⊗ s) = Σ_abcd K4_abcd T_acd s_b`` (``K4 = ∇⁴ log|x|``,
    ``T`` symmetric in ``c, d``), contracted through the traces and projections of ``T``
    (``K4 = −2w²(δδ)₃ + 8w³(δxx)₆ − 48w⁴ xxxx``, ``w = 1/|x|²``); adds ``wt`` times its
    derivatives in ``s`` and ``x`` (as asked) to ``gs``, ``gx``. The derivative in ``T``,
    ``δ_cd α_a + δ_ac α_d + δ_ad α_c + β_acd + β_cad + β_dac`` with ``α = −2w² s + 8w³<x,s> x``
    and ``β = σ ⊗ x ⊗ x``, ``σ = 8w³ s − 16w⁴<x,s> x``, is summed as ``α`` into ``gal`` and
    ``β`` (entries ``c ≤ d``) into ``gbe`` (see :func:`_quadrupole_gradient`). ``v`` (7, 3) and
    ``Tx`` (3, 3) are scratch."""
    w2 = w * w
    w3 = w2 * w
    w4 = w3 * w
    for a in range(3):
        v[0, a] = T[a, 0, 0] + T[a, 1, 1] + T[a, 2, 2]
        v[1, a] = T[0, 0, a] + T[1, 1, a] + T[2, 2, a]
        for c in range(3):
            Tx[a, c] = T[a, c, 0] * x[0] + T[a, c, 1] * x[1] + T[a, c, 2] * x[2]
    for a in range(3):
        v[2, a] = Tx[a, 0] * x[0] + Tx[a, 1] * x[1] + Tx[a, 2] * x[2]  # T(·, x, x)
        v[3, a] = x[0] * Tx[0, a] + x[1] * Tx[1, a] + x[2] * Tx[2, a]  # T(x, ·, x)
    xs = x[0] * s[0] + x[1] * s[1] + x[2] * s[2]
    st = 0.0
    sq = 0.0
    lin = 0.0
    txxx = 0.0
    for a in range(3):
        st += s[a] * (v[0, a] + 2.0 * v[1, a])
        sq += s[a] * (v[2, a] + 2.0 * v[3, a])
        lin += x[a] * (v[0, a] + 2.0 * v[1, a])
        txxx += x[a] * v[2, a]
    inner = sq + xs * lin
    val = -2.0 * w2 * st + 8.0 * w3 * inner - 48.0 * w4 * xs * txxx
    if grad_s:
        for k in range(3):
            gs[k] += wt * (-2.0 * w2 * (v[0, k] + 2.0 * v[1, k])
                           + 8.0 * w3 * (v[2, k] + 2.0 * v[3, k] + x[k] * lin)
                           - 48.0 * w4 * x[k] * txxx)
    if grad_t:
        for a in range(3):
            gal[a] += wt * (8.0 * w3 * xs * x[a] - 2.0 * w2 * s[a])
            sig = wt * (8.0 * w3 * s[a] - 16.0 * w4 * xs * x[a])
            gbe[a, 0, 0] += sig * x[0] * x[0]
            gbe[a, 0, 1] += sig * x[0] * x[1]
            gbe[a, 0, 2] += sig * x[0] * x[2]
            gbe[a, 1, 1] += sig * x[1] * x[1]
            gbe[a, 1, 2] += sig * x[1] * x[2]
            gbe[a, 2, 2] += sig * x[2] * x[2]
    if grad_x:
        for k in range(3):
            p = s[0] * Tx[0, k] + s[1] * Tx[1, k] + s[2] * Tx[2, k]
            q = Tx[k, 0] * s[0] + Tx[k, 1] * s[1] + Tx[k, 2] * s[2]
            r = 0.0
            for a in range(3):
                r += x[a] * (T[a, k, 0] * s[0] + T[a, k, 1] * s[1] + T[a, k, 2] * s[2])
            g = 8.0 * w3 * (st * x[k] + 2.0 * (p + q + r) + s[k] * lin
                            + xs * (v[0, k] + 2.0 * v[1, k]))
            g -= 48.0 * w4 * (x[k] * inner + s[k] * txxx + xs * (v[2, k] + 2.0 * v[3, k]))
            g += 384.0 * w4 * w * xs * txxx * x[k]
            gx[k] += wt * g
    return val


@nb.njit(cache=True, inline="always")
def _quadrupole_gradient(gal, gbe, scale, out):
    """``scale`` times the derivative in ``T`` summed by :func:`_quadrupole` into ``out``."""
    for a in range(3):
        for c in range(3):
            for d in range(3):
                g = (gbe[a, min(c, d), max(c, d)] + gbe[c, min(a, d), max(a, d)]
                     + gbe[d, min(a, c), max(a, c)])
                if c == d:
                    g += gal[a]
                if a == c:
                    g += gal[d]
                if a == d:
                    g += gal[c]
                out[a, c, d] = scale * g


@nb.njit(cache=True, inline="always")
def _dipole_pair(P, R, x, w, wt, grad, gP, gx, v):
    """Second-order tangent term of two dipoles ``K4 : (P ⊗ R) = Σ_abcd K4_abcd P_ac R_bd``;
    adds ``wt`` times its derivatives in ``P`` and ``x`` to ``gP``, ``gx``. ``v`` (7, 3) is
    scratch."""
    w2 = w * w
    w3 = w2 * w
    w4 = w3 * w
    trp = P[0, 0] + P[1, 1] + P[2, 2]
    trr = R[0, 0] + R[1, 1] + R[2, 2]
    pr = 0.0
    for i in range(3):
        v[0, i] = 0.0
        v[1, i] = 0.0
        for j in range(3):
            pr += P[i, j] * (R[i, j] + R[j, i])
            v[0, i] += (P[i, j] + P[j, i]) * x[j]  # (P + Pᵀ) x
            v[1, i] += (R[i, j] + R[j, i]) * x[j]
    xpx = 0.5 * (x[0] * v[0, 0] + x[1] * v[0, 1] + x[2] * v[0, 2])
    xrx = 0.5 * (x[0] * v[1, 0] + x[1] * v[1, 1] + x[2] * v[1, 2])
    pp = v[0, 0] * v[1, 0] + v[0, 1] * v[1, 1] + v[0, 2] * v[1, 2]
    zero = pr + trp * trr
    two = pp + trp * xrx + trr * xpx
    val = -2.0 * w2 * zero + 8.0 * w3 * two - 48.0 * w4 * xpx * xrx
    if grad:
        for i in range(3):
            for j in range(3):
                g = (-2.0 * w2 * (R[i, j] + R[j, i])
                     + 8.0 * w3 * (v[1, i] * x[j] + x[i] * v[1, j] + trr * x[i] * x[j])
                     - 48.0 * w4 * xrx * x[i] * x[j])
                if i == j:
                    g += 8.0 * w3 * xrx - 2.0 * w2 * trr
                gP[i, j] += wt * g
        for k in range(3):
            a = 0.0
            for j in range(3):
                a += (P[k, j] + P[j, k]) * v[1, j] + (R[k, j] + R[j, k]) * v[0, j]
            g = 8.0 * w3 * (zero * x[k] + a + trp * v[1, k] + trr * v[0, k])
            g -= 48.0 * w4 * (two * x[k] + xrx * v[0, k] + xpx * v[1, k])
            g += 384.0 * w4 * w * xpx * xrx * x[k]
            gx[k] += wt * g
    return val


# No fast-math here: with it, the code LLVM made for this kernel in the compiling process and
# the code numba's cache loads in later processes fused and ordered operations differently
# (gradients differed in the last bits between a first and a second run; measured with
# "contract" alone too). Without it _far took 37 instead of 32 ms at 20 000 edges (7_2).
@nb.njit(cache=True, parallel=True, error_model="numpy")
def _far(L, C, S, D, Q, T, nc, foff, fpart, grad):
    """Per target node: Σ_B F(A, B) and, with ``grad``, twice Σ_B ∂F(A, B)/∂(L_A, S_A, c_A, D_A,
    Q_A, T_A) (the derivative of the ordered sum: F is symmetric). F: both parts of the kernel
    expanded to second order in the cluster sizes around the centres, the same order for
    both: they cancel for two pieces of one straight line (exact F = 0), and expanding one
    part further than the other measured larger errors."""
    m = L.shape[0]
    eF = np.zeros(m)
    gL = np.zeros(m)
    gS = np.zeros((m, 3))
    gC = np.zeros((m, 3))
    gD = np.zeros((m, 3, 3))
    gQ = np.zeros((m, 3, 3))
    gT = np.zeros((m, 3, 3, 3))
    for aa in nb.prange(m):
        a = np.int64(aa)
        if foff[a] == foff[a + 1]:
            continue
        La = L[a]
        cx, cy, cz = C[a, 0], C[a, 1], C[a, 2]
        sax, say, saz = S[a, 0], S[a, 1], S[a, 2]
        Da = D[a]
        Qa = Q[a]
        trqa = Qa[0, 0] + Qa[1, 1] + Qa[2, 2]
        e = 0.0
        g_l = 0.0
        gs = np.zeros(3)
        gc = np.zeros(3)
        gx = np.zeros((3, 3))
        gq = np.zeros((3, 3))
        gal = np.zeros(3)
        gbe = np.zeros((3, 3, 3))
        scratch = np.zeros((3, 3))
        v = np.zeros((7, 3))
        x = np.zeros(3)
        for p in range(foff[a], foff[a + 1]):
            b = fpart[p]
            Lb = L[b]
            dx = cx - C[b, 0]
            dy = cy - C[b, 1]
            dz = cz - C[b, 2]
            inv = 1.0 / (dx * dx + dy * dy + dz * dz)
            # length part, second order: ½ ∇²k : (L_B Q_A + L_A Q_B), k = 1/|d|² (the first
            # order vanishes: Σ l δ = 0)
            x[0], x[1], x[2] = dx, dy, dz
            Qb = Q[b]
            i2 = inv * inv
            i3 = i2 * inv
            trqb = Qb[0, 0] + Qb[1, 1] + Qb[2, 2]
            xqa = 0.0
            xqb = 0.0
            for i in range(3):
                v[0, i] = Qa[i, 0] * dx + Qa[i, 1] * dy + Qa[i, 2] * dz
                v[1, i] = Qb[i, 0] * dx + Qb[i, 1] * dy + Qb[i, 2] * dz
                xqa += x[i] * v[0, i]
                xqb += x[i] * v[1, i]
            trq = Lb * trqa + La * trqb
            xqx = Lb * xqa + La * xqb
            e += 4.0 * i3 * xqx - i2 * trq
            if grad:
                g_l += 4.0 * i3 * xqb - i2 * trqb
                for i in range(3):
                    gc[i] += (4.0 * i3 * trq - 24.0 * i3 * inv * xqx) * x[i] + 8.0 * i3 * (
                        Lb * v[0, i] + La * v[1, i])
                    for j in range(3):
                        gq[i, j] += 4.0 * Lb * i3 * x[i] * x[j]
                    gq[i, i] -= Lb * i2
            if nc[a] == nc[b]:
                sbx, sby, sbz = S[b, 0], S[b, 1], S[b, 2]
                ab = sax * sbx + say * sby + saz * sbz
                da = dx * sax + dy * say + dz * saz
                db = dx * sbx + dy * sby + dz * sbz
                sv = (La * Lb + ab) * inv
                q = da * db * inv * inv
                e += sv - 2.0 * q
                e += _dipole(Da, sbx, sby, sbz, dx, dy, dz, inv, 1.0, False, grad, gs, gx, gc)
                e -= _dipole(D[b], sax, say, saz, dx, dy, dz, inv, -1.0, grad, False, gs, gx, gc)
                # tangent part, second order: ½ K4:(T_A⊗S_B) − K4:(D_A⊗D_B) + ½ K4:(S_A⊗T_B)
                e += 0.5 * _quadrupole(T[a], S[b], x, inv, 0.5, grad, False, grad, gal, gbe,
                                       scratch[0], gc, v, scratch)
                e += 0.5 * _quadrupole(T[b], S[a], x, inv, 0.5, False, grad, grad, gal, gbe, gs,
                                       gc, v, scratch)
                e -= _dipole_pair(Da, D[b], x, inv, -1.0, grad, gx, gc, v)
                if grad:
                    g_l += Lb * inv
                    tb = 2.0 * db * inv
                    ta = 2.0 * da * inv
                    gs[0] += (sbx - tb * dx) * inv
                    gs[1] += (sby - tb * dy) * inv
                    gs[2] += (sbz - tb * dz) * inv
                    cd = 8.0 * q - 2.0 * sv
                    gc[0] += (cd * dx - tb * sax - ta * sbx) * inv
                    gc[1] += (cd * dy - tb * say - ta * sby) * inv
                    gc[2] += (cd * dz - tb * saz - ta * sbz) * inv
            else:
                f = La * Lb * inv
                e += f
                if grad:
                    g_l += Lb * inv
                    cd = -2.0 * f * inv
                    gc[0] += cd * dx
                    gc[1] += cd * dy
                    gc[2] += cd * dz
        eF[a] = e
        if grad:
            gL[a] = 2.0 * g_l
            for k in range(3):
                gS[a, k] = 2.0 * gs[k]
                gC[a, k] = 2.0 * gc[k]
                for j in range(3):
                    gD[a, k, j] = 2.0 * gx[k, j]
                    gQ[a, k, j] = 2.0 * gq[k, j]
            _quadrupole_gradient(gal, gbe, 2.0, gT[a])
    return eF, gL, gS, gC, gD, gQ, gT


@nb.njit(cache=True)
def _push_down(L, C, S, D, gL, gS, gC, gD, gQ, gT, left, right):
    """What every leaf's edges receive from the far field of the leaf and its ancestors.

    A node's share of the derivative is the first variation of ``Σ_I l_I a(δ_I) + <e_I,
    b(δ_I)>`` with the polynomials (``δ = m − c``) ``a = g_L + <g_c, δ>/L + δᵀ G_Q δ`` (the
    centre ``c = Σ l m / L``, with ``g_c`` including the explicit dependence of ``D`` and ``T``
    on ``c``: ``−G_Dᵀ S`` and ``−2 Σ G_T,ack D_ac``; ``Q``'s vanishes, ``Σ l δ = 0``) and
    ``b_a = g_S,a + G_D,ac δ_c + G_T,acd δ_c δ_d``. The polynomials are moved to the
    children's centres and summed down. Columns: 0 ``a0``, 1–3 ``a1``, 4–12 ``A2``, 13–15
    ``b0``, 16–24 ``B1``, 25–51 ``B2`` (row-major, ``A2`` and ``B2`` symmetrized)."""
    m = L.shape[0]
    acc = np.zeros((m, 52))
    for node in range(m):
        g = gD[node]
        t = gT[node]
        r = acc[node]
        inv = 1.0 / L[node]
        for k in range(3):
            gc = gC[node, k]
            for a in range(3):
                gc -= g[a, k] * S[node, a]
                for c in range(3):
                    gc -= (t[a, c, k] + t[a, k, c]) * D[node, a, c]
            r[1 + k] = gc * inv
            r[13 + k] = gS[node, k]
            for j in range(3):
                r[4 + 3 * k + j] = 0.5 * (gQ[node, k, j] + gQ[node, j, k])
                r[16 + 3 * k + j] = g[k, j]
                for i in range(3):
                    r[25 + 9 * k + 3 * j + i] = 0.5 * (t[k, j, i] + t[k, i, j])
        r[0] = gL[node]
    h = np.empty(3)
    for node in range(m):  # parents come before their children
        r = acc[node]
        for child in (left[node], right[node]):
            if child < 0:
                continue
            o = acc[child]
            for k in range(3):
                h[k] = C[child, k] - C[node, k]
            # a(δ + h), b(δ + h) as polynomials in the child's δ
            o[0] += r[0]
            for k in range(3):
                o[0] += r[1 + k] * h[k]
                o[1 + k] += r[1 + k]
                o[13 + k] += r[13 + k]
                for j in range(3):
                    a2 = r[4 + 3 * k + j]
                    o[0] += a2 * h[k] * h[j]
                    o[1 + k] += 2.0 * a2 * h[j]
                    o[4 + 3 * k + j] += a2
                    b1 = r[16 + 3 * k + j]
                    o[13 + k] += b1 * h[j]
                    o[16 + 3 * k + j] += b1
                    for i in range(3):
                        b2 = r[25 + 9 * k + 3 * j + i]
                        o[13 + k] += b2 * h[j] * h[i]
                        o[16 + 3 * k + j] += 2.0 * b2 * h[i]
                        o[25 + 9 * k + 3 * j + i] += b2
    return acc


# ------------------------------------------------------------------------------------------------
# near field


@nb.njit(cache=True)
def _near_lists(pairs, perm, nxt, prv, lo, hi, left):
    """What the near field reads besides the edges: every leaf's near partners (CSR
    ``(offsets, partners)`` of :func:`_by_target`: both directions of each pair, a self pair
    once), per tree position the leaf holding it, and the tree positions of the previous and
    the next edge along the curve (always in a near partner: boxes of edges that share a
    vertex touch)."""
    m = lo.shape[0]
    n = perm.shape[0]
    noff, npart = _by_target(pairs, m)
    leaf_of = np.empty(n, np.int64)
    for node in range(m):
        if left[node] < 0:
            for q in range(lo[node], hi[node]):
                leaf_of[q] = node
    at = np.empty(n, np.int64)
    for q in range(n):
        at[perm[q]] = q
    nbr = np.empty((n, 2), np.int64)
    for q in range(n):
        i = perm[q]
        nbr[q, 0] = at[prv[i]]
        nbr[q, 1] = at[nxt[i]]
    return noff, npart, leaf_of, nbr


@nb.njit(cache=True, fastmath=_NEAR_FASTMATH, error_model="numpy", inline="always")
def _near_row(mx, my, mz, ex, ey, ez, ln, cp, count, skip, cq, px, py, pz, ax, ay, az, li, grad):
    """One edge (midpoint ``p``, edge vector ``a``, length ``li``, component ``cq``) against
    ``count`` staged edges: its ordered sum ``Σ_J f`` and, with ``grad``, ``Σ_J l_J/|d|²`` and
    the partial sums of ``∂f/∂e_I`` without its length term and of ``∂f/∂m_I``. Staged edges
    ``skip`` (the edge itself and its two neighbours) count zero, edges of another component
    with their length part only: both by selects, so that the loop vectorizes (and so
    ``error_model="numpy"``: no zero test on the division)."""
    s = 0.0
    wl = 0.0
    gax = gay = gaz = gmx = gmy = gmz = 0.0
    j0, j1, j2 = skip
    for r in range(count):
        dx = px - mx[r]
        dy = py - my[r]
        dz = pz - mz[r]
        inv = 1.0 / (dx * dx + dy * dy + dz * dz)
        inv = 0.0 if (r == j0 or r == j1 or r == j2) else inv
        same = cp[r] == cq
        bx = ex[r] if same else 0.0
        by = ey[r] if same else 0.0
        bz = ez[r] if same else 0.0
        lj = ln[r]
        ab = ax * bx + ay * by + az * bz
        da = dx * ax + dy * ay + dz * az
        db = dx * bx + dy * by + dz * bz
        sv = (li * lj + ab) * inv
        qq = da * db * inv * inv
        s += sv - 2.0 * qq
        if grad:
            tb = 2.0 * db * inv
            ta = 2.0 * da * inv
            wl += lj * inv
            gax += (bx - tb * dx) * inv
            gay += (by - tb * dy) * inv
            gaz += (bz - tb * dz) * inv
            cd = 8.0 * qq - 2.0 * sv
            gmx += (cd * dx - tb * ax - ta * bx) * inv
            gmy += (cd * dy - tb * ay - ta * by) * inv
            gmz += (cd * dz - tb * az - ta * bz) * inv
    return s, wl, gax, gay, gaz, gmx, gmy, gmz


@nb.njit(cache=True, parallel=True, fastmath=_NEAR_FASTMATH, error_model="numpy")
def _near(E, M, ln, cp, lo, hi, leaves, noff, npart, leaf_of, nbr, grad):
    """The near field as an ordered sum: every edge of a leaf against every edge of the leaf's
    near partners (itself included), except itself and its neighbours along the curve, with
    the kernel of ``energy.py``. Per edge (tree order): ``rows[0]`` its share ``Σ_J f(I, J)``
    of the energy and, with ``grad``, rows 1–3 and 4–6 the derivatives of the ordered sum
    (``2 Σ_J ∂f(I, J)``, ``f`` symmetric) in its edge vector and midpoint. A leaf's partners
    are first copied to one contiguous array (coordinates in rows), so the loop over them
    vectorizes; every pair is summed twice (once per side), and nothing is shared between
    edges: the same bits for any thread count and any split of the leaves."""
    n = ln.shape[0]
    m = lo.shape[0]
    nl = leaves.shape[0]
    rows = np.empty((7 if grad else 1, n))
    nchunks = min(nl, _NEAR_CHUNKS)
    for cc in nb.prange(nchunks):
        ch = np.int64(cc)
        l0 = ch * nl // nchunks
        l1 = (ch + 1) * nl // nchunks
        room = 1
        for t in range(l0, l1):
            a = leaves[t]
            c = 0
            for p in range(noff[a], noff[a + 1]):
                c += hi[npart[p]] - lo[npart[p]]
            room = max(room, c)
        st = np.empty((7, room))
        sc = np.empty(room, np.int64)
        where = np.empty(m, np.int64)  # staged position of a partner's first edge
        for t in range(l0, l1):
            a = leaves[t]
            c = 0
            for p in range(noff[a], noff[a + 1]):
                b = npart[p]
                where[b] = c
                for r in range(lo[b], hi[b]):
                    st[0, c] = M[r, 0]
                    st[1, c] = M[r, 1]
                    st[2, c] = M[r, 2]
                    st[3, c] = E[r, 0]
                    st[4, c] = E[r, 1]
                    st[5, c] = E[r, 2]
                    st[6, c] = ln[r]
                    sc[c] = cp[r]
                    c += 1
            for q in range(lo[a], hi[a]):
                skip = (where[a] + q - lo[a],
                        where[leaf_of[nbr[q, 0]]] + nbr[q, 0] - lo[leaf_of[nbr[q, 0]]],
                        where[leaf_of[nbr[q, 1]]] + nbr[q, 1] - lo[leaf_of[nbr[q, 1]]])
                li = ln[q]
                s, wl, gax, gay, gaz, gmx, gmy, gmz = _near_row(
                    st[0], st[1], st[2], st[3], st[4], st[5], st[6], sc, c, skip, cp[q],
                    M[q, 0], M[q, 1], M[q, 2], E[q, 0], E[q, 1], E[q, 2], li, grad)
                rows[0, q] = s
                if grad:
                    w = wl / li  # the length term of ∂f/∂e_I: (l_J/l_I) e_I/|d|²
                    rows[1, q] = 2.0 * (gax + w * E[q, 0])
                    rows[2, q] = 2.0 * (gay + w * E[q, 1])
                    rows[3, q] = 2.0 * (gaz + w * E[q, 2])
                    rows[4, q] = 2.0 * gmx
                    rows[5, q] = 2.0 * gmy
                    rows[6, q] = 2.0 * gmz
    return rows


@nb.njit(cache=True, parallel=True)
def _far_to_edges(E, M, ln, C, lo, hi, leaves, acc, part):
    """Add what every edge receives from the far field (the polynomials ``acc`` of its leaf,
    see :func:`_push_down`) to its partial derivatives ``part`` (rows 1–3: edge vector, 4–6:
    midpoint): ``∂/∂e = b(δ) + a(δ) e / l``, ``∂/∂m = l ∇a(δ) + ∇b(δ)ᵀ e``."""
    for kk in nb.prange(leaves.shape[0]):
        leaf = leaves[np.int64(kk)]
        r = acc[leaf]
        dl = np.empty(3)
        av = np.empty(3)
        for q in range(lo[leaf], hi[leaf]):
            li = ln[q]
            for k in range(3):
                dl[k] = M[q, k] - C[leaf, k]
            a = r[0]
            for k in range(3):
                ga = r[1 + k]
                a += r[1 + k] * dl[k]
                for j in range(3):
                    a += r[4 + 3 * k + j] * dl[k] * dl[j]
                    ga += 2.0 * r[4 + 3 * k + j] * dl[j]
                av[k] = ga
            for k in range(3):
                b = r[13 + k]
                for j in range(3):
                    b += r[16 + 3 * k + j] * dl[j]
                    for i in range(3):
                        b += r[25 + 9 * k + 3 * j + i] * dl[j] * dl[i]
                part[1 + k, q] += b + a * E[q, k] / li
            for k in range(3):  # ∂b_a/∂δ_k e_a
                gm = li * av[k]
                for a2 in range(3):
                    jb = r[16 + 3 * a2 + k]
                    for i in range(3):
                        jb += 2.0 * r[25 + 9 * a2 + 3 * k + i] * dl[i]
                    gm += jb * E[q, a2]
                part[4 + k, q] += gm


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
    """

    def __init__(self, X: np.ndarray, layout: Layout, theta: float = THETA,
                 leaf_size: int = bvh.LEAF_SIZE):
        self.layout = layout
        self.theta = check_theta(theta)
        tree = bvh.build(X, layout, leaf_size)
        self.tree = tree
        bmin, bmax = bvh.segment_boxes(tree, X, layout)
        E, M, ln, cp, pos, size = _edge_arrays(X, layout.nxt, layout.comp, layout.starts,
                                               tree.perm)
        nc = _cluster_data(E, M, ln, cp, tree.lo, tree.hi, tree.left, tree.right)[-1]
        m = tree.size
        # each list holds about 2.8–3.9 m / theta pairs (measured from 5 000 to 100 000 edges)
        cap = max(256, int(8 * m / self.theta / _SPLIT_CHUNKS))
        far, near = _split(tree.left, tree.right, bmin, bmax, nc, self.theta**2, _SPLIT_CHUNKS,
                           64 * _SPLIT_CHUNKS, cap)
        self.far_pairs = far.shape[0]
        self.near_pairs = near.shape[0]
        self.foff, self.fpart = _by_target(far, m)
        self.near = near
        self.leaves = np.flatnonzero(tree.left < 0).astype(np.int64)
        self._near_lists = _near_lists(near, tree.perm, layout.nxt, layout.prv, tree.lo, tree.hi,
                                       tree.left)

    def _evaluate(self, X: np.ndarray, grad: bool):
        lay, tree = self.layout, self.tree
        E, M, ln, cp, pos, size = _edge_arrays(X, lay.nxt, lay.comp, lay.starts, tree.perm)
        L, C, S, D, Q, T, nc = _cluster_data(E, M, ln, cp, tree.lo, tree.hi, tree.left,
                                             tree.right)
        eF, gL, gS, gC, gD, gQ, gT = _far(L, C, S, D, Q, T, nc, self.foff, self.fpart, grad)
        part = _near(E, M, ln, cp, tree.lo, tree.hi, self.leaves, *self._near_lists, grad)
        energy = 4.0 * lay.k + float(np.sum(part[0])) + float(np.sum(eF))
        if not grad:
            return energy, None
        acc = _push_down(L, C, S, D, gL, gS, gC, gD, gQ, gT, tree.left, tree.right)
        _far_to_edges(E, M, ln, C, tree.lo, tree.hi, self.leaves, acc, part)
        ga = part[1:4].T
        gm = part[4:7].T
        G = np.zeros_like(X)
        # e_I = P[nxt I] − P[I], m_I = (P[I] + P[nxt I]) / 2, with I = perm[q]
        i = tree.perm
        G[i] += 0.5 * gm - ga
        G[lay.nxt[i]] += ga + 0.5 * gm
        return energy, G

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
