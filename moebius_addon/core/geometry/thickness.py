"""Tubes that never meet: the contact rule of a run given ``thickness=`` (a tube radius ``r``).

With ``r > 0`` the contact tests (:mod:`.collision`, :mod:`.tree_contact`, the obstacles')
run with a contact distance of ``2r`` between strands and ``r`` to an obstacle or the
container, at every iterate and on the straight path between iterates. Pairs of edges of one
strand nearer each other along it than π r are left out: a tube bends within that stretch (a
circle of radius ``r``, the tightest bend a tube of radius ``r`` allows, brings points π r apart
along it to ``2r``), so no curve could keep them ``2r`` apart. The stretch is counted in edges,
``⌈π r / ℓ⌉`` of each strand's target edge length ``ℓ`` at the start of a run (a refinement
starts a run and counts again); without a thickness it is 1, the edges that share a vertex.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .edge_pairs import SLACK, segment_distance2, tested
from .layout import Layout


def near_counts(layout: Layout, lengths: np.ndarray, radius: float,
                scale: float = 1.0) -> np.ndarray:
    """Per component, the edges along it within which pairs are not tested: ``⌈π r / ℓ⌉``
    (at least 1) with ``ℓ`` its mean target edge length (``lengths`` per edge slot, the
    run's; an open component's dummy slot left out) and ``r`` the ``radius`` in the same
    units. ValueError where that leaves no pair of the component to test: its tube would
    cover the whole strand (the largest thickness named in the caller's units, the run's
    times ``scale``)."""
    near = np.ones(layout.k, np.int64)
    if radius <= 0.0:
        return near
    real = layout.real
    flags = layout.closed_flags
    for c in range(layout.k):
        a, b = int(layout.starts[c]), int(layout.starts[c + 1])
        ell = float(lengths[a:b][real[a:b]].mean())
        m = b - a
        # the farthest pair along it: half way round a closed one, end to end on an open one
        # (edges 0 and m − 2)
        most = m // 2 if flags[c] else m - 2
        near[c] = max(1, math.ceil(math.pi * radius / ell))
        if near[c] >= most:
            raise ValueError(
                f"thickness too large for {_strand(layout, c)}: its {m - (0 if flags[c] else 1)} "
                f"edges are too few for a tube that bends within π × thickness along it "
                f"({near[c]} edges); use a thickness below "
                f"{max(most - 1, 0) * ell * scale / math.pi:.4g} "
                f"({max(most - 1, 0) / math.pi:.3g} edge lengths) or more edges")
    return near


def _strand(layout: Layout, c: int) -> str:
    return f"component {c}" if layout.is_link else "the curve"


@nb.njit(cache=True)
def _closest_tested(X, nxt, starts, comp, closed, near, cut, axis):
    """Closest pair of edges the contact tests look at (:func:`._pairs.tested`) closer than
    ``cut``: ``(d², i, j)``, or ``(cut², -1, -1)``. Sweep and prune along ``axis``: edges
    sorted by their lower end there, each compared with those that start before its upper end
    plus the best distance so far."""
    n = X.shape[0]
    lo = np.empty(n)
    hi = np.empty(n)
    for i in range(n):
        lo[i] = min(X[i, axis], X[nxt[i], axis])
        hi[i] = max(X[i, axis], X[nxt[i], axis])
    order = np.argsort(lo, kind="mergesort")
    best = cut * cut
    bi = -1
    bj = -1
    for a in range(n):
        p = order[a]
        if nxt[p] == p:  # an open component's dummy edge: its point is the last edge's end
            continue
        for b in range(a + 1, n):
            q = order[b]
            if lo[q] > hi[p] + np.sqrt(best):
                break
            if nxt[q] == q:
                continue
            i, j = (p, q) if p < q else (q, p)
            if not tested(i, j, starts, comp, closed, near):
                continue
            i1, j1 = nxt[i], nxt[j]
            d2, _s, _t = segment_distance2(
                X[i, 0], X[i, 1], X[i, 2], X[i1, 0], X[i1, 1], X[i1, 2],
                X[j, 0], X[j, 1], X[j, 2], X[j1, 0], X[j1, 1], X[j1, 2])
            if d2 < best or (d2 == best and bi >= 0 and (i < bi or (i == bi and j < bj))):
                best, bi, bj = d2, i, j
    return best, bi, bj


def closest_tested(X: np.ndarray, layout: Layout, near: np.ndarray, cut: float):
    """``(distance, (i, j))`` of the closest edges ``i < j`` the contact tests look at with
    ``near`` (:func:`._pairs.tested`), or ``(inf, None)`` when no such pair is closer than
    ``cut``."""
    axis = int(np.argmax(X.max(axis=0) - X.min(axis=0)))
    d2, i, j = _closest_tested(X, layout.nxt, layout.starts, layout.comp, layout.closed_flags,
                               near, float(cut), axis)
    if i < 0:
        return np.inf, None
    return float(np.sqrt(d2)), (int(i), int(j))


def check_thickness(X: np.ndarray, layout: Layout, near: np.ndarray, radius: float,
                    scale: float, thickness: float) -> None:
    """Refuse a start whose tubes of ``radius`` (``thickness`` in the caller's units, ``X``
    in the run's: caller = run × ``scale``) meet: two tested edges (:func:`._pairs.tested`)
    within ``2 × radius``, or within the contact test's margin above it (``SLACK``: a pair
    that close stops every step), named with the distance found."""
    contact = 2.0 * radius
    d, pair = closest_tested(X, layout, near, SLACK * contact)
    if pair is None:
        return
    i, j = pair
    ci, cj = int(layout.comp[i]), int(layout.comp[j])
    ei, ej = i - int(layout.starts[ci]), j - int(layout.starts[cj])
    if ci != cj:
        where = f"component {ci} and component {cj} are {d * scale:.4g} apart (edges {ei} and {ej})"
    else:
        where = (f"{_strand(layout, ci)} comes within {d * scale:.4g} of itself (edges {ei} and "
                 f"{ej}, more than π × thickness apart along it)")
    if d < contact:
        why = f"below twice the thickness {thickness:.4g}"
    else:
        why = (f"within {100 * (SLACK - 1):g}% of twice the thickness {thickness:.4g} (the "
               f"contact test needs that margin to move them)")
    raise ValueError(f"{where}, {why}: move them apart or use a thickness below "
                     f"{d * scale / (2.0 * SLACK):.4g}")
