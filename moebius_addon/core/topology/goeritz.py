"""The signature of a knot or link from a planar diagram, by the Goeritz matrix and the
Gordon–Litherland correction.

Colour the faces of a connected diagram like a chessboard and number the faces of one colour
(the "white" ones) ``R_0 … R_n``. At every crossing two opposite corners are white. With the
crossing ``X[i, j, k, l]`` and its corners numbered from the corner between ``i`` and ``j``
counter-clockwise, ``η = +1`` when corners 0 and 2 (swept counter-clockwise from the
under-strand to the over-strand) are white and ``−1`` otherwise. The Goeritz matrix has
``g_ab = −Σ η`` over the crossings whose white corners lie in ``R_a`` and ``R_b`` (``a ≠ b``)
and rows summing to zero; ``G`` is it without row and column 0. A crossing is of type II when
its oriented smoothing joins its two black corners. Then (Gordon and Litherland, *On the
signature of a link*, Invent. Math. 47, 1978)::

    σ = sign(G) − Σ_{type II} η,      |det G| = the determinant of the link.

The sign convention is KnotInfo's and LinkInfo's: the positive trefoil (KnotInfo's 3_1, three
positive crossings) has σ = −2, the positive Hopf link −1. Either colour gives the same value;
every knot and link of the shipped table has its source's signature (tests/core/test_goeritz.py).
The signature changes sign with the mirror image, so it tells some chiral knots from their mirror
images where the Jones polynomial cannot (9_42, 10_125). Cost: the faces in O(c), the inertia of
``G`` exactly, in rationals, O(c³) for c crossings.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np

from .pd import DisjointSets, PlanarDiagram, edge_slots, faces

__all__ = ["goeritz", "inertia", "signature"]


def _pieces(d: PlanarDiagram) -> list[PlanarDiagram]:
    """The connected pieces of the diagram (crossings joined by edges), each a diagram."""
    sets = DisjointSets()
    for (m1, _), (m2, _) in edge_slots(d.X).values():
        sets.union(m1, m2)
    groups: dict = {}
    for m in range(d.crossings):
        groups.setdefault(sets.find(m), []).append(m)
    return [PlanarDiagram(d.X[g], d.sign[g]) for g in groups.values()]


def _colours(d: PlanarDiagram) -> tuple[list[int], dict]:
    """A chessboard colouring of the faces of a connected diagram: ``(colour of each face,
    {corner (crossing, position): face})``; corner ``p`` lies between the edges in positions
    ``p`` and ``p + 1``, and neighbouring corners of a crossing have different colours."""
    face_of = {s: f for f, corners in enumerate(faces(d)) for s in corners}
    nf = max(face_of.values()) + 1
    adjacent: list[list[int]] = [[] for _ in range(nf)]
    for m in range(d.crossings):
        for p in range(4):
            a, b = face_of[(m, p)], face_of[(m, (p + 1) % 4)]
            adjacent[a].append(b)
            adjacent[b].append(a)
    colour = [-1] * nf
    colour[0] = 0
    todo = [0]
    while todo:
        f = todo.pop()
        for g in adjacent[f]:
            if colour[g] < 0:
                colour[g] = 1 - colour[f]
                todo.append(g)
            elif colour[g] == colour[f]:  # pragma: no cover - faces() of a planar diagram
                raise ValueError("the diagram's faces cannot be coloured like a chessboard")
    return colour, face_of


def goeritz(d: PlanarDiagram, white: int = 0) -> tuple[np.ndarray, int]:
    """``(G, μ)`` of a connected diagram with crossings: the Goeritz matrix of the faces of
    colour ``white`` (0 or 1, :func:`_colours`) without its first row and column, and the
    Gordon–Litherland correction ``μ = Σ_{type II} η``; the signature is ``sign(G) − μ``."""
    colour, face_of = _colours(d)
    white_faces = [f for f, c in enumerate(colour) if c == white]
    row = {f: k for k, f in enumerate(white_faces)}
    G = np.zeros((len(white_faces), len(white_faces)), dtype=np.int64)
    mu = 0
    for m in range(d.crossings):
        eta = 1 if colour[face_of[(m, 0)]] == white else -1
        a, b = (face_of[(m, 0)], face_of[(m, 2)]) if eta > 0 else (face_of[(m, 1)],
                                                                  face_of[(m, 3)])
        if a != b:  # a nugatory crossing touches one white face twice: no term
            i, j = row[a], row[b]
            G[i, j] -= eta
            G[j, i] -= eta
            G[i, i] += eta
            G[j, j] += eta
        # A positive crossing's oriented smoothing joins corners 1 and 3, a negative one's
        # corners 0 and 2: type II when those are the black ones.
        if eta * int(d.sign[m]) > 0:
            mu += eta
    return G[1:, 1:], mu


def inertia(A: np.ndarray) -> tuple[int, int, int]:
    """``(positive, negative, zero)`` eigenvalue counts of the symmetric integer matrix ``A``,
    exactly: congruence to a diagonal matrix over the rationals (a zero pivot is replaced by
    adding a row and column with a non-zero off-diagonal entry, Sylvester's law of inertia)."""
    A = np.asarray(A)
    n = len(A)
    M = [[Fraction(int(x)) for x in row] for row in A]
    pos = neg = 0
    rest = list(range(n))
    while rest:
        k = next((i for i in rest if M[i][i] != 0), None)
        if k is None:
            pair = next(((i, j) for i in rest for j in rest if i < j and M[i][j] != 0), None)
            if pair is None:
                break  # the rest is zero
            i, j = pair
            for r in range(n):
                M[i][r] += M[j][r]
            for r in range(n):
                M[r][i] += M[r][j]
            k = i  # M[i][i] is now 2 M[i][j] != 0
        p = M[k][k]
        pos, neg = (pos + 1, neg) if p > 0 else (pos, neg + 1)
        rest.remove(k)
        for i in rest:
            f = M[i][k] / p
            if f:
                Mk = M[k]
                Mi = M[i]
                for j in rest:
                    Mi[j] -= f * Mk[j]
        for i in rest:
            M[i][k] = M[k][i] = Fraction(0)
    return pos, neg, n - pos - neg


def signature(d: PlanarDiagram) -> int:
    """The signature of the oriented knot or link of the diagram ``d`` (KnotInfo's and
    LinkInfo's convention: 3_1 has −2). A split diagram is the sum of its pieces; circles
    without crossings add nothing."""
    total = 0
    for piece in _pieces(d):
        G, mu = goeritz(piece)
        pos, neg, _ = inertia(G)
        total += pos - neg - mu
    return total
