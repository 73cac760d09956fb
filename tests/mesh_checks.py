"""An independent test of curves against triangle meshes (numpy only, no extension code): the
tests of obstacles use it to check every iterate the flow accepted."""

import numpy as np


def crossings(P, V, F, closed: bool = True) -> int:
    """Number of (edge, triangle) pairs of the polygon ``P`` (N, 3) that meet a triangle of
    the mesh ``(V, F)``: every pair's 3 × 3 system ``p0 + t (p1 − p0) = a + v e1 + w e2``
    solved at once (an edge meets the triangle where 0 ≤ t ≤ 1, v, w ≥ 0, v + w ≤ 1)."""
    P = np.asarray(P, dtype=np.float64)
    p0, p1 = (P, np.roll(P, -1, axis=0)) if closed else (P[:-1], P[1:])
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    M = np.stack(np.broadcast_arrays((p0 - p1)[:, None], (b - a)[None], (c - a)[None]), -1)
    rhs = p0[:, None] - a[None]
    ok = np.abs(np.linalg.det(M)) > 1e-300
    sol = np.zeros(rhs.shape)
    sol[ok] = np.linalg.solve(M[ok], rhs[ok][..., None])[..., 0]
    t, v, w = sol[..., 0], sol[..., 1], sol[..., 2]
    return int(np.count_nonzero(ok & (t >= 0) & (t <= 1) & (v >= 0) & (w >= 0)
                                & (v + w <= 1)))
