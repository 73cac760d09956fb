"""Push apart strands that nearly touch, without passing one through another (private to the
adaptive run: ``refine=`` of :func:`.flow.relax`, docs/api.md "Adaptive resolution").

A start whose strands pass within a small fraction of an edge is too coarse for the discrete
energy, and splitting its edges does not help quickly: two edges 0.05 edge lengths apart stay
that far apart when split, so only a polygon of some 20× the edges passes the contact check
(a braid-tangled trefoil of 111 edges needed 3 552, docs/lab/flows-and-methods.md "Untangling
benchmark"). :func:`separate` moves such strands apart instead, by the least it takes:
descent on a barrier of the *segment* distances of edges at least :data:`CONTACT_GAP` apart
(so edges that nearly cross between their vertices are seen), the motion smoothed along the
curve so that a strand moves as a piece, every step bounded by the continuous collision test
(docs/design.md step 3) and the polygon made equilateral again after it (the path of that
correction checked too). The curve keeps its knot or link type; only strands closer than
:data:`REACH` edge lengths move.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ..metrics._tridiagonal import cyclic_tridiagonal_solve
from .collision import closest_vertices, contact_time_x
from .edge_pairs import segment_distance2
from .layout import as_layout, as_unit_layout
from .polygon import CONTACT_GAP, CONTACT_RATIO, _mean_edge, equalize

#: Edges closer than this many mean edge lengths repel (the barrier is 0 beyond).
REACH = 1.4
#: Done when vertices at least CONTACT_GAP apart are this many edge lengths apart (the start
#: check wants CONTACT_RATIO: a margin so that the first iterate does not fall below it) ...
VERTEX_TARGET = 1.05 * CONTACT_RATIO
#: ... and edges at least CONTACT_GAP apart this many (edges that nearly cross between their
#: vertices are what jams a flow whose vertices are apart).
EDGE_TARGET = 0.9
#: Largest vertex move of one step, in mean edge lengths.
STEP = 0.1
#: Smoothing of the motion along the curve: (I + SMOOTH · Laplacian) u = −∇B spreads a push
#: over about sqrt(SMOOTH) edges each way.
SMOOTH = 4.0
#: Most edges separated (the pair search is all pairs: O(N²) per step).
MAX_EDGES = 20000


@nb.njit(cache=True)
def _barrier(X, nxt, starts, comp, closed, min_gap, h, reach):
    """Value and gradient of Σ (h/d − 1/reach)² over pairs of edges at least ``min_gap`` apart
    along a component (or on different ones) closer than ``reach · h`` (segment distance
    ``d``), and the smallest such ``d``. Open components' dummy edges are left out."""
    n = X.shape[0]
    G = np.zeros((n, 3))
    value = 0.0
    dmin = np.inf
    cut = reach * h
    for i in range(n):
        i1 = nxt[i]
        if i1 == i:
            continue
        c = comp[i]
        size = starts[c + 1] - starts[c]
        for j in range(i + 1, n):
            j1 = nxt[j]
            if j1 == j:
                continue
            if comp[j] == c:
                gap = j - i
                if closed[c]:
                    gap = min(gap, size - gap)
                if gap < min_gap:
                    continue
            # edges no longer than 2h (equilateral up to the step's drift): far midpoints
            # rule a pair out
            mx = 0.5 * (X[i, 0] + X[i1, 0] - X[j, 0] - X[j1, 0])
            my = 0.5 * (X[i, 1] + X[i1, 1] - X[j, 1] - X[j1, 1])
            mz = 0.5 * (X[i, 2] + X[i1, 2] - X[j, 2] - X[j1, 2])
            if mx * mx + my * my + mz * mz > (cut + 2.0 * h) ** 2:
                continue
            d2, s, t = segment_distance2(
                X[i, 0], X[i, 1], X[i, 2], X[i1, 0], X[i1, 1], X[i1, 2],
                X[j, 0], X[j, 1], X[j, 2], X[j1, 0], X[j1, 1], X[j1, 2])
            d = np.sqrt(d2)
            dmin = min(dmin, d)
            if d >= cut or d <= 0.0:
                continue
            x = d / h
            f = 1.0 / x - 1.0 / reach
            value += f * f
            # d(value)/dd = 2 f · (−1/x²) / h; dd/dp = n at the closest point of edge i
            w = -2.0 * f / (x * x) / h / d
            for k in range(3):
                nk = w * ((X[i, k] + s * (X[i1, k] - X[i, k]))
                          - (X[j, k] + t * (X[j1, k] - X[j, k])))
                G[i, k] += (1.0 - s) * nk
                G[i1, k] += s * nk
                G[j, k] -= (1.0 - t) * nk
                G[j1, k] -= t * nk
    return value, G, dmin


def barrier(P, closed=True, reach: float = REACH, min_gap: int = CONTACT_GAP,
            h: float | None = None):
    """``(B, ∇B, d)``: the separation barrier of polygon or link ``P`` (Σ (h/d − 1/reach)²
    over pairs of edges ``min_gap`` or more apart closer than ``reach · h``, ``h`` the mean
    edge length unless given), its gradient with ``h`` held (rows as ``P`` stacked) and the
    smallest such edge distance in units of ``h`` (inf when no pair is that close)."""
    X, layout = as_layout(P, closed)
    h = _mean_edge(X, layout) if h is None else float(h)
    B, G, d = _barrier(X, layout.nxt, layout.starts, layout.comp, _closed_flags(layout),
                       int(min_gap), h, float(reach))
    return B, G, d / h


def _closed_flags(layout):
    return np.ones(layout.k, bool) if layout.closed is None else layout.closed.astype(bool)


def _smooth(G, layout, flags):
    """(I + SMOOTH · L) U = G per component (L the path or cycle Laplacian)."""
    U = np.empty_like(G)
    for c in range(layout.k):
        a, b = int(layout.starts[c]), int(layout.starts[c + 1])
        m = b - a
        diag = np.full(m, 1.0 + 2.0 * SMOOTH)
        off = np.full(m, -SMOOTH)
        if not flags[c]:
            diag[[0, -1]] = 1.0 + SMOOTH
            off[-1] = 0.0
        for k in range(3):
            U[a:b, k] = cyclic_tridiagonal_solve(diag, off, np.ascontiguousarray(G[a:b, k]))
    return U


def _equalized(Y, layout, flags):
    out = np.empty_like(Y)
    for c in range(layout.k):
        a, b = int(layout.starts[c]), int(layout.starts[c + 1])
        out[a:b] = equalize(Y[a:b], closed=bool(flags[c]))
    return out


def _vertex_ratio(X, layout):
    """The start check's contact ratio (polygon.contact_ratio) of stacked rows."""
    dv, _ = closest_vertices(X, layout, CONTACT_GAP)
    return dv / _mean_edge(X, layout)


def separate(P, closed=True, max_steps: int = 400):
    """``(path, moved)``: polygons from ``P`` (the first) to ``P`` with strands that nearly
    touch pushed apart (the last), one per step: until vertices at least ``CONTACT_GAP``
    apart along the curve are :data:`VERTEX_TARGET` mean edge lengths apart and such edges
    :data:`EDGE_TARGET`, every component equilateral (its length grows a little where strands
    bend apart); ``moved`` is the largest distance a vertex went, in edge lengths.

    No strand passes through another on the way (each step's straight path and the
    equalization after it are checked by the continuous collision test), so ``Q`` has the
    knot or link type of ``P``. ``P`` must be equilateral per component and touch nothing.

    Raises ValueError when the strands cannot be pushed that far apart at this resolution in
    ``max_steps`` steps (too little room: try more edges).
    """
    X0, layout, scale = as_unit_layout(P, closed)
    if layout.n > MAX_EDGES:
        raise ValueError(f"not separated: {layout.n} edges is above the {MAX_EDGES} this "
                         "all-pairs search takes")
    flags = _closed_flags(layout)
    X = X0.copy()
    h0 = _mean_edge(X, layout)
    path = [X0]
    for _ in range(max_steps):
        h = _mean_edge(X, layout)  # grows a little as strands bend apart
        eps = 1e-3 * h
        B, G, d = _barrier(X, layout.nxt, layout.starts, layout.comp, flags, CONTACT_GAP, h,
                           REACH)
        vr = _vertex_ratio(X, layout)
        if vr >= VERTEX_TARGET and d >= EDGE_TARGET * h:
            moved = float(np.linalg.norm(X - X0, axis=1).max() / h0)
            return [layout.split(np.ldexp(Y, scale) if scale else Y) for Y in path], moved
        if B == 0.0:  # vertices close but no edge pair within reach: nothing to push
            break
        U = _smooth(G, layout, flags)  # X − τU descends
        U /= np.linalg.norm(U, axis=1).max()
        tau = STEP * h
        tau = min(tau, 0.5 * contact_time_x(X, U, layout, tau, eps))
        for _ in range(20):
            Y = _equalized(X - tau * U, layout, flags)
            # the straight path X → Y (the step and its correction together) touches nothing
            if contact_time_x(X, X - Y, layout, 1.0, eps) >= 1.0:
                break
            tau *= 0.5
        else:
            break
        X = Y
        path.append(X)
    raise ValueError(
        f"strands could not be pushed apart at {layout.n} edges (closest vertices "
        f"{_vertex_ratio(X, layout):.2f} edge lengths apart after {max_steps} steps)")
