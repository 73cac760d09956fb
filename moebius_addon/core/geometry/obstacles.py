"""Obstacles: triangle meshes a relaxing curve is repelled from and never crosses.

A run given ``obstacles=[(V, F), ...]`` (``V`` an (M, 3) array of vertices, ``F`` a (K, 3)
array of triangles, per mesh) minimizes the curve's Möbius energy plus ``obstacle_weight``
times the obstacle energy

    E_obs = Σ_I Σ_T  l_I A_T / d(m_I, T)³,

a quadrature of ``∫_γ ∫_M |γ(s) − y|⁻³ dA(y) ds`` over edges ``I`` (length ``l_I``, midpoint
``m_I``) and triangles ``T`` (area ``A_T``), with ``d(m_I, T)`` the distance from the midpoint
to the nearest point of the triangle (not its centroid). Why this kernel: like the curve's own
energy it is scale invariant (length × area / length³), so one weight means the same for
curves and scenes of any size; far from the mesh it is the continuous integral; and it grows
without bound as an edge approaches any point of a triangle (as ``d⁻³`` for a midpoint
approaching a triangle's interior, where the continuous integral grows as ``d⁻¹`` per unit of
length: the discrete barrier is steeper, and depends on the triangles' size there). The mesh
is fixed, so the gradient is with respect to the curve's vertices alone: exact, by the
envelope theorem ``∇_m d = (m − q) / d`` with ``q`` the nearest point.

The energy keeps the curve away from the mesh; the guarantee that it never crosses it does
not depend on the energy: every step the flow takes is bounded by the first time any moving
edge comes within the contact distance ``eps`` of any triangle (:meth:`ObstacleField.
contact_time`, conservative advancement with the exact segment–triangle distance, as the
curve's own contact search does for pairs of edges), searched through a bounding-box
hierarchy of the triangles (:func:`triangle_tree`; the same value as all pairs, tested): 0.3
ms against 2.0 s over all pairs for 2 000 edges and 80 000 triangles. The energy and its
gradient visit every edge–triangle pair (numba, parallel over edges; bitwise the same for any
thread count): 1.3 s there, 10 ms for 240 edges and 1 536 triangles. A Barnes–Hut far field
with one term per box (area-weighted centre) was tried and not kept: its centre distances
differ from the kernel's nearest-point distances to first order in the triangle size, 3–5 %
error in the energy at θ = 0.1 on a torus of 20 000 triangles.

The far field (``tol > 0``, :func:`_edge_terms_tree`) keeps the kernel's nearest points in its
bounds instead (:func:`_box_bounds`). For a box of the triangle hierarchy (area ``A``,
area-weighted centre ``c`` of its triangles' centroids ``c_k``, all within ``Rc`` of ``c``,
second moments ``Q`` and ``S3 = Σ A_k |c_k − c|³``, triangles of radius at most ``h``) and a
midpoint at ``r = m − c``, ``D = |r|``:

* Σ A_k |m − c_k|⁻³ lies within ``10 S3 / (D − Rc)⁶`` of its second-order Taylor value
  ``T = A/D³ + 3/2 (5 rᵀQr/D⁷ − tr Q/D⁵)`` (no first-order term about ``c``; the third
  derivative of ``r⁻³`` along a line is at most ``60 r⁻⁶``);
* each nearest point is nearer than its centroid by at most ``h |P_k u_k|`` (``u_k`` the unit
  vector from the centroid to ``m``, ``P_k`` the projection onto the triangle's plane), and
  with the box's cone of normal lines (axis, half-angle ``φ``) ``|P_k u_k| ≤ sin(ψ + φ +
  asin(Rc/D))``, ``ψ`` the angle of ``r`` to the axis: a box seen face-on has a small gain.

So the box's sum lies in ``[L, U]``, ``L = T − 10 S3/(D − Rc)⁶``, ``U = (T + 10 S3/(D −
Rc)⁶)·((D − Rc)/(D − Rc − gain))³``. Visiting the nearer box first, a box is accepted when
``U − L ≤ tol (U + L)`` or ``(U − L)/2 ≤ tol · (A / total area) · (lower bound of the edge's
sum so far)``, and counts ``G``: ``T`` with its nearest points ``GAIN_GUESS`` (0.5) times
``hbar sin ψ`` nearer (``hbar`` the mean triangle radius), clipped to ``[L, U]``, so off by
at most ``U − L``: each edge's sum is then within ``4 tol / (1 − tol)`` of its exact value,
relatively (proven; measured far below, docs/lab/cables-and-obstacles.md). The gradient of an
accepted box
is its Taylor value's, scaled to ``G``: no proven bound, measured. The previous bounds (a
first-order Taylor bound and the gain ``h`` in every direction, counting ``(L + U)/2``)
summed 3.5 times as many triangles exactly on the 100 cables with the torus.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .edge_pairs import SLACK, segment_distance2
from .layout import unit_exponent

_MAX_ADVANCE = 100_000
# An accepted box's value: its Taylor value with the nearest points this fraction of hbar sin ψ
# nearer (the mean triangle radius, ψ the angle to the box's axis), clipped to the proven
# bounds. Fractions 0.3 to 0.8 measured on two scenes (docs/lab/cables-and-obstacles.md): 0.5 erred
# least in
# energy overall, 3 to 8 times less than the bounds' midpoint.
GAIN_GUESS = 0.5


def check_obstacles(obstacles) -> list[tuple[np.ndarray, np.ndarray]]:
    """``obstacles`` as a list of ``(V, F)`` float64 / int64 arrays, checked.

    Raises
    ------
    ValueError
        Not a list of ``(V, F)`` pairs; a mesh without triangles; ``V`` not (M, 3) finite
        numbers; ``F`` not (K, 3) integers indexing ``V``; a triangle with a repeated vertex
        or no area; an edge shared by more than two triangles (non-manifold). Each message
        names the mesh and the triangle or edge.
    """
    if isinstance(obstacles, tuple) and len(obstacles) == 2 and not isinstance(
            obstacles[0], tuple):
        obstacles = [obstacles]  # one mesh given as (V, F)
    try:
        meshes = list(obstacles)
    except TypeError:
        raise ValueError("obstacles must be a list of (V, F) meshes: V an (M, 3) array of "
                         "vertices, F a (K, 3) array of triangles") from None
    out = []
    for m, mesh in enumerate(meshes):
        try:
            V, F = mesh
        except (TypeError, ValueError):
            raise ValueError(f"obstacle {m} is not a (V, F) pair of vertices and triangles"
                             ) from None
        V_in, F_in = np.asarray(V), np.asarray(F)
        if V_in.dtype.kind not in "iuf" or F_in.dtype.kind not in "iuf":
            what, arr = ("V", V_in) if V_in.dtype.kind not in "iuf" else ("F", F_in)
            raise ValueError(f"obstacle {m}: {what} must hold real numbers, got an array of "
                             f"{arr.dtype}; convert it (take the real part, .real, if that "
                             f"is what you mean)")
        V = V_in.astype(np.float64)
        if V.ndim != 2 or V.shape[1] != 3 or len(V) < 3:
            raise ValueError(f"obstacle {m}: V must be an (M, 3) array of at least 3 vertices, "
                             f"got shape {V.shape}")
        if not np.all(np.isfinite(V)):
            bad = int(np.flatnonzero(~np.all(np.isfinite(V), axis=1))[0])
            raise ValueError(f"obstacle {m}: vertex {bad} has a non-finite coordinate "
                             f"{V[bad].tolist()}")
        if F_in.size == 0:
            raise ValueError(f"obstacle {m} is empty: it has no triangles")
        if F_in.ndim != 2 or F_in.shape[1] != 3:
            raise ValueError(f"obstacle {m}: F must be a (K, 3) array of triangles (vertex "
                             f"indices), got shape {F_in.shape}")
        if not np.issubdtype(F_in.dtype, np.integer):
            if not np.all(np.isfinite(F_in)) or np.any(F_in != np.round(F_in)):
                raise ValueError(f"obstacle {m}: F must hold integer vertex indices")
        F = F_in.astype(np.int64)
        if F.min() < 0 or F.max() >= len(V):
            k = int(np.flatnonzero((F < 0).any(axis=1) | (F >= len(V)).any(axis=1))[0])
            raise ValueError(f"obstacle {m}: triangle {k} {F[k].tolist()} indexes a vertex "
                             f"outside 0..{len(V) - 1}")
        rep = (F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 0] == F[:, 2])
        if rep.any():
            k = int(np.flatnonzero(rep)[0])
            raise ValueError(f"obstacle {m}: triangle {k} {F[k].tolist()} repeats a vertex")
        # relative to the mesh's own size, taken near 1 (exact scaling): the areas of meshes
        # 1e-150 or 1e160 across under- or overflow
        k = unit_exponent(V)
        ab = np.ldexp(V[F[:, 1]] - V[F[:, 0]], -k)
        ac = np.ldexp(V[F[:, 2]] - V[F[:, 0]], -k)
        area = 0.5 * np.linalg.norm(np.cross(ab, ac), axis=1)
        size = 2.0 * float(np.ldexp(V.max(axis=0) / 2 - V.min(axis=0) / 2, -k).max())
        flat = area <= 1e-12 * size * size
        if flat.any():
            k = int(np.flatnonzero(flat)[0])
            raise ValueError(f"obstacle {m}: triangle {k} {F[k].tolist()} has no area (its "
                             f"vertices lie on a line)")
        edges = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
        uniq, counts = np.unique(edges, axis=0, return_counts=True)
        if counts.max() > 2:
            e = uniq[int(np.argmax(counts))]
            raise ValueError(f"obstacle {m} is not a manifold: its edge between vertices "
                             f"{int(e[0])} and {int(e[1])} belongs to {int(counts.max())} "
                             f"triangles (at most 2)")
        out.append((V, F))
    if not out:
        raise ValueError("obstacles is empty: give at least one (V, F) mesh, or None")
    return out


# -- geometry (scalar arithmetic: no allocation in the pair loops) -----------------------------


@nb.njit(cache=True)
def _closest_on_triangle(px, py, pz, T, k):
    """Nearest point of triangle ``k`` (``T[k]``: its three corners) to ``p``, by the region
    of the triangle's plane ``p`` projects into (corner, edge or face)."""
    ax, ay, az = T[k, 0, 0], T[k, 0, 1], T[k, 0, 2]
    bx, by, bz = T[k, 1, 0], T[k, 1, 1], T[k, 1, 2]
    cx, cy, cz = T[k, 2, 0], T[k, 2, 1], T[k, 2, 2]
    abx, aby, abz = bx - ax, by - ay, bz - az
    acx, acy, acz = cx - ax, cy - ay, cz - az
    apx, apy, apz = px - ax, py - ay, pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return ax, ay, az
    bpx, bpy, bpz = px - bx, py - by, pz - bz
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return bx, by, bz
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        t = d1 / (d1 - d3)
        return ax + t * abx, ay + t * aby, az + t * abz
    cpx, cpy, cpz = px - cx, py - cy, pz - cz
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        return cx, cy, cz
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        t = d2 / (d2 - d6)
        return ax + t * acx, ay + t * acy, az + t * acz
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and d4 - d3 >= 0.0 and d5 - d6 >= 0.0:
        t = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return bx + t * (cx - bx), by + t * (cy - by), bz + t * (cz - bz)
    s = 1.0 / (va + vb + vc)
    v = vb * s
    w = vc * s
    return ax + v * abx + w * acx, ay + v * aby + w * acy, az + v * abz + w * acz


@nb.njit(cache=True)
def _segment_crosses(p0x, p0y, p0z, p1x, p1y, p1z, T, k):
    """Whether the segment [p0, p1] meets triangle ``k`` (ends on opposite sides of its
    plane, or on it, and the meeting point inside the triangle)."""
    ax, ay, az = T[k, 0, 0], T[k, 0, 1], T[k, 0, 2]
    e1x, e1y, e1z = T[k, 1, 0] - ax, T[k, 1, 1] - ay, T[k, 1, 2] - az
    e2x, e2y, e2z = T[k, 2, 0] - ax, T[k, 2, 1] - ay, T[k, 2, 2] - az
    nx = e1y * e2z - e1z * e2y
    ny = e1z * e2x - e1x * e2z
    nz = e1x * e2y - e1y * e2x
    s0 = nx * (p0x - ax) + ny * (p0y - ay) + nz * (p0z - az)
    s1 = nx * (p1x - ax) + ny * (p1y - ay) + nz * (p1z - az)
    if (s0 > 0.0 and s1 > 0.0) or (s0 < 0.0 and s1 < 0.0) or s0 == s1:
        return False  # one side, or in the plane (then an edge or end is nearest)
    t = s0 / (s0 - s1)
    qx = p0x + t * (p1x - p0x) - ax
    qy = p0y + t * (p1y - p0y) - ay
    qz = p0z + t * (p1z - p0z) - az
    # barycentric coordinates of q in the triangle
    d11 = e1x * e1x + e1y * e1y + e1z * e1z
    d12 = e1x * e2x + e1y * e2y + e1z * e2z
    d22 = e2x * e2x + e2y * e2y + e2z * e2z
    dq1 = qx * e1x + qy * e1y + qz * e1z
    dq2 = qx * e2x + qy * e2y + qz * e2z
    den = d11 * d22 - d12 * d12
    v = (d22 * dq1 - d12 * dq2) / den
    w = (d11 * dq2 - d12 * dq1) / den
    return v >= 0.0 and w >= 0.0 and v + w <= 1.0


@nb.njit(cache=True)
def _segment_triangle_distance2(p0x, p0y, p0z, p1x, p1y, p1z, T, k):
    """Squared distance of the segment [p0, p1] and triangle ``k``: 0 when they meet, else
    the least of the ends' distances to the triangle and the segment's to its three sides
    (a segment apart from a triangle has its nearest pair at one of those)."""
    if _segment_crosses(p0x, p0y, p0z, p1x, p1y, p1z, T, k):
        return 0.0
    qx, qy, qz = _closest_on_triangle(p0x, p0y, p0z, T, k)
    best = (p0x - qx) ** 2 + (p0y - qy) ** 2 + (p0z - qz) ** 2
    qx, qy, qz = _closest_on_triangle(p1x, p1y, p1z, T, k)
    best = min(best, (p1x - qx) ** 2 + (p1y - qy) ** 2 + (p1z - qz) ** 2)
    for s in range(3):
        a = T[k, s]
        b = T[k, (s + 1) % 3]
        d2, _s, _t = segment_distance2(p0x, p0y, p0z, p1x, p1y, p1z,
                                       a[0], a[1], a[2], b[0], b[1], b[2])
        best = min(best, d2)
    return best


#: ``obstacle_tol=None`` (the default): the hierarchy at this tolerance from
#: ``OBSTACLE_TREE_FROM`` edge–triangle pairs on, every pair exactly below.
AUTO_OBSTACLE_TOL = 0.1
#: All pairs cost about 12 ms per pass there; the hierarchy paid 1.6x at 0.37M pairs, 5x at
#: 2.9M (docs/lab/cables-and-obstacles.md, "obstacle energy through the triangle hierarchy").
OBSTACLE_TREE_FROM = 1_000_000


def auto_obstacle_tol(tol, layout, meshes) -> float:
    """The obstacle energy's tolerance of a run: ``tol`` if given, else
    :data:`AUTO_OBSTACLE_TOL` when the run's edges times the meshes' triangles reach
    :data:`OBSTACLE_TREE_FROM`, else 0 (every pair, exactly)."""
    if tol is not None:
        return float(tol)
    pairs = int(layout.real.sum() if layout.has_open else layout.n) * sum(len(F) for _, F in meshes)
    return AUTO_OBSTACLE_TOL if pairs >= OBSTACLE_TREE_FROM else 0.0


# -- energy and gradient ----------------------------------------------------------------------


@nb.njit(cache=True, parallel=True, error_model="numpy")
def _edge_terms(X, nxt, T, area, skip, grad):
    """Per edge: its energy ``Σ_T l A / d³`` and, with ``grad``, the derivatives of that sum
    with respect to the midpoint (``gm``) and to the length (``gl``); 0 for the edges of
    ``skip`` (fixed by pins: a constant, infinite where a pinned end lies on a mesh)."""
    n = X.shape[0]
    e = np.zeros(n)
    gm = np.zeros((n, 3))
    gl = np.zeros(n)
    for i in nb.prange(n):
        if skip[i]:
            continue
        j = nxt[i]
        mx = 0.5 * (X[i, 0] + X[j, 0])
        my = 0.5 * (X[i, 1] + X[j, 1])
        mz = 0.5 * (X[i, 2] + X[j, 2])
        ln = np.sqrt((X[j, 0] - X[i, 0]) ** 2 + (X[j, 1] - X[i, 1]) ** 2
                     + (X[j, 2] - X[i, 2]) ** 2)
        s = 0.0
        sx = 0.0
        sy = 0.0
        sz = 0.0
        for k in range(T.shape[0]):
            qx, qy, qz = _closest_on_triangle(mx, my, mz, T, k)
            rx, ry, rz = mx - qx, my - qy, mz - qz
            d2 = rx * rx + ry * ry + rz * rz
            inv3 = area[k] / (d2 * np.sqrt(d2))  # A / d³
            s += inv3
            if grad:
                f = -3.0 * inv3 / d2  # ∂(A d⁻³)/∂m = −3 A d⁻⁵ (m − q)
                sx += f * rx
                sy += f * ry
                sz += f * rz
        e[i] = ln * s
        if grad:
            gm[i, 0] = ln * sx
            gm[i, 1] = ln * sy
            gm[i, 2] = ln * sz
            gl[i] = s
    return e, gm, gl


@nb.njit(cache=True)
def _principal_axis(N, out):
    """Write into ``out`` a unit eigenvector of the largest eigenvalue of the symmetric 3×3
    ``N``, by cyclic Jacobi rotations (Golub & Van Loan, §8.5): written out because numba's
    ``np.linalg`` calls scipy's LAPACK, which Blender's Python does not have. Any unit vector
    is a valid cone axis (the cone's angle is measured about it); the eigenvector keeps it
    narrow."""
    a = N.copy()
    v = np.eye(3)
    scale = abs(a[0, 0]) + abs(a[1, 1]) + abs(a[2, 2]) + abs(a[0, 1]) + abs(a[0, 2]) \
        + abs(a[1, 2])
    for _ in range(50):
        off = abs(a[0, 1]) + abs(a[0, 2]) + abs(a[1, 2])
        if off <= 1e-17 * scale:
            break
        for p in range(2):
            for q in range(p + 1, 3):
                apq = a[p, q]
                if apq == 0.0:
                    continue
                # the rotation that zeroes a[p, q]: t = tan of its angle, the smaller root
                theta = (a[q, q] - a[p, p]) / (2.0 * apq)
                t = 1.0 / (abs(theta) + np.sqrt(theta * theta + 1.0))
                if theta < 0.0:
                    t = -t
                c = 1.0 / np.sqrt(t * t + 1.0)
                s = t * c
                for k in range(3):  # columns p, q of a, then rows p, q
                    akp, akq = a[k, p], a[k, q]
                    a[k, p], a[k, q] = c * akp - s * akq, s * akp + c * akq
                for k in range(3):
                    apk, aqk = a[p, k], a[q, k]
                    a[p, k], a[q, k] = c * apk - s * aqk, s * apk + c * aqk
                for k in range(3):
                    vkp, vkq = v[k, p], v[k, q]
                    v[k, p], v[k, q] = c * vkp - s * vkq, s * vkp + c * vkq
    best = 2
    for j in (1, 0):  # ties go to the later column, as LAPACK's ascending order gives
        if a[j, j] > a[best, best]:
            best = j
    for d in range(3):
        out[d] = v[d, best]


@nb.njit(cache=True)
def _node_moments(T, area, centre, radius, lo, hi):
    """Per node of the hierarchy, what :func:`_box_bounds` needs: its area ``A``; the
    area-weighted centre ``c`` of its triangles' centroids ``c_k``; ``Q`` (xx, yy, zz, xy, xz,
    yz), the area-weighted second moment of the ``c_k − c``; ``S3 = Σ A_k |c_k − c|³``; ``Rc``,
    the largest ``|c_k − c|``; ``h`` and ``hbar``, the largest and the area-weighted mean
    triangle radius (about the triangle's own centroid); and the cone of its triangles' normal
    lines: an axis ``nrm`` and the cosine and sine of the largest angle between a triangle's
    normal line and it (triangles of zero area, whose terms are zero, left out)."""
    m = lo.shape[0]
    A = np.zeros(m)
    c = np.zeros((m, 3))
    Q = np.zeros((m, 6))
    S3 = np.zeros(m)
    Rc = np.zeros(m)
    h = np.zeros(m)
    hbar = np.zeros(m)
    nrm = np.zeros((m, 3))
    phi = np.zeros(m)
    nk = np.zeros((T.shape[0], 3))
    for k in range(T.shape[0]):
        ux, uy, uz = T[k, 1, 0] - T[k, 0, 0], T[k, 1, 1] - T[k, 0, 1], T[k, 1, 2] - T[k, 0, 2]
        vx, vy, vz = T[k, 2, 0] - T[k, 0, 0], T[k, 2, 1] - T[k, 0, 1], T[k, 2, 2] - T[k, 0, 2]
        wx, wy, wz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
        w = np.sqrt(wx * wx + wy * wy + wz * wz)
        if w > 0.0:
            nk[k, 0], nk[k, 1], nk[k, 2] = wx / w, wy / w, wz / w
    N = np.zeros((3, 3))
    for node in range(m):
        N[:] = 0.0
        for k in range(lo[node], hi[node]):
            A[node] += area[k]
            hbar[node] += area[k] * radius[k]
            h[node] = max(h[node], radius[k])
            for d in range(3):
                c[node, d] += area[k] * centre[k, d]
                for e in range(3):
                    N[d, e] += area[k] * nk[k, d] * nk[k, e]
        hbar[node] /= A[node]
        for d in range(3):
            c[node, d] /= A[node]
        _principal_axis(N, nrm[node])  # the axis: the normal lines' principal direction
        for k in range(lo[node], hi[node]):
            dx = centre[k, 0] - c[node, 0]
            dy = centre[k, 1] - c[node, 1]
            dz = centre[k, 2] - c[node, 2]
            Q[node, 0] += area[k] * dx * dx
            Q[node, 1] += area[k] * dy * dy
            Q[node, 2] += area[k] * dz * dz
            Q[node, 3] += area[k] * dx * dy
            Q[node, 4] += area[k] * dx * dz
            Q[node, 5] += area[k] * dy * dz
            dk = np.sqrt(dx * dx + dy * dy + dz * dz)
            S3[node] += area[k] * dk * dk * dk
            Rc[node] = max(Rc[node], dk)
            if area[k] > 0.0:
                cosa = abs(nk[k, 0] * nrm[node, 0] + nk[k, 1] * nrm[node, 1]
                           + nk[k, 2] * nrm[node, 2])
                phi[node] = max(phi[node], np.arccos(min(1.0, cosa)))
    phi = np.minimum(0.5 * np.pi, phi * (1.0 + 1e-12) + 1e-12)  # rounding: widened a little
    return A, c, Q, S3, Rc, h, hbar, nrm, np.cos(phi), np.sin(phi)


@nb.njit(cache=True, inline="always")
def _box_bounds(rx, ry, rz, node, A, Q, S3, Rc, h, hbar, nrm, cphi, sphi):
    """For a midpoint ``m`` at ``r = m − c`` from a node's centre: ``(L, U, T, G)`` with the
    node's sum ``Σ A_k / d(m, T_k)³`` proven within ``[L, U]``, ``T`` its second-order Taylor
    value at the centroids and ``G`` the estimate an accepted node counts (module text, "the
    far field"); ``L = U = −1`` when the node is too near for bounds."""
    D2 = rx * rx + ry * ry + rz * rz
    D = np.sqrt(D2)
    near = D - Rc[node]  # no centroid nearer than this
    if near <= 0.0:
        return -1.0, -1.0, 0.0, 0.0
    # the nearest point's gain over a centroid: at most h |P_k u_k|, u_k the unit vector from
    # the centroid to m, P_k the projection onto the triangle's plane; the angle of u_k to the
    # normal line is at most ψ + φ + asin(Rc / D), ψ the angle of u = r / D to the axis
    # (sines and cosines of the sum, no trigonometric calls; past π/2 the sine is taken as 1)
    cp = min(1.0, abs(rx * nrm[node, 0] + ry * nrm[node, 1] + rz * nrm[node, 2]) / D)
    sp = np.sqrt(1.0 - cp * cp)
    c2 = cp * cphi[node] - sp * sphi[node]
    s2 = sp * cphi[node] + cp * sphi[node]
    sb = Rc[node] / D
    cb = np.sqrt(1.0 - sb * sb)
    c3 = c2 * cb - s2 * sb
    gain = h[node] * (min(1.0, s2 * cb + c2 * sb) if c2 > 0.0 and c3 > 0.0 else 1.0)
    if near - gain <= 0.0:
        return -1.0, -1.0, 0.0, 0.0
    inv2 = 1.0 / D2
    inv3 = inv2 / D
    inv5 = inv3 * inv2
    qr = (Q[node, 0] * rx * rx + Q[node, 1] * ry * ry + Q[node, 2] * rz * rz
          + 2.0 * (Q[node, 3] * rx * ry + Q[node, 4] * rx * rz + Q[node, 5] * ry * rz))
    tr = Q[node, 0] + Q[node, 1] + Q[node, 2]
    # Σ A_k |r − δ_k|⁻³ = A/D³ + ½ Σ A_k δ_kᵀ H δ_k + remainder, H = 3 D⁻⁵ (5 r̂ r̂ᵀ − I)
    # (no first-order term: c is the area-weighted centre); the third derivative of r⁻³ along
    # any line is at most 60 r⁻⁶, so the remainder is at most 10 Σ A_k |δ_k|³ / (D − Rc)⁶
    val = A[node] * inv3 + 1.5 * inv5 * (5.0 * qr * inv2 - tr)
    rem = 10.0 * S3[node] / near ** 6
    lw = max(val - rem, 0.0)
    up = (val + rem) * (near / (near - gain)) ** 3
    guess = val * (near / (near - GAIN_GUESS * hbar[node] * sp)) ** 3
    return lw, up, val, min(up, max(lw, guess))


@nb.njit(cache=True, parallel=True, error_model="numpy")
def _edge_terms_tree(X, nxt, T, area, skip, left, right, lo, hi, A, c, Q, S3, Rc, h, hbar,
                     nrm, cphi, sphi, tol, grad):
    """:func:`_edge_terms` through the triangles' hierarchy, each edge's sum within relative
    ``tol`` of the exact one (module text, "the far field"). Nodes are visited nearer centre
    first; a node whose bounds ``[L, U]`` on its sum are accepted counts the estimate ``G``
    and its gradient as its Taylor value's (:func:`_box_bounds`), scaled to ``G``; leaves are
    summed exactly."""
    n = X.shape[0]
    e = np.zeros(n)
    gm = np.zeros((n, 3))
    gl = np.zeros(n)
    total = A[0]
    for i in nb.prange(n):
        if skip[i]:
            continue
        stack = np.empty(256, np.int64)
        j = nxt[i]
        mx = 0.5 * (X[i, 0] + X[j, 0])
        my = 0.5 * (X[i, 1] + X[j, 1])
        mz = 0.5 * (X[i, 2] + X[j, 2])
        ln = np.sqrt((X[j, 0] - X[i, 0]) ** 2 + (X[j, 1] - X[i, 1]) ** 2
                     + (X[j, 2] - X[i, 2]) ** 2)
        s = 0.0  # the estimate of Σ_T A / d³
        low = 0.0  # a lower bound of it: the budget of the far field's error
        sx = 0.0
        sy = 0.0
        sz = 0.0
        stack[0] = 0
        top = 1
        while top > 0:
            top -= 1
            node = stack[top]
            rx, ry, rz = mx - c[node, 0], my - c[node, 1], mz - c[node, 2]
            lw, up, val, guess = _box_bounds(rx, ry, rz, node, A, Q, S3, Rc, h, hbar, nrm,
                                             cphi, sphi)
            # accepted when its bounds' spread is within tol of its own value or of its
            # area's share of the sum so far; G is off by at most the spread, so the accepted
            # errors add up to at most 4 tol / (1 − tol) of the edge's sum (module text)
            if up >= 0.0 and (up - lw <= tol * (up + lw)
                              or 0.5 * (up - lw) <= tol * (A[node] / total) * low):
                s += guess
                low += lw
                if grad and val > 0.0:
                    # the gradient of the Taylor value, scaled to G
                    D2 = rx * rx + ry * ry + rz * rz
                    inv2 = 1.0 / D2
                    inv5 = inv2 * inv2 / np.sqrt(D2)
                    inv7 = inv5 * inv2
                    qx = Q[node, 0] * rx + Q[node, 3] * ry + Q[node, 4] * rz
                    qy = Q[node, 3] * rx + Q[node, 1] * ry + Q[node, 5] * rz
                    qz = Q[node, 4] * rx + Q[node, 5] * ry + Q[node, 2] * rz
                    qr = qx * rx + qy * ry + qz * rz
                    tr = Q[node, 0] + Q[node, 1] + Q[node, 2]
                    # ∇(A D⁻³) = −3 A D⁻⁵ r; ∇ 3/2 (5 rᵀQr D⁻⁷ − tr Q D⁻⁵)
                    #   = 15/2 (2 Q r D⁻⁷ − 7 rᵀQr D⁻⁹ r + tr Q D⁻⁷ r)
                    radial = -3.0 * A[node] * inv5 + 7.5 * (tr * inv7 - 7.0 * qr * inv7 * inv2)
                    f = guess / val
                    sx += f * (radial * rx + 15.0 * qx * inv7)
                    sy += f * (radial * ry + 15.0 * qy * inv7)
                    sz += f * (radial * rz + 15.0 * qz * inv7)
                continue
            if left[node] < 0:
                for k in range(lo[node], hi[node]):
                    qx, qy, qz = _closest_on_triangle(mx, my, mz, T, k)
                    px, py, pz = mx - qx, my - qy, mz - qz
                    d2 = px * px + py * py + pz * pz
                    inv3 = area[k] / (d2 * np.sqrt(d2))
                    s += inv3
                    low += inv3
                    if grad:
                        f = -3.0 * inv3 / d2
                        sx += f * px
                        sy += f * py
                        sz += f * pz
                continue
            a, b = left[node], right[node]
            da = (mx - c[a, 0]) ** 2 + (my - c[a, 1]) ** 2 + (mz - c[a, 2]) ** 2
            db = (mx - c[b, 0]) ** 2 + (my - c[b, 1]) ** 2 + (mz - c[b, 2]) ** 2
            if da < db:  # the nearer child on top: its exact terms raise the budget first
                a, b = b, a
            stack[top] = a
            stack[top + 1] = b
            top += 2
        e[i] = ln * s
        if grad:
            gm[i, 0] = ln * sx
            gm[i, 1] = ln * sy
            gm[i, 2] = ln * sz
            gl[i] = s
    return e, gm, gl


@nb.njit(cache=True)
def _gather(X, nxt, prv, gm, gl):
    """Vertex gradient from the edges' midpoint and length derivatives."""
    n = X.shape[0]
    G = np.empty((n, 3))
    for v in range(n):
        p = prv[v]
        j = nxt[v]
        lv = np.sqrt((X[j, 0] - X[v, 0]) ** 2 + (X[j, 1] - X[v, 1]) ** 2
                     + (X[j, 2] - X[v, 2]) ** 2)
        lp = np.sqrt((X[v, 0] - X[p, 0]) ** 2 + (X[v, 1] - X[p, 1]) ** 2
                     + (X[v, 2] - X[p, 2]) ** 2)
        # an open component's dummy edge (length 0, ._layout) has no length derivative, and
        # does not end at its first vertex (prv of that vertex)
        has_v = lv > 0.0
        has_p = nxt[p] == v
        for d in range(3):
            # edge v = (v, nxt v): ∂l/∂x_v = −t_v; edge p = (p, v): ∂l/∂x_v = t_p
            tv = gl[v] * (X[j, d] - X[v, d]) / lv if has_v else 0.0
            tp = gl[p] * (X[v, d] - X[p, d]) / lp if has_p else 0.0
            G[v, d] = 0.5 * (gm[v, d] + gm[p, d]) - tv + tp
    return G


# -- contact ----------------------------------------------------------------------------------


@nb.njit(cache=True)
def _pair_time(X, U, i, j, v, mx, my, mz, half, T, centre, radius, k, eps, tb):
    """First τ < tb at which edge (i, j) of ``X − τU`` (speed at most ``v``, midpoint ``m``,
    half length ``half``) comes within ``eps`` of triangle ``k``, or a τ ≥ tb when it does not
    before tb: from the first time their bounding spheres could meet, advanced by
    ``(d − eps) / v`` with the exact distance ``d`` (the triangles do not move)."""
    gap = np.sqrt((mx - centre[k, 0]) ** 2 + (my - centre[k, 1]) ** 2
                  + (mz - centre[k, 2]) ** 2) - half - radius[k] - eps
    tau = max(gap / v, 0.0)
    if tau >= tb:
        return tau
    for _ in range(_MAX_ADVANCE):
        d2 = _segment_triangle_distance2(
            X[i, 0] - tau * U[i, 0], X[i, 1] - tau * U[i, 1], X[i, 2] - tau * U[i, 2],
            X[j, 0] - tau * U[j, 0], X[j, 1] - tau * U[j, 1], X[j, 2] - tau * U[j, 2], T, k)
        d = np.sqrt(d2)
        if d <= SLACK * eps:
            return tau
        tau += (d - eps) / v
        if tau >= tb:
            return tau
    return tau


@nb.njit(cache=True, inline="always")
def _edge_motion(X, U, i, j):
    v = max(np.sqrt(U[i, 0] ** 2 + U[i, 1] ** 2 + U[i, 2] ** 2),
            np.sqrt(U[j, 0] ** 2 + U[j, 1] ** 2 + U[j, 2] ** 2))
    mx = 0.5 * (X[i, 0] + X[j, 0])
    my = 0.5 * (X[i, 1] + X[j, 1])
    mz = 0.5 * (X[i, 2] + X[j, 2])
    half = 0.5 * np.sqrt((X[j, 0] - X[i, 0]) ** 2 + (X[j, 1] - X[i, 1]) ** 2
                         + (X[j, 2] - X[i, 2]) ** 2)
    return v, mx, my, mz, half


@nb.njit(cache=True, parallel=True)
def _contact_pairs(X, U, nxt, T, centre, radius, tau_max, eps, nchunks):
    """First τ ≤ tau_max at which an edge of ``X − τU`` comes within ``eps`` of a triangle
    (conservative: never later than the true time), over all edge–triangle pairs (the
    reference of :func:`_contact_tree`)."""
    n = X.shape[0]
    best = np.full(nchunks, tau_max)
    for cc in nb.prange(nchunks):
        tb = tau_max
        for i in range(cc, n, nchunks):
            j = nxt[i]
            v, mx, my, mz, half = _edge_motion(X, U, i, j)
            if v == 0.0:
                continue
            for k in range(T.shape[0]):
                tb = min(tb, _pair_time(X, U, i, j, v, mx, my, mz, half, T, centre, radius,
                                        k, eps, tb))
        best[cc] = tb
    return best.min()


@nb.njit(cache=True, parallel=True)
def _contact_tree(X, U, nxt, T, centre, radius, lo, hi, left, right, bmin, bmax, tau_max,
                  eps, nchunks):
    """:func:`_contact_pairs` through the triangles' hierarchy: a node is skipped when even
    its box, less the edge's half length and ``eps``, is farther from the edge's midpoint than
    the edge can travel before the best time so far (every point of a moving edge stays within
    ``half + v τ`` of its start midpoint). The pairs it visits are timed as there, and the
    pairs it skips would have met no sooner: the same value."""
    n = X.shape[0]
    best = np.full(nchunks, tau_max)
    stack = np.empty((nchunks, 128), np.int64)
    for cc in nb.prange(nchunks):
        tb = tau_max
        for i in range(cc, n, nchunks):
            j = nxt[i]
            v, mx, my, mz, half = _edge_motion(X, U, i, j)
            if v == 0.0:
                continue
            top = 0
            stack[cc, 0] = 0
            top = 1
            while top > 0:
                top -= 1
                node = stack[cc, top]
                dx = max(bmin[node, 0] - mx, 0.0, mx - bmax[node, 0])
                dy = max(bmin[node, 1] - my, 0.0, my - bmax[node, 1])
                dz = max(bmin[node, 2] - mz, 0.0, mz - bmax[node, 2])
                if (np.sqrt(dx * dx + dy * dy + dz * dz) - half - eps) / v >= tb:
                    continue
                if left[node] < 0:
                    for k in range(lo[node], hi[node]):
                        tb = min(tb, _pair_time(X, U, i, j, v, mx, my, mz, half, T, centre,
                                                radius, k, eps, tb))
                else:
                    stack[cc, top] = left[node]
                    stack[cc, top + 1] = right[node]
                    top += 2
        best[cc] = tb
    return best.min()


def triangle_tree(T: np.ndarray, leaf: int = 8):
    """A bounding-box hierarchy over triangles ``T`` (K, 3, 3), split at the median centroid
    along the longest side of each box: ``(order, lo, hi, left, right, bmin, bmax)``, with the
    triangles of node ``i`` at ``order[lo[i]:hi[i]]`` and ``left[i] < 0`` at leaves."""
    K = T.shape[0]
    centre = T.mean(axis=1)
    order = np.arange(K)
    lo, hi, left, right = [0], [K], [-1], [-1]
    todo = [0]
    while todo:
        node = todo.pop()
        a, b = lo[node], hi[node]
        if b - a <= leaf:
            continue
        idx = order[a:b]
        c = centre[idx]
        axis = int(np.argmax(c.max(axis=0) - c.min(axis=0)))
        m = (b - a) // 2
        part = np.argpartition(c[:, axis], m)
        order[a:b] = idx[part]
        for s, e in ((a, a + m), (a + m, b)):
            lo.append(s)
            hi.append(e)
            left.append(-1)
            right.append(-1)
            todo.append(len(lo) - 1)
        left[node], right[node] = len(lo) - 2, len(lo) - 1
    lo, hi = np.array(lo, np.int64), np.array(hi, np.int64)
    pts = T[order]
    bmin = np.array([pts[s:e].reshape(-1, 3).min(axis=0) for s, e in zip(lo, hi, strict=True)])
    bmax = np.array([pts[s:e].reshape(-1, 3).max(axis=0) for s, e in zip(lo, hi, strict=True)])
    return (order, lo, hi, np.array(left, np.int64), np.array(right, np.int64),
            np.ascontiguousarray(bmin), np.ascontiguousarray(bmax))


@nb.njit(cache=True, parallel=True)
def _nearest(X, nxt, T, skip):
    """Per edge: the nearest triangle and the squared distance to it (0 where they meet);
    infinitely far for the edges of ``skip``."""
    n = X.shape[0]
    which = np.full(n, -1, np.int64)
    dist2 = np.full(n, np.inf)
    for i in nb.prange(n):
        if skip[i]:
            continue
        j = nxt[i]
        b = np.inf
        w = -1
        for k in range(T.shape[0]):
            d2 = _segment_triangle_distance2(X[i, 0], X[i, 1], X[i, 2],
                                             X[j, 0], X[j, 1], X[j, 2], T, k)
            if d2 < b:
                b = d2
                w = k
        which[i] = w
        dist2[i] = b
    return which, dist2


@nb.njit(cache=True, parallel=True)
def _nearest_tree(X, nxt, T, skip, lo, hi, left, right, bmin, bmax):
    """:func:`_nearest` through the triangles' hierarchy: a node is skipped when the squared
    gap between its box and the edge's box exceeds the best squared distance so far (no
    triangle in it can be nearer, or as near). Ties go to the lower triangle index, as in
    the full scan, so both give the same triangle and the same distance."""
    n = X.shape[0]
    which = np.full(n, -1, np.int64)
    dist2 = np.full(n, np.inf)
    for i in nb.prange(n):
        if skip[i]:
            continue
        stack = np.empty(128, np.int64)
        j = nxt[i]
        b = np.inf
        w = -1
        stack[0] = 0
        top = 1
        while top > 0:
            top -= 1
            node = stack[top]
            g2 = 0.0
            for d in range(3):
                e0 = min(X[i, d], X[j, d])
                e1 = max(X[i, d], X[j, d])
                g = max(bmin[node, d] - e1, 0.0, e0 - bmax[node, d])
                g2 += g * g
            if g2 > b:
                continue
            if left[node] < 0:
                for k in range(lo[node], hi[node]):
                    d2 = _segment_triangle_distance2(X[i, 0], X[i, 1], X[i, 2],
                                                     X[j, 0], X[j, 1], X[j, 2], T, k)
                    if d2 < b or (d2 == b and k < w):
                        b = d2
                        w = k
            else:
                stack[top] = left[node]
                stack[top + 1] = right[node]
                top += 2
        which[i] = w
        dist2[i] = b
    return which, dist2


#: A start nearer an obstacle than this many contact distances is refused: every step stops
#: at the contact distance, so a curve that starts barely outside it can hardly move (a trefoil
#: 1.2 contact distances above a plate stalled at once, energy ~1e9; at 1.6 it relaxed).
START_CLEARANCE = 2.0


class ObstacleField:
    """The triangles of all obstacles in a run's coordinates (``(x − shift) / scale``), and
    what the flow asks of them.

    Parameters
    ----------
    meshes : list of (V, F)
        As :func:`check_obstacles` returns them (in the caller's coordinates).
    shift, scale
        The run's map from the caller's coordinates to its own.
    weight : float
        Factor of the obstacle energy in the flow's objective.
    labels : list of str, optional
        What each mesh is called in messages ("obstacle m" by default; "the container").
    """

    def __init__(self, meshes, shift=0.0, scale: float = 1.0, weight: float = 1.0,
                 labels=None, tol: float = 0.0):
        self.labels = (list(labels) if labels is not None
                       else [f"obstacle {m}" for m in range(len(meshes))])
        tri, owner, local = [], [], []
        for m, (V, F) in enumerate(meshes):
            tri.append(((V - shift) / scale)[F])
            owner.append(np.full(len(F), m))
            local.append(np.arange(len(F)))
        T = np.concatenate(tri)  # (K, 3, 3)
        # the triangles in the order of their hierarchy (the step bound's search)
        order, *self.tree = triangle_tree(T)
        self.T = np.ascontiguousarray(T[order])
        self.owner = np.concatenate(owner)[order]
        self.local = np.concatenate(local)[order]
        a, b, c = self.T[:, 0], self.T[:, 1], self.T[:, 2]
        self.area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
        self.centre = np.ascontiguousarray((a + b + c) / 3.0)
        self.radius = np.max(np.linalg.norm(self.T - self.centre[:, None, :], axis=2), axis=1)
        self.weight = float(weight)
        self.scale = float(scale)
        #: Relative error bound of each edge's obstacle energy (0: every pair, exactly).
        self.tol = float(tol)
        lo, hi = self.tree[0], self.tree[1]
        self._moments = _node_moments(self.T, self.area, self.centre, self.radius, lo, hi)
        #: vertices that never move (pins): an edge between two of them (the first edge of a
        #: cable whose end and tangent are pinned on the plate it hangs from) is left out of
        #: the energy and the start check; a step never moves it, so no contact is possible
        self.fixed: np.ndarray | None = None
        self._skipped: tuple | None = None  # (nxt, fixed, the mask _skip made of them)

    def _skip(self, nxt: np.ndarray) -> np.ndarray:
        """The edge slots whose two ends are :attr:`fixed` (an open end's dummy slot, whose
        two ends are its last vertex, too); made once per layout (every evaluation asks)."""
        if (self._skipped is not None and self._skipped[0] is nxt
                and self._skipped[1] is self.fixed):
            return self._skipped[2]
        skip = np.zeros(len(nxt), dtype=np.bool_)
        if self.fixed is not None:
            pinned = np.zeros(len(nxt), dtype=np.bool_)
            pinned[self.fixed] = True
            skip = pinned & pinned[nxt]
        self._skipped = (nxt, self.fixed, skip)
        return skip

    @property
    def triangles(self) -> int:
        return int(self.T.shape[0])

    def energy(self, X: np.ndarray, nxt: np.ndarray) -> float:
        """``weight × E_obs`` of the polygon(s) ``X`` with successor array ``nxt``."""
        e, _, _ = self._terms(X, nxt, False)
        return self.weight * float(e.sum())

    def _terms(self, X, nxt, grad):
        if self.tol > 0.0:
            lo, hi, left, right = self.tree[:4]
            return _edge_terms_tree(X, nxt, self.T, self.area, self._skip(nxt), left, right, lo,
                                    hi, *self._moments, self.tol, grad)
        return _edge_terms(X, nxt, self.T, self.area, self._skip(nxt), grad)

    def energy_gradient(self, X: np.ndarray, nxt: np.ndarray, prv: np.ndarray
                        ) -> tuple[float, np.ndarray]:
        """``weight × (E_obs, ∇E_obs)``; the gradient is (N, 3)."""
        e, gm, gl = self._terms(X, nxt, True)
        G = _gather(X, nxt, prv, gm, gl)
        return self.weight * float(e.sum()), self.weight * G

    def contact_time(self, X: np.ndarray, U: np.ndarray, nxt: np.ndarray, tau_max: float,
                     eps: float, search: str = "tree") -> float:
        """Smallest ``τ ≤ tau_max`` at which ``X − τU`` comes within ``eps`` of a triangle
        (conservative), or ``tau_max``; ``search`` "tree" (the triangles' hierarchy) or
        "pairs" (all pairs): the same value."""
        U = np.ascontiguousarray(U, dtype=np.float64)
        chunks = 4 * nb.get_num_threads()
        if search == "pairs":
            return float(_contact_pairs(X, U, nxt, self.T, self.centre, self.radius,
                                        float(tau_max), float(eps), chunks))
        return float(_contact_tree(X, U, nxt, self.T, self.centre, self.radius, *self.tree,
                                   float(tau_max), float(eps), chunks))

    def nearest(self, X: np.ndarray, nxt: np.ndarray, search: str = "tree"
                ) -> tuple[int, int, float]:
        """``(edge, triangle, distance)`` of the closest edge–triangle pair (0: they meet);
        ``search`` "tree" (the triangles' hierarchy; 100 cables of 200 edges and 2 048
        triangles: 0.43 s against 2.7 s for all pairs, docs/lab/cables-and-obstacles.md) or
        "pairs": the
        same value."""
        if search == "pairs":
            which, dist2 = _nearest(X, nxt, self.T, self._skip(nxt))
        else:
            lo, hi, left, right, bmin, bmax = self.tree
            which, dist2 = _nearest_tree(X, nxt, self.T, self._skip(nxt), lo, hi, left, right,
                                         bmin, bmax)
        i = int(np.argmin(dist2))
        return i, int(which[i]), float(np.sqrt(dist2[i]))

    def check_clear(self, X: np.ndarray, layout, eps: float, thickness: float = 0.0) -> None:
        """Refuse a start that crosses or touches an obstacle (within :data:`START_CLEARANCE`
        times the contact distance ``eps``; with a tube radius ``thickness`` in the caller's
        units, within ``SLACK`` × ``eps``, the contact test's margin), naming the edge, the
        obstacle and its triangle, in the caller's units."""
        i, k, d = self.nearest(X, layout.nxt)
        if d > (SLACK * eps if thickness > 0 else START_CLEARANCE * eps):
            return
        c = int(layout.comp[i])
        edge = int(i - layout.starts[c])
        where = f"edge {edge} of component {c}" if layout.is_link else f"edge {edge}"
        label = self.labels[int(self.owner[k])]
        tri = f"triangle {int(self.local[k])} of {label}"
        what = "the container's wall" if label.startswith("the container") else "an obstacle"
        ends = [] if self.fixed is None else [v for v in (i, int(layout.nxt[i]))
                                               if np.any(self.fixed == v)]
        if ends:  # a pinned end on the mesh: fixed with its neighbour, its edge never moves
            v = ends[0]
            where = (f"vertex {v - int(layout.starts[c])} of component {c}" if layout.is_link
                     else f"vertex {v}")
            raise ValueError(f"the pinned {where} touches {what} ({tri}) and the edge beside "
                             "it can move: pin its tangent too (pin_tangents=True; the panel's "
                             "Pin Tangents) so that the edge stays where it is, or move the "
                             f"point more than {eps * self.scale:.3g} off")
        if d == 0.0:
            raise ValueError(f"the curve crosses {what}: {where} passes through {tri}; "
                             f"move the curve or {label} so that they do not meet")
        if thickness > 0:
            below = (f"below the thickness {thickness:.4g}" if d * self.scale < thickness
                     else f"within {100 * (SLACK - 1):g}% of the thickness {thickness:.4g} "
                          f"(the contact test needs that margin to move it)")
            raise ValueError(f"the curve's tube meets {what}: {where} is "
                             f"{d * self.scale:.4g} from {tri}, {below}; move it clear or use "
                             f"a thickness below {d * self.scale / SLACK:.4g}")
        raise ValueError(f"the curve touches {what}: {where} is {d * self.scale:.3g} "
                         f"from {tri}, nearer than the {START_CLEARANCE * eps * self.scale:.3g} "
                         "the flow needs to move; move it clear first")
