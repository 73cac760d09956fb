"""Gram matrices of the metrics (docs/design.md, "Metrics"; the paper's "Discrete inner product").

Every metric is the ``N × N`` matrix ``A`` of one coordinate; the 3N × 3N Gram matrix is
``G = A ⊗ I₃``. With ``D`` the edge-difference operator ``(Du)_I = (u[i+1] − u[i]) / l_I``,
``M`` the edge average ``(Mu)_I = (u[i] + u[i+1]) / 2``, an order ``s`` in (1, 2) and, over
disjoint edge pairs (``d = m_I − m_J``),

    w_IJ = l_I l_J / |d|^(2s−1)                       (|d|² at s = 3/2)
    v_IJ = l_I l_J (1/|d|² − 1/ρ_IJ²) / |d|^(2s−1)

the geometric W^{s,2} matrix is ``A_hs = 2 Dᵀ(diag(W1) − W)D + 2 Mᵀ(diag(V1) − V)M``, the
quadratic form ``Σ_{I,J} w_IJ |(Du)_I − (Du)_J|² + v_IJ |(Mu)_I − (Mu)_J|²``: the Gagliardo
seminorm of ``u′`` in W^{s−1,2} (kernel ``1/|x − y|^(1 + 2(s−1))``) plus its lower-order
term, whose extra ``1/|d|²`` gives it the top part's dimension. The order is the energy's
(:attr:`.energy_choice.EnergyChoice.metric_order`): 3/2, the paper's, for the Möbius energy,
``(β − 1)/α`` for the tangent-point energy. At s = 3/2 the kernels run the arithmetic they
always had (:func:`kernel_exponent`), so that order's matrices are bit for bit as before.

Every matrix gets the barycenter term ``N b bᵀ / L^(2s+1)`` (``L⁴`` at s = 3/2 and for the
banded metrics; ``b_k = (l_{k−1} + l_k)/2`` per component, ``N`` the number of vertices of the
whole polygon or link): the paper's ``<∫u, ∫w>``, which makes ``A`` invertible and vanishes on
the constraint tangent space; the factor ``N`` puts its eigenvalue beside the lowest shape
modes' instead of far below them (better conditioning, the same tangent-space metric). Under
``P → λP`` the hs parts scale as ``λ^(3−2s)`` (w) times ``λ^(−2)`` (D twice, or v's
``1/|d|²``), ``b bᵀ`` as ``λ²``; so the factor ``N/L^(2s+1)``, the L² terms of ``hs_pure``
and open curves over ``L^(2s)``, and the powers of ``L`` on the lower-order metrics make every
``A`` scale as ``λ^(1−2s)`` (1/λ² for the lower-order metrics and s = 3/2), and steps and
tolerances do not depend on the curve's size.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ..geometry.layout import Layout, as_checked_layout
from ..runs.memory import check_memory
from .hs_weight import hs_weight
from .open import open_hs
from .records import METRIC_RECORDS, ORDERED

# Tiny L² term that keeps the pure W^{3/2,2} matrix definite for 4-gons, where disjoint edge
# pairs do not connect all edges (docs/design.md: "+ a small L² term if needed").
_PURE_L2 = 1e-6
# Fixed work split (independent of the thread count) so results are reproducible everywhere.
_CHUNKS = 16
#: The order of the paper's metric, W^{3/2,2} (the Möbius energy's; the default).
PAPER_ORDER = 1.5
#: The metrics with an order s (the others ignore it): :mod:`.records`.
ORDERED_METRICS = ORDERED


def check_order(order) -> float:
    """``order`` as a float in (1, 2), the range of ``(β − 1)/α`` over the tangent-point
    exponents (``α + 1 < β`` gives s > 1, ``β < 2α + 1`` gives s < 2); else ValueError."""
    try:
        s = float(order)
    except (TypeError, ValueError):
        raise ValueError(f"the metric's order must be a number in (1, 2), got {order!r}") from None
    if not 1.0 < s < 2.0:
        raise ValueError(f"the metric's order must be a number in (1, 2), got {order!r}")
    return s


def kernel_exponent(order: float):
    """What the weight kernels take as ``expo``: None at order 3/2 (``w = l l / |d|²`` by the
    arithmetic that order always had, bit for bit), else the power ``s − 1/2`` of ``|d|²``."""
    return None if order == PAPER_ORDER else order - 0.5


def length_power(order: float) -> float:
    """The power ``2s`` of the total length ``L`` that an L²-sized term (``∫u²``, of length
    dimension 1) is divided by so that it scales like the order-``s`` metric, as ``λ^(1−2s)``
    under ``P → λP`` (3 at order 3/2)."""
    return 2.0 * order


@nb.njit(cache=True, inline="always")
def _other_ranges(i, start, end):
    """Edges of the component [start, end) disjoint from edge i: two half-open ranges."""
    lo1 = start + 1 if i == end - 1 else start
    hi1 = i - 1
    lo2 = i + 2
    hi2 = end - 1 if i == start else end
    return lo1, hi1, lo2, hi2


@nb.njit(cache=True, fastmath={"reassoc", "contract", "nsz", "arcp"})
def _edge_row(i, mx, my, mz, ln, arc, clen, starts, comp, low, expo, kw, kv):
    """Weights ``w_iJ`` and ``v_iJ`` of edge ``i`` against every edge J (0 where not disjoint)
    into ``kw``, ``kv``; returns their row sums. ``expo``: None at order 3/2 (``w = l l /
    |d|²``, the arithmetic of that order kept as it was), else ``s − 1/2`` (``w = l l /
    (|d|²)^expo``); the branch on it is pruned at compile time."""
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
            r2 = dx * dx + dy * dy + dz * dz
            w, inv = hs_weight(li, ln[j], r2, expo)
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
        r2 = dx * dx + dy * dy + dz * dz
        w, inv = hs_weight(li, ln[j], r2, expo)
        kw[j] = w
        kv[j] = low * w * inv  # 1/ρ² = 0 between components
        sw += w
        sv += kv[j]
    for j in range(starts[c + 1], n):
        dx = px - mx[j]
        dy = py - my[j]
        dz = pz - mz[j]
        r2 = dx * dx + dy * dy + dz * dz
        w, inv = hs_weight(li, ln[j], r2, expo)
        kw[j] = w
        kv[j] = low * w * inv
        sw += w
        sv += kv[j]
    return sw, sv


@nb.njit(cache=True, parallel=True, fastmath={"reassoc", "contract", "nsz", "arcp"})
def _hs_rows(mx, my, mz, ln, arc, clen, starts, comp, nxt, prv, low, expo, nchunks, A):
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
                tw, tv = _edge_row(q, mx, my, mz, ln, arc, clen, starts, comp, low, expo, qw, qv)
            sw, sv = _edge_row(p, mx, my, mz, ln, arc, clen, starts, comp, low, expo, kw, kv)
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


def barycenter_beta(ln: np.ndarray, layout: Layout, total: float,
                    order: float = PAPER_ORDER) -> np.ndarray:
    """β with the barycenter term ``N b bᵀ / L^(2s+1)`` = ``β βᵀ`` per component (``L⁴`` at
    order 3/2 and for the banded metrics): ``b bᵀ`` has length dimension 2, so ``L^(2s+1)``
    makes it scale as the order-``s`` metric, ``λ^(1−2s)``. The factor N puts the constant
    mode's eigenvalue (``N |b|² / L^(2s+1)`` ~ ``L^(1−2s)``) next to the lowest shape modes'
    instead of far below them, which keeps A well conditioned."""
    return _barycenter_weights(ln, layout) * np.sqrt(len(ln)) / total**(order + 0.5)


def _add_barycenter_term(A: np.ndarray, ln: np.ndarray, layout: Layout, total: float,
                         order: float) -> None:
    _add_outer_blocks(A, barycenter_beta(ln, layout, total, order), layout.starts)


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


def _hs_family(X, layout, ln, total, out, low, order):
    """``A_hs`` of ``order`` with its V part times ``low`` (1: ``hs``, 0: the top-order part
    alone)."""
    if layout.closed is not None:
        # Open components: an affine field along a straight stretch is in the kernel of both
        # seminorms (v_IJ = 0 where the chord equals the arc), so the L² term of l2 (at the
        # metric's scaling) is added to keep A definite on every polyline; closed curves are
        # never straight.
        return (open_hs(X, layout, ln, low, kernel_exponent(order))
                + _mass(ln, layout) / total**length_power(order))
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
        kernel_exponent(order),
        _CHUNKS,
        out if out is not None and out.shape == (len(ln),) * 2 else np.empty((len(ln),) * 2),
    )


def _gram_l2(X, layout, ln, total, out, order):
    return _mass(ln, layout) / total**3


def _gram_h1(X, layout, ln, total, out, order):
    return (_stiffness(ln, layout) + _mass(ln, layout) / total**2) / total


def _gram_h2(X, layout, ln, total, out, order):
    return total * _bending(ln, layout) + _gram_h1(X, layout, ln, total, out, order)


def _gram_hs_pure(X, layout, ln, total, out, order):
    A = _hs_family(X, layout, ln, total, out, 0.0, order)
    A += _PURE_L2 * _mass(ln, layout) / total**length_power(order)
    return A


def _gram_hs(X, layout, ln, total, out, order):
    return _hs_family(X, layout, ln, total, out, 1.0, order)


# Builder of every metric's matrix without the barycenter term, from the vertices ``X``, their
# edge lengths ``ln``, total length and ``order`` (hs, hs_pure; the others ignore it); ``out``
# is memory a builder may overwrite. The order of the table is the one of METRICS (weakest
# first).
_BUILDERS = {
    "l2": _gram_l2,
    "h1": _gram_h1,
    "h2": _gram_h2,
    "hs_pure": _gram_hs_pure,
    "hs": _gram_hs,
}
METRICS = tuple(_BUILDERS)
assert set(METRICS) == set(METRIC_RECORDS), "a metric without its record in .records"


def gram_x(metric: str, X: np.ndarray, layout: Layout, out: np.ndarray | None = None,
           order: float = PAPER_ORDER) -> np.ndarray:
    """Gram matrix ``A`` of the stacked vertex array (private fast path used by the engine).

    ``out``: an (N, N) float64 array to overwrite with ``hs``/``hs_pure`` (the flow passes the
    previous iterate's: a fresh 72 MB array at 3000 vertices costs 27 ms of page faults).
    ``order``: the order s in (1, 2) of ``hs`` and ``hs_pure`` (:func:`gram_matrix`)."""
    if metric not in _BUILDERS:
        raise ValueError(f"unknown metric {metric!r}; choose one of {', '.join(METRICS)}")
    order = check_order(order) if metric in ORDERED_METRICS else PAPER_ORDER
    E, ln = _lengths(X, layout)
    total = float(ln.sum())
    A = _BUILDERS[metric](X, layout, ln, total, out, order)
    _add_barycenter_term(A, ln, layout, total, order)
    return A


def gram_matrix(metric: str, P, closed=True, order: float = PAPER_ORDER) -> np.ndarray:
    """Gram matrix of one coordinate for the given metric.

    Parameters
    ----------
    metric : {"l2", "h1", "h2", "hs_pure", "hs"}
        ``hs`` is the paper's geometric W^{s,2} metric (the default of the flow), ``hs_pure``
        its top-order part alone; ``l2``, ``h1``, ``h2`` are the classical metrics for comparison.
    P : (N, 3) array or list of arrays
        Closed polygon or link.
    closed : bool or sequence of bool
        False for an open polyline (one flag per component of a link, or one for all):
        docs/api.md, "Open curves".
    order : float in (1, 2)
        The order s of ``hs`` and ``hs_pure``: 3/2 (the paper's, the Möbius energy's) or the
        tangent-point energy's ``(β − 1)/α``; the other metrics ignore it.

    Returns
    -------
    (N, N) array
        Symmetric positive definite ``A`` with ``G = A ⊗ I₃``; entries scale as
        ``length^(1−2s)`` (1/length² for all but hs and hs_pure of order s ≠ 3/2).
    """
    if metric not in METRICS:
        raise ValueError(f"unknown metric {metric!r}; choose one of {', '.join(METRICS)}")
    order = check_order(order) if metric in ORDERED_METRICS else PAPER_ORDER
    X, layout, k = as_checked_layout(P, closed)
    n = layout.n
    # the matrix itself, and room for its assembly (measured 7.9 bytes per entry at 3 000)
    check_memory(16.0 * n * n, f"the {n} x {n} Gram matrix",
                 "resample the curve to fewer vertices (core.resample(P, n))")
    A = gram_x(metric, X, layout, order=order)
    if not k:
        return A
    if order == PAPER_ORDER:
        out = np.ldexp(A, -2 * k)  # A(2^k X) = 4^-k A(X)
    else:
        out = A * 2.0 ** (k * (1.0 - 2.0 * order))  # A(2^k X) = 2^(k(1−2s)) A(X)
    if not np.isfinite(out).all() or np.any((out == 0) & (A != 0)):
        raise ValueError("the Gram matrix of a curve this size is outside the float64 range "
                         "(its entries scale as a power of the length); scale the curve "
                         "towards size 1")
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
    return rows, cols, vals, barycenter_beta(ln, layout, total)
