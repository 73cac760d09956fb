"""The far field of the tree engine: cluster moments, the expansion of the kernel between two
clusters, and its derivative pushed down to the edges (private; :mod:`barnes_hut` splits the
pairs and sums the near field).

The pair sum ``Σ_IJ l_I l_J k + e_Iᵀ H e_J`` of two clusters ``(A, B)`` (``k = 1/|d|²``,
``H = ∇² log|d|``) is replaced by its Taylor expansion to second order in the offsets
``δ_I = m_I − c`` from the clusters' length-weighted centres, ``d = c_A − c_B``, written with
the clusters' moments: total length ``L``, summed edge vector ``S``, tangent dipole
``D = Σ e δᵀ``, length quadrupole ``Q = Σ l δ δᵀ`` and tangent quadrupole ``T = Σ e ⊗ δ ⊗ δ``:

    F(A, B) = L_A L_B k + ½ ∇²k : (L_B Q_A + L_A Q_B) + S_Aᵀ H S_B + T(D_A, S_B) − T(D_B, S_A)
              + ½ K4 : (T_A ⊗ S_B) − K4 : (D_A ⊗ D_B) + ½ K4 : (S_A ⊗ T_B)

with ``T`` the first-order term (:func:`_dipole`) and ``K4 = ∇⁴ log|d|`` contracted through
traces and projections of the moments (:func:`_quadrupole`, :func:`_dipole_pair`); between
components the length part ``L_A L_B k + ½ ∇²k : (…)`` alone, the O'Hara kernel. Both parts
to the same order: for two pieces of one straight line they cancel (the exact F is 0), and
expanding the length part alone further measured larger errors. The zeroth order
``L_A L_B k + S_Aᵀ H S_B`` is the energy's pair kernel itself (:func:`.energies.moebius.pair`
with the clusters' ``L`` and ``S``); the higher orders are this module's.

Each target cluster sums its own partners (:func:`_far`), so the sums are the same bits for
any thread count. The partners are taken eight at a time, one per SIMD lane: a block of
partners is staged in one work array, the lanes' sums are kept apart and added in lane order
at the end (no fast-math: with it the code compiled in a first process and the code numba's
cache gave later ones differed in the last bits, c2e95fb).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ..energies.moebius import SPLIT, pair

# Targets of the far field per parallel piece: m / _FAR_CHUNKS (each target's sums are its own,
# so any split gives the same bits; a piece reuses one work array).
_FAR_CHUNKS = 256
# Levels of the hierarchy with fewer nodes than this are walked by one thread (a parallel loop
# costs more than their work).
_PARALLEL_LEVEL = 256


# ------------------------------------------------------------------------------------------------
# cluster moments


@nb.njit(cache=True)
def _levels(left, right):
    """The nodes by depth: ``(order, offsets)``, the nodes of depth ``d`` being
    ``order[offsets[d]:offsets[d + 1]]`` (in index order; a parent comes before its children)."""
    m = left.shape[0]
    depth = np.zeros(m, np.int64)
    for node in range(m):
        if left[node] >= 0:
            depth[left[node]] = depth[node] + 1
            depth[right[node]] = depth[node] + 1
    nd = depth.max() + 1 if m > 0 else 0
    offsets = np.zeros(nd + 1, np.int64)
    for node in range(m):
        offsets[depth[node] + 1] += 1
    for d in range(nd):
        offsets[d + 1] += offsets[d]
    fill = offsets[:nd].copy()
    order = np.empty(m, np.int64)
    for node in range(m):
        order[fill[depth[node]]] = node
        fill[depth[node]] += 1
    return order, offsets


@nb.njit(cache=True, parallel=True)
def _cluster_data(E, M, ln, cp, lo, hi, left, right):
    """Per node, bottom-up: total length ``L``, length-weighted centre ``c``, summed edge vector
    ``S``, tangent dipole ``D = Σ e_I δ_Iᵀ``, length quadrupole ``Q = Σ l_I δ_I δ_Iᵀ``, tangent
    quadrupole ``T_acd = Σ e_I,a δ_I,c δ_I,d`` (``δ_I = m_I − c``) and the node's kind
    (:func:`_kind`: its component; −1 for a node of several components, −2 of several open
    ones). A parent takes its children's moments
    moved to its centre (``δ = δ_child + h``, ``h = c_child − c``; ``Σ l δ_child = 0``). One
    depth at a time from the deepest, its nodes in parallel (each writes its own row)."""
    m = lo.shape[0]
    L = np.empty(m)
    C = np.empty((m, 3))
    S = np.empty((m, 3))
    D = np.zeros((m, 3, 3))
    Q = np.zeros((m, 3, 3))
    T = np.zeros((m, 3, 3, 3))
    nc = np.empty(m, np.int64)
    order, offsets = _levels(left, right)
    for d in range(offsets.shape[0] - 2, -1, -1):
        if offsets[d + 1] - offsets[d] >= _PARALLEL_LEVEL:
            for t in nb.prange(offsets[d], offsets[d + 1]):
                _node_moments(order[t], E, M, ln, cp, lo, hi, left, right, L, C, S, D, Q, T, nc)
        else:
            for t in range(offsets[d], offsets[d + 1]):
                _node_moments(order[t], E, M, ln, cp, lo, hi, left, right, L, C, S, D, Q, T, nc)
    return L, C, S, D, Q, T, nc


@nb.njit(cache=True, inline="always")
def _node_moments(node, E, M, ln, cp, lo, hi, left, right, L, C, S, D, Q, T, nc):
    if left[node] < 0:
        _leaf_moments(E, M, ln, cp, lo[node], hi[node], node, L, C, S, D, Q, T, nc)
    else:
        _parent_moments(left[node], right[node], node, L, C, S, D, Q, T, nc)


@nb.njit(cache=True, inline="always")
def _kind(a, b):
    """The kind of a node of edges of kinds ``a`` and ``b``: a component ``c ≥ 0`` (closed)
    or ``≤ −3`` (open, :data:`.barnes_hut.OPEN_KIND` − c) when one, −2 for several open
    components, −1 for any other mixture."""
    if a == b:
        return a
    if a <= -2 and b <= -2:
        return -2
    return -1


@nb.njit(cache=True, inline="always")
def _leaf_moments(E, M, ln, cp, q0, q1, node, L, C, S, D, Q, T, nc):
    """A leaf's moments from its edges ``q0 ≤ q < q1`` (see :func:`_cluster_data`)."""
    tot = 0.0
    cx = cy = cz = sx = sy = sz = 0.0
    c0 = cp[q0]
    for q in range(q0, q1):
        w = ln[q]
        tot += w
        cx += w * M[q, 0]
        cy += w * M[q, 1]
        cz += w * M[q, 2]
        sx += E[q, 0]
        sy += E[q, 1]
        sz += E[q, 2]
        c0 = _kind(c0, cp[q])
    L[node] = tot
    C[node, 0] = cx / tot
    C[node, 1] = cy / tot
    C[node, 2] = cz / tot
    S[node, 0] = sx
    S[node, 1] = sy
    S[node, 2] = sz
    nc[node] = c0
    for q in range(q0, q1):
        d0 = M[q, 0] - C[node, 0]
        d1 = M[q, 1] - C[node, 1]
        d2 = M[q, 2] - C[node, 2]
        for a in range(3):
            for b in range(3):
                db = d0 if b == 0 else (d1 if b == 1 else d2)
                da = d0 if a == 0 else (d1 if a == 1 else d2)
                D[node, a, b] += E[q, a] * db
                Q[node, a, b] += ln[q] * da * db
                for c in range(3):
                    dc = d0 if c == 0 else (d1 if c == 1 else d2)
                    T[node, a, b, c] += E[q, a] * db * dc


@nb.njit(cache=True, inline="always")
def _parent_moments(a0, b0, node, L, C, S, D, Q, T, nc):
    """A parent's moments from its children's (see :func:`_cluster_data`)."""
    tot = L[a0] + L[b0]
    L[node] = tot
    for k in range(3):
        C[node, k] = (L[a0] * C[a0, k] + L[b0] * C[b0, k]) / tot
        S[node, k] = S[a0, k] + S[b0, k]
    for ch in (a0, b0):
        h0 = C[ch, 0] - C[node, 0]
        h1 = C[ch, 1] - C[node, 1]
        h2 = C[ch, 2] - C[node, 2]
        for a in range(3):
            for b in range(3):
                hb = h0 if b == 0 else (h1 if b == 1 else h2)
                ha = h0 if a == 0 else (h1 if a == 1 else h2)
                D[node, a, b] += D[ch, a, b] + S[ch, a] * hb
                Q[node, a, b] += Q[ch, a, b] + L[ch] * ha * hb
                for c in range(3):
                    hc = h0 if c == 0 else (h1 if c == 1 else h2)
                    T[node, a, b, c] += (T[ch, a, b, c] + D[ch, a, b] * hc + D[ch, a, c] * hb
                                         + S[ch, a] * hb * hc)
    nc[node] = _kind(nc[a0], nc[b0])


# ------------------------------------------------------------------------------------------------
# the expansion of one pair, written for SIMD lanes


# Partners per block, one per lane. One work array ``W`` per parallel piece holds a block's
# partners, moment k of lane j at ``W[_W_STAGE + _LANES k + j]``, and the lanes' partial sums,
# sum k of lane j at ``W[_W_SUMS + _LANES k + j]``: every access in the loop over lanes is a
# constant offset plus j in one array, so LLVM vectorizes it (with separate arrays it could
# not prove the rows independent, and scratch arrays inside the loop kept it scalar).
_LANES = 8
# moments of a node (a row of :func:`_moment_rows`; staged: x = c_A − c_B in place of c): centre,
# L, S, D (row-major), Q (row-major), T (row-major)
_MC, _ML, _MS, _MD, _MQ, _MT = 0, 3, 4, 7, 16, 25
_NMOM = 52
# partial sums: energy, ∂/∂L, ∂/∂S, ∂/∂c, ∂/∂D, the length part's Σ L_B x xᵀ/|x|⁶ (6
# entries, i ≤ j) and Σ L_B/|x|⁴, and the quadrupole's α (3) and σ x x (18: a, then c ≤ d)
_AE, _AL, _AS, _AC, _AD, _AQ, _AQL, _AAL, _ABE = 0, 1, 2, 5, 8, 17, 23, 24, 27
_NSUM = 45
_W_STAGE = 0
_W_SUMS = _LANES * _NMOM
_W_SIZE = _W_SUMS + _LANES * _NSUM
_UPPER = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))


@nb.njit(cache=True, inline="always")
def _dipole(X, s0, s1, s2, d0, d1, d2, inv):
    """First-order tangent term ``T(X, s) = Σ_abc ∂_c H_ab(d) X_ac s_b`` of the expansion of
    ``Σ e_Iᵀ H(m_I − m_J) e_J`` (``H = ∇² log|d|``, the tangent kernel of the energy) around
    the clusters' centres (``X`` a 9-tuple, row-major; ``inv = 1/|d|²``). Returns ``T`` and
    its derivatives in ``s`` (3), ``X`` (9) and ``d`` (3), one tuple."""
    x00, x01, x02, x10, x11, x12, x20, x21, x22 = X
    w4 = inv * inv
    w6 = w4 * inv
    xd0 = x00 * d0 + x01 * d1 + x02 * d2
    xd1 = x10 * d0 + x11 * d1 + x12 * d2
    xd2 = x20 * d0 + x21 * d1 + x22 * d2
    xt0 = x00 * d0 + x10 * d1 + x20 * d2
    xt1 = x01 * d0 + x11 * d1 + x21 * d2
    xt2 = x02 * d0 + x12 * d1 + x22 * d2
    tr = x00 + x11 + x22
    ds = d0 * s0 + d1 * s1 + d2 * s2
    dxd = d0 * xd0 + d1 * xd1 + d2 * xd2
    bb = s0 * (xd0 + xt0) + s1 * (xd1 + xt1) + s2 * (xd2 + xt2) + tr * ds
    t = -2.0 * w4 * bb + 8.0 * w6 * dxd * ds
    a4 = -2.0 * w4
    a6 = 8.0 * w6
    gs0 = a4 * (xd0 + xt0 + tr * d0) + a6 * dxd * d0
    gs1 = a4 * (xd1 + xt1 + tr * d1) + a6 * dxd * d1
    gs2 = a4 * (xd2 + xt2 + tr * d2) + a6 * dxd * d2
    e = a6 * ds
    g00 = a4 * (2.0 * s0 * d0 + ds) + e * d0 * d0
    g01 = a4 * (s0 * d1 + d0 * s1) + e * d0 * d1
    g02 = a4 * (s0 * d2 + d0 * s2) + e * d0 * d2
    g10 = a4 * (s1 * d0 + d1 * s0) + e * d1 * d0
    g11 = a4 * (2.0 * s1 * d1 + ds) + e * d1 * d1
    g12 = a4 * (s1 * d2 + d1 * s2) + e * d1 * d2
    g20 = a4 * (s2 * d0 + d2 * s0) + e * d2 * d0
    g21 = a4 * (s2 * d1 + d2 * s1) + e * d2 * d1
    g22 = a4 * (2.0 * s2 * d2 + ds) + e * d2 * d2
    xs0 = x00 * s0 + x01 * s1 + x02 * s2
    xs1 = x10 * s0 + x11 * s1 + x12 * s2
    xs2 = x20 * s0 + x21 * s1 + x22 * s2
    ts0 = x00 * s0 + x10 * s1 + x20 * s2
    ts1 = x01 * s0 + x11 * s1 + x21 * s2
    ts2 = x02 * s0 + x12 * s1 + x22 * s2
    c1 = 8.0 * w6 * bb - 48.0 * w6 * inv * dxd * ds
    gd0 = c1 * d0 + a4 * (ts0 + tr * s0 + xs0) + a6 * ((xd0 + xt0) * ds + dxd * s0)
    gd1 = c1 * d1 + a4 * (ts1 + tr * s1 + xs1) + a6 * ((xd1 + xt1) * ds + dxd * s1)
    gd2 = c1 * d2 + a4 * (ts2 + tr * s2 + xs2) + a6 * ((xd2 + xt2) * ds + dxd * s2)
    return (t, gs0, gs1, gs2, g00, g01, g02, g10, g11, g12, g20, g21, g22, gd0, gd1, gd2)


@nb.njit(cache=True, inline="always")
def _t3(T, a, c, y0, y1, y2):
    """``Σ_d T_acd y_d`` (``T`` a 27-tuple, row-major; ``a``, ``c`` constants)."""
    b = 9 * a + 3 * c
    return T[b] * y0 + T[b + 1] * y1 + T[b + 2] * y2


@nb.njit(cache=True, inline="always")
def _quadrupole(T, s0, s1, s2, x0, x1, x2, w):
    """Second-order tangent term ``K4 : (T ⊗ s) = Σ_abcd K4_abcd T_acd s_b`` (``K4 = ∇⁴ log|x|``,
    ``T`` a 27-tuple symmetric in ``c, d``), contracted through the traces and projections of
    ``T`` (``K4 = −2w²(δδ)₃ + 8w³(δxx)₆ − 48w⁴ xxxx``, ``w = 1/|x|²``). Returns its value, its
    derivatives in ``s`` (3) and in ``x`` (3) and the derivative in ``T``,
    ``δ_cd α_a + δ_ac α_d + δ_ad α_c + β_acd + β_cad + β_dac`` with ``α = −2w² s + 8w³<x,s> x``
    and ``β = σ ⊗ x ⊗ x``, ``σ = 8w³ s − 16w⁴<x,s> x``, as ``α`` (3) and ``σ`` (3); one tuple
    (value, ∂s, α, σ, ∂x)."""
    w2 = w * w
    w3 = w2 * w
    w4 = w3 * w
    v00 = T[0] + T[4] + T[8]  # T(a, ·, ·) traced
    v01 = T[9] + T[13] + T[17]
    v02 = T[18] + T[22] + T[26]
    v10 = T[0] + T[12] + T[24]  # T(·, ·, a) traced
    v11 = T[1] + T[13] + T[25]
    v12 = T[2] + T[14] + T[26]
    t00 = _t3(T, 0, 0, x0, x1, x2)
    t01 = _t3(T, 0, 1, x0, x1, x2)
    t02 = _t3(T, 0, 2, x0, x1, x2)
    t10 = _t3(T, 1, 0, x0, x1, x2)
    t11 = _t3(T, 1, 1, x0, x1, x2)
    t12 = _t3(T, 1, 2, x0, x1, x2)
    t20 = _t3(T, 2, 0, x0, x1, x2)
    t21 = _t3(T, 2, 1, x0, x1, x2)
    t22 = _t3(T, 2, 2, x0, x1, x2)
    v20 = t00 * x0 + t01 * x1 + t02 * x2  # T(·, x, x)
    v21 = t10 * x0 + t11 * x1 + t12 * x2
    v22 = t20 * x0 + t21 * x1 + t22 * x2
    v30 = x0 * t00 + x1 * t10 + x2 * t20  # T(x, ·, x)
    v31 = x0 * t01 + x1 * t11 + x2 * t21
    v32 = x0 * t02 + x1 * t12 + x2 * t22
    xs = x0 * s0 + x1 * s1 + x2 * s2
    u0 = v00 + 2.0 * v10
    u1 = v01 + 2.0 * v11
    u2 = v02 + 2.0 * v12
    y0 = v20 + 2.0 * v30
    y1 = v21 + 2.0 * v31
    y2 = v22 + 2.0 * v32
    st = s0 * u0 + s1 * u1 + s2 * u2
    sq = s0 * y0 + s1 * y1 + s2 * y2
    lin = x0 * u0 + x1 * u1 + x2 * u2
    txxx = x0 * v20 + x1 * v21 + x2 * v22
    inner = sq + xs * lin
    val = -2.0 * w2 * st + 8.0 * w3 * inner - 48.0 * w4 * xs * txxx
    gs0 = -2.0 * w2 * u0 + 8.0 * w3 * (y0 + x0 * lin) - 48.0 * w4 * x0 * txxx
    gs1 = -2.0 * w2 * u1 + 8.0 * w3 * (y1 + x1 * lin) - 48.0 * w4 * x1 * txxx
    gs2 = -2.0 * w2 * u2 + 8.0 * w3 * (y2 + x2 * lin) - 48.0 * w4 * x2 * txxx
    al0 = 8.0 * w3 * xs * x0 - 2.0 * w2 * s0
    al1 = 8.0 * w3 * xs * x1 - 2.0 * w2 * s1
    al2 = 8.0 * w3 * xs * x2 - 2.0 * w2 * s2
    sg0 = 8.0 * w3 * s0 - 16.0 * w4 * xs * x0
    sg1 = 8.0 * w3 * s1 - 16.0 * w4 * xs * x1
    sg2 = 8.0 * w3 * s2 - 16.0 * w4 * xs * x2
    # p_k = Σ_a s_a (T x)_ak, q_k = Σ_a (T x)_ka s_a, r_k = Σ_a x_a Σ_d T_akd s_d
    p0 = s0 * t00 + s1 * t10 + s2 * t20
    p1 = s0 * t01 + s1 * t11 + s2 * t21
    p2 = s0 * t02 + s1 * t12 + s2 * t22
    q0 = t00 * s0 + t01 * s1 + t02 * s2
    q1 = t10 * s0 + t11 * s1 + t12 * s2
    q2 = t20 * s0 + t21 * s1 + t22 * s2
    r0 = (x0 * _t3(T, 0, 0, s0, s1, s2) + x1 * _t3(T, 1, 0, s0, s1, s2)
          + x2 * _t3(T, 2, 0, s0, s1, s2))
    r1 = (x0 * _t3(T, 0, 1, s0, s1, s2) + x1 * _t3(T, 1, 1, s0, s1, s2)
          + x2 * _t3(T, 2, 1, s0, s1, s2))
    r2 = (x0 * _t3(T, 0, 2, s0, s1, s2) + x1 * _t3(T, 1, 2, s0, s1, s2)
          + x2 * _t3(T, 2, 2, s0, s1, s2))
    k5 = 384.0 * w4 * w * xs * txxx
    gx0 = (8.0 * w3 * (st * x0 + 2.0 * (p0 + q0 + r0) + s0 * lin + xs * u0)
           - 48.0 * w4 * (x0 * inner + s0 * txxx + xs * y0) + k5 * x0)
    gx1 = (8.0 * w3 * (st * x1 + 2.0 * (p1 + q1 + r1) + s1 * lin + xs * u1)
           - 48.0 * w4 * (x1 * inner + s1 * txxx + xs * y1) + k5 * x1)
    gx2 = (8.0 * w3 * (st * x2 + 2.0 * (p2 + q2 + r2) + s2 * lin + xs * u2)
           - 48.0 * w4 * (x2 * inner + s2 * txxx + xs * y2) + k5 * x2)
    return (val, gs0, gs1, gs2, al0, al1, al2, sg0, sg1, sg2, gx0, gx1, gx2)


@nb.njit(cache=True, inline="always")
def _dipole_pair(P, R, x0, x1, x2, w):
    """Second-order tangent term of two dipoles ``K4 : (P ⊗ R) = Σ_abcd K4_abcd P_ac R_bd``
    (9-tuples, row-major). Returns its value and its derivatives in ``P`` (9) and ``x`` (3),
    one tuple."""
    w2 = w * w
    w3 = w2 * w
    w4 = w3 * w
    trp = P[0] + P[4] + P[8]
    trr = R[0] + R[4] + R[8]
    # P + Pᵀ and R + Rᵀ
    p00 = 2.0 * P[0]
    p11 = 2.0 * P[4]
    p22 = 2.0 * P[8]
    p01 = P[1] + P[3]
    p02 = P[2] + P[6]
    p12 = P[5] + P[7]
    r00 = 2.0 * R[0]
    r11 = 2.0 * R[4]
    r22 = 2.0 * R[8]
    r01 = R[1] + R[3]
    r02 = R[2] + R[6]
    r12 = R[5] + R[7]
    pr = (P[0] * r00 + P[1] * r01 + P[2] * r02 + P[3] * r01 + P[4] * r11 + P[5] * r12
          + P[6] * r02 + P[7] * r12 + P[8] * r22)
    v00 = p00 * x0 + p01 * x1 + p02 * x2  # (P + Pᵀ) x
    v01 = p01 * x0 + p11 * x1 + p12 * x2
    v02 = p02 * x0 + p12 * x1 + p22 * x2
    v10 = r00 * x0 + r01 * x1 + r02 * x2  # (R + Rᵀ) x
    v11 = r01 * x0 + r11 * x1 + r12 * x2
    v12 = r02 * x0 + r12 * x1 + r22 * x2
    xpx = 0.5 * (x0 * v00 + x1 * v01 + x2 * v02)
    xrx = 0.5 * (x0 * v10 + x1 * v11 + x2 * v12)
    pp = v00 * v10 + v01 * v11 + v02 * v12
    zero = pr + trp * trr
    two = pp + trp * xrx + trr * xpx
    val = -2.0 * w2 * zero + 8.0 * w3 * two - 48.0 * w4 * xpx * xrx
    dg = 8.0 * w3 * xrx - 2.0 * w2 * trr
    c3 = 8.0 * w3
    c4 = 48.0 * w4 * xrx
    g00 = -2.0 * w2 * r00 + c3 * (2.0 * v10 * x0 + trr * x0 * x0) - c4 * x0 * x0 + dg
    g01 = -2.0 * w2 * r01 + c3 * (v10 * x1 + x0 * v11 + trr * x0 * x1) - c4 * x0 * x1
    g02 = -2.0 * w2 * r02 + c3 * (v10 * x2 + x0 * v12 + trr * x0 * x2) - c4 * x0 * x2
    g10 = -2.0 * w2 * r01 + c3 * (v11 * x0 + x1 * v10 + trr * x1 * x0) - c4 * x1 * x0
    g11 = -2.0 * w2 * r11 + c3 * (2.0 * v11 * x1 + trr * x1 * x1) - c4 * x1 * x1 + dg
    g12 = -2.0 * w2 * r12 + c3 * (v11 * x2 + x1 * v12 + trr * x1 * x2) - c4 * x1 * x2
    g20 = -2.0 * w2 * r02 + c3 * (v12 * x0 + x2 * v10 + trr * x2 * x0) - c4 * x2 * x0
    g21 = -2.0 * w2 * r12 + c3 * (v12 * x1 + x2 * v11 + trr * x2 * x1) - c4 * x2 * x1
    g22 = -2.0 * w2 * r22 + c3 * (2.0 * v12 * x2 + trr * x2 * x2) - c4 * x2 * x2 + dg
    a0 = p00 * v10 + p01 * v11 + p02 * v12 + r00 * v00 + r01 * v01 + r02 * v02
    a1 = p01 * v10 + p11 * v11 + p12 * v12 + r01 * v00 + r11 * v01 + r12 * v02
    a2 = p02 * v10 + p12 * v11 + p22 * v12 + r02 * v00 + r12 * v01 + r22 * v02
    k5 = 384.0 * w4 * w * xpx * xrx
    gx0 = (8.0 * w3 * (zero * x0 + a0 + trp * v10 + trr * v00)
           - 48.0 * w4 * (two * x0 + xrx * v00 + xpx * v10) + k5 * x0)
    gx1 = (8.0 * w3 * (zero * x1 + a1 + trp * v11 + trr * v01)
           - 48.0 * w4 * (two * x1 + xrx * v01 + xpx * v11) + k5 * x1)
    gx2 = (8.0 * w3 * (zero * x2 + a2 + trp * v12 + trr * v02)
           - 48.0 * w4 * (two * x2 + xrx * v02 + xpx * v12) + k5 * x2)
    return (val, g00, g01, g02, g10, g11, g12, g20, g21, g22, gx0, gx1, gx2)


@nb.njit(cache=True, inline="always")
def _lane9(W, b):
    """A staged 3 × 3 moment of one lane (first entry at ``W[b]``) as a 9-tuple."""
    return (W[b], W[b + _LANES], W[b + 2 * _LANES], W[b + 3 * _LANES], W[b + 4 * _LANES],
            W[b + 5 * _LANES], W[b + 6 * _LANES], W[b + 7 * _LANES], W[b + 8 * _LANES])


@nb.njit(cache=True, inline="always")
def _far_lanes(W, grad, La, sa0, sa1, sa2, Da, Qa, Ta):
    """Every lane's pair, the target (moments given: ``Da``, ``Qa`` 9-tuples, ``Ta`` a
    27-tuple) against the partner staged in the lane, added to the lane's partial sums: the
    value of ``F`` and, with ``grad``, its derivatives in the target's moments (``∂/∂Q`` and
    ``∂/∂T`` through the sums they are made of). A partner of another component is staged
    with ``S = D = T = 0``: what is left is the length part alone."""
    trqa = Qa[0] + Qa[4] + Qa[8]
    for j in range(_LANES):
        sb = _W_STAGE + j
        x0 = W[sb + _LANES * _MC]
        x1 = W[sb + _LANES * (_MC + 1)]
        x2 = W[sb + _LANES * (_MC + 2)]
        Lb = W[sb + _LANES * _ML]
        sb0 = W[sb + _LANES * _MS]
        sb1 = W[sb + _LANES * (_MS + 1)]
        sb2 = W[sb + _LANES * (_MS + 2)]
        Db = _lane9(W, sb + _LANES * _MD)
        Qb = _lane9(W, sb + _LANES * _MQ)
        Tb = (_lane9(W, sb + _LANES * _MT) + _lane9(W, sb + _LANES * (_MT + 9))
              + _lane9(W, sb + _LANES * (_MT + 18)))
        r2 = x0 * x0 + x1 * x1 + x2 * x2
        inv = 1.0 / r2
        i2 = inv * inv
        i3 = i2 * inv
        # length part, second order: ½ ∇²k : (L_B Q_A + L_A Q_B), k = 1/|d|² (the first order
        # vanishes: Σ l δ = 0)
        trqb = Qb[0] + Qb[4] + Qb[8]
        va0 = Qa[0] * x0 + Qa[1] * x1 + Qa[2] * x2
        va1 = Qa[3] * x0 + Qa[4] * x1 + Qa[5] * x2
        va2 = Qa[6] * x0 + Qa[7] * x1 + Qa[8] * x2
        vb0 = Qb[0] * x0 + Qb[1] * x1 + Qb[2] * x2
        vb1 = Qb[3] * x0 + Qb[4] * x1 + Qb[5] * x2
        vb2 = Qb[6] * x0 + Qb[7] * x1 + Qb[8] * x2
        xqa = x0 * va0 + x1 * va1 + x2 * va2
        xqb = x0 * vb0 + x1 * vb1 + x2 * vb2
        trq = Lb * trqa + La * trqb
        xqx = Lb * xqa + La * xqb
        e = 4.0 * i3 * xqx - i2 * trq
        # tangent part: S_Aᵀ H S_B + T(D_A, S_B) − T(D_B, S_A) + ½ K4:(T_A⊗S_B) + ½ K4:(S_A⊗T_B)
        # − K4:(D_A⊗D_B)
        # the zeroth order: the pair kernel itself with the clusters' L and S (SPLIT form: ∂/∂S
        # and ∂/∂L apart)
        f, fs0, fs1, fs2, _, _, _, fx0, fx1, fx2, fl, _ = pair(
            x0, x1, x2, sa0, sa1, sa2, sb0, sb1, sb2, La, Lb, r2, SPLIT)
        d1 = _dipole(Da, sb0, sb1, sb2, x0, x1, x2, inv)
        d2 = _dipole(Db, sa0, sa1, sa2, x0, x1, x2, inv)
        q1 = _quadrupole(Ta, sb0, sb1, sb2, x0, x1, x2, inv)
        q2 = _quadrupole(Tb, sa0, sa1, sa2, x0, x1, x2, inv)
        pq = _dipole_pair(Da, Db, x0, x1, x2, inv)
        e += f + d1[0] - d2[0] + 0.5 * q1[0] + 0.5 * q2[0] - pq[0]
        a = _W_SUMS + j
        W[a + _LANES * _AE] += e
        if grad:
            W[a + _LANES * _AL] += 4.0 * i3 * xqb - i2 * trqb + fl
            c0 = 4.0 * i3 * trq - 24.0 * i3 * inv * xqx
            W[a + _LANES * _AC] += (c0 * x0 + 8.0 * i3 * (Lb * va0 + La * vb0) + fx0
                                    + d1[13] - d2[13] + 0.5 * (q1[10] + q2[10]) - pq[10])
            W[a + _LANES * (_AC + 1)] += (c0 * x1 + 8.0 * i3 * (Lb * va1 + La * vb1) + fx1
                                          + d1[14] - d2[14] + 0.5 * (q1[11] + q2[11]) - pq[11])
            W[a + _LANES * (_AC + 2)] += (c0 * x2 + 8.0 * i3 * (Lb * va2 + La * vb2) + fx2
                                          + d1[15] - d2[15] + 0.5 * (q1[12] + q2[12]) - pq[12])
            W[a + _LANES * _AS] += fs0 - d2[1] + 0.5 * q2[1]
            W[a + _LANES * (_AS + 1)] += fs1 - d2[2] + 0.5 * q2[2]
            W[a + _LANES * (_AS + 2)] += fs2 - d2[3] + 0.5 * q2[3]
            W[a + _LANES * _AD] += d1[4] - pq[1]
            W[a + _LANES * (_AD + 1)] += d1[5] - pq[2]
            W[a + _LANES * (_AD + 2)] += d1[6] - pq[3]
            W[a + _LANES * (_AD + 3)] += d1[7] - pq[4]
            W[a + _LANES * (_AD + 4)] += d1[8] - pq[5]
            W[a + _LANES * (_AD + 5)] += d1[9] - pq[6]
            W[a + _LANES * (_AD + 6)] += d1[10] - pq[7]
            W[a + _LANES * (_AD + 7)] += d1[11] - pq[8]
            W[a + _LANES * (_AD + 8)] += d1[12] - pq[9]
            xx0 = x0 * x0
            xx1 = x0 * x1
            xx2 = x0 * x2
            xx3 = x1 * x1
            xx4 = x1 * x2
            xx5 = x2 * x2
            lb3 = Lb * i3
            W[a + _LANES * _AQ] += lb3 * xx0
            W[a + _LANES * (_AQ + 1)] += lb3 * xx1
            W[a + _LANES * (_AQ + 2)] += lb3 * xx2
            W[a + _LANES * (_AQ + 3)] += lb3 * xx3
            W[a + _LANES * (_AQ + 4)] += lb3 * xx4
            W[a + _LANES * (_AQ + 5)] += lb3 * xx5
            W[a + _LANES * _AQL] += Lb * i2
            W[a + _LANES * _AAL] += 0.5 * q1[4]
            W[a + _LANES * (_AAL + 1)] += 0.5 * q1[5]
            W[a + _LANES * (_AAL + 2)] += 0.5 * q1[6]
            for c in range(3):
                sg = 0.5 * (q1[7] if c == 0 else (q1[8] if c == 1 else q1[9]))
                r = a + _LANES * (_ABE + 6 * c)
                W[r] += sg * xx0
                W[r + _LANES] += sg * xx1
                W[r + 2 * _LANES] += sg * xx2
                W[r + 3 * _LANES] += sg * xx3
                W[r + 4 * _LANES] += sg * xx4
                W[r + 5 * _LANES] += sg * xx5


@nb.njit(cache=True, parallel=True)
def _moment_rows(L, C, S, D, Q, T):
    """Every node's moments in one row (columns ``_MC``, ``_ML``, …): what staging copies."""
    m = L.shape[0]
    rows = np.empty((m, _NMOM))
    for nn in nb.prange(m):
        node = np.int64(nn)
        r = rows[node]
        r[_ML] = L[node]
        for k in range(3):
            r[_MC + k] = C[node, k]
            r[_MS + k] = S[node, k]
            for i in range(3):
                r[_MD + 3 * k + i] = D[node, k, i]
                r[_MQ + 3 * k + i] = Q[node, k, i]
                for h in range(3):
                    r[_MT + 9 * k + 3 * i + h] = T[node, k, i, h]
    return rows


@nb.njit(cache=True, inline="always")
def _row9(X):
    return (X[0, 0], X[0, 1], X[0, 2], X[1, 0], X[1, 1], X[1, 2], X[2, 0], X[2, 1], X[2, 2])


@nb.njit(cache=True, inline="always")
def _stage(W, j, rows, a, b, same):
    """Partner ``b`` of target ``a`` into lane ``j``: ``x = c_a − c_b`` for the centre, and
    ``S``, ``D``, ``T`` zero for a partner of another component (its length part alone)."""
    s = _W_STAGE + j
    for k in range(3):
        W[s + _LANES * (_MC + k)] = rows[a, _MC + k] - rows[b, _MC + k]
    W[s + _LANES * _ML] = rows[b, _ML]
    for k in range(_MQ, _MQ + 9):
        W[s + _LANES * k] = rows[b, k]
    if same:
        for k in range(_MS, _MQ):
            W[s + _LANES * k] = rows[b, k]
        for k in range(_MT, _NMOM):
            W[s + _LANES * k] = rows[b, k]
    else:
        for k in range(_MS, _MQ):
            W[s + _LANES * k] = 0.0
        for k in range(_MT, _NMOM):
            W[s + _LANES * k] = 0.0


@nb.njit(cache=True, inline="always")
def _far_lanes_open(W, grad, La, Qa):
    """:func:`_far_lanes` where every component is open (cables): every partner is staged with
    ``S = D = T = 0`` (:func:`_stage_open` leaves them out), so every pair is the length part
    alone and the tangent terms and their derivatives are zeros. What is left is computed in
    the full kernel's operations and order: the same bits (``tests/core/test_open_tree.py``);
    the sums of the target's ``S``, ``D`` and ``T`` derivatives stay 0. The length part
    repeats :func:`_far_lanes`' lines: as inline helpers of both, the full kernel's energy
    measured 8 % slower (35 → 38 ms, 100 cables × 200 edges) and this one no faster."""
    trqa = Qa[0] + Qa[4] + Qa[8]
    for j in range(_LANES):
        sb = _W_STAGE + j
        x0 = W[sb + _LANES * _MC]
        x1 = W[sb + _LANES * (_MC + 1)]
        x2 = W[sb + _LANES * (_MC + 2)]
        Lb = W[sb + _LANES * _ML]
        Qb = _lane9(W, sb + _LANES * _MQ)
        r2 = x0 * x0 + x1 * x1 + x2 * x2
        inv = 1.0 / r2
        i2 = inv * inv
        i3 = i2 * inv
        trqb = Qb[0] + Qb[4] + Qb[8]
        va0 = Qa[0] * x0 + Qa[1] * x1 + Qa[2] * x2
        va1 = Qa[3] * x0 + Qa[4] * x1 + Qa[5] * x2
        va2 = Qa[6] * x0 + Qa[7] * x1 + Qa[8] * x2
        vb0 = Qb[0] * x0 + Qb[1] * x1 + Qb[2] * x2
        vb1 = Qb[3] * x0 + Qb[4] * x1 + Qb[5] * x2
        vb2 = Qb[6] * x0 + Qb[7] * x1 + Qb[8] * x2
        xqa = x0 * va0 + x1 * va1 + x2 * va2
        xqb = x0 * vb0 + x1 * vb1 + x2 * vb2
        trq = Lb * trqa + La * trqb
        xqx = Lb * xqa + La * xqb
        e = 4.0 * i3 * xqx - i2 * trq
        # the pair kernel with both S zero (SPLIT): f = L_A L_B / |x|², ∂f/∂x = −2 f x / |x|²
        f = (La * Lb) * inv
        e += f
        a = _W_SUMS + j
        W[a + _LANES * _AE] += e
        if grad:
            cd = -2.0 * f
            W[a + _LANES * _AL] += 4.0 * i3 * xqb - i2 * trqb + Lb * inv
            c0 = 4.0 * i3 * trq - 24.0 * i3 * inv * xqx
            W[a + _LANES * _AC] += (c0 * x0 + 8.0 * i3 * (Lb * va0 + La * vb0)
                                    + (cd * x0) * inv)
            W[a + _LANES * (_AC + 1)] += (c0 * x1 + 8.0 * i3 * (Lb * va1 + La * vb1)
                                          + (cd * x1) * inv)
            W[a + _LANES * (_AC + 2)] += (c0 * x2 + 8.0 * i3 * (Lb * va2 + La * vb2)
                                          + (cd * x2) * inv)
            xx0 = x0 * x0
            xx1 = x0 * x1
            xx2 = x0 * x2
            xx3 = x1 * x1
            xx4 = x1 * x2
            xx5 = x2 * x2
            lb3 = Lb * i3
            W[a + _LANES * _AQ] += lb3 * xx0
            W[a + _LANES * (_AQ + 1)] += lb3 * xx1
            W[a + _LANES * (_AQ + 2)] += lb3 * xx2
            W[a + _LANES * (_AQ + 3)] += lb3 * xx3
            W[a + _LANES * (_AQ + 4)] += lb3 * xx4
            W[a + _LANES * (_AQ + 5)] += lb3 * xx5
            W[a + _LANES * _AQL] += Lb * i2


@nb.njit(cache=True, inline="always")
def _stage_open(W, j, rows, a, b):
    """:func:`_stage` of a partner of an open component: the centre, ``L`` and ``Q`` (what
    :func:`_far_lanes_open` reads)."""
    s = _W_STAGE + j
    for k in range(3):
        W[s + _LANES * (_MC + k)] = rows[a, _MC + k] - rows[b, _MC + k]
    W[s + _LANES * _ML] = rows[b, _ML]
    for k in range(_MQ, _MQ + 9):
        W[s + _LANES * k] = rows[b, k]


@nb.njit(cache=True, inline="always")
def _empty_lane(W, j):
    """A lane with no partner: no length and no moments add exactly 0 (every term of F has a
    factor from each side), at a centre 1 away (a finite 1/|x|²)."""
    s = _W_STAGE + j
    for k in range(_NMOM):
        W[s + _LANES * k] = 0.0
    for k in range(3):
        W[s + _LANES * (_MC + k)] = 1.0


# No fast-math here: with it, the code LLVM made for this kernel in the compiling process and
# the code numba's cache loads in later processes fused and ordered operations differently
# (gradients differed in the last bits between a first and a second run; measured with
# "contract" alone too). error_model="numpy": no zero test on the divisions, which kept the
# loop over lanes from vectorizing.
@nb.njit(cache=True, parallel=True, error_model="numpy")
def _far(L, C, S, D, Q, T, nc, foff, fpart, grad, opened):
    """Per target node: Σ_B F(A, B) and, with ``grad``, twice Σ_B ∂F(A, B)/∂(L_A, S_A, c_A, D_A,
    Q_A, T_A) (the derivative of the ordered sum: F is symmetric). F: both parts of the kernel
    expanded to second order in the cluster sizes around the centres, the same order for
    both: they cancel for two pieces of one straight line (exact F = 0), and expanding one
    part further than the other measured larger errors. The partners are evaluated eight at a
    time (:func:`_far_lanes`), each lane summing its own, the lanes added in order at the end:
    the same bits for any thread count. ``opened``: every component is open, every pair the
    length part alone (:func:`_far_lanes_open`: the same bits, fewer operations)."""
    m = L.shape[0]
    rows = _moment_rows(L, C, S, D, Q, T)
    eF = np.zeros(m)
    mg = m if grad else 0  # the derivatives' arrays are empty for the energy alone
    gL = np.zeros(mg)
    gS = np.zeros((mg, 3))
    gC = np.zeros((mg, 3))
    gD = np.zeros((mg, 3, 3))
    gQ = np.zeros((mg, 3, 3))
    gT = np.zeros((mg, 3, 3, 3))
    nchunks = min(m, _FAR_CHUNKS)
    for cc in nb.prange(nchunks):
        ch = np.int64(cc)
        W = np.zeros(_W_SIZE)
        tot = np.empty(_NSUM)
        gal = np.empty(3)
        gbe = np.zeros((3, 3, 3))
        for a in range(ch * m // nchunks, (ch + 1) * m // nchunks):
            if foff[a] == foff[a + 1]:
                continue
            La = L[a]
            sa0, sa1, sa2 = S[a, 0], S[a, 1], S[a, 2]
            Da = _row9(D[a])
            Qa = _row9(Q[a])
            Ta = _row9(T[a, 0]) + _row9(T[a, 1]) + _row9(T[a, 2])
            W[_W_SUMS:] = 0.0
            for p0 in range(foff[a], foff[a + 1], _LANES):
                for j in range(_LANES):
                    p = p0 + j
                    if p >= foff[a + 1]:
                        _empty_lane(W, j)
                    elif opened:
                        _stage_open(W, j, rows, a, fpart[p])
                    else:
                        # one closed component: the whole kernel (else O'Hara's, length part)
                        _stage(W, j, rows, a, fpart[p], nc[fpart[p]] == nc[a] and nc[a] >= 0)
                if opened:
                    if grad:
                        _far_lanes_open(W, True, La, Qa)
                    else:
                        _far_lanes_open(W, False, La, Qa)
                elif grad:
                    _far_lanes(W, True, La, sa0, sa1, sa2, Da, Qa, Ta)
                else:
                    _far_lanes(W, False, La, sa0, sa1, sa2, Da, Qa, Ta)
            for k in range(_NSUM if grad else 1):  # the lanes' sums, in lane order
                acc = 0.0
                for j in range(_LANES):
                    acc += W[_W_SUMS + _LANES * k + j]
                tot[k] = acc
            eF[a] = tot[_AE]
            if not grad:
                continue
            gL[a] = 2.0 * tot[_AL]
            for k in range(3):
                gS[a, k] = 2.0 * tot[_AS + k]
                gC[a, k] = 2.0 * tot[_AC + k]
                for i in range(3):
                    gD[a, k, i] = 2.0 * tot[_AD + 3 * k + i]
            # ∂/∂Q of the length part: ½ ∇²k = 4 x xᵀ/|x|⁶ − I/|x|⁴, times L_B
            for k in range(6):
                i, h = _UPPER[k]
                gQ[a, i, h] = 8.0 * tot[_AQ + k]
                gQ[a, h, i] = 8.0 * tot[_AQ + k]
            for k in range(3):
                gQ[a, k, k] -= 2.0 * tot[_AQL]
            for k in range(3):
                gal[k] = tot[_AAL + k]
                for h in range(6):
                    i, i2 = _UPPER[h]
                    gbe[k, i, i2] = tot[_ABE + 6 * k + h]
            _quadrupole_gradient(gal, gbe, 2.0, gT[a])
    return eF, gL, gS, gC, gD, gQ, gT


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


@nb.njit(cache=True, parallel=True)
def _push_down(L, C, S, D, gL, gS, gC, gD, gQ, gT, left, right):
    """What every leaf's edges receive from the far field of the leaf and its ancestors.

    A node's share of the derivative is the first variation of ``Σ_I l_I a(δ_I) + <e_I,
    b(δ_I)>`` with the polynomials (``δ = m − c``) ``a = g_L + <g_c, δ>/L + δᵀ G_Q δ`` (the
    centre ``c = Σ l m / L``, with ``g_c`` including the explicit dependence of ``D`` and ``T``
    on ``c``: ``−G_Dᵀ S`` and ``−2 Σ G_T,ack D_ac``; ``Q``'s vanishes, ``Σ l δ = 0``) and
    ``b_a = g_S,a + G_D,ac δ_c + G_T,acd δ_c δ_d``. The polynomials are moved to the
    children's centres and summed down, one depth at a time, each node taking its parent's
    (in parallel within a depth). Columns: 0 ``a0``, 1–3 ``a1``, 4–12 ``A2``, 13–15 ``b0``,
    16–24 ``B1``, 25–51 ``B2`` (row-major, ``A2`` and ``B2`` symmetrized)."""
    m = L.shape[0]
    acc = np.empty((m, 52))
    for nn in nb.prange(m):
        node = np.int64(nn)
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
    order, offsets = _levels(left, right)
    parent = np.empty(m, np.int64)
    for node in range(m):
        if left[node] >= 0:
            parent[left[node]] = node
            parent[right[node]] = node
    for d in range(1, offsets.shape[0] - 1):
        if offsets[d + 1] - offsets[d] >= _PARALLEL_LEVEL:
            for t in nb.prange(offsets[d], offsets[d + 1]):
                node = order[t]
                _from_parent(acc, C, parent[node], node)
        else:
            for t in range(offsets[d], offsets[d + 1]):
                node = order[t]
                _from_parent(acc, C, parent[node], node)
    return acc


@nb.njit(cache=True, inline="always")
def _from_parent(acc, C, node, child):
    """Add the polynomials of ``node`` moved to its child's centre to the child's."""
    r = acc[node]
    o = acc[child]
    h0 = C[child, 0] - C[node, 0]
    h1 = C[child, 1] - C[node, 1]
    h2 = C[child, 2] - C[node, 2]
    # a(δ + h), b(δ + h) as polynomials in the child's δ
    o[0] += r[0]
    for k in range(3):
        hk = h0 if k == 0 else (h1 if k == 1 else h2)
        o[0] += r[1 + k] * hk
        o[1 + k] += r[1 + k]
        o[13 + k] += r[13 + k]
        for j in range(3):
            hj = h0 if j == 0 else (h1 if j == 1 else h2)
            a2 = r[4 + 3 * k + j]
            o[0] += a2 * hk * hj
            o[1 + k] += 2.0 * a2 * hj
            o[4 + 3 * k + j] += a2
            b1 = r[16 + 3 * k + j]
            o[13 + k] += b1 * hj
            o[16 + 3 * k + j] += b1
            for i in range(3):
                hi = h0 if i == 0 else (h1 if i == 1 else h2)
                b2 = r[25 + 9 * k + 3 * j + i]
                o[13 + k] += b2 * hj * hi
                o[16 + 3 * k + j] += 2.0 * b2 * hi
                o[25 + 9 * k + 3 * j + i] += b2


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
