"""Discrete Möbius energy and its exact derivative (docs/design.md, "Energy").

Midpoint rule for the Ishizeki–Nagasawa integrand over ordered pairs of disjoint edges::

    E(P) = 4 + Σ_{(I,J) disjoint} (l_I l_J + <e_I, e_J>) / |d|² − 2 <d, e_I> <d, e_J> / |d|⁴

with ``d = m_I − m_J``; between components of a link the O'Hara kernel ``l_I l_J / |d|²``.
The sum is symmetric, so the kernels visit each unordered pair once and double it. The pair
terms are :mod:`.energies.moebius`'s; the public evaluators, which choose between this exact
sum and the tree (:mod:`.barnes_hut`) by the engine's name, are in :mod:`.engine`.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ..geometry.layout import Layout
from ._dense import CHUNKS, FASTMATH, edge_data, row_range
from .moebius import CLOSED_CONSTANT, FOLDED, VALUE, link_pair, pair
from .moebius_open import open_energy_gradient_x, open_energy_x


@nb.njit(cache=True, parallel=True, fastmath=FASTMATH)
def _energy_rows(ex, ey, ez, mx, my, mz, ln, starts, comp):
    """Per-row sums Σ_{J>I, disjoint} f_IJ (unordered pairs)."""
    n = ln.shape[0]
    rows = np.zeros(n)
    half = (n + 1) // 2
    for kk in nb.prange(half):
        k = np.int64(kk)  # prange indices may be unsigned; keep index arithmetic signed
        for side in range(2):
            i = k if side == 0 else n - 1 - k
            if side == 1 and i == k:
                break
            c = comp[i]
            lo, hi = row_range(i, starts[c], starts[c + 1])
            ax, ay, az, li = ex[i], ey[i], ez[i], ln[i]
            px, py, pz = mx[i], my[i], mz[i]
            s = 0.0
            for j in range(lo, hi):
                dx = px - mx[j]
                dy = py - my[j]
                dz = pz - mz[j]
                s += pair(dx, dy, dz, ax, ay, az, ex[j], ey[j], ez[j], li, ln[j],
                          dx * dx + dy * dy + dz * dz, VALUE)[0]
            for j in range(starts[c + 1], n):
                dx = px - mx[j]
                dy = py - my[j]
                dz = pz - mz[j]
                s += link_pair(li, ln[j], dx * dx + dy * dy + dz * dz, VALUE)[0]
            rows[i] = s
    return rows


@nb.njit(cache=True, parallel=True, fastmath=FASTMATH)
def _energy_gradient_parts(ex, ey, ez, mx, my, mz, ln, starts, comp, nchunks):
    """Row sums of f and the partial derivatives of Σ_{I<J} f_IJ with respect to every edge
    vector (ga) and midpoint (gm), accumulated in ``nchunks`` fixed buffers."""
    n = ln.shape[0]
    rows = np.zeros(n)
    buf = np.zeros((nchunks, 6, n))
    half = (n + 1) // 2
    for cc in nb.prange(nchunks):
        ch = np.int64(cc)  # prange indices may be unsigned; keep index arithmetic signed
        b = buf[ch]
        for k in range(ch, half, nchunks):
            for side in range(2):
                i = k if side == 0 else n - 1 - k
                if side == 1 and i == k:
                    break
                c = comp[i]
                lo, hi = row_range(i, starts[c], starts[c + 1])
                ax, ay, az, li = ex[i], ey[i], ez[i], ln[i]
                px, py, pz = mx[i], my[i], mz[i]
                s = 0.0
                gax = gay = gaz = gmx = gmy = gmz = 0.0
                for j in range(lo, hi):
                    # loads in this order: under reassociation LLVM ranks values by it (the
                    # bits of the energy's sum depend on it)
                    bx, by, bz, lj = ex[j], ey[j], ez[j], ln[j]
                    dx = px - mx[j]
                    dy = py - my[j]
                    dz = pz - mz[j]
                    # f, ∂f/∂e_I, ∂f/∂e_J, ∂f/∂d (d = m_I − m_J)
                    f, fax, fay, faz, fbx, fby, fbz, fdx, fdy, fdz, _, _ = pair(
                        dx, dy, dz, ax, ay, az, bx, by, bz, li, lj, dx * dx + dy * dy + dz * dz,
                        FOLDED)
                    s += f
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
                for j in range(starts[c + 1], n):
                    bx, by, bz, lj = ex[j], ey[j], ez[j], ln[j]
                    dx = px - mx[j]
                    dy = py - my[j]
                    dz = pz - mz[j]
                    f, ci, cj, cd, _, _ = link_pair(li, lj, dx * dx + dy * dy + dz * dz, FOLDED)
                    s += f
                    gax += ci * ax
                    gay += ci * ay
                    gaz += ci * az
                    gmx += cd * dx
                    gmy += cd * dy
                    gmz += cd * dz
                    b[0, j] += cj * bx
                    b[1, j] += cj * by
                    b[2, j] += cj * bz
                    b[3, j] -= cd * dx
                    b[4, j] -= cd * dy
                    b[5, j] -= cd * dz
                rows[i] = s
                b[0, i] += gax
                b[1, i] += gay
                b[2, i] += gaz
                b[3, i] += gmx
                b[4, i] += gmy
                b[5, i] += gmz
    return rows, buf


def _energy_from_rows(rows: np.ndarray, layout: Layout) -> float:
    # E = 4 per component + Σ over ordered pairs = 4K + 2 Σ over unordered pairs.
    return CLOSED_CONSTANT * layout.k + 2.0 * float(np.sum(rows))


def energy_x(X: np.ndarray, layout: Layout) -> float:
    """Energy of the stacked vertex array (private fast path used by the flow)."""
    if layout.closed is not None:
        return open_energy_x(X, layout)
    ed = edge_data(X, layout)
    return _energy_from_rows(_energy_rows(*ed, layout.starts, layout.comp), layout)


def energy_gradient_x(X: np.ndarray, layout: Layout) -> tuple[float, np.ndarray]:
    """Energy and exact gradient ``(N, 3)`` of the stacked vertex array."""
    if layout.closed is not None:
        return open_energy_gradient_x(X, layout)
    ed = edge_data(X, layout)
    rows, buf = _energy_gradient_parts(*ed, layout.starts, layout.comp, CHUNKS)
    part = buf.sum(axis=0)  # (6, N): ∂/∂e_I then ∂/∂m_I of the unordered sum
    ga = part[:3].T
    gm = part[3:].T
    # e_I = P[nxt I] − P[I], m_I = (P[I] + P[nxt I]) / 2; factor 2 for ordered pairs.
    G = 2.0 * (0.5 * gm - ga)
    G[layout.nxt] += 2.0 * (ga + 0.5 * gm)  # nxt is a permutation: no repeated index
    return _energy_from_rows(rows, layout), G
