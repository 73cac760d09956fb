"""The arc-length part of the energy of open components on the tree engine (private).

On an open polyline the energy is O'Hara's ``Σ l_I l_J (1/|m_I − m_J|² − 1/D_IJ²)`` over ordered
pairs of disjoint edges (:mod:`.open_energy`, ``D`` the arc length between the midpoints). The
tree (:mod:`.barnes_hut`) sums its 3-D part ``l_I l_J / |m_I − m_J|²`` with the other kernels;
this module sums the 1-D part

    E₁ = Σ_{(I,J) ordered, |I − J| ≥ 2, one open component}  l_I l_J / D_IJ²

and its exact derivative in the edge lengths, the only thing it depends on. With the midpoints'
arc positions ``s`` and the one-sided sums

    R_p⁺(I) = Σ_{J ≥ I+2} l_J (s_J − s_I)^−p,    R_p⁻(I) = Σ_{J ≤ I−2} l_J (s_I − s_J)^−p

(p = 2, 3), ``E₁ = Σ_I l_I (R₂⁺ + R₂⁻)(I)`` and, as ``∂D_IJ/∂l_K`` is 1 for ``I < K < J`` and
½ for ``K = I, J``,

    ∂E₁/∂l_K = 2 (R₂⁺ + R₂⁻)(K) − 2 l_K (R₃⁺ + R₃⁻)(K) − 4 B(K),
    B(K) = Σ_{I < K < J} l_I l_J / D_IJ³,   B(K+1) = B(K) + l_K R₃⁺(K) − l_{K+1} R₃⁻(K+1).

The one-sided sums go by a 1-D hierarchy: for a target, the sources past it are taken in
aligned blocks of 2^k edges (the largest whose arc extent is at most ``ETA`` times its distance
from the target), a block by its moments ``Σ l δ^m`` (``δ`` from the block's middle) to order
``ORDER``, single edges exactly: O(n log n) per component. ``R⁻`` is ``R⁺`` of the reversed
component. Each target sums its own sources in a fixed order: the same bits for any thread
count.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ..geometry.layout import Layout

# A block is taken by its moments when its arc extent is at most ETA times the arc length from
# the target to its first edge; the expansion's ratio is then at most ETA / (2 + ETA) = 0.2, and
# ORDER terms leave a relative error below C(ORDER + 2, 2) 0.2^ORDER ≈ 4e-7 of the block's share
# (the tree's far field errs by about 1e-5 of the energy: this part adds nothing noticeable).
ETA = 0.25
ORDER = 20


def open_segments(layout: Layout) -> np.ndarray:
    """``(K_open, 2)`` first and one-past-last real edge of every open component (its edges
    ``a … b − 1``; the dummy edge ``b`` left out), empty for a layout of closed curves."""
    if not layout.has_open:
        return np.zeros((0, 2), np.int64)
    c = np.flatnonzero(~layout.closed)
    return np.stack([layout.starts[c], layout.starts[c + 1] - 1], axis=1).astype(np.int64)


@nb.njit(cache=True)
def _block_table(seg):
    """Blocks of levels k ≥ 1 of every segment: ``offsets[k, c]`` the index of block 0 of
    segment ``c`` at level ``k`` (−1 above the segment's top level), and per block its edge
    range ``lo``, ``hi`` (local to its segment)."""
    ns = seg.shape[0]
    top = 1
    for c in range(ns):
        n = seg[c, 1] - seg[c, 0]
        while (1 << top) < n:
            top += 1
    offsets = np.full((top + 1, ns), -1, np.int64)
    count = 0
    for k in range(1, top + 1):
        for c in range(ns):
            n = seg[c, 1] - seg[c, 0]
            if (1 << (k - 1)) < n:
                offsets[k, c] = count
                count += (n + (1 << k) - 1) >> k
    owner = np.empty(count, np.int64)
    lo = np.empty(count, np.int64)
    hi = np.empty(count, np.int64)
    for k in range(1, top + 1):
        for c in range(ns):
            if offsets[k, c] < 0:
                continue
            n = seg[c, 1] - seg[c, 0]
            nb_ = (n + (1 << k) - 1) >> k
            for b in range(nb_):
                t = offsets[k, c] + b
                owner[t] = c
                lo[t] = b << k
                hi[t] = min((b + 1) << k, n)
    return offsets, owner, lo, hi


@nb.njit(cache=True, parallel=True)
def _moments(s, w, seg, owner, lo, hi):
    """Per block ``Σ l δ^m`` for m < ORDER, ``δ = s − (s_first + s_last) / 2``."""
    nbk = owner.shape[0]
    mom = np.zeros((nbk, ORDER))
    for tt in nb.prange(nbk):
        t = np.int64(tt)
        a = seg[owner[t], 0]
        c = 0.5 * (s[a + lo[t]] + s[a + hi[t] - 1])
        for j in range(a + lo[t], a + hi[t]):
            d = s[j] - c
            p = w[j]
            for m in range(ORDER):
                mom[t, m] += p
                p *= d
    return mom


@nb.njit(cache=True, parallel=True)
def _one_sided(s, w, seg, offsets, mom):
    """``(R₂⁺, R₃⁺)`` of every edge of the segments (see the module docstring), by the aligned
    blocks of :func:`_block_table` and their moments."""
    n = s.shape[0]
    r2 = np.zeros(n)
    r3 = np.zeros(n)
    top = offsets.shape[0] - 1
    ns = seg.shape[0]
    for cc in nb.prange(ns):
        c = np.int64(cc)
        a = seg[c, 0]
        m = seg[c, 1] - a
        for i in range(m):
            si = s[a + i]
            t2 = 0.0
            t3 = 0.0
            j = i + 2
            while j < m:
                dist = s[a + j] - si
                k = 0
                while k < top and offsets[k + 1, c] >= 0 and (j >> (k + 1)) << (k + 1) == j:
                    h = min(j + (1 << (k + 1)), m)
                    if s[a + h - 1] - s[a + j] <= ETA * dist:
                        k += 1
                    else:
                        break
                if k == 0:
                    u = 1.0 / dist
                    u2 = u * u
                    t2 += w[a + j] * u2
                    t3 += w[a + j] * u2 * u
                    j += 1
                    continue
                h = min(j + (1 << k), m)
                u = 1.0 / (0.5 * (s[a + j] + s[a + h - 1]) - si)
                row = offsets[k, c] + (j >> k)
                # Σ_q l_q (x + δ_q)^−p = Σ_m C(m + p − 1, m) (−δ)^m x^(−p−m): Horner in −u
                acc2 = 0.0
                acc3 = 0.0
                for q in range(ORDER - 1, -1, -1):
                    acc2 = acc2 * -u + (q + 1) * mom[row, q]
                    acc3 = acc3 * -u + 0.5 * (q + 1) * (q + 2) * mom[row, q]
                u2 = u * u
                t2 += acc2 * u2
                t3 += acc3 * u2 * u
                j = h
            r2[a + i] = t2
            r3[a + i] = t3
    return r2, r3


@nb.njit(cache=True)
def _reverse(s, seg):
    """Per segment the reversed order (as a permutation) and ``−s`` in it (increasing again)."""
    n = s.shape[0]
    perm = np.arange(n)
    for c in range(seg.shape[0]):
        a, b = seg[c, 0], seg[c, 1]
        for i in range(a, b):
            perm[i] = a + b - 1 - i
    return perm, -s[perm]


@nb.njit(cache=True)
def _length_gradient(w, seg, r2f, r2b, r3f, r3b, out):
    """``∂E₁/∂l`` per edge of the segments into ``out`` (module docstring; B by its recurrence
    along each segment)."""
    for c in range(seg.shape[0]):
        a, b = seg[c, 0], seg[c, 1]
        bk = 0.0
        for k in range(a, b):
            if k > a:
                bk += w[k - 1] * r3f[k - 1] - w[k] * r3b[k]
            out[k] = 2.0 * (r2f[k] + r2b[k]) - 2.0 * w[k] * (r3f[k] + r3b[k]) - 4.0 * bk


# ------------------------------------------------------------------------------------------------
# the far field's arc-length terms beyond second order
#
# The tree expands the 3-D kernel ``l_I l_J/|d|²`` of a far pair of clusters to second order
# (:mod:`._far_field`), while E₁ is summed to ~1e-7: on an open polyline the two parts nearly
# cancel (exactly on a straight piece, where ``|d| = D``), so the 3-D truncation error alone
# would be amplified by the ratio of the 3-D sum to the energy (measured 1e-3 to 1e-2 relative
# errors on single cables of 500 to 2 000 edges). For a far pair of two arcs of one open
# component the terms of orders 3 to PAIR_ORDER of the same expansion in arc length,
#
#   C(A, B) = Σ_{n=3..P} (n+1) x^(−2−n) Σ_k C(n,k) (−1)^k M_k(B) M_(n−k)(A)
#
# (``x = σ_B − σ_A`` the arcs' length-weighted centres, ``M_m = Σ l (s − σ)^m``), are added
# back: on a straight piece they are the 3-D truncation error itself, so the pair's error is
# that of the 1-D series at order P. Pairs whose arcs are long against their distance
# (``span_A + span_B > PAIR_ETA |x|``) or clusters that are not one arc keep the second order.
PAIR_ORDER = 16
PAIR_ETA = 0.6


@nb.njit(cache=True)
def _node_arcs(perm, lo, hi, left, right, comp, open_comp):
    """Per node of the tree: its open component when its edges are one contiguous arc of one
    (else −1), and the arc's first and last edge."""
    m = lo.shape[0]
    arc = np.full(m, -1, np.int64)
    first = np.zeros(m, np.int64)
    last = np.zeros(m, np.int64)
    for node in range(m - 1, -1, -1):  # children come after their parents
        if left[node] < 0:
            c = comp[perm[lo[node]]]
            a = perm[lo[node]]
            b = a
            ok = open_comp[c]
            for q in range(lo[node], hi[node]):
                i = perm[q]
                if comp[i] != c:
                    ok = False
                a = min(a, i)
                b = max(b, i)
            if ok and b - a + 1 == hi[node] - lo[node]:
                arc[node] = c
                first[node] = a
                last[node] = b
        else:
            u, v = left[node], right[node]
            if arc[u] >= 0 and arc[u] == arc[v] and (last[u] + 1 == first[v]
                                                     or last[v] + 1 == first[u]):
                arc[node] = arc[u]
                first[node] = min(first[u], first[v])
                last[node] = max(last[u], last[v])
    return arc, first, last


@nb.njit(cache=True)
def _pair_lists(arc, first, last, s, ln, foff, fpart):
    """The ordered far pairs (CSR over targets) that take the arc terms: two arcs of one open
    component, short against the distance of their centres (at the frame's polygon)."""
    m = arc.shape[0]
    off = np.zeros(m + 1, np.int64)
    part = np.empty(fpart.shape[0], np.int64)
    cnt = 0
    for a in range(m):
        if arc[a] >= 0:
            sa = (s[first[a]] - 0.5 * ln[first[a]], s[last[a]] + 0.5 * ln[last[a]])
            ca = 0.5 * (sa[0] + sa[1])
            for p in range(foff[a], foff[a + 1]):
                b = fpart[p]
                if arc[b] != arc[a]:
                    continue
                sb0 = s[first[b]] - 0.5 * ln[first[b]]
                sb1 = s[last[b]] + 0.5 * ln[last[b]]
                span = (sa[1] - sa[0]) + (sb1 - sb0)
                if span <= PAIR_ETA * abs(0.5 * (sb0 + sb1) - ca):
                    part[cnt] = b
                    cnt += 1
        off[a + 1] = cnt
    return off, part[:cnt].copy()


@nb.njit(cache=True, parallel=True)
def _arc_moments(used, first, last, s, ln):
    """Per used node ``(L, σ)`` and ``M_m = Σ l (s − σ)^m``, m ≤ PAIR_ORDER."""
    m = used.shape[0]
    mom = np.zeros((m, PAIR_ORDER + 1))
    sig = np.zeros(m)
    for nn in nb.prange(m):
        node = np.int64(nn)
        if not used[node]:
            continue
        tot = 0.0
        acc = 0.0
        for i in range(first[node], last[node] + 1):
            tot += ln[i]
            acc += ln[i] * s[i]
        c = acc / tot
        sig[node] = c
        for i in range(first[node], last[node] + 1):
            d = s[i] - c
            p = ln[i]
            for k in range(PAIR_ORDER + 1):
                mom[node, k] += p
                p *= d
    return sig, mom


@nb.njit(cache=True)
def _binomials():
    B = np.zeros((PAIR_ORDER + 1, PAIR_ORDER + 1))
    for n in range(PAIR_ORDER + 1):
        B[n, 0] = 1.0
        for k in range(1, n + 1):
            B[n, k] = B[n - 1, k - 1] + (B[n - 1, k] if k < n else 0.0)
    return B


@nb.njit(cache=True, parallel=True)
def _pair_terms(sig, mom, off, part, grad):
    """Per target node ``Σ_B C(A, B)`` and, with ``grad``, twice its derivatives in the
    target's moments ``M_m`` (at fixed σ) and in ``σ_A`` (explicit, through ``x``)."""
    m = sig.shape[0]
    e = np.zeros(m)
    gm = np.zeros((m if grad else 0, PAIR_ORDER + 1))
    gs = np.zeros(m if grad else 0)
    B = _binomials()
    for aa in nb.prange(m):
        a = np.int64(aa)
        if off[a] == off[a + 1]:
            continue
        tot = 0.0
        for p in range(off[a], off[a + 1]):
            b = part[p]
            x = sig[b] - sig[a]
            ix = 1.0 / x
            w = ix * ix * ix * ix * ix  # x^(−2−n) at n = 3
            for n in range(3, PAIR_ORDER + 1):
                sn = 0.0
                sgn = 1.0
                for k in range(n + 1):
                    sn += B[n, k] * sgn * mom[b, k] * mom[a, n - k]
                    if grad:
                        gm[a, n - k] += 2.0 * (n + 1) * w * B[n, k] * sgn * mom[b, k]
                    sgn = -sgn
                tot += (n + 1) * w * sn
                if grad:  # ∂/∂σ_A = −∂/∂x
                    gs[a] += 2.0 * (n + 1) * (n + 2) * w * ix * sn
                w *= ix
        e[a] = tot
    return e, gm, gs


@nb.njit(cache=True, parallel=True)
def _pair_to_edges(parent, leaves, lo, hi, perm, has, first, last, sig, mom, gm, gs, s, ln,
                   gl, gsa):
    """What every edge's length and arc position receive from the arc terms of its ancestors
    (the chain rule through ``M_m = Σ l (s − σ)^m`` and ``σ = Σ l s / L``)."""
    for kk in nb.prange(leaves.shape[0]):
        leaf = leaves[np.int64(kk)]
        for q in range(lo[leaf], hi[leaf]):
            i = perm[q]
            node = leaf
            while node >= 0:
                if has[node]:
                    c = sig[node]
                    tot = 0.0
                    for j in range(first[node], last[node] + 1):
                        tot += ln[j]
                    g = gs[node]  # σ's total coefficient: explicit and through the M_m
                    for k in range(1, PAIR_ORDER + 1):
                        g -= gm[node, k] * k * mom[node, k - 1]
                    d = s[i] - c
                    al = 0.0  # Σ gM_m d^m and Σ gM_m m d^(m−1)
                    ds = 0.0
                    p = 1.0
                    for k in range(PAIR_ORDER + 1):
                        if k + 1 <= PAIR_ORDER:
                            ds += gm[node, k + 1] * (k + 1) * p
                        al += gm[node, k] * p
                        p *= d
                    gl[i] += al + g * d / tot
                    gsa[i] += ln[i] * ds + g * ln[i] / tot
                node = parent[node]


@nb.njit(cache=True)
def _positions_to_lengths(seg, gsa, gl):
    """``s_I = Σ_{K<I} l_K + l_I/2``: ``∂/∂l_K += Σ_{I>K} ∂/∂s_I + ½ ∂/∂s_K`` per segment."""
    for c in range(seg.shape[0]):
        a, b = seg[c, 0], seg[c, 1]
        tail = 0.0
        for k in range(b - 1, a - 1, -1):
            gl[k] += tail + 0.5 * gsa[k]
            tail += gsa[k]


class ArcField:
    """The 1-D part ``E₁`` of a layout's open components and the far field's arc terms (module
    docstring) for a tree ``tree`` with ordered far pairs ``(foff, fpart)``, chosen at ``X``."""

    def __init__(self, layout: Layout, X: np.ndarray, tree, foff, fpart):
        self.layout = layout
        self.seg = open_segments(layout)
        self.offsets, owner, lo, hi = _block_table(self.seg)
        self._blocks = (owner, lo, hi)
        self.tree = tree
        open_comp = np.zeros(layout.k, bool)
        open_comp[~layout.closed] = True
        self._arc, self._first, self._last = _node_arcs(
            tree.perm, tree.lo, tree.hi, tree.left, tree.right, layout.comp, open_comp)
        ln, s = self._lengths(X)
        self.off, self.part = _pair_lists(self._arc, self._first, self._last, s, ln, foff,
                                          fpart)
        #: Ordered far pairs that take the arc terms.
        self.pairs = int(self.part.shape[0])
        self._has = np.diff(self.off) > 0
        self._used = self._has.copy()
        self._used[self.part] = True
        m = tree.size
        parent = np.full(m, -1, np.int64)
        inner = np.flatnonzero(tree.left >= 0)
        parent[tree.left[inner]] = inner
        parent[tree.right[inner]] = inner
        self._parent = parent
        self._leaves = np.flatnonzero(tree.left < 0).astype(np.int64)

    def _lengths(self, X: np.ndarray):
        lay = self.layout
        E = X[lay.nxt] - X
        ln = np.sqrt(np.einsum("ij,ij->i", E, E))
        ln[~lay.real] = 0.0
        s = np.zeros_like(ln)
        for a, b in self.seg:  # midpoints' arc positions from each component's first vertex
            s[a:b] = np.cumsum(ln[a:b]) - 0.5 * ln[a:b]
        return ln, s

    def _sums(self, ln: np.ndarray, s: np.ndarray):
        seg = self.seg
        r2f, r3f = _one_sided(s, ln, seg, self.offsets, _moments(s, ln, seg, *self._blocks))
        perm, sr = _reverse(s, seg)
        wr = ln[perm]
        r2b, r3b = _one_sided(sr, wr, seg, self.offsets, _moments(sr, wr, seg, *self._blocks))
        return r2f, r3f, r2b[perm], r3b[perm]  # perm is its own inverse

    def energy_gradient(self, X: np.ndarray, grad: bool) -> tuple[float, np.ndarray | None]:
        """What the open components add to the tree's 3-D sum at ``X``: ``C − E₁`` (the far
        pairs' arc terms ``C``, module docstring) and, with ``grad``, its gradient ``(N, 3)``
        (else None)."""
        lay, tree = self.layout, self.tree
        ln, s = self._lengths(X)
        r2f, r3f, r2b, r3b = self._sums(ln, s)
        sig, mom = _arc_moments(self._used, self._first, self._last, s, ln)
        ec, gm, gs = _pair_terms(sig, mom, self.off, self.part, grad)
        energy = float(np.sum(ec)) - float(np.dot(ln, r2f + r2b))
        if not grad:
            return energy, None
        gl = np.zeros_like(ln)
        _length_gradient(ln, self.seg, r2f, r2b, r3f, r3b, gl)
        gl = -gl
        gsa = np.zeros_like(ln)
        _pair_to_edges(self._parent, self._leaves, tree.lo, tree.hi, tree.perm, self._has,
                       self._first, self._last, sig, mom, gm, gs, s, ln, gl, gsa)
        _positions_to_lengths(self.seg, gsa, gl)
        real = np.flatnonzero(lay.real)
        E = X[lay.nxt[real]] - X[real]
        T = np.zeros_like(X)
        T[real] = (gl[real] / ln[real])[:, None] * E  # ∂l/∂e = e/l
        G = -T
        G[lay.nxt[real]] += T[real]
        return energy, G
