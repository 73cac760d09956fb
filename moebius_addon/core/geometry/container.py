"""Containers: a closed triangle mesh a relaxing curve stays inside.

A run given ``container=(V, F)`` keeps the curve in the region the mesh bounds. The mesh's
triangles join the obstacles' (:mod:`.obstacles`): the same energy repels the curve from the
wall (from the inside) and the same contact bound stops every step before any edge comes
within the contact distance of a triangle. A curve that starts strictly inside therefore never
leaves: to leave, some edge would have to meet the wall, and no step lets it come that close.

What is checked (:func:`check_container`): everything :func:`.obstacles.check_obstacles`
checks (finite vertices, triangles with area, no edge on more than two triangles), and that
the mesh is *closed* — every edge on exactly two triangles — and *consistently oriented* —
the two triangles of each edge run along it in opposite directions. A mesh whose triangles all
face inwards (negative enclosed volume) is turned round; the region is the same. At the start
(:func:`inside`), every vertex of the curve must be inside, by the winding number of the mesh
about it (the sum of its triangles' signed solid angles over 4π: 1 inside, 0 outside).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .layout import unit_exponent
from .obstacles import check_obstacles


def check_container(container) -> tuple[np.ndarray, np.ndarray]:
    """``container`` as ``(V, F)`` float64 / int64 arrays of a closed, consistently oriented
    mesh with its triangles facing outwards.

    Raises
    ------
    ValueError
        Not a ``(V, F)`` mesh (:func:`.obstacles.check_obstacles`, naming it "container"); an
        edge on one triangle only (a hole: the mesh is not closed); an edge whose two triangles
        run along it in the same direction (inconsistent orientation, e.g. a Möbius band or
        flipped faces); a mesh that encloses no volume.
    """
    try:
        ((V, F),) = check_obstacles([container])
    except ValueError as err:
        raise ValueError(str(err).replace("obstacle 0", "the container")
                         .replace("obstacles must", "container must")) from None
    directed = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    und = np.sort(directed, axis=1)
    uniq, counts = np.unique(und, axis=0, return_counts=True)
    if counts.min() < 2:
        e = uniq[int(np.argmin(counts))]
        holes = int((counts == 1).sum())
        raise ValueError(f"the container is not closed: its edge between vertices {int(e[0])} "
                         f"and {int(e[1])} belongs to one triangle only ({holes} such edges); "
                         "a container must be a closed (watertight) mesh — fill its holes "
                         "(in Blender: select the boundary, F) or merge duplicate vertices "
                         "(Merge by Distance)")
    duniq, dcounts = np.unique(directed, axis=0, return_counts=True)
    if dcounts.max() > 1:
        e = duniq[int(np.argmax(dcounts))]
        raise ValueError(f"the container is not consistently oriented: its two triangles at "
                         f"the edge between vertices {int(e[0])} and {int(e[1])} run along it "
                         "in the same direction; recalculate its normals (in Blender: Mesh > "
                         "Normals > Recalculate Outside)")
    # at the mesh's own size near 1 (exact scaling): the volume of a mesh 1e-150 across
    # underflows to 0, the cube of one 1e160 across overflows
    Vu = np.ldexp(V - (V.max(axis=0) / 2 + V.min(axis=0) / 2), -unit_exponent(V))
    a, b, c = Vu[F[:, 0]], Vu[F[:, 1]], Vu[F[:, 2]]
    volume = float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum()) / 6.0
    size = float(np.ptp(Vu, axis=0).max())
    if abs(volume) <= 1e-9 * size ** 3:
        raise ValueError("the container encloses no volume (its triangles cancel out); "
                         "give a closed mesh around the region the curve must stay in")
    if volume < 0.0:
        F = np.ascontiguousarray(F[:, ::-1])  # facing inwards: turn every triangle round
    return V, F


@nb.njit(cache=True, parallel=True)
def _winding(P, T):
    """Winding number of the triangles ``T`` (K, 3, 3) about each point of ``P`` (N, 3): the
    sum of their signed solid angles (Van Oosterom and Strackee's formula) over 4π."""
    n = P.shape[0]
    w = np.empty(n)
    for i in nb.prange(n):
        s = 0.0
        for k in range(T.shape[0]):
            ax, ay, az = T[k, 0, 0] - P[i, 0], T[k, 0, 1] - P[i, 1], T[k, 0, 2] - P[i, 2]
            bx, by, bz = T[k, 1, 0] - P[i, 0], T[k, 1, 1] - P[i, 1], T[k, 1, 2] - P[i, 2]
            cx, cy, cz = T[k, 2, 0] - P[i, 0], T[k, 2, 1] - P[i, 1], T[k, 2, 2] - P[i, 2]
            la = np.sqrt(ax * ax + ay * ay + az * az)
            lb = np.sqrt(bx * bx + by * by + bz * bz)
            lc = np.sqrt(cx * cx + cy * cy + cz * cz)
            det = (ax * (by * cz - bz * cy) - ay * (bx * cz - bz * cx)
                   + az * (bx * cy - by * cx))
            den = (la * lb * lc + (ax * bx + ay * by + az * bz) * lc
                   + (bx * cx + by * cy + bz * cz) * la + (cx * ax + cy * ay + cz * az) * lb)
            s += 2.0 * np.arctan2(det, den)
        w[i] = s / (4.0 * np.pi)
    return w


def inside(V: np.ndarray, F: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Whether each point of ``P`` (N, 3) is inside the closed, outward-oriented mesh
    ``(V, F)`` (a winding number above one half); points on the wall are not told apart."""
    T = np.ascontiguousarray(np.asarray(V, np.float64)[np.asarray(F)])
    return _winding(np.ascontiguousarray(P, dtype=np.float64), T) > 0.5


def check_inside(V: np.ndarray, F: np.ndarray, X: np.ndarray, layout,
                 label: str = "the container") -> None:
    """Refuse a curve ``X`` (the run's vertices; ``V`` in the same coordinates) that is not
    inside the container (called ``label``), saying how much of it is out and which vertex
    first."""
    out = np.flatnonzero(~inside(V, F, X))
    if out.size == 0:
        return
    v = int(out[0])
    c = int(layout.comp[v])
    where = (f"vertex {v - int(layout.starts[c])} of component {c}" if layout.is_link
             else f"vertex {v}")
    if out.size == len(X):
        raise ValueError(f"the curve is outside {label}: a container keeps the curve "
                         "inside it, so the curve must start inside; move the curve into the "
                         "container (or give it as an obstacle instead)")
    raise ValueError(f"the curve is partly outside {label}: {out.size} of its {len(X)} "
                     f"vertices are outside (the first: {where}); move the curve wholly "
                     "inside the container")
