"""Symmetric cyclic tridiagonal solves in O(n) (private; shared by ``polygon.equalize`` and
the Euclidean projection of ``constraints``)."""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True)
def cyclic_tridiagonal_solve(a, b, r):
    """Solve ``M x = r`` for the symmetric cyclic tridiagonal M with diagonal ``a`` and
    ``M[i, i+1] = M[i+1, i] = b[i]`` (indices mod n): Thomas' algorithm on the tridiagonal
    part, the corners by Sherman–Morrison (Numerical Recipes' ``cyclic``). ``b[n−1] = 0``
    leaves the plain tridiagonal system (``equalize``'s open chains)."""
    n = a.shape[0]
    c = b[n - 1]
    g = -a[0]
    d = a.copy()
    d[0] -= g
    d[n - 1] -= c * c / g
    u = np.zeros(n)
    u[0] = g
    u[n - 1] = c
    # forward elimination on both right-hand sides
    y = r.copy()
    z = u
    w = np.empty(n)
    piv = d[0]
    y[0] /= piv
    z[0] /= piv
    for i in range(1, n):
        w[i] = b[i - 1] / piv
        piv = d[i] - b[i - 1] * w[i]
        y[i] = (y[i] - b[i - 1] * y[i - 1]) / piv
        z[i] = (z[i] - b[i - 1] * z[i - 1]) / piv
    for i in range(n - 2, -1, -1):
        y[i] -= w[i + 1] * y[i + 1]
        z[i] -= w[i + 1] * z[i + 1]
    f = (y[0] + c / g * y[n - 1]) / (1.0 + z[0] + c / g * z[n - 1])
    return y - f * z
