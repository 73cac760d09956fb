"""Knot and link invariants of closed polygons, read off a generic planar projection.

A projection to a plane is a diagram: crossings, each with an over- and an under-strand and a
sign, and arcs, the strands between two undercrossings. Its Alexander matrix has one row per
crossing and one column per arc; a crossing whose over-arc is ``k`` and whose under-strand
runs from arc ``i`` into arc ``j`` has the row ``(1 - t) k + t i - j`` when it is positive and
``(1 - t) k - i + t j`` when it is negative (Fox derivatives of the Wirtinger relations).
Deleting one row and one column leaves a matrix whose determinant is the Alexander polynomial
``Δ(t)`` up to a factor ``±t^m``, the same for every diagram of the knot or link (Lickorish,
*An Introduction to Knot Theory*, ch. 6); ``|Δ(-1)|`` is the determinant. The unknot has
``Δ = 1``; so do a few knots of 11 and more crossings (11n_34, the Conway knot), and the
determinant is 1 for a few from 10 crossings on (10_124), so a non-trivial value proves the
curve knotted, a trivial one only fails to detect a knot. Linking numbers are half the sum of
the signs of the crossings between two components.

The crossings are found by a sweep over the edges sorted by their smallest x; of a dozen
random projections the generic one with the fewest crossings is used. Determinants are taken
by Gaussian elimination modulo two primes near 2^31 (exact below 2^61 in size); ``Δ(t)`` by
interpolating the determinant at ``c`` points. Cost O(c^3) for the determinant and O(c^4) for
``Δ(t)`` in the crossing count ``c`` (relaxed curves of up to 12 crossings have a few dozen).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from ..geometry.layout import as_unit_layout, check_distinct
from . import goeritz, jones
from .pd import DisjointSets, PlanarDiagram, from_passages, simplify

# Two primes below 2^31: products of residues stay below 2^62 in int64.
_PRIMES = (2147483647, 2147483629)
_PROJECTIONS = 12
# Projections (those with the fewest crossings) simplified by planar_diagram.
_SIMPLIFIED = 4
# Alexander and Jones polynomials of diagrams with more crossings are not attempted (O(c^4);
# the Jones sum of a 614-crossing diagram ran 135 s before it gave up on its state budget).
MAX_ALEXANDER_CROSSINGS = 200
# Projections with more crossings than this in every direction tried are not simplified:
# simplification costs about c² (a closed 3 000-step random walk, 2 735 crossings at best:
# 9 s for its four diagrams, down to 614 crossings). Table curves have at most a few dozen.
MAX_PROJECTION_CROSSINGS = 2000


@dataclass(frozen=True)
class Diagram:
    """Crossings of a generic projection of a knot or link.

    ``over`` and ``under`` are positions along the curve (vertex index + parameter along the
    edge, vertices numbered through all components), ``sign`` is +1 for a positive
    (right-handed) crossing, ``starts`` the first vertex of each component, then N."""

    over: np.ndarray
    under: np.ndarray
    sign: np.ndarray
    starts: np.ndarray

    @property
    def crossings(self) -> int:
        return len(self.over)

    def component(self, position: np.ndarray) -> np.ndarray:
        return np.searchsorted(self.starts, position, side="right") - 1


def _projections(P, seed: int = 0):
    """Generic projections of ``P`` in a dozen seeded random directions: ``(layout, rows)``
    with the rows of :func:`_sweep` of each direction where no crossing is degenerate.
    ``seed`` picks another dozen. The curve is taken at a size near 1 (exact scaling), as
    the other checks take it: the check of repeated points measures edges by their squares,
    which underflow for a curve 1e-200 across."""
    X, layout, _ = as_unit_layout(P)
    if not np.isfinite(X).all():
        raise ValueError("the curve has NaN or infinite coordinates")
    if (np.diff(layout.starts) < 3).any():
        raise ValueError("every component needs at least 3 vertices")
    check_distinct(X, layout)  # a collapsed curve projects to a diagram of the wrong knot
    Q = X - X.mean(axis=0)
    Q /= max(np.abs(Q).max(), np.finfo(float).tiny)  # only the shape matters
    rng = np.random.default_rng(20261125 + seed)
    found = []
    for _ in range(_PROJECTIONS):
        q, r = np.linalg.qr(rng.normal(size=(3, 3)))
        q = q * np.sign(np.diag(r))
        # a rotation, not a reflection: with det -1 (half the draws) the projection showed
        # the mirror image, which flipped linking numbers and the Jones polynomial
        q[:, 2] *= np.sign(np.linalg.det(q))
        rows = _sweep(np.ascontiguousarray(Q @ q.T), layout.nxt)
        if not (rows[:, 3] == 0).any():  # no crossing at a vertex or of touching strands
            found.append(rows)
    if not found:
        raise ValueError("no generic projection found: the curve touches or nearly touches "
                         "itself")
    return layout, found


def _as_diagram(rows, starts) -> Diagram:
    return Diagram(rows[:, 0].copy(), rows[:, 1].copy(), rows[:, 2].astype(np.int64), starts)


def diagram(P) -> Diagram:
    """The generic projection of the knot or link ``P`` with the fewest crossings among a dozen
    random directions (the same for every call: the directions are seeded)."""
    layout, found = _projections(P)
    return _as_diagram(min(found, key=len), layout.starts)


def planar_diagram(P, seed: int = 0) -> PlanarDiagram:
    """A PD code of the knot or link ``P``: of the generic projections of :func:`diagram`'s
    directions, simplified by Reidemeister I and II moves (:func:`pd.simplify`), the one with
    the fewest crossings left (``seed``: another dozen directions, for another diagram of the
    same curve). A ``PlanarDiagram`` is returned as it is."""
    if isinstance(P, PlanarDiagram):
        return P
    layout, found = _projections(P, seed)
    found.sort(key=len)
    if len(found[0]) > MAX_PROJECTION_CROSSINGS:
        raise ValueError(f"every projection tried has more than {MAX_PROJECTION_CROSSINGS} "
                         f"crossings ({len(found[0])} at best), too many to simplify; relax "
                         f"the curve first (the flow keeps its knot type)")
    best = None
    for rows in found[:_SIMPLIFIED]:
        d = simplify(from_passages(rows[:, 0], rows[:, 1], rows[:, 2].astype(np.int64),
                                   layout.starts)[0])
        if best is None or d.crossings < best.crossings:
            best = d
    return best


def determinant(P) -> int:
    """The determinant ``|Δ(-1)|`` of the knot or link traced by the closed polygon(s) ``P``.

    Parameters
    ----------
    P : (n, 3) array or list of them, or a :class:`~.pd.PlanarDiagram`
        A closed polygon (the edge from the last vertex back to the first is implied) or a
        link; it must not touch itself.

    Returns
    -------
    int
        1 for the unknot, 3 for the trefoil, 5 for the figure-eight knot, 2 for the Hopf link,
        0 for a split link (the same for every polygon of one knot or link type).
    """
    A0, A1 = _alexander_matrix(planar_diagram(P))
    if A0 is None:
        return 0
    return _exact(A0 - A1, lambda A, p: _det_mod(A, p))


def knot_determinant(P: np.ndarray) -> int:
    """:func:`determinant` of one closed polygon (an ``(n, 3)`` array; lists are refused)."""
    P = np.asarray(P, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3 or len(P) < 3:
        raise ValueError(f"expected one closed polygon as an (n, 3) array with n >= 3, got "
                         f"shape {P.shape}")
    return determinant(P)


def is_knotted(P: np.ndarray) -> bool:
    """True when the closed polygon ``P`` is certainly knotted (its determinant exceeds 1).

    False means that the determinant did not detect a knot: the unknot, or one of the rare
    knots of determinant 1 (none below 10 crossings)."""
    return knot_determinant(P) != 1


def alexander_polynomial(P) -> list[int]:
    """Coefficients of the Alexander polynomial ``Δ(t)`` of a knot (or the one-variable
    polynomial of a link), lowest degree first, normalized as KnotInfo writes it: the lowest
    power is ``t^0`` and its coefficient positive (3_1: ``[1, -1, 1]``, 4_1: ``[1, -3, 1]``,
    the unknot ``[1]``, a split link ``[0]``). ``P`` may be a :class:`~.pd.PlanarDiagram`."""
    d = _small_diagram(P)
    A0, A1 = _alexander_matrix(d)
    if A0 is None:
        return [0]
    m = A0.shape[0]  # the determinant of an m x m matrix linear in t: degree at most m
    coeffs = _exact((A0, A1), lambda A, p: _interpolate(A[0], A[1], m, p), vector=True)
    nz = np.flatnonzero(coeffs)
    if len(nz) == 0:
        return [0]
    c = coeffs[nz[0]: nz[-1] + 1]
    return [int(x) for x in (c if c[0] > 0 else -c)]


def jones_polynomial(P, max_states: int = jones.MAX_STATES) -> tuple[float, list[int]]:
    """The Jones polynomial ``V(t) = Σ_k c_k t^(low + k)`` as ``(low, [c_0, c_1, …])``, in
    KnotInfo's and LinkInfo's convention (3_1: ``(1, [1, 0, 1, -1])``, i.e. ``t + t³ − t⁴``;
    the unknot ``(0, [1])``; the positive Hopf link ``(0.5, [-1, 0, -1])``: links with an even
    number of components have half-integer powers). ``P`` may be a :class:`~.pd.PlanarDiagram`.

    Kauffman's bracket summed tangle by tangle (:mod:`.jones`) on the simplified diagram of
    :func:`planar_diagram`; a diagram that needs more than ``max_states`` intermediate states
    raises :class:`~.jones.TooComplex` (a ``ValueError``)."""
    return laurent(jones.jones(_small_diagram(P), max_states))


def _small_diagram(P) -> PlanarDiagram:
    """:func:`planar_diagram`, refused above :data:`MAX_ALEXANDER_CROSSINGS` crossings."""
    d = planar_diagram(P)
    if d.crossings > MAX_ALEXANDER_CROSSINGS:
        raise ValueError(f"every projection tried has more than {MAX_ALEXANDER_CROSSINGS} "
                         f"crossings after simplification ({d.crossings} at best); relax the "
                         f"curve first")
    return d


def signature(P) -> int:
    """The signature of the knot or link ``P`` (polygon, list of polygons or a
    :class:`~.pd.PlanarDiagram`), in KnotInfo's and LinkInfo's convention: 3_1 has −2, its
    mirror image 2, the figure-eight knot 0, the positive Hopf link −1. Gordon–Litherland's
    formula on the simplified diagram of :func:`planar_diagram` (:mod:`.goeritz`); the value
    changes sign with the mirror image and, for a link, depends on the orientations."""
    return goeritz.signature(planar_diagram(P))


def laurent(poly: dict[int, int]) -> tuple[float, list[int]]:
    """``{exponent of t^(1/2): coefficient}`` as ``(lowest power of t, coefficients of the
    powers low, low + 1, …)``."""
    lo, hi = min(poly), max(poly)
    if any(e % 2 != lo % 2 for e in poly):
        raise ValueError("powers of t that differ by half-integers")  # pragma: no cover
    coeffs = [poly.get(e, 0) for e in range(lo, hi + 1, 2)]
    return (lo // 2 if lo % 2 == 0 else lo / 2), coeffs


def linking_numbers(P) -> np.ndarray:
    """The (K, K) symmetric integer matrix of linking numbers of the K components of ``P``
    (zero diagonal; the signs follow the components' orientations)."""
    d = diagram(P)
    K = len(d.starts) - 1
    L = np.zeros((K, K), dtype=np.int64)
    a, b = d.component(d.over), d.component(d.under)
    mixed = a != b
    np.add.at(L, (a[mixed], b[mixed]), d.sign[mixed])
    L = L + L.T
    return L // 2


def _alexander_matrix(d: PlanarDiagram):
    """``(A0, A1)`` with ``A0 + t A1`` the Alexander matrix of the diagram ``d`` without its
    first row and column, or ``(None, None)`` when the link splits (a component passes over
    everything, or a loop lies apart: ``Δ = 0``)."""
    c = d.crossings
    K = len(d.components()) + d.loops
    if c == 0:
        if K > 1:
            return None, None
        return np.zeros((0, 0), np.int64), np.zeros((0, 0), np.int64)  # the unknot
    if d.loops:
        return None, None
    # arcs: the edges joined through the crossings they pass over (j and l)
    sets = DisjointSets()
    find = sets.find
    for m in range(c):
        sets.union(int(d.X[m, 1]), int(d.X[m, 3]))
    roots = sorted({find(int(e)) for e in np.unique(d.X)})
    if len(roots) != c:  # a component never passes under: it lies above the rest
        return None, None
    arc = {r: k for k, r in enumerate(roots)}
    over_arc = np.array([arc[find(int(e))] for e in d.X[:, 1]])
    incoming = np.array([arc[find(int(e))] for e in d.X[:, 0]])
    outgoing = np.array([arc[find(int(e))] for e in d.X[:, 2]])
    positive = d.sign > 0
    A0 = np.zeros((c, c), dtype=np.int64)
    A1 = np.zeros((c, c), dtype=np.int64)
    rows = np.arange(c)
    np.add.at(A0, (rows, over_arc), 1)
    np.add.at(A1, (rows, over_arc), -1)
    np.add.at(A1, (rows[positive], incoming[positive]), 1)
    np.add.at(A0, (rows[positive], outgoing[positive]), -1)
    np.add.at(A0, (rows[~positive], incoming[~positive]), -1)
    np.add.at(A1, (rows[~positive], outgoing[~positive]), 1)
    return np.ascontiguousarray(A0[1:, 1:]), np.ascontiguousarray(A1[1:, 1:])


def _exact(A, residue, vector: bool = False):
    """Integer value(s) from residues modulo the two primes (Chinese remainder theorem), the
    representative nearest zero."""
    p, q = _PRIMES
    r0, r1 = (np.asarray(residue(A, m), dtype=object) for m in _PRIMES)
    x = (r0 + p * ((r1 - r0) * pow(p, -1, q) % q)) % (p * q)
    x = np.where(x > p * q // 2, x - p * q, x)
    return np.array([int(v) for v in np.atleast_1d(x)]) if vector else abs(int(x))


@nb.njit(cache=True)
def _sweep(X, nxt):
    """Rows ``(over position, under position, sign, generic)`` of the crossings of the
    projection of ``X`` to the xy-plane (over: the larger z); ``generic`` is 0 for a crossing
    within 1e-9 of a vertex or of strands closer than 1e-12 in height."""
    n = X.shape[0]
    lo = np.empty(n)
    hi = np.empty(n)
    for i in range(n):
        a, b = X[i, 0], X[nxt[i], 0]
        lo[i] = min(a, b)
        hi[i] = max(a, b)
    order = np.argsort(lo, kind="mergesort")
    rows = [(0.0, 0.0, 0.0, 0.0) for _ in range(0)]
    margin, height = 1e-9, 1e-12
    for oi in range(n):
        i = order[oi]
        ax, ay, az = X[i, 0], X[i, 1], X[i, 2]
        dx, dy, dz = X[nxt[i], 0] - ax, X[nxt[i], 1] - ay, X[nxt[i], 2] - az
        for oj in range(oi + 1, n):
            j = order[oj]
            if lo[j] > hi[i]:
                break
            if j == nxt[i] or i == nxt[j]:
                continue
            bx, by, bz = X[j, 0], X[j, 1], X[j, 2]
            ex, ey, ez = X[nxt[j], 0] - bx, X[nxt[j], 1] - by, X[nxt[j], 2] - bz
            den = dx * ey - dy * ex
            if den == 0.0:
                continue
            qx, qy = bx - ax, by - ay
            s = (qx * ey - qy * ex) / den
            t = (qx * dy - qy * dx) / den
            if s < -margin or s > 1.0 + margin or t < -margin or t > 1.0 + margin:
                continue
            zi = az + s * dz
            zj = bz + t * ez
            near = (s < margin or s > 1.0 - margin or t < margin or t > 1.0 - margin
                    or abs(zi - zj) <= height)
            # right-handed (positive) when the over-strand turns counter-clockwise into the
            # under-strand, seen from above
            if zi > zj:
                sign = 1.0 if dx * ey - dy * ex > 0.0 else -1.0
                rows.append((i + s, j + t, sign, 0.0 if near else 1.0))
            else:
                sign = 1.0 if ex * dy - ey * dx > 0.0 else -1.0
                rows.append((j + t, i + s, sign, 0.0 if near else 1.0))
    out = np.empty((len(rows), 4))
    for k in range(len(rows)):
        out[k, 0], out[k, 1], out[k, 2], out[k, 3] = rows[k]
    return out


@nb.njit(cache=True)
def _det_mod(A, p):
    """``det(A) mod p`` by Gaussian elimination over the integers modulo the prime ``p``."""
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
def _interpolate(A0, A1, m, p):
    """Coefficients (lowest first, modulo ``p``) of the polynomial ``det(A0 + t A1)`` of
    degree at most ``m``, from its values at ``t = 1 … m + 1`` (Newton's divided
    differences)."""
    npts = m + 1
    xs = np.arange(1, npts + 1).astype(np.int64)
    dd = np.empty(npts, dtype=np.int64)
    for k in range(npts):
        dd[k] = _det_mod((A0 + xs[k] * A1) % p, p)
    for level in range(1, npts):
        for k in range(npts - 1, level - 1, -1):
            num = (dd[k] - dd[k - 1]) % p
            dd[k] = num * _inverse_mod((xs[k] - xs[k - level]) % p, p) % p
    # expand the Newton form into monomial coefficients
    coeffs = np.zeros(npts, dtype=np.int64)
    for k in range(npts - 1, -1, -1):
        # coeffs = coeffs * (t - xs[k]) + dd[k]
        for i in range(npts - 1, 0, -1):
            coeffs[i] = (coeffs[i - 1] - xs[k] * coeffs[i]) % p
        coeffs[0] = (dd[k] - xs[k] * coeffs[0]) % p
    return coeffs


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
