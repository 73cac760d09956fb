"""Knot invariants of a closed polygon, read off a generic planar projection.

The determinant of a knot, ``|Δ(-1)|`` with ``Δ`` its Alexander polynomial, is computed from
the colouring (Alexander) matrix of a diagram: one row per crossing, one column per arc (the
strands between two undercrossings); a crossing whose over-arc is ``a`` and whose under-strand
runs from arc ``b`` into arc ``c`` contributes ``2`` at ``a`` and ``-1`` at ``b`` and ``c``
(the rows of ``(1 - t) a + t b - c`` at ``t = -1``; the sign of the crossing drops out there).
Deleting one row and one column leaves a matrix whose determinant is ``±Δ(-1)`` for every
diagram of the knot (Lickorish, *An Introduction to Knot Theory*, ch. 6), so it does not
depend on the projection. The unknot has determinant 1, every knot of the table up to 9
crossings more (3_1: 3, 4_1: 5, 8_19: 3); the first knots with determinant 1 have 10 crossings
or more (10_124, the Conway knot). So a determinant above 1 proves the curve knotted; 1 means
"no knot detected", not "unknot".

The crossings are found by a sweep over the edges sorted by their smallest x; the determinant
by Gaussian elimination modulo two primes near 2^31 (exact for determinants below 2^61 in
size), both O(c^3) in the crossing count ``c`` of the diagram.
"""

from __future__ import annotations

import numba as nb
import numpy as np

# Two primes below 2^31: products of residues stay below 2^62 in int64.
_PRIMES = (2147483647, 2147483629)
_GENERIC_TRIES = 8


def knot_determinant(P: np.ndarray) -> int:
    """The determinant ``|Δ(-1)|`` of the knot traced by the closed polygon ``P``.

    Parameters
    ----------
    P : (n, 3) array
        Vertices of one closed polygon (the edge from the last vertex back to the first is
        implied). It must not intersect itself.

    Returns
    -------
    int
        1 for the unknot and for a few knots of 10 and more crossings; 3 for the trefoil, 5
        for the figure-eight knot, ... (the same for every projection and every polygon of the
        same knot type).
    """
    P = np.asarray(P, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3 or len(P) < 3:
        raise ValueError(f"expected one closed polygon as an (n, 3) array with n >= 3, got "
                         f"shape {P.shape}")
    if not np.isfinite(P).all():
        raise ValueError("the polygon has NaN or infinite coordinates")
    Q = P - P.mean(axis=0)
    Q /= max(np.abs(Q).max(), np.finfo(float).tiny)  # only the shape matters
    rng = np.random.default_rng(20261125)
    for _ in range(_GENERIC_TRIES):
        R = _rotation(rng)
        X = Q @ R.T
        crossings = _crossings(np.ascontiguousarray(X))
        if crossings is not None:
            return _determinant(_colouring_matrix(crossings, len(X)))
    raise ValueError("no generic projection found: the polygon touches or nearly touches "
                     "itself")


def is_knotted(P: np.ndarray) -> bool:
    """True when the closed polygon ``P`` is certainly knotted (its determinant exceeds 1).

    False means that the determinant did not detect a knot: the unknot, or one of the rare
    knots of determinant 1 (none below 10 crossings)."""
    return knot_determinant(P) != 1


def _rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.diag(r))


# A crossing closer than this (in units of the edge's own parameter) to a vertex, or two
# strands whose heights differ by less than this fraction of the curve's size, make the
# projection non-generic: another rotation is tried.
_PARAM_MARGIN = 1e-9
_HEIGHT_MARGIN = 1e-12


def _crossings(X: np.ndarray):
    """Crossings of the projection of ``X`` to the xy-plane as rows ``(over position,
    under position)``, a position being ``edge index + parameter along the edge``; None when
    the projection is not generic."""
    found = _sweep(X)
    if found.shape[0] and (found[:, 2] < 0.0).any():
        return None
    return found[:, :2]


@nb.njit(cache=True)
def _sweep(X):
    n = X.shape[0]
    lo = np.empty(n)
    hi = np.empty(n)
    for i in range(n):
        a, b = X[i, 0], X[(i + 1) % n, 0]
        lo[i] = min(a, b)
        hi[i] = max(a, b)
    order = np.argsort(lo, kind="mergesort")
    span = 0.0
    for k in range(3):
        span = max(span, X[:, k].max() - X[:, k].min())
    rows = [(0.0, 0.0, 0.0) for _ in range(0)]
    for oi in range(n):
        i = order[oi]
        ax, ay, az = X[i, 0], X[i, 1], X[i, 2]
        j1 = (i + 1) % n
        dx, dy, dz = X[j1, 0] - ax, X[j1, 1] - ay, X[j1, 2] - az
        for oj in range(oi + 1, n):
            j = order[oj]
            if lo[j] > hi[i]:
                break
            if j == (i + 1) % n or i == (j + 1) % n:
                continue
            bx, by, bz = X[j, 0], X[j, 1], X[j, 2]
            k1 = (j + 1) % n
            ex, ey, ez = X[k1, 0] - bx, X[k1, 1] - by, X[k1, 2] - bz
            den = dx * ey - dy * ex
            qx, qy = bx - ax, by - ay
            if den == 0.0:
                continue
            s = (qx * ey - qy * ex) / den
            t = (qx * dy - qy * dx) / den
            if s < -_PARAM_MARGIN or s > 1.0 + _PARAM_MARGIN or t < -_PARAM_MARGIN \
                    or t > 1.0 + _PARAM_MARGIN:
                continue
            near = (s < _PARAM_MARGIN or s > 1.0 - _PARAM_MARGIN or t < _PARAM_MARGIN
                    or t > 1.0 - _PARAM_MARGIN)
            zi = az + s * dz
            zj = bz + t * ez
            flag = -1.0 if near or abs(zi - zj) <= _HEIGHT_MARGIN * span else 1.0
            if zi > zj:
                rows.append((i + s, j + t, flag))
            else:
                rows.append((j + t, i + s, flag))
    out = np.empty((len(rows), 3))
    for k in range(len(rows)):
        out[k, 0], out[k, 1], out[k, 2] = rows[k]
    return out


def _colouring_matrix(crossings: np.ndarray, n: int) -> np.ndarray:
    """The (c, c) colouring matrix of the diagram: row ``k`` for the crossing whose
    under-position is the ``k``-th along the curve; arc ``k`` runs from that undercrossing to
    the next one."""
    c = len(crossings)
    if c == 0:
        return np.zeros((0, 0), dtype=np.int64)
    order = np.argsort(crossings[:, 1], kind="stable")
    under = crossings[order, 1]
    over = crossings[order, 0]
    # the arc holding a position: the last undercrossing at or before it, cyclically
    over_arc = (np.searchsorted(under, over, side="right") - 1) % c
    M = np.zeros((c, c), dtype=np.int64)
    rows = np.arange(c)
    np.add.at(M, (rows, over_arc), 2)
    np.add.at(M, (rows, (rows - 1) % c), -1)  # the arc arriving at the undercrossing
    np.add.at(M, (rows, rows), -1)  # the arc leaving it
    return M


def _determinant(M: np.ndarray) -> int:
    """``|det|`` of ``M`` without its first row and column, exact below 2^61."""
    A = np.ascontiguousarray(M[1:, 1:])
    if A.shape[0] == 0:
        return 1
    r = [_det_mod(A, p) for p in _PRIMES]
    p, q = _PRIMES
    # Chinese remainder: the value modulo p*q, then the representative nearest zero
    x = (r[0] + p * ((r[1] - r[0]) * pow(p, -1, q) % q)) % (p * q)
    return abs(x - p * q if x > p * q // 2 else x)


@nb.njit(cache=True)
def _det_mod(A, p):
    n = A.shape[0]
    B = np.empty((n, n), dtype=np.int64)
    for i in range(n):
        for j in range(n):
            B[i, j] = A[i, j] % p
    det = 1
    for k in range(n):
        piv = -1
        for i in range(k, n):
            if B[i, k] != 0:
                piv = i
                break
        if piv < 0:
            return 0
        if piv != k:
            for j in range(n):
                B[k, j], B[piv, j] = B[piv, j], B[k, j]
            det = (p - det) % p
        det = det * B[k, k] % p
        inv = _inverse_mod(B[k, k], p)
        for i in range(k + 1, n):
            f = B[i, k] * inv % p
            if f != 0:
                for j in range(k, n):
                    B[i, j] = (B[i, j] - f * B[k, j]) % p
    return det


@nb.njit(cache=True)
def _inverse_mod(a, p):
    # Fermat: a^(p-2) mod p, by squaring
    result, base, e = 1, a % p, p - 2
    while e > 0:
        if e & 1:
            result = result * base % p
        base = base * base % p
        e >>= 1
    return result
