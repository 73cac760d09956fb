"""Continuous edge–edge collision detection (docs/design.md, step 3) and static proximity queries.

The step bound ``τ*`` is the smallest ``τ`` at which ``P − τU`` touches itself. Each pair of
disjoint edges is tested by conservative advancement: the distance between two segments changes
at most at the largest relative speed ``v`` of their endpoints, so ``τ`` may advance by
``(d − ε) / v`` without contact. This needs no root finding and is exact for planar
motions, where the coplanarity cubic of the classical test vanishes identically. Pairs whose
midpoint distance rules out contact before the current bound are skipped at once; the others
start advancing at the first time their midpoint spheres could meet (midpoints move on
straight lines; the spheres grow with the spread of the endpoint velocities), found by one
quadratic root. At 1648 edges that cut the step-bound search of the FHW flow from 42 to 4 ms
(same result to 1e-5 relative: a different, still conservative advancement sequence).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ..runs.checks import check_number
from ..tree import contact as tree_contact
from .edge_pairs import _pair_contact, edge_motion, pair_time, segment_distance2, tested  # noqa: F401
from .layout import Layout, as_checked_layout, as_layout, check_finite

# From these many edges on, the queries go through the hierarchy (tree_contact): the same answers,
# measured faster there (FHW and 5_2, ms all pairs / tree: contact 0.33/0.38 at 700 edges,
# 0.66/0.41 at 1 000; closest pairs 0.31/0.25 at 200, 0.50/0.33 at 400).
CONTACT_TREE_FROM = 1000
CLOSEST_TREE_FROM = 400
_SEARCHES = ("auto", "pairs", "tree")


def _use_tree(search: str, n: int, crossover: int) -> bool:
    if search not in _SEARCHES:
        raise ValueError(f"search must be one of {', '.join(_SEARCHES)}, got {search!r}")
    return search == "tree" or (search == "auto" and n >= crossover)


@nb.njit(cache=True, parallel=True)
def _contact_rows(X, U, nxt, starts, comp, closed, near, tau_max, eps, nchunks):
    n = X.shape[0]
    mid, vel, spread, half, vmax = edge_motion(X, U, nxt)
    best = np.full(nchunks, tau_max)
    for cc in nb.prange(nchunks):
        ch = np.int64(cc)
        tb = tau_max
        for i in range(ch, n, nchunks):
            for j in range(i + 2, n):
                if tested(i, j, starts, comp, closed, near):
                    tb = pair_time(X, U, nxt, i, j, mid, vel, spread, half, vmax, eps, tb)
        best[ch] = tb
    return best.min()


def contact_time_x(X, U, layout: Layout, tau_max: float, eps: float,
                   search: str = "auto", near=None, tree=None) -> float:
    """First contact of ``X − τU`` up to ``tau_max``; ``search`` "pairs" (all pairs), "tree"
    (the hierarchy: the same value) or "auto" (the tree from ``CONTACT_TREE_FROM`` edges).
    ``near``: per component, pairs
    of its edges this many apart along it or nearer are not tested (:func:`._pairs.tested`;
    default 1, the edges that share a vertex; a thickness leaves out more, :mod:`.thickness`).
    Open components' dummy edges (._layout) are points at their last vertex, tested as such
    (by both searches: the hierarchy's rule for the pairs it skips is the all-pairs one).
    ``tree``: the hierarchy of ``X``'s edges if already built (:func:`.tree.bvh.build`)."""
    near = np.ones(layout.k, np.int64) if near is None else near
    if _use_tree(search, layout.n, CONTACT_TREE_FROM):
        return tree_contact.contact_time_tree(X, U, layout, tau_max, eps, near, tree)
    return float(
        _contact_rows(X, np.ascontiguousarray(U), layout.nxt, layout.starts, layout.comp,
                      layout.closed_flags, near, float(tau_max), float(eps), 16)
    )


def max_collision_free_step(P, U, tau_max: float, eps: float | None = None) -> float:
    """Smallest step ``τ ≤ tau_max`` at which ``P − τU`` touches itself.

    Parameters
    ----------
    P : (N, 3) array or list of arrays
        Closed polygon or link.
    U : same shape as P
        Direction field; the motion is ``P − τU``.
    tau_max : float
        Search bound; returned when no contact happens before it.
    eps : float, optional
        Distance that counts as contact (default 1e-3 of the mean edge length).

    Returns
    -------
    float
        Conservative (never larger than the true contact time).
    """
    tau_max = check_number("tau_max", tau_max, 0)
    if eps is not None:
        eps = check_number("eps", eps, 0, above=True)
    X, layout, k = as_checked_layout(P, touching=False)
    Ux, ulayout = as_layout(U)
    if not np.array_equal(ulayout.starts, layout.starts) or ulayout.is_link != layout.is_link:
        raise ValueError("U must have the shape of P: one (N, 3) row per vertex (a list of "
                         "such arrays for a link)")
    check_finite(Ux, layout, "the direction U")
    if k:  # P, U and eps scaled alike (exactly, by 2^-k): the same contact time
        Ux = np.ldexp(Ux, -k)
        eps = None if eps is None else float(np.ldexp(eps, -k))
    if eps is None:
        eps = 1e-3 * float(np.linalg.norm(X[layout.nxt] - X, axis=1).mean())
    return contact_time_x(X, Ux, layout, tau_max, eps)


@nb.njit(cache=True, parallel=True)
def _closest_pairs(X, nxt, starts, comp, closed, min_gap, nchunks):
    """Per chunk: the smallest distance between vertices at least ``min_gap`` apart along a
    component (any two vertices of different components; around a closed component the
    shorter way, along an open one without wrapping) and the smallest distance between
    disjoint edges, with the indices where they occur (an open component's dummy edge, a
    point at its last vertex, is left out)."""
    n = X.shape[0]
    vbest = np.full(nchunks, np.inf)
    vidx = np.zeros((nchunks, 2), dtype=np.int64)
    ebest = np.full(nchunks, np.inf)
    eidx = np.zeros((nchunks, 2), dtype=np.int64)
    epar = np.zeros((nchunks, 2))
    for cc in nb.prange(nchunks):
        ch = np.int64(cc)
        for i in range(ch, n, nchunks):
            c = comp[i]
            size = starts[c + 1] - starts[c]
            i1 = nxt[i]
            for j in range(i + 1, n):
                same = comp[j] == c
                gap = j - i
                if same and closed[c]:
                    gap = min(gap, size - gap)
                if (not same) or gap >= min_gap:
                    d2 = (X[i, 0] - X[j, 0]) ** 2 + (X[i, 1] - X[j, 1]) ** 2 + (
                        X[i, 2] - X[j, 2]
                    ) ** 2
                    if d2 < vbest[ch]:
                        vbest[ch] = d2
                        vidx[ch, 0] = i
                        vidx[ch, 1] = j
                j1 = nxt[j]
                if ((not same) or gap >= 2) and i1 != i and j1 != j:
                    d2, s, t = segment_distance2(
                        X[i, 0], X[i, 1], X[i, 2], X[i1, 0], X[i1, 1], X[i1, 2],
                        X[j, 0], X[j, 1], X[j, 2], X[j1, 0], X[j1, 1], X[j1, 2],
                    )
                    if d2 < ebest[ch]:
                        ebest[ch] = d2
                        eidx[ch, 0] = i
                        eidx[ch, 1] = j
                        epar[ch, 0] = s
                        epar[ch, 1] = t
    return vbest, vidx, ebest, eidx, epar


def closest_vertices(X: np.ndarray, layout: Layout, min_gap: int = 4,
                     search: str = "auto") -> tuple[float, tuple[int, int]]:
    """The first half of :func:`closest_pairs`, ``(vertex distance, (i, j))``; through the
    hierarchy it leaves out the edges' distances (the same vertices)."""
    if _use_tree(search, layout.n, CLOSEST_TREE_FROM):
        return tree_contact.closest_vertices_tree(X, layout, min_gap)
    return closest_pairs(X, layout, min_gap, search)[0]


def closest_pairs(X: np.ndarray, layout: Layout, min_gap: int = 4, search: str = "auto"):
    """``(vertex distance, (i, j)), (edge distance, (I, J), (s, t))``: the closest vertices at
    least ``min_gap`` apart along the curve and the closest disjoint edges (parameters s, t
    of the closest points on them). ``search`` as in :func:`contact_time_x` (the same
    distances; of pairs at equal distance the tree reports the one with the smallest indices;
    "auto": the tree from ``CLOSEST_TREE_FROM`` edges)."""
    if _use_tree(search, layout.n, CLOSEST_TREE_FROM):
        return tree_contact.closest_pairs_tree(X, layout, min_gap)
    closed = np.ones(layout.k, np.bool_) if layout.closed is None else layout.closed
    vb, vi, eb, ei, ep = _closest_pairs(X, layout.nxt, layout.starts, layout.comp, closed,
                                        min_gap, 16)
    a = int(np.argmin(vb))
    b = int(np.argmin(eb))
    return (
        (float(np.sqrt(vb[a])), (int(vi[a, 0]), int(vi[a, 1]))),
        (float(np.sqrt(eb[b])), (int(ei[b, 0]), int(ei[b, 1])), (float(ep[b, 0]), float(ep[b, 1]))),
    )
