"""An independent certificate that a recorded live run never crossed (numpy only, no extension
code): between two consecutive states every vertex of the curves and of the meshes moves on a
straight line, so a point of an edge or a triangle moves by at most its farthest vertex's move.
Walking along the move from a state whose least distance is ``d``, nothing can meet before
the walk has gone ``d`` divided by the largest relative speed — the next state checked is
there (conservative advancement). Used by tests/core/test_live.py and tests/blender/test_live.py.
"""

import numpy as np

from tests.mesh_checks import crossings, segments_closest

#: Walks that need more states than this to certify a move fail (the move passes too close).
MAX_SAMPLES = 4000


def _edges(parts, closed):
    """(p, q, component, index) of every real edge of ``parts``."""
    p, q, comp, idx = [], [], [], []
    for c, (P, cl) in enumerate(zip(parts, closed, strict=True)):
        n = len(P)
        m = n if cl else n - 1
        p.append(P[:m])
        q.append(np.roll(P, -1, axis=0)[:m])
        comp.append(np.full(m, c))
        idx.append(np.arange(m))
    return np.concatenate(p), np.concatenate(q), np.concatenate(comp), np.concatenate(idx)


def _pairs(parts, closed):
    """Index pairs (i, j), i < j, of edges that share no vertex."""
    _, _, comp, idx = _edges(parts, closed)
    sizes = [len(P) for P in parts]
    i, j = np.triu_indices(len(comp), 1)
    same = comp[i] == comp[j]
    gap = np.abs(idx[i] - idx[j])
    n = np.array(sizes)[comp[i]]
    cyc = np.array(closed)[comp[i]]
    adjacent = same & ((gap <= 1) | (cyc & (gap == n - 1)))
    return i[~adjacent], j[~adjacent]


def curve_distance(parts, closed) -> float:
    """Least distance between two edges of the curves that share no vertex."""
    p, q, _, _ = _edges(parts, closed)
    i, j = _pairs(parts, closed)
    if len(i) == 0:
        return np.inf
    return float(segments_closest(p[i], q[i], p[j], q[j]).min())


def mesh_distance(parts, closed, V, F) -> float:
    """Least distance between an edge of the curves and a triangle of ``(V, F)`` (0 where
    they meet): an edge that does not cross the triangle is nearest it at a triangle's edge or
    where an end of the edge projects inside the triangle."""
    p, q, _, _ = _edges(parts, closed)
    for P, cl in zip(parts, closed, strict=True):
        if crossings(P, V, F, closed=cl):
            return 0.0
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    best = np.inf
    for e0, e1 in ((a, b), (b, c), (c, a)):
        P0 = np.repeat(p, len(F), axis=0)
        Q0 = np.repeat(q, len(F), axis=0)
        best = min(best, float(segments_closest(P0, Q0, np.tile(e0, (len(p), 1)),
                                                np.tile(e1, (len(p), 1))).min()))
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1)[:, None]
    for x in (p, q):
        r = x[:, None, :] - a[None]
        h = np.einsum("ijk,jk->ij", r, n)
        foot = x[:, None, :] - h[..., None] * n[None]
        inside = np.ones(h.shape, bool)
        for u, v in ((a, b), (b, c), (c, a)):
            inside &= np.einsum("ijk,jk->ij", np.cross(v - u, foot - u[None]), n) >= 0
        if inside.any():
            best = min(best, float(np.abs(h[inside]).min()))
    return best


def certify_move(A, B, closed, meshes=(), floor: float = 1e-12) -> float:
    """Certify that the straight move of the curves from ``A`` to ``B`` (lists of arrays) with
    the meshes moving straight from ``VA`` to ``VB`` (``meshes``: ``(VA, VB, F)`` each) never
    lets two edges or an edge and a triangle meet. Returns the least distance seen; raises
    AssertionError when they meet or come too close to certify."""
    A = [np.asarray(P, np.float64) for P in A]
    B = [np.asarray(P, np.float64) for P in B]
    curve_speed = max(float(np.sqrt(np.max(np.sum((b - a) ** 2, axis=1))))
                      for a, b in zip(A, B, strict=True))
    least = np.inf
    s, samples = 0.0, 0
    while True:
        X = [a + s * (b - a) for a, b in zip(A, B, strict=True)]
        d = curve_distance(X, closed)
        speed = 2.0 * curve_speed
        for VA, VB, F in meshes:
            V = VA + s * (VB - VA)
            d = min(d, mesh_distance(X, closed, V, F) * 2.0)  # scaled: see speed below
            speed = max(speed, 2.0 * (curve_speed + float(
                np.sqrt(np.max(np.sum((VB - VA) ** 2, axis=1))))))
        least = min(least, d)
        assert d > floor, f"contact at s = {s:.6g} of the move (distance {d:.3g})"
        if s >= 1.0:
            return least
        if speed == 0.0:
            return least
        s = min(1.0, s + d / speed)
        samples += 1
        assert samples < MAX_SAMPLES, f"the move passes too close to certify (d = {d:.3g})"


def certify_record(states, closed, mesh_states=None) -> float:
    """:func:`certify_move` over every consecutive pair of ``states`` (lists of arrays);
    ``mesh_states``: per state, a list of ``(V, F)`` of the meshes then. The least distance."""
    least = np.inf
    for k in range(len(states) - 1):
        meshes = [] if mesh_states is None else [
            (VA, VB, F) for (VA, F), (VB, _) in zip(mesh_states[k], mesh_states[k + 1],
                                                   strict=True)]
        least = min(least, certify_move(states[k], states[k + 1], closed, meshes))
    return least
