"""Gram matrices of the metrics (docs/design.md, "Metrics"; the paper's "Discrete inner product").

Every metric is the ``N × N`` matrix ``A`` of one coordinate; the 3N × 3N Gram matrix is
``G = A ⊗ I₃``. With ``D`` the edge-difference operator ``(Du)_I = (u[i+1] − u[i]) / l_I``,
``M`` the edge average ``(Mu)_I = (u[i] + u[i+1]) / 2`` and, over disjoint edge pairs,

    w_IJ = l_I l_J / |m_I − m_J|²
    v_IJ = l_I l_J (1/|m_I − m_J|² − 1/ρ_IJ²) / |m_I − m_J|²

the geometric W^{3/2,2} matrix is ``A_hs = 2 Dᵀ(diag(W1) − W)D + 2 Mᵀ(diag(V1) − V)M``, the
quadratic form ``Σ_{I,J} w_IJ |(Du)_I − (Du)_J|² + v_IJ |(Mu)_I − (Mu)_J|²``.

Every matrix gets the barycenter term ``N b bᵀ / L⁴`` (``b_k = (l_{k−1} + l_k)/2`` per
component, ``N`` the number of vertices of the whole polygon or link): the paper's
``<∫u, ∫w>``, which makes ``A`` invertible and vanishes on the constraint tangent space; the
factor ``N`` puts its eigenvalue beside the lowest shape modes' instead of far below them
(better conditioning, the same tangent-space metric). Its factor N/L⁴ and the powers of ``L``
on the lower-order metrics make every ``A`` scale as 1/c² under ``P → cP``, so steps and
tolerances do not depend on the curve's size.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ._layout import Layout, as_checked_layout
from ._memory import check_memory
from .open_metrics import open_hs

# Tiny L² term that keeps the pure W^{3/2,2} matrix definite for 4-gons, where disjoint edge
# pairs do not connect all edges (docs/design.md: "+ a small L² term if needed").
_PURE_L2 = 1e-6
# Fixed work split (independent of the thread count) so results are reproducible everywhere.
_CHUNKS = 16


@nb.njit(cache=True, inline="always")
def _other_ranges(i, start, end):
    """Edges of the component [start, end) disjoint from edge i: two half-open ranges."""
    lo1 = start + 1 if i == end - 1 else start
    hi1 = i - 1
    lo2 = i + 2
    hi2 = end - 1 if i == start else end
    return lo1, hi1, lo2, hi2


@nb.njit(cache=True, fastmath={"reassoc", "contract", "nsz", "arcp"})
def _edge_row(i, mx, my, mz, ln, arc, clen, starts, comp, low, kw, kv):
    """Weights ``w_iJ`` and ``v_iJ`` of edge ``i`` against every edge J (0 where not disjoint)
    into ``kw``, ``kv``; returns their row sums."""
    n = ln.shape[0]
    c = comp[i]
    px, py, pz, li, si, lc = mx[i], my[i], mz[i], ln[i], arc[i], clen[c]
    sw = 0.0
    sv = 0.0
    lo1, hi1, lo2, hi2 = _other_ranges(i, starts[c], starts[c + 1])
    # every entry is written below except edge i and its two neighbours (not disjoint)
    s0 = starts[c]
    s1 = starts[c + 1]
    for j in (i - 1 if i > s0 else s1 - 1, i, i + 1 if i + 1 < s1 else s0):
        kw[j] = 0.0
        kv[j] = 0.0
    for rng in range(2):
        lo = lo1 if rng == 0 else lo2
        hi = hi1 if rng == 0 else hi2
        for j in range(lo, hi):
            dx = px - mx[j]
            dy = py - my[j]
            dz = pz - mz[j]
            inv = 1.0 / (dx * dx + dy * dy + dz * dz)
            w = li * ln[j] * inv
            fwd = abs(arc[j] - si)
            rho = min(fwd, lc - fwd)
            v = low * w * (inv - 1.0 / (rho * rho))
            kw[j] = w
            kv[j] = v
            sw += w
            sv += v
    for j in range(0, starts[c]):
        dx = px - mx[j]
        dy = py - my[j]
        dz = pz - mz[j]
        inv = 1.0 / (dx * dx + dy * dy + dz * dz)
        w = li * ln[j] * inv
        kw[j] = w
        kv[j] = low * w * inv  # 1/ρ² = 0 between components
        sw += w
        sv += kv[j]
    for j in range(starts[c + 1], n):
        dx = px - mx[j]
        dy = py - my[j]
        dz = pz - mz[j]
        inv = 1.0 / (dx * dx + dy * dy + dz * dz)
        w = li * ln[j] * inv
        kw[j] = w
        kv[j] = low * w * inv
        sw += w
        sv += kv[j]
    return sw, sv


@nb.njit(cache=True, parallel=True, fastmath={"reassoc", "contract", "nsz", "arcp"})
def _hs_rows(mx, my, mz, ln, arc, clen, starts, comp, nxt, prv, low, nchunks, A):
    """Rows of ``2 Dᵀ(diag(W1) − W)D + 2 Mᵀ(diag(V1) − V)M`` (the V part times ``low``).

    Vertex ``p`` lies on the edges ``p`` (coefficient −1/l_p in D) and ``prv[p]`` (+1/l in D);
    both have coefficient 1/2 in M. Each chunk walks a block of consecutive vertices, so the
    weights of edge ``prv[p] = p − 1`` are reused from the previous row. Writes into A (N × N).
    """
    n = ln.shape[0]
    inv_ln = 1.0 / ln
    block = (n + nchunks - 1) // nchunks
    for cc in nb.prange(nchunks):
        ch = np.int64(cc)
        p0 = ch * block
        p1 = min(n, p0 + block)
        kw = np.empty(n)
        kv = np.empty(n)
        qw = np.empty(n)
        qv = np.empty(n)
        tmp = np.empty(n)
        sw = 0.0
        sv = 0.0
        have = -1  # edge whose weights are in (kw, kv)
        for p in range(p0, p1):
            q = prv[p]
            # weights of edge q = prv[p] into (qw, qv): from the previous row when possible
            if have == q:
                qw, kw = kw, qw
                qv, kv = kv, qv
                tw, tv = sw, sv
            else:
                tw, tv = _edge_row(q, mx, my, mz, ln, arc, clen, starts, comp, low, qw, qv)
            sw, sv = _edge_row(p, mx, my, mz, ln, arc, clen, starts, comp, low, kw, kv)
            have = p
            ap = -1.0 / ln[p]
            aq = 1.0 / ln[q]
            row = A[p]
            for j in range(n):  # the first write of every entry of the row
                xd = -2.0 * (ap * kw[j] + aq * qw[j]) * inv_ln[j]
                xm = -(kv[j] + qv[j]) * 0.5
                row[j] = xm - xd
                tmp[j] = xm + xd  # goes to column nxt[j]
            for c in range(starts.shape[0] - 1):
                s0 = starts[c]
                s1 = starts[c + 1]
                for j in range(s0, s1 - 1):
                    row[j + 1] += tmp[j]
                row[s0] += tmp[s1 - 1]
            # diagonal part 2 Sᵀ diag(K1) S restricted to row p, for both edges through p
            row[p] += 2.0 * ap * sw * (-1.0 / ln[p]) + 0.5 * sv
            row[nxt[p]] += 2.0 * ap * sw * (1.0 / ln[p]) + 0.5 * sv
            row[q] += 2.0 * aq * tw * (-1.0 / ln[q]) + 0.5 * tv
            row[p] += 2.0 * aq * tw * (1.0 / ln[q]) + 0.5 * tv
    return A


def _lengths(X: np.ndarray, layout: Layout):
    E = X[layout.nxt] - X
    return E, np.sqrt(np.einsum("ij,ij->i", E, E))


def _barycenter_weights(ln: np.ndarray, layout: Layout) -> np.ndarray:
    return 0.5 * (ln[layout.prv] + ln)


def _add_barycenter_term(A: np.ndarray, ln: np.ndarray, layout: Layout, total: float) -> None:
    # b bᵀ · N / L⁴: the factor N puts the constant mode's eigenvalue (|b|² ~ L²/N) next to the
    # lowest shape modes (~1/L²) instead of far below them, which keeps A well conditioned.
    b = _barycenter_weights(ln, layout) * np.sqrt(len(ln)) / total**2
    _add_outer_blocks(A, b, layout.starts)


@nb.njit(cache=True, parallel=True)
def _add_outer_blocks(A, b, starts):
    """``A[s, s] += b[s] b[s]ᵀ`` for every component block ``s``, in place (np.outer plus
    the addition cost 8 ms at 1648 vertices, as much as a third of the Gram assembly)."""
    for p in nb.prange(A.shape[0]):
        c = 0
        while starts[c + 1] <= p:
            c += 1
        bp = b[p]
        for j in range(starts[c], starts[c + 1]):
            A[p, j] += bp * b[j]


def _sparse_to_dense(n: int, rows, cols, vals) -> np.ndarray:
    A = np.zeros((n, n))
    np.add.at(A, (np.concatenate(rows), np.concatenate(cols)), np.concatenate(vals))
    return A


def _mass_triplets(ln, layout):
    """P1 mass matrix of the polygon with edge lengths ``ln`` (the L² product), as triplets."""
    i = np.arange(len(ln))
    j = layout.nxt
    return (i, j, i, j), (i, j, j, i), (ln / 3, ln / 3, ln / 6, ln / 6)


def _stiffness_triplets(ln, layout):
    """``Dᵀ diag(l) D``: Σ_I |u[i+1] − u[i]|² / l_I, as triplets."""
    i = np.arange(len(ln))
    j = layout.nxt
    k = _inverse_lengths(ln, layout)
    return (i, j, i, j), (i, j, j, i), (k, k, -k, -k)


def _inverse_lengths(ln, layout):
    """``1 / l`` per edge slot; 0 at the dummy edges of open components (:mod:`._layout`)."""
    if layout.closed is None:
        return 1.0 / ln
    real = layout.real
    inv = np.zeros_like(ln)
    inv[real] = 1.0 / ln[real]
    return inv


def _bending_triplets(ln, layout):
    """``D2ᵀ diag(dual) D2`` with ``(D2 u)_p = ((Du)_p − (Du)_{p−1}) / dual_p``, as
    triplets."""
    p = np.arange(len(ln))
    q = layout.prv
    dual = 0.5 * (ln[q] + ln)
    # (D2 u)_p = c_prev u[prv p] + c_mid u[p] + c_next u[nxt p]
    cols = np.stack([q, p, layout.nxt])
    if layout.closed is None:
        coef = np.stack([1.0 / ln[q], -1.0 / ln[q] - 1.0 / ln, 1.0 / ln]) / dual
    else:  # open ends: no bending term at a vertex with one edge (the ends bend freely)
        inv = _inverse_lengths(ln, layout)
        inner = layout.real & layout.real[q]
        coef = np.stack([inv[q], -inv[q] - inv, inv]) / dual * inner
    rows, cs, vals = [], [], []
    for a in range(3):
        for b in range(3):
            rows.append(cols[a])
            cs.append(cols[b])
            vals.append(dual * coef[a] * coef[b])
    return rows, cs, vals


def _mass(ln, layout):
    return _sparse_to_dense(len(ln), *_mass_triplets(ln, layout))


def _stiffness(ln, layout):
    return _sparse_to_dense(len(ln), *_stiffness_triplets(ln, layout))


def _bending(ln, layout):
    return _sparse_to_dense(len(ln), *_bending_triplets(ln, layout))


def _hs_family(X, layout, ln, total, out, low):
    """``A_hs`` with its V part times ``low`` (1: ``hs``, 0: the top-order part alone)."""
    if layout.closed is not None:
        # Open components: an affine field along a straight stretch is in the kernel of both
        # seminorms (v_IJ = 0 where the chord equals the arc), so the L² term of l2 is added
        # to keep A definite on every polyline; closed curves are never straight.
        return open_hs(X, layout, ln, low) + _mass(ln, layout) / total**3
    M = 0.5 * (X[layout.nxt] + X)
    arc = np.empty_like(ln)
    clen = np.empty(layout.k)
    for c in range(layout.k):
        s = slice(layout.starts[c], layout.starts[c + 1])
        cum = np.cumsum(ln[s])
        arc[s] = cum - 0.5 * ln[s]  # arc-length position of each edge midpoint
        clen[c] = cum[-1]
    return _hs_rows(
        np.ascontiguousarray(M[:, 0]),
        np.ascontiguousarray(M[:, 1]),
        np.ascontiguousarray(M[:, 2]),
        ln,
        arc,
        clen,
        layout.starts,
        layout.comp,
        layout.nxt,
        layout.prv,
        low,
        _CHUNKS,
        out if out is not None and out.shape == (len(ln),) * 2 else np.empty((len(ln),) * 2),
    )


def _gram_l2(X, layout, ln, total, out):
    return _mass(ln, layout) / total**3


def _gram_h1(X, layout, ln, total, out):
    return (_stiffness(ln, layout) + _mass(ln, layout) / total**2) / total


def _gram_h2(X, layout, ln, total, out):
    return total * _bending(ln, layout) + _gram_h1(X, layout, ln, total, out)


def _gram_hs_pure(X, layout, ln, total, out):
    A = _hs_family(X, layout, ln, total, out, 0.0)
    A += _PURE_L2 * _mass(ln, layout) / total**3
    return A


def _gram_hs(X, layout, ln, total, out):
    return _hs_family(X, layout, ln, total, out, 1.0)


# Builder of every metric's matrix without the barycenter term, from the vertices ``X``, their
# edge lengths ``ln`` and total length; ``out`` is memory a builder may overwrite. The order is
# the one of METRICS (weakest first).
_BUILDERS = {
    "l2": _gram_l2,
    "h1": _gram_h1,
    "h2": _gram_h2,
    "hs_pure": _gram_hs_pure,
    "hs": _gram_hs,
}
METRICS = tuple(_BUILDERS)


def gram_x(metric: str, X: np.ndarray, layout: Layout, out: np.ndarray | None = None) -> np.ndarray:
    """Gram matrix ``A`` of the stacked vertex array (private fast path used by the engine).

    ``out``: an (N, N) float64 array to overwrite with ``hs``/``hs_pure`` (the flow passes the
    previous iterate's: a fresh 72 MB array at 3000 vertices costs 27 ms of page faults)."""
    if metric not in _BUILDERS:
        raise ValueError(f"unknown metric {metric!r}; choose one of {', '.join(METRICS)}")
    E, ln = _lengths(X, layout)
    total = float(ln.sum())
    A = _BUILDERS[metric](X, layout, ln, total, out)
    _add_barycenter_term(A, ln, layout, total)
    return A


def gram_matrix(metric: str, P, closed=True) -> np.ndarray:
    """Gram matrix of one coordinate for the given metric.

    Parameters
    ----------
    metric : {"l2", "h1", "h2", "hs_pure", "hs"}
        ``hs`` is the paper's geometric W^{3/2,2} metric (the default of the flow), ``hs_pure``
        its top-order part alone; ``l2``, ``h1``, ``h2`` are the classical metrics for comparison.
    P : (N, 3) array or list of arrays
        Closed polygon or link.
    closed : bool or sequence of bool
        False for an open polyline (one flag per component of a link, or one for all):
        docs/api.md, "Open curves".

    Returns
    -------
    (N, N) array
        Symmetric positive definite ``A`` with ``G = A ⊗ I₃``; entries scale as 1/length².
    """
    if metric not in METRICS:
        raise ValueError(f"unknown metric {metric!r}; choose one of {', '.join(METRICS)}")
    X, layout, k = as_checked_layout(P, closed)
    n = layout.n
    # the matrix itself, and room for its assembly (measured 7.9 bytes per entry at 3 000)
    check_memory(16.0 * n * n, f"the {n} x {n} Gram matrix",
                 "resample the curve to fewer vertices (core.resample(P, n))")
    A = gram_x(metric, X, layout)
    if not k:
        return A
    out = np.ldexp(A, -2 * k)  # A(2^k X) = 4^-k A(X)
    if not np.isfinite(out).all() or np.any((out == 0) & (A != 0)):
        raise ValueError("the Gram matrix of a curve this size is outside the float64 range "
                         "(its entries scale as 1/length²); scale the curve towards size 1")
    return out


def banded_parts(metric: str, X: np.ndarray, layout: Layout):
    """The banded metrics (``l2``, ``h1``, ``h2``) without a matrix: ``(rows, cols, vals,
    beta)``, the matrix of :func:`gram_x` as ``A = Σ vals at (rows, cols) + β βᵀ`` per
    component (β: the barycenter term's weights). For :mod:`.banded`'s O(N) solver."""
    return banded_parts_of_lengths(metric, _lengths(X, layout)[1], layout)


def banded_parts_of_lengths(metric: str, ln: np.ndarray, layout: Layout):
    """:func:`banded_parts` from the edge lengths ``ln`` alone (all these metrics depend on)."""
    if metric not in ("l2", "h1", "h2"):
        raise ValueError(f"{metric!r} is not a banded metric (l2, h1, h2)")
    total = float(ln.sum())
    parts = [(_mass_triplets(ln, layout), 1.0 / total**3)]  # as _gram_l2 .. _gram_h2
    if metric != "l2":
        parts.append((_stiffness_triplets(ln, layout), 1.0 / total))
    if metric == "h2":
        parts.append((_bending_triplets(ln, layout), total))
    rows = np.concatenate([np.concatenate(r) for (r, _, _), _ in parts]).astype(np.int64)
    cols = np.concatenate([np.concatenate(c) for (_, c, _), _ in parts]).astype(np.int64)
    vals = np.concatenate([np.concatenate(v) * f for (_, _, v), f in parts])
    beta = _barycenter_weights(ln, layout) * np.sqrt(len(ln)) / total**2
    return rows, cols, vals, beta
