"""Möbius energy and its exact derivative by Barnes–Hut on the edge hierarchy (the tree engine).

The energy of DESIGN.md is a sum over ordered pairs of disjoint edges (``energy.py`` sums all of
them). Here the pairs are split by a dual traversal of the hierarchy (:mod:`bvh`) into

* the **far field**: pairs of clusters ``(A, B)`` of one component each whose boxes are apart,
  ``max(diam A, diam B) ≤ θ · gap(A, B)``. The pair sum is replaced by the kernel at the
  clusters' data, total length ``L``, length-weighted centre ``c``, summed edge vector ``S`` and
  tangent dipole ``D = Σ e_I (m_I − c)ᵀ``:

      F(A, B) = (L_A L_B + <S_A, S_B>) / |d|² − 2 <d, S_A><d, S_B> / |d|⁴ + T(D_A, S_B)
                − T(D_B, S_A),   d = c_A − c_B

  where ``<S_A, S_B>/|d|² − 2<d,S_A><d,S_B>/|d|⁴ = S_Aᵀ H(d) S_B`` with ``H = ∇² log|d|`` and
  ``T`` is its first-order term (:func:`_dipole`); between components ``L_A L_B / |d|²``, the
  O'Hara kernel of ``energy.py``. Both parts are exact to first order in the cluster sizes.
* the **near field**: every other pair (always the pairs close in space, and so those close
  along the curve: boxes of edges sharing a vertex touch), summed exactly with the kernel of
  ``energy.py``.

The gradient is the exact derivative of this approximated sum for the fixed split: each
cluster's derivative with respect to ``(L, S, c, D)`` is pushed down to its edges by the chain
rule. Both passes are parallel over targets (each target sums its own ordered pairs, so nothing
is shared between threads): the results are the same bits for every thread count.

The split (the "frame": hierarchy and interaction lists) is a function of the polygon it was
built at. :class:`Frame` keeps it so that several polygons can be evaluated with one split (a
line search sees one smooth function); :func:`tree_energy` builds a fresh one.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from . import bvh
from ._layout import Layout

THETA = 0.0625  # default admissibility (docs/benchmarks.md, "Tree engine: accuracy")
_FASTMATH = {"reassoc", "contract", "nsz", "arcp"}
# Fixed split of the traversal into chunks (the same lists for every thread count).
_SPLIT_CHUNKS = 16
# Fixed work split of the near field (independent of the thread count: the same bits on every
# machine); each chunk holds a buffer of 7 values per edge.
_CHUNKS = 8


ENGINE_NAMES = ("auto", "exact", "tree")
# From this many edges on, "auto" takes the tree: at the default theta its energy+gradient
# measured 0.8x the exact speed at 2 000 edges, 1.7x at 5 000, 3.6x at 10 000, 7.8x at 20 000
# (docs/benchmarks.md, "Tree engine").
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
    """Per node: total length ``L``, length-weighted centre ``c``, summed edge vector ``S``,
    tangent dipole ``D = Σ e_I (m_I − c)ᵀ`` and its component (−1 for a node holding edges of
    several components), bottom-up."""
    m = lo.shape[0]
    L = np.empty(m)
    C = np.empty((m, 3))
    S = np.empty((m, 3))
    D = np.zeros((m, 3, 3))
    nc = np.empty(m, np.int64)
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
                for a in range(3):
                    for b in range(3):
                        D[node, a, b] += E[q, a] * (M[q, b] - C[node, b])
        else:
            a, b = left[node], right[node]
            tot = L[a] + L[b]
            L[node] = tot
            for k in range(3):
                C[node, k] = (L[a] * C[a, k] + L[b] * C[b, k]) / tot
                S[node, k] = S[a, k] + S[b, k]
            for ch in (a, b):  # moments of the children moved to this node's centre
                for u in range(3):
                    for v in range(3):
                        D[node, u, v] += D[ch, u, v] + S[ch, u] * (C[ch, v] - C[node, v])
            nc[node] = nc[a] if nc[a] == nc[b] else -1
    return L, C, S, D, nc


# ------------------------------------------------------------------------------------------------
# the split into far and near pairs


@nb.njit(cache=True)
def _push_pair(buf, count, a, b):
    if count == buf.shape[0]:
        grown = np.empty((2 * buf.shape[0], 2), np.int64)
        grown[:count] = buf
        buf = grown
    buf[count, 0] = a
    buf[count, 1] = b
    return buf


@nb.njit(cache=True)
def _descend(a0, b0, left, right, bmin, bmax, nc, diam2, theta2, far, nfar, near, nnear, grow):
    """Depth-first split of the pair (a0, b0): far pairs (admissible clusters) and near pairs of
    leaves appended to ``far``/``near`` from ``nfar``/``nnear`` on. Without ``grow`` a full
    array ends the descent: the counts come back as -1."""
    stack = np.empty((128, 2), np.int64)
    stack[0, 0] = a0
    stack[0, 1] = b0
    top = 1
    while top > 0:
        top -= 1
        a = stack[top, 0]
        b = stack[top, 1]
        is_far = a != b and _admissible(a, b, bmin, bmax, nc, diam2, theta2)
        if not is_far and (left[a] >= 0 or left[b] >= 0):
            stack, top = bvh.push_split(stack, top, a, b, left, right, diam2)
            continue
        full = nfar == far.shape[0] if is_far else nnear == near.shape[0]
        if full and not grow:
            return far, -1, near, -1
        if is_far:
            far = _push_pair(far, nfar, a, b)
            nfar += 1
        else:
            near = _push_pair(near, nnear, a, b)
            nnear += 1
    return far, nfar, near, nnear


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
    pairs, and concatenated in chunk order: the same lists for every thread count."""
    diam2 = bvh.node_diam2(bmin, bmax)
    tasks = _tasks(left, right, bmin, bmax, nc, diam2, theta2, want)
    fbuf = np.empty((nchunks, cap, 2), np.int64)
    nbuf = np.empty((nchunks, cap, 2), np.int64)
    nf = np.zeros(nchunks, np.int64)
    nn = np.zeros(nchunks, np.int64)
    for cc in nb.prange(nchunks):
        ch = np.int64(cc)
        f, n = 0, 0
        for t in range(ch, tasks.shape[0], nchunks):
            _, f, _, n = _descend(tasks[t, 0], tasks[t, 1], left, right, bmin, bmax, nc, diam2,
                                  theta2, fbuf[ch], f, nbuf[ch], n, False)
            if f < 0:
                break
        nf[ch] = f
        nn[ch] = n
    # a chunk that ran out of room is split again on its own, into growing arrays
    ok = nf >= 0
    redo_f = [np.empty((0, 2), np.int64) for _ in range(nchunks)]
    redo_n = [np.empty((0, 2), np.int64) for _ in range(nchunks)]
    for ch in range(nchunks):
        if not ok[ch]:
            f_arr = np.empty((2 * cap, 2), np.int64)
            n_arr = np.empty((2 * cap, 2), np.int64)
            f, n = 0, 0
            for t in range(ch, tasks.shape[0], nchunks):
                f_arr, f, n_arr, n = _descend(tasks[t, 0], tasks[t, 1], left, right, bmin, bmax,
                                              nc, diam2, theta2, f_arr, f, n_arr, n, True)
            redo_f[ch] = f_arr[:f].copy()
            redo_n[ch] = n_arr[:n].copy()
            nf[ch] = f
            nn[ch] = n
    far = np.empty((nf.sum(), 2), np.int64)
    near = np.empty((nn.sum(), 2), np.int64)
    pf = 0
    pn = 0
    for ch in range(nchunks):
        if ok[ch]:
            far[pf:pf + nf[ch]] = fbuf[ch, :nf[ch]]
            near[pn:pn + nn[ch]] = nbuf[ch, :nn[ch]]
        else:
            far[pf:pf + nf[ch]] = redo_f[ch]
            near[pn:pn + nn[ch]] = redo_n[ch]
        pf += nf[ch]
        pn += nn[ch]
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
def _dipole(X, s0, s1, s2, d0, d1, d2, inv, w, grad, gs, gX, gd):
    """First-order tangent term ``T(X, s) = Σ_abc ∂_c H_ab(d) X_ac s_b`` of the expansion of
    ``Σ e_Iᵀ H(m_I − m_J) e_J`` (``H = ∇² log|d|``, the tangent kernel of the energy) around
    the clusters' centres; adds ``w`` times its derivatives in ``s``, ``X`` and ``d`` to ``gs``,
    ``gX``, ``gd`` with ``grad``. Returns ``T``."""
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
    if grad:
        a4 = -2.0 * w4 * w
        a6 = 8.0 * w6 * w
        gs[0] += a4 * (xd0 + xt0 + tr * d0) + a6 * dxd * d0
        gs[1] += a4 * (xd1 + xt1 + tr * d1) + a6 * dxd * d1
        gs[2] += a4 * (xd2 + xt2 + tr * d2) + a6 * dxd * d2
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


@nb.njit(cache=True, parallel=True, fastmath=_FASTMATH)
def _far(L, C, S, D, nc, foff, fpart, grad):
    """Per target node: Σ_B F(A, B) and, with ``grad``, twice Σ_B ∂F(A, B)/∂(L_A, S_A, c_A,
    D_A) (the derivative of the ordered sum: F is symmetric). F: the length part at the
    centres, the tangent part to first order (monopole and dipole ``D``): both are then exact
    to first order, and exact (zero) for two pieces of one straight line, where the two parts
    cancel: expanding one part further than the other measured larger errors."""
    m = L.shape[0]
    eF = np.zeros(m)
    gL = np.zeros(m)
    gS = np.zeros((m, 3))
    gC = np.zeros((m, 3))
    gD = np.zeros((m, 3, 3))
    for aa in nb.prange(m):
        a = np.int64(aa)
        if foff[a] == foff[a + 1]:
            continue
        La = L[a]
        cx, cy, cz = C[a, 0], C[a, 1], C[a, 2]
        sax, say, saz = S[a, 0], S[a, 1], S[a, 2]
        Da = D[a]
        e = 0.0
        g_l = 0.0
        gs = np.zeros(3)
        gc = np.zeros(3)
        gx = np.zeros((3, 3))
        scratch = np.zeros((3, 3))
        for p in range(foff[a], foff[a + 1]):
            b = fpart[p]
            Lb = L[b]
            dx = cx - C[b, 0]
            dy = cy - C[b, 1]
            dz = cz - C[b, 2]
            inv = 1.0 / (dx * dx + dy * dy + dz * dz)
            if nc[a] == nc[b]:
                sbx, sby, sbz = S[b, 0], S[b, 1], S[b, 2]
                ab = sax * sbx + say * sby + saz * sbz
                da = dx * sax + dy * say + dz * saz
                db = dx * sbx + dy * sby + dz * sbz
                sv = (La * Lb + ab) * inv
                q = da * db * inv * inv
                e += sv - 2.0 * q
                e += _dipole(Da, sbx, sby, sbz, dx, dy, dz, inv, 1.0, grad, scratch[0], gx, gc)
                e -= _dipole(D[b], sax, say, saz, dx, dy, dz, inv, -1.0, grad, gs, scratch, gc)
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
    return eF, gL, gS, gC, gD


@nb.njit(cache=True)
def _push_down(L, C, S, gL, gS, gC, gD, left, right):
    """Sums over each node and its ancestors of what its edges receive from the far field.

    Chain rule through ``L = Σ l``, ``S = Σ e``, ``c = Σ l m / L`` and
    ``D = Σ e (m − c)ᵀ`` (whose dependence on ``c`` adds ``−g_Dᵀ S`` to ``g_c``)::

        ∂/∂e_I += P1 + t_I (P2 + <m_I, P3>) + G_D m_I − G_D c,   ∂/∂m_I += l_I P3 + G_Dᵀ e_I

    with ``P1 = g_S``, ``P2 = g_L − <g_c, c>/L``, ``P3 = g_c / L``: columns 0–2 P1, 3 P2,
    4–6 P3, 7–15 ``G_D`` (row-major), 16–18 ``G_D c``."""
    m = L.shape[0]
    acc = np.empty((m, 19))
    for node in range(m):
        inv = 1.0 / L[node]
        g = gD[node]
        gc = np.empty(3)
        for k in range(3):
            gc[k] = gC[node, k] - (g[0, k] * S[node, 0] + g[1, k] * S[node, 1]
                                   + g[2, k] * S[node, 2])
        for k in range(3):
            acc[node, k] = gS[node, k]
            acc[node, 4 + k] = gc[k] * inv
            acc[node, 16 + k] = g[k, 0] * C[node, 0] + g[k, 1] * C[node, 1] + g[k, 2] * C[node, 2]
            for j in range(3):
                acc[node, 7 + 3 * k + j] = g[k, j]
        acc[node, 3] = gL[node] - (gc[0] * C[node, 0] + gc[1] * C[node, 1]
                                   + gc[2] * C[node, 2]) * inv
    for node in range(m):  # parents come before their children
        for child in (left[node], right[node]):
            if child >= 0:
                for k in range(19):
                    acc[child, k] += acc[node, k]
    return acc


# ------------------------------------------------------------------------------------------------
# near field


@nb.njit(cache=True, parallel=True, fastmath=_FASTMATH)
def _near(E, M, ln, cp, pos, size, lo, hi, pairs, nchunks, grad):
    """The near field, each unordered pair of edges once (pairs of leaves, self pairs
    included): per edge (tree order) its share of the ordered sum (``rows``: f for each end
    of every pair) and, with ``grad``, the partial derivatives of the ordered sum with respect
    to its edge vector and midpoint. The leaf pairs are cut into ``nchunks`` fixed runs with a
    buffer each, summed in order: the same bits for every thread count."""
    n = ln.shape[0]
    npairs = pairs.shape[0]
    width = 7 if grad else 1
    buf = np.zeros((nchunks, width, n))
    for cc in nb.prange(nchunks):
        ch = np.int64(cc)
        b = buf[ch]
        for p in range(ch * npairs // nchunks, (ch + 1) * npairs // nchunks):
            la = pairs[p, 0]
            lb = pairs[p, 1]
            for q in range(lo[la], hi[la]):
                ax, ay, az, li = E[q, 0], E[q, 1], E[q, 2], ln[q]
                px, py, pz = M[q, 0], M[q, 1], M[q, 2]
                cq, iq, sq = cp[q], pos[q], size[q]
                s = 0.0
                gax = gay = gaz = gmx = gmy = gmz = 0.0
                r0 = q + 1 if la == lb else lo[lb]
                for r in range(r0, hi[lb]):
                    dx = px - M[r, 0]
                    dy = py - M[r, 1]
                    dz = pz - M[r, 2]
                    inv = 1.0 / (dx * dx + dy * dy + dz * dz)
                    bx, by, bz, lj = E[r, 0], E[r, 1], E[r, 2], ln[r]
                    if cp[r] == cq:
                        gap = pos[r] - iq
                        if gap < 0:
                            gap += sq
                        if gap <= 1 or gap == sq - 1:
                            continue  # the edge itself or a neighbour: not disjoint
                        ab = ax * bx + ay * by + az * bz
                        da = dx * ax + dy * ay + dz * az
                        db = dx * bx + dy * by + dz * bz
                        sv = (li * lj + ab) * inv
                        qq = da * db * inv * inv
                        f = sv - 2.0 * qq
                        s += f
                        b[0, r] += f
                        if grad:
                            tb = 2.0 * db * inv
                            ta = 2.0 * da * inv
                            ci = lj / li
                            cj = li / lj
                            gax += (ci * ax + bx - tb * dx) * inv
                            gay += (ci * ay + by - tb * dy) * inv
                            gaz += (ci * az + bz - tb * dz) * inv
                            b[1, r] += 2.0 * (cj * bx + ax - ta * dx) * inv
                            b[2, r] += 2.0 * (cj * by + ay - ta * dy) * inv
                            b[3, r] += 2.0 * (cj * bz + az - ta * dz) * inv
                            cd = 8.0 * qq - 2.0 * sv
                            fdx = (cd * dx - tb * ax - ta * bx) * inv
                            fdy = (cd * dy - tb * ay - ta * by) * inv
                            fdz = (cd * dz - tb * az - ta * bz) * inv
                            gmx += fdx
                            gmy += fdy
                            gmz += fdz
                            b[4, r] -= 2.0 * fdx
                            b[5, r] -= 2.0 * fdy
                            b[6, r] -= 2.0 * fdz
                    else:
                        f = li * lj * inv
                        s += f
                        b[0, r] += f
                        if grad:
                            ci = lj * inv / li
                            cj = li * inv / lj
                            gax += ci * ax
                            gay += ci * ay
                            gaz += ci * az
                            b[1, r] += 2.0 * cj * bx
                            b[2, r] += 2.0 * cj * by
                            b[3, r] += 2.0 * cj * bz
                            cd = -2.0 * f * inv
                            gmx += cd * dx
                            gmy += cd * dy
                            gmz += cd * dz
                            b[4, r] -= 2.0 * cd * dx
                            b[5, r] -= 2.0 * cd * dy
                            b[6, r] -= 2.0 * cd * dz
                b[0, q] += s
                if grad:
                    b[1, q] += 2.0 * gax
                    b[2, q] += 2.0 * gay
                    b[3, q] += 2.0 * gaz
                    b[4, q] += 2.0 * gmx
                    b[5, q] += 2.0 * gmy
                    b[6, q] += 2.0 * gmz
    out = buf[0].copy()
    for ch in range(1, nchunks):
        out += buf[ch]
    return out


@nb.njit(cache=True, parallel=True, fastmath=_FASTMATH)
def _far_to_edges(E, M, ln, lo, hi, leaves, acc, part):
    """Add what every edge receives from the far field (``acc`` of its leaf, see
    :func:`_push_down`) to its partial derivatives ``part`` (rows 1–3: edge vector, 4–6:
    midpoint)."""
    for kk in nb.prange(leaves.shape[0]):
        a = leaves[np.int64(kk)]
        t = acc[a]
        for q in range(lo[a], hi[a]):
            ax, ay, az, li = E[q, 0], E[q, 1], E[q, 2], ln[q]
            px, py, pz = M[q, 0], M[q, 1], M[q, 2]
            far_t = (t[3] + px * t[4] + py * t[5] + pz * t[6]) / li
            part[1, q] += t[0] + far_t * ax + t[7] * px + t[8] * py + t[9] * pz - t[16]
            part[2, q] += t[1] + far_t * ay + t[10] * px + t[11] * py + t[12] * pz - t[17]
            part[3, q] += t[2] + far_t * az + t[13] * px + t[14] * py + t[15] * pz - t[18]
            part[4, q] += li * t[4] + t[7] * ax + t[10] * ay + t[13] * az
            part[5, q] += li * t[5] + t[8] * ax + t[11] * ay + t[14] * az
            part[6, q] += li * t[6] + t[9] * ax + t[12] * ay + t[15] * az


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

    def _evaluate(self, X: np.ndarray, grad: bool):
        lay, tree = self.layout, self.tree
        E, M, ln, cp, pos, size = _edge_arrays(X, lay.nxt, lay.comp, lay.starts, tree.perm)
        L, C, S, D, nc = _cluster_data(E, M, ln, cp, tree.lo, tree.hi, tree.left, tree.right)
        eF, gL, gS, gC, gD = _far(L, C, S, D, nc, self.foff, self.fpart, grad)
        part = _near(E, M, ln, cp, pos, size, tree.lo, tree.hi, self.near, _CHUNKS, grad)
        energy = 4.0 * lay.k + float(np.sum(part[0])) + float(np.sum(eF))
        if not grad:
            return energy, None
        acc = _push_down(L, C, S, gL, gS, gC, gD, tree.left, tree.right)
        _far_to_edges(E, M, ln, tree.lo, tree.hi, self.leaves, acc, part)
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
