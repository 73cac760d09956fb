"""Möbius energy of layouts with open components (docs/api.md, "Open curves").

A closed component keeps the energy of :mod:`.moebius_dense` (``4 + Σ`` of the
Ishizeki–Nagasawa integrand over ordered pairs of disjoint edges). That form and its constant
4 come from the decomposition of the energy of a *closed* curve; for an open polyline the
energy is O'Hara's regularized form itself, with the midpoint rule:

    E_open(P) = Σ_{(I,J) ordered, disjoint} l_I l_J (1/|m_I − m_J|² − 1/D_IJ²)

``D_IJ`` the arc length between the two midpoints along the polyline (``l_I/2 + Σ_{I<K<J} l_K
+ l_J/2``; no way round the ends). Disjoint: the edges share no vertex, ``|I − J| ≥ 2``. Every
term is ≥ 0 (a chord is never longer than the arc), and 0 exactly for pairs on one straight
line: a straight polyline has energy 0. Between components, as for links of closed curves,
the O'Hara kernel ``l_I l_J / |m_I − m_J|²``.

The gradient is exact: the ``1/D²`` terms depend on the lengths of every edge between I and
J, ``∂D_IJ/∂l_K = 1`` for ``I < K < J`` (1/2 for I and J). Each pair adds ``2 l_I l_J / D³``
to every K strictly between them; that is a difference array (``+h`` at ``I + 1``, ``−h`` at
``J``) summed once at the end, so the whole gradient stays O(N²).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ..geometry.layout import Layout
from ._dense import CHUNKS, FASTMATH, edge_data, row_range
from .moebius import CLOSED_CONSTANT, FOLDED, SPLIT, link_pair, open_pair, pair


@nb.njit(cache=True, parallel=True, fastmath=FASTMATH)
def _open_parts(ex, ey, ez, mx, my, mz, ln, arc, starts, comp, closed, real, grad, nchunks):
    """Row sums of the unordered pair sum, and with ``grad`` its partial derivatives per edge:
    rows 0–2 the edge vector (closed components' kernel), 3–5 the midpoint, 6 the length, 7 the
    difference array of the ``1/D²`` terms' length derivatives (see the module docstring)."""
    n = ln.shape[0]
    rows = np.zeros(n)
    buf = np.zeros((nchunks, 8 if grad else 0, n))
    half = (n + 1) // 2
    for cc in nb.prange(nchunks):
        ch = np.int64(cc)
        b = buf[ch]
        for k in range(ch, half, nchunks):
            for side in range(2):
                i = k if side == 0 else n - 1 - k
                if side == 1 and i == k:
                    break
                if not real[i]:
                    continue
                c = comp[i]
                s0 = starts[c]
                s1 = starts[c + 1]
                ax, ay, az, li = ex[i], ey[i], ez[i], ln[i]
                px, py, pz = mx[i], my[i], mz[i]
                s = 0.0
                gax = gay = gaz = gmx = gmy = gmz = gl = 0.0
                if closed[c]:  # the Ishizeki–Nagasawa kernel of moebius_dense.py
                    lo, hi = row_range(i, s0, s1)
                    for j in range(lo, hi):
                        bx, by, bz, lj = ex[j], ey[j], ez[j], ln[j]  # loads first (moebius_dense)
                        dx = px - mx[j]
                        dy = py - my[j]
                        dz = pz - mz[j]
                        f, fax, fay, faz, fbx, fby, fbz, fdx, fdy, fdz, _, _ = pair(
                            dx, dy, dz, ax, ay, az, bx, by, bz, li, lj,
                            dx * dx + dy * dy + dz * dz, FOLDED)
                        s += f
                        if grad:
                            gax += fax
                            gay += fay
                            gaz += faz
                            gmx += fdx
                            gmy += fdy
                            gmz += fdz
                            b[0, j] += fbx
                            b[1, j] += fby
                            b[2, j] += fbz
                            b[3, j] -= fdx
                            b[4, j] -= fdy
                            b[5, j] -= fdz
                else:  # O'Hara's regularized kernel along the polyline (j < s1 − 1: real)
                    for j in range(i + 2, s1 - 1):
                        lj = ln[j]
                        dx = px - mx[j]
                        dy = py - my[j]
                        dz = pz - mz[j]
                        f, cd, wi, wj, h = open_pair(li, lj, dx * dx + dy * dy + dz * dz,
                                                     arc[j] - arc[i], SPLIT)
                        s += f
                        if grad:
                            gl += wi
                            b[6, j] += wj
                            b[7, i + 1] += 2.0 * h
                            b[7, j] -= 2.0 * h
                            gmx += cd * dx
                            gmy += cd * dy
                            gmz += cd * dz
                            b[3, j] -= cd * dx
                            b[4, j] -= cd * dy
                            b[5, j] -= cd * dz
                for j in range(s1, n):  # other components: O'Hara kernel
                    if not real[j]:
                        continue
                    lj = ln[j]
                    dx = px - mx[j]
                    dy = py - my[j]
                    dz = pz - mz[j]
                    f, _, _, cd, wi, wj = link_pair(li, lj, dx * dx + dy * dy + dz * dz, SPLIT)
                    s += f
                    if grad:
                        gl += wi
                        b[6, j] += wj
                        gmx += cd * dx
                        gmy += cd * dy
                        gmz += cd * dz
                        b[3, j] -= cd * dx
                        b[4, j] -= cd * dy
                        b[5, j] -= cd * dz
                rows[i] = s
                if grad:
                    b[0, i] += gax
                    b[1, i] += gay
                    b[2, i] += gaz
                    b[3, i] += gmx
                    b[4, i] += gmy
                    b[5, i] += gmz
                    b[6, i] += gl
    return rows, buf


def _arc_positions(ln: np.ndarray, layout: Layout) -> np.ndarray:
    """Arc-length position of every edge midpoint from its component's first vertex."""
    arc = np.empty_like(ln)
    for c in range(layout.k):
        s = slice(layout.starts[c], layout.starts[c + 1])
        arc[s] = np.cumsum(ln[s]) - 0.5 * ln[s]
    return arc


def _parts(X: np.ndarray, layout: Layout, grad: bool):
    ed = edge_data(X, layout)
    arc = _arc_positions(ed[6], layout)
    rows, buf = _open_parts(*ed, arc, layout.starts, layout.comp, layout.closed, layout.real,
                            grad, CHUNKS)
    energy = CLOSED_CONSTANT * int(layout.closed.sum()) + 2.0 * float(np.sum(rows))
    return energy, rows, buf, ed


def open_energy_x(X: np.ndarray, layout: Layout) -> float:
    """Energy of a stacked vertex array with open components (``layout.has_open``)."""
    return _parts(X, layout, False)[0]


def open_energy_gradient_x(X: np.ndarray, layout: Layout) -> tuple[float, np.ndarray]:
    """Energy and exact gradient ``(N, 3)`` of a layout with open components."""
    energy, _, buf, ed = _parts(X, layout, True)
    part = buf.sum(axis=0)  # (8, N)
    ln = ed[6]
    real = layout.real
    gl = part[6] + np.cumsum(part[7])  # ∂/∂l_K, the 1/D² terms of every pair around K
    E = np.stack(ed[:3], axis=1)
    inv = np.zeros_like(ln)
    inv[real] = 1.0 / ln[real]
    ga = part[:3].T + (gl * inv)[:, None] * E  # ∂/∂e_I with the length's share (t_I = e_I/l_I)
    gm = part[3:6].T
    # e_I = P[nxt I] − P[I], m_I = (P[I] + P[nxt I]) / 2; factor 2 for ordered pairs. The
    # dummy edges' parts are 0; their nxt repeats a vertex, so only real edges are scattered.
    G = 2.0 * (0.5 * gm - ga)
    G[layout.nxt[real]] += 2.0 * (ga + 0.5 * gm)[real]
    return energy, G
