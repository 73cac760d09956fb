"""The discrete tangent-point energy and its exact derivative, summed over every pair
(docs/design.md, "Tangent-point energy"; the pair kernel is :func:`.energies.tangent_point.pair`).

    E(P) = Σ_{(I, J) ordered, disjoint} l_I l_J |T_I × (m_I − m_J)|^α / |m_I − m_J|^β

Disjoint: not the same edge and not neighbours along a component (closed: cyclically; open:
the first and last edge are no neighbours, the dummy edge slot of an open component is no
edge); every pair of edges of different components counts. The kernel is not symmetric, so
each row ``I`` sums its own ordered pairs; the derivatives a pair gives its second edge ``J``
(midpoint and length) go to ``CHUNKS`` fixed buffers, the rows dealt to them round-robin:
the same bits for every thread count. The public evaluators are :func:`..engine.energy` and
:func:`..engine.energy_gradient`.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ..geometry.layout import Layout
from ._dense import CHUNKS, FASTMATH, edge_data
from .tangent_point import (
    DEFAULT_ALPHA,
    DEFAULT_BETA,
    KIND_2,
    KIND_2_4,
    KIND_2_45,
    KIND_GENERAL,
    check_exponents,
    kind_of,
    pair,
)


@nb.njit(cache=True, inline="always")
def _segment(i, lo, hi, ex, ey, ez, mx, my, mz, ln, b, alpha, beta, kind, grad, acc):
    """Row ``i`` against the edges ``lo ≤ j < hi``: its energy and the partials in its own
    edge vector and midpoint added to ``acc`` (7), those of each ``j`` (midpoint, length) to
    the buffer ``b``."""
    ax, ay, az, li = ex[i], ey[i], ez[i], ln[i]
    il = 1.0 / li
    px, py, pz = mx[i], my[i], mz[i]
    s = acc[0]
    gax, gay, gaz, gmx, gmy, gmz = acc[1], acc[2], acc[3], acc[4], acc[5], acc[6]
    for j in range(lo, hi):
        dx = px - mx[j]
        dy = py - my[j]
        dz = pz - mz[j]
        f, fax, fay, faz, fdx, fdy, fdz, fl = pair(
            dx, dy, dz, ax, ay, az, li, il, ln[j], dx * dx + dy * dy + dz * dz, alpha, beta, kind)
        s += f
        if grad:
            gax += fax
            gay += fay
            gaz += faz
            gmx += fdx
            gmy += fdy
            gmz += fdz
            b[3, j] -= fdx
            b[4, j] -= fdy
            b[5, j] -= fdz
            b[6, j] += fl
    acc[0] = s
    acc[1], acc[2], acc[3], acc[4], acc[5], acc[6] = gax, gay, gaz, gmx, gmy, gmz


@nb.njit(cache=True, parallel=True, fastmath=FASTMATH)
def _tp_parts(ex, ey, ez, mx, my, mz, ln, starts, comp, closed, alpha, beta, kind, grad,
              nchunks):
    """Row sums ``Σ_J f_IJ`` and, with ``grad``, per chunk the partials of the ordered sum in
    every edge vector (rows 0–2, with their length terms, but for the ``∂/∂l_J`` of row 6),
    midpoint (3–5) and length (6)."""
    n = ln.shape[0]
    k = starts.shape[0] - 1
    rows = np.zeros(n)
    buf = np.zeros((nchunks, 7 if grad else 0, n))
    for cc in nb.prange(nchunks):
        ch = np.int64(cc)  # prange indices may be unsigned; keep index arithmetic signed
        b = buf[ch]
        acc = np.empty(7)
        for i in range(ch, n, nchunks):
            c = comp[i]
            if not closed[c] and i == starts[c + 1] - 1:
                continue  # the dummy slot of an open component
            acc[:] = 0.0
            for c2 in range(k):
                t0 = starts[c2]
                t1 = starts[c2 + 1] if closed[c2] else starts[c2 + 1] - 1
                if c2 != c:
                    lo1, hi1, lo2, hi2 = t0, t1, t1, t1
                elif closed[c]:  # cyclic neighbours i − 1 and i + 1 left out
                    lo1 = t0 + 1 if i == t1 - 1 else t0
                    hi1 = i - 1
                    lo2 = i + 2
                    hi2 = t1 - 1 if i == t0 else t1
                else:  # open: no way round the ends
                    lo1, hi1, lo2, hi2 = t0, i - 1, i + 2, t1
                for seg in range(2):
                    lo = lo1 if seg == 0 else lo2
                    hi = hi1 if seg == 0 else hi2
                    if kind == KIND_2_4:
                        _segment(i, lo, hi, ex, ey, ez, mx, my, mz, ln, b, alpha, beta,
                                 KIND_2_4, grad, acc)
                    elif kind == KIND_2_45:
                        _segment(i, lo, hi, ex, ey, ez, mx, my, mz, ln, b, alpha, beta,
                                 KIND_2_45, grad, acc)
                    elif kind == KIND_2:
                        _segment(i, lo, hi, ex, ey, ez, mx, my, mz, ln, b, alpha, beta, KIND_2,
                                 grad, acc)
                    else:
                        _segment(i, lo, hi, ex, ey, ez, mx, my, mz, ln, b, alpha, beta,
                                 KIND_GENERAL, grad, acc)
            rows[i] = acc[0]
            if grad:
                for r in range(6):
                    b[r, i] += acc[1 + r]
    return rows, buf


def _parts(X: np.ndarray, layout: Layout, alpha: float, beta: float, grad: bool):
    alpha, beta = check_exponents(alpha, beta)
    ed = edge_data(X, layout)
    closed = (np.ones(layout.k, dtype=np.bool_) if layout.closed is None
              else np.asarray(layout.closed, dtype=np.bool_))
    rows, buf = _tp_parts(*ed, layout.starts, layout.comp, closed, alpha, beta,
                          kind_of(alpha, beta), grad, CHUNKS)
    return float(np.sum(rows)), buf, ed


def tp_energy_x(X: np.ndarray, layout: Layout, alpha: float = DEFAULT_ALPHA,
                beta: float = DEFAULT_BETA) -> float:
    """Tangent-point energy of the stacked vertex array (closed, link or open components)."""
    return _parts(X, layout, alpha, beta, False)[0]


def tp_energy_gradient_x(X: np.ndarray, layout: Layout, alpha: float = DEFAULT_ALPHA,
                         beta: float = DEFAULT_BETA) -> tuple[float, np.ndarray]:
    """Tangent-point energy and its exact gradient ``(N, 3)`` of the stacked vertex array."""
    energy, buf, ed = _parts(X, layout, alpha, beta, True)
    part = buf.sum(axis=0)  # (7, N)
    ln = ed[6]
    real = layout.real if layout.has_open else np.ones(layout.n, dtype=bool)
    inv = np.zeros_like(ln)
    inv[real] = 1.0 / ln[real]
    E = np.stack(ed[:3], axis=1)
    ga = part[:3].T + (part[6] * inv)[:, None] * E  # ∂l_J/∂e_J = e_J / l_J
    gm = part[3:6].T
    # e_I = P[nxt I] − P[I], m_I = (P[I] + P[nxt I]) / 2; only real edges are scattered (the
    # dummy's nxt repeats its vertex, and its parts are 0)
    G = 0.5 * gm - ga
    G[layout.nxt[real]] += (ga + 0.5 * gm)[real]
    return energy, G
