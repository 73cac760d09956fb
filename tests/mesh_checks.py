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


def segments_closest(p1, q1, p2, q2) -> np.ndarray:
    """Distances between the segments ``p1 q1`` and ``p2 q2``, rows at a time (the clamped
    closest points of Ericson, *Real-Time Collision Detection*, 5.1.9; numpy only): the
    independent check that no two edges of a curve meet."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a = np.einsum("ij,ij->i", d1, d1)
    e = np.einsum("ij,ij->i", d2, d2)
    f = np.einsum("ij,ij->i", d2, r)
    c = np.einsum("ij,ij->i", d1, r)
    b = np.einsum("ij,ij->i", d1, d2)
    denom = a * e - b * b
    parallel = denom <= 1e-14 * a * e
    s = np.where(parallel, 0.0, np.clip((b * f - c * e) / np.where(parallel, 1.0, denom), 0, 1))
    t = (b * s + f) / e
    s = np.where(t < 0, np.clip(-c / a, 0, 1), np.where(t > 1, np.clip((b - c) / a, 0, 1), s))
    t = np.clip(t, 0, 1)
    diff = (p1 + d1 * s[:, None]) - (p2 + d2 * t[:, None])
    return np.sqrt(np.einsum("ij,ij->i", diff, diff))


def ray_parity_inside(P, V, F, rng):
    """Inside by the parity of a ray's crossings with the triangles (Möller–Trumbore, all
    pairs at once), along one random direction (hitting an edge or a vertex exactly has
    probability zero)."""
    d = rng.normal(size=3)
    d /= np.linalg.norm(d)
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    e1, e2 = b - a, c - a
    h = np.cross(d, e2)
    det = np.einsum("kj,kj->k", e1, h)
    s = P[:, None, :] - a[None]
    u = np.einsum("nkj,kj->nk", s, h) / det
    q = np.cross(s, e1[None])
    v = np.einsum("j,nkj->nk", d, q) / det
    t = np.einsum("kj,nkj->nk", e2, q) / det
    hit = (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
    return hit.sum(axis=1) % 2 == 1
