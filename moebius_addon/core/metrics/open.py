"""The ``hs`` family of Gram matrices for layouts with open components (docs/api.md,
"Open curves"; the closed form is in :mod:`.metrics`).

The same quadratic form as for closed curves, ``Σ_{I,J} w_IJ |(Du)_I − (Du)_J|² + v_IJ |(Mu)_I −
(Mu)_J|²`` over disjoint pairs, with the weights of docs/design.md; on an open component the
pairs are those of the polyline (``|I − J| ≥ 2``, its dummy edge left out, see
:mod:`._layout`) and ``ρ_IJ`` is the arc length between the midpoints along it (no way round
the ends). The order s of the metric enters as in :mod:`.metrics`: ``w_IJ = l_I l_J /
|d|^(2s−1)``, ``v_IJ = w_IJ (1/|d|² − 1/ρ²)``. Nothing else marks the ends: the operators
``D`` and ``M`` are those of the polyline's edges. The matrix is built from the weights as
``2 Dᵀ(diag(W1) − W)D + 2 Mᵀ(diag(V1) − V)M`` with sparse ``D`` and ``M`` in O(N²).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ..geometry.layout import Layout
from .hs_weight import hs_weight


@nb.njit(cache=True, parallel=True, fastmath={"reassoc", "contract", "nsz", "arcp"})
def _weights(mx, my, mz, ln, arc, clen, starts, comp, closed, real, low, expo):
    """``W`` and ``V`` (times ``low``) over every pair of edges, 0 where not disjoint;
    ``expo`` as in :func:`.metrics.kernel_exponent` (None: order 3/2)."""
    n = ln.shape[0]
    W = np.zeros((n, n))
    V = np.zeros((n, n))
    for ii in nb.prange(n):
        i = np.int64(ii)
        if not real[i]:
            continue
        c = comp[i]
        size = starts[c + 1] - starts[c]
        for j in range(n):
            if not real[j]:
                continue
            same = comp[j] == c
            if same:
                gap = abs(j - i)
                if closed[c]:
                    gap = min(gap, size - gap)
                if gap < 2:
                    continue
            dx = mx[i] - mx[j]
            dy = my[i] - my[j]
            dz = mz[i] - mz[j]
            r2 = dx * dx + dy * dy + dz * dz
            w, inv = hs_weight(ln[i], ln[j], r2, expo)
            W[i, j] = w
            if same:
                rho = abs(arc[j] - arc[i])
                if closed[c]:
                    rho = min(rho, clen[c] - rho)
                V[i, j] = low * w * (inv - 1.0 / (rho * rho))
            else:
                V[i, j] = low * w * inv  # 1/ρ² = 0 between components
    return W, V


def _sandwich(K: np.ndarray, a: np.ndarray, b: np.ndarray, nxt: np.ndarray,
              real: np.ndarray) -> np.ndarray:
    """``Rᵀ K R`` for the edge operator ``(Ru)_I = a_I u[I] + b_I u[nxt I]`` (real edges;
    ``a``, ``b`` are 0 at the dummies)."""
    r = np.flatnonzero(real)
    to = nxt[r]  # one real edge ends at each of these vertices
    Y = K * a[None, :]
    Y[:, to] += K[:, r] * b[r][None, :]
    Z = Y * a[:, None]
    Z[to] += Y[r] * b[r][:, None]
    return Z


def open_hs(X: np.ndarray, layout: Layout, ln: np.ndarray, low: float,
            expo: float | None = None) -> np.ndarray:
    """``2 Dᵀ(diag(W1) − W)D + 2 Mᵀ(diag(V1) − V)M`` (the V part times ``low``) of a layout
    with per-component ``closed`` flags, without the barycenter term; ``expo``: the weights'
    power of ``|d|²``, ``s − 1/2`` (None: order 3/2, :func:`.metrics.kernel_exponent`)."""
    real = layout.real
    closed = layout.closed if layout.closed is not None else np.ones(layout.k, bool)
    M = 0.5 * (X[layout.nxt] + X)
    arc = np.empty_like(ln)
    clen = np.empty(layout.k)
    for c in range(layout.k):
        s = slice(layout.starts[c], layout.starts[c + 1])
        cum = np.cumsum(ln[s])
        arc[s] = cum - 0.5 * ln[s]
        clen[c] = cum[-1]
    W, V = _weights(np.ascontiguousarray(M[:, 0]), np.ascontiguousarray(M[:, 1]),
                    np.ascontiguousarray(M[:, 2]), ln, arc, clen, layout.starts, layout.comp,
                    closed, real, float(low), expo)
    inv = np.zeros_like(ln)
    inv[real] = 1.0 / ln[real]
    halves = 0.5 * real
    KW = -W
    KW[np.diag_indices_from(KW)] += W.sum(axis=1)
    KV = -V
    KV[np.diag_indices_from(KV)] += V.sum(axis=1)
    A = 2.0 * _sandwich(KW, -inv, inv, layout.nxt, real)
    A += 2.0 * _sandwich(KV, halves, halves, layout.nxt, real)
    return A
