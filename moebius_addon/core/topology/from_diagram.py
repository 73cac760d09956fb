"""A planar diagram drawn as a space curve: a PD code becomes a knot or link to relax.

1. Kinks and nugatory crossings are removed (Reidemeister I, and the twist that removes a
   crossing whose two opposite corners lie in one face): the link is unchanged, and what is left
   is a *reduced* diagram, each of whose crossings meets four distinct faces.
2. The diagram's map is subdivided barycentrically: a vertex per crossing, per edge and per
   face, joined where they meet. For a reduced diagram this is a triangulation of the sphere
   without double edges, so it is 3-connected, and Tutte's barycentric embedding (every inner
   vertex at the average of its neighbours, the boundary of the largest face fixed on a
   circle) draws it in the plane without crossings of its edges (Tutte, *How to draw a
   graph*, 1963; Floater 2003 for a triangulated disk).
3. Each strand follows crossing → edge vertex → crossing of that drawing, at height +h where
   it passes over and −h where it passes under, 0 at the edge vertices; corner cutting
   (Chaikin) smooths it. The drawing is reflected if the embedding came out clockwise, so the
   crossings keep their signs.

The result is checked: its own projection's Jones polynomial (or, for diagrams too large for
it, the Alexander polynomial) must equal the code's.
"""

from __future__ import annotations

import numpy as np

from . import jones
from .pd import DisjointSets, PlanarDiagram, edge_slots, faces, remove_crossings, simplify

__all__ = ["diagram_curves"]

_HEIGHT = 0.35  # crossing heights, in mean edge lengths of the drawing
_CUTS = 4  # rounds of corner cutting
_REWEIGHT = 3  # rounds of Tutte's embedding with weights from the last one's edge lengths
_POWER = 1.0  # weights ∝ length^_POWER (10 % fewer edges needed than plain Tutte on 22 knots)


def _nugatory(d: PlanarDiagram) -> int | None:
    """A crossing whose opposite corners lie in one face (a cut vertex of the diagram)."""
    face_of = {}
    for k, face in enumerate(faces(d)):
        for s in face:
            face_of[s] = k
    for m in range(d.crossings):
        if face_of[(m, 0)] == face_of[(m, 2)] or face_of[(m, 1)] == face_of[(m, 3)]:
            return m
    return None


def reduce(d: PlanarDiagram) -> PlanarDiagram:
    """Remove kinks and nugatory crossings (both leave the link as it is)."""
    while d.crossings:
        m = _nugatory(d)  # a kink's crossing is nugatory too
        if m is None:
            return d
        d = remove_crossings(d, [m])
    return d


def _pieces(d: PlanarDiagram) -> list[list[int]]:
    """Crossings of each connected piece of the diagram."""
    sets = DisjointSets()
    for slots in edge_slots(d.X).values():
        (m1, _), (m2, _) = slots
        sets.union(m2, m1)
    groups: dict[int, list[int]] = {}
    for m in range(d.crossings):
        groups.setdefault(sets.find(m), []).append(m)
    return list(groups.values())


def _tutte(d: PlanarDiagram):
    """Positions of the crossings and edges of a connected reduced diagram: ``(crossing xy
    (c, 2), {edge label: xy})``."""
    c = d.crossings
    labels = sorted({int(e) for e in d.X.ravel()})
    eidx = {e: c + k for k, e in enumerate(labels)}
    fs = faces(d)
    nv = c + len(labels) + len(fs)
    adj: list[set[int]] = [set() for _ in range(nv)]

    def join(a, b):
        adj[a].add(b)
        adj[b].add(a)

    for m in range(c):
        for p in range(4):
            join(m, eidx[int(d.X[m, p])])
    cycles = []
    for k, face in enumerate(fs):
        fv = c + len(labels) + k
        cycle = []
        for m, p in face:  # corner between slot p and p + 1: crossing m, then the edge at p
            cycle += [m, eidx[int(d.X[m, p])]]
        for v in cycle:
            join(fv, v)
        cycles.append(cycle)
    outer = max(range(len(fs)), key=lambda k: len(cycles[k]))
    boundary = cycles[outer]
    pos = np.zeros((nv, 2))
    t = 2.0 * np.pi * np.arange(len(boundary)) / len(boundary)
    pos[boundary] = np.column_stack([np.cos(t), np.sin(t)])
    fixed = np.zeros(nv, bool)
    fixed[boundary] = True
    fixed[c + len(labels) + outer] = True  # the outer face's centre is left out
    inner = np.flatnonzero(~fixed)
    where = {v: i for i, v in enumerate(inner)}
    skip = c + len(labels) + outer
    pairs = [(v, u) for v in inner for u in adj[v] if u != skip]
    w = np.ones(len(pairs))
    for _ in range(_REWEIGHT + 1):
        A = np.zeros((len(inner), len(inner)))
        b = np.zeros((len(inner), 2))
        for (v, u), wk in zip(pairs, w, strict=True):
            i = where[v]
            A[i, i] += wk
            if fixed[u]:
                b[i] += wk * pos[u]
            else:
                A[i, where[u]] -= wk
        if len(inner):
            pos[inner] = np.linalg.solve(A, b)
        # any positive weights keep the drawing planar (Floater): pulling harder along long
        # edges spreads the crowded middle of the barycentric drawing
        w = np.array([np.linalg.norm(pos[v] - pos[u]) for v, u in pairs]) ** _POWER
        w = np.maximum(w / w.max(), 1e-6)
    # the PD lists each crossing's edges counter-clockwise: reflect a clockwise drawing
    v = pos[[eidx[int(e)] for e in d.X[0]]] - pos[0]
    order = np.argsort(np.arctan2(v[:, 1], v[:, 0])).tolist()  # slots by increasing angle
    k = order.index(0)
    if order[k:] + order[:k] != [0, 1, 2, 3]:
        pos[:, 0] *= -1.0
    return pos[:c], {e: pos[eidx[e]] for e in labels}


def _chaikin(P: np.ndarray, rounds: int) -> np.ndarray:
    for _ in range(rounds):
        Q = np.roll(P, -1, axis=0)
        P = np.stack([0.75 * P + 0.25 * Q, 0.25 * P + 0.75 * Q], axis=1).reshape(-1, 3)
    return P


def _piece_curves(d: PlanarDiagram) -> list[np.ndarray]:
    xy, exy = _tutte(d)
    # heights: the scale of the drawing's edges
    seg = [np.linalg.norm(xy[m] - exy[int(d.X[m, p])]) for m in range(d.crossings)
           for p in range(4)]
    h = _HEIGHT * float(np.mean(seg))
    # where each edge ends: the crossing it enters and whether it passes over there
    enters = {}
    for m in range(d.crossings):
        i, j, k, l = (int(v) for v in d.X[m])  # noqa: E741 - X[i, j, k, l]
        enters[i] = (m, -1.0, k)
        if d.sign[m] > 0:
            enters[l] = (m, 1.0, j)
        else:
            enters[j] = (m, 1.0, l)
    curves = []
    for comp in d.components():
        pts = []
        for e in comp:
            m, z, _ = enters[e]
            pts.append([*exy[e], 0.0])
            pts.append([*xy[m], z * h])
        curves.append(_chaikin(np.array(pts), _CUTS))
    return curves


def diagram_curves(d: PlanarDiagram) -> list[np.ndarray]:
    """Dense closed space curves, one per component, whose projection to the xy-plane is the
    diagram ``d`` with its kinks and nugatory crossings removed (the same link)."""
    d = reduce(d)
    curves: list[np.ndarray] = []
    offset = 0.0
    for piece in _pieces(d):
        keep = np.zeros(d.crossings, bool)
        keep[piece] = True
        sub = PlanarDiagram(d.X[keep], d.sign[keep], 0)
        cs = _piece_curves(sub)
        lo = min(c[:, 0].min() for c in cs)
        hi = max(c[:, 0].max() for c in cs)
        curves += [c + [offset - lo, 0.0, 0.0] for c in cs]
        offset += hi - lo + 0.5
    t = 2.0 * np.pi * np.arange(256) / 256
    for _ in range(d.loops):  # circles apart from the rest
        curves.append(np.column_stack([offset + 0.4 + 0.4 * np.cos(t), 0.4 * np.sin(t),
                                       np.zeros_like(t)]))
        offset += 1.3
    return curves


def check_same(d: PlanarDiagram, P, max_states: int = 20_000) -> None:
    """RuntimeError unless the curve ``P`` has the diagram's Jones polynomial (its Alexander
    polynomial when the Jones polynomial is too costly): a guard on the drawing."""
    from .invariants import alexander_polynomial, planar_diagram

    e = planar_diagram(P)
    try:
        same = jones.jones(simplify(d), max_states) == jones.jones(e, max_states)
    except jones.TooComplex:
        same = alexander_polynomial(d) == alexander_polynomial(e)
    if not same:
        raise RuntimeError("the curve drawn from this diagram is not the diagram's link "
                           "(a bug in core.topology.from_diagram; please report the PD code)")
