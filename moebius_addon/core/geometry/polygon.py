"""Equilateral resampling and the checks every start must pass (docs/design.md, "Constraints").

The flow keeps every edge at its target length, so a start has to be an equilateral polygon
that is fine enough for its own shape: vertices several edges apart along the curve must be
farther apart in space than about one edge length, or the discrete energy is no barrier there
(the paper's rule of thumb in "Discrete constraints").
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from ..metrics._tridiagonal import cyclic_tridiagonal_solve
from ..runs.checks import check_flag, check_number
from ..runs.memory import check_memory
from .collision import closest_pairs, closest_vertices
from .layout import (
    MIN_CLOSED_VERTICES,
    MIN_OPEN_VERTICES,
    Layout,
    as_checked_layout,
    as_unit_layout,
    check_counts,
    check_distinct,
    check_finite,
    check_not_points,
    real_array,
    unit_exponent,
    vertex_name,
)

# Closest pair of vertices at least CONTACT_GAP edges apart, divided by the mean edge length,
# must reach CONTACT_RATIO. docs/design.md measured 0.71 for the FHW unknot at 300 edges (a true
# near-contact: every metric fails) against >= 1.06 at index distance >= 4 for curves that relax;
# here the FHW unknot jammed at 460 edges (ratio 0.92) and relaxed at 500 (1.05).
CONTACT_GAP = 4
# Fewest vertices per component at which the coarseness check has a vertex pair to compare
# (CONTACT_GAP edges apart both ways along the curve); below it a knot can pass unchecked.
MIN_CHECKED_VERTICES = 2 * CONTACT_GAP + 1
CONTACT_RATIO = 1.0
MIN_VERTICES = MIN_CLOSED_VERTICES
# Chord lengths probed (evenly below the mean arc per edge) for sign changes of the closing
# condition before bisecting.
_SCAN = 64
# Start points tried along a closed curve when no equal-chord polygon starts at its first point.
_SHIFTS = 16
# Relative error of the closing chord accepted as equal.
_EQUAL = 5e-11
# A first march that closes to within this (but not _EQUAL) missed by rounding accumulated over
# many chords, not at a corner: the table's trefoil missed by 3e-10 to 1.4e-9 from each of the
# 16 starts at 20 000 edges and by 1.0e-7 to 1.9e-7 at 100 000 (corners make misses of 1e-3
# and more), so the other starts are not tried (resampling it to 100 000 edges took 3.5 s).
# That rounding grows like n²: 1.8e-7 at 100 000 edges, 3.3e-6 at 300 000, 3.1e-5 at 10⁶ (the
# trefoil's first march), so the bound grows as 3e-16 n² from 57 735 edges on (ten times the
# misses measured); with 1e-6 alone, 10⁶ edges tried all 16 starts and took 267 s.
_ROUNDING_MISS = 1e-6
_ROUNDING_PER_N2 = 3e-16
# Peak memory of resample per vertex of the result (the marches' arrays and equalize's), with
# room: measured 234 bytes per vertex at 300 000 vertices (the trefoil).
_RESAMPLE_BYTES = 400
_FEWER_VERTICES = ("ask for fewer vertices: a few hundred untangle most knots, and Blender "
                   "takes at most 100 000")


@nb.njit(cache=True)
def _point_at(P, cum, s):
    """Point at arc length ``s`` of the polyline with vertices P and cumulative lengths cum,
    and the index of the segment it lies on."""
    m = cum.shape[0] - 1
    k = np.searchsorted(cum, s, side="right") - 1
    if k < 0:
        k = 0
    if k >= m:
        k = m - 1
    seg = cum[k + 1] - cum[k]
    t = (s - cum[k]) / seg if seg > 0 else 0.0
    return P[k] + t * (P[k + 1] - P[k]), k


@nb.njit(cache=True)
def _march(P, cum, h, count):
    """From the polyline's start, walk ``count`` chords of length ``h``: each next vertex is the
    first point further along the polyline at distance ``h`` from the current one. Returns the
    vertices (count+1, 3) and the arc-length position of the last one (inf if it ran off)."""
    m = cum.shape[0] - 1
    out = np.empty((count + 1, 3))
    out[0] = P[0]
    k = 0
    cur = P[0].copy()
    s_cur = 0.0
    h2 = h * h
    for step in range(1, count + 1):
        found = False
        while k < m:
            a = P[k]
            d = P[k + 1] - a
            # the chord leaves the ball |x − cur| < h on segment k: solve |a + t d − cur| = h
            f = a - cur
            dd = d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
            fd = f[0] * d[0] + f[1] * d[1] + f[2] * d[2]
            ff = f[0] * f[0] + f[1] * f[1] + f[2] * f[2] - h2
            t0 = (s_cur - cum[k]) / (cum[k + 1] - cum[k]) if cum[k + 1] > cum[k] else 0.0
            if dd > 0.0:
                disc = fd * fd - dd * ff
                if disc >= 0.0:
                    t = (-fd + np.sqrt(disc)) / dd
                    if t >= t0 and t <= 1.0:
                        cur = a + t * d
                        s_cur = cum[k] + t * (cum[k + 1] - cum[k])
                        out[step] = cur
                        found = True
                        break
            k += 1
        if not found:
            return out, np.inf
    return out, s_cur


def _resample_one(P: np.ndarray, n: int, closed: bool) -> np.ndarray:
    if closed:
        P = np.vstack([P, P[:1]])
    seg = np.linalg.norm(np.diff(P, axis=0), axis=1)
    keep = np.concatenate(([True], seg > 0))
    P = np.ascontiguousarray(P[keep])
    seg = seg[seg > 0]
    if len(seg) == 0:
        raise ValueError("all points coincide: there is no curve to resample")
    cum = np.concatenate(([0.0], np.cumsum(seg)))
    out, miss = _equal_chords(P, cum, n, closed)
    if miss <= _EQUAL:
        return out
    if not closed:  # both ends are fixed: make the closest march equilateral between them
        return equalize(out, closed=False)
    if miss <= max(_ROUNDING_MISS, _ROUNDING_PER_N2 * n * n):  # rounding: equalize corrects it
        return equalize(out)
    # Curves with sharp turns often have no equal-chord polygon through the first point (the
    # march jumps where a chord cuts a corner): start elsewhere, keep the closest miss.
    total = cum[-1]
    best, best_miss = out, miss
    for k in range(1, _SHIFTS):
        x0, i = _point_at(P, cum, total * k / _SHIFTS)
        Q = np.vstack([x0[None], P[i + 1 :], P[1 : i + 1], x0[None]])
        seg = np.linalg.norm(np.diff(Q, axis=0), axis=1)
        Q = np.ascontiguousarray(Q[np.concatenate(([True], seg > 0))])
        shifted, miss = _equal_chords(Q, np.concatenate(([0.0], np.cumsum(seg[seg > 0]))),
                                      n, True)
        if miss <= _EQUAL:
            return shifted
        if miss < best_miss:
            best, best_miss = shifted, miss
    # none exists at this count (often, for turns sharper than 90°; see resample): make the
    # closest one equilateral, which moves its vertices off the polyline
    return equalize(best)


def _equal_chords(P, cum, n, closed):
    """Vertices marched along the polyline P (cumulative arc lengths cum) with chord h, for the
    h at which the last chord (closed: back to the start) is h too, and the relative error of
    that last chord (0 up to round-off where such an h exists)."""
    total = cum[-1]
    steps = n if closed else n - 1
    end = P[-1]

    def closing_error(h):
        pts, s_last = _march(P, cum, h, steps - 1)
        if not np.isfinite(s_last):
            return -1.0, pts
        # closed: the last chord back to the start must also be h; open: the last vertex
        # must be the polyline's end. Positive when h is too short.
        return np.linalg.norm(end - pts[-1]) - h, pts

    def bisect(lo, hi):
        """Root of closing_error between lo (> 0) and hi (≤ 0), or the jump it has there
        instead: the points on the side of the smaller error, and that relative error."""
        lo_pts = hi_pts = None
        hi_err = np.inf
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            err, cand = closing_error(mid)
            if err > 0:
                lo, lo_pts = mid, cand
            else:
                hi, hi_pts, hi_err = mid, cand, err
            if hi - lo <= 4e-16 * hi:
                break
        if lo_pts is None:
            return None, np.inf
        lo_miss = abs(np.linalg.norm(end - lo_pts[-1]) - lo) / lo
        pts, miss = lo_pts, lo_miss
        if hi_pts is not None and abs(hi_err) / hi < lo_miss and closed:
            pts, miss = hi_pts, abs(hi_err) / hi
        return (pts if closed else np.vstack([pts, end[None, :]])), miss

    # The chord length lies below the mean arc length per edge. The closing condition can
    # have several roots: a polyline through its start point twice (a lemniscate started
    # at its crossing) also closes after one lobe, and a coarse march jumps where a chord
    # cuts a sharp corner. The wanted root is the largest one at which the closing chord
    # really is h, so scan downward from the top and bisect each sign change.
    top = total / steps
    grid = top * np.arange(_SCAN, -1, -1) / _SCAN
    signs = {_SCAN: True}  # evaluated as the scan reaches them: a march per probe

    def positive(k):
        if k not in signs:
            signs[k] = closing_error(grid[k])[0] > 0
        return signs[k]

    best, best_miss = None, np.inf
    for k in range(_SCAN):
        if not positive(k) and positive(k + 1):
            pts, miss = bisect(grid[k + 1], grid[k])
            if miss <= _EQUAL:
                return pts, miss
            if miss < best_miss:
                best, best_miss = pts, miss
    if best is None:
        best, best_miss = bisect(0.0, top)
    if best is None:
        raise ValueError("could not resample this curve: it is too short for the edge count")
    return best, best_miss


def equalize(P: np.ndarray, tol: float = 1e-13, closed: bool = True) -> np.ndarray:
    """The equilateral polygon nearest to ``P`` found by Gauss–Newton on the log edge lengths:
    every step moves the vertices by the least (Euclidean) amount that corrects the linearized
    lengths, toward targets that go from the current lengths to their mean in stages of at
    most 0.1 in log length. Edge lengths end equal to ``tol`` (relative), or to the rounding
    of edges taken as differences of coordinates where that is coarser: 8 ε |x| / l for
    coordinates up to |x| and edges of length l (1.6e-11 for the table's trefoil at 100 000
    edges, where the residual stalled at 1e-12; with a fixed 1e-13, resampling it to 20 000,
    30 000, 40 000 and 100 000 edges failed).
    ``closed=False``: an open chain whose two end vertices stay where they are.

    Raises ValueError if the iteration does not converge (degenerate polygons)."""
    closed = check_flag("closed", closed)
    X = np.array(P, dtype=np.float64)

    def edges(X):
        return np.roll(X, -1, axis=0) - X if closed else np.diff(X, axis=0)

    ln = np.linalg.norm(edges(X), axis=1)
    if not np.all(ln > 0):
        raise ValueError("the polygon repeats a point; remove repeated points first")
    tol = max(tol, 8.0 * np.finfo(float).eps * float(np.abs(X).max()) / float(ln.mean()))
    start = np.log(ln)
    final = np.log(ln.mean())
    stages = max(1, int(np.ceil(np.abs(start - final).max() / 0.1)))
    # vertices free to move per edge: both, but an open chain's first and last edge have one
    free = np.full(len(ln), 2.0)
    if not closed:
        free[[0, -1]] = 1.0
    for k in range(1, stages + 1):
        target = start + k / stages * (final - start)
        last = k == stages
        for _ in range(30):
            E = edges(X)
            l2 = np.einsum("ij,ij->i", E, E)
            phi = 0.5 * np.log(l2) - target
            if np.abs(phi).max() <= (tol if last else 1e-3):
                break
            F = E / l2[:, None]  # row i of the Jacobian: −F_i at vertex i, +F_i at i + 1
            b = -np.einsum("ij,ij->i", F, np.roll(F, -1, axis=0))
            if not closed:
                b[-1] = 0.0  # the last edge does not wrap around to the first
            mu = cyclic_tridiagonal_solve(free / l2, b, phi)
            if closed:
                X -= np.roll(mu[:, None] * F, 1, axis=0) - mu[:, None] * F
            else:
                X[1:-1] -= mu[:-1, None] * F[:-1] - mu[1:, None] * F[1:]
        else:
            raise ValueError("could not make this polygon equilateral (it is degenerate)")
    return X


def resample(points, n, closed: bool = True):
    """Equilateral polygon through a polyline.

    Parameters
    ----------
    points : (M, 3) array or list of arrays
        Polyline vertices (a link: one array per component).
    n : int or list of int
        Vertices of the result, at least 4 (3 with ``closed=False``); for a link one total,
        shared by length, or one count per component.
    closed : bool
        The polyline is closed (last point joined to the first). For ``closed=False`` the
        result starts and ends at the polyline's ends. ``True`` or ``False`` only: text such
        as ``"False"`` is refused (``bool("False")`` is True).

    Returns
    -------
    (n, 3) array or list of arrays
        Equilateral: consecutive vertices at equal distance (to 1e-10 relative, the closing
        chord included when ``closed``), in the polyline's order. The vertices lie on the
        polyline, starting at its first point, wherever such a polygon exists. A polyline
        with turns sharper than 90° often has none at a given count (the chords jump where
        they cut a corner; measured on a bowtie, two stars and a random 12-point polyline:
        47 to 69 of 101 counts from 8 to 396). Then the march starts at other points of a
        closed curve and, if none closes either, the closest march is made equilateral by
        :func:`equalize`, which moves vertices off the polyline (on those polylines: by at
        most 0.85 edge lengths; per count, the largest move has a median of 0.01 to 0.2
        edge lengths). An open polyline (``closed=False``) keeps its two ends; where no
        equal-chord march reaches the far end, the closest one is made equilateral between
        them by :func:`equalize` (``closed=False``) in the same way.
    """
    closed = check_flag("closed", closed)
    if isinstance(points, (list, tuple)):
        if not points:
            raise ValueError("empty link: give at least one polyline")
        check_not_points(points, "points")
        if np.ndim(n):
            ns = [check_number("n", k, integer=True) for k in n]
            if len(ns) != len(points):
                raise ValueError(f"n has {len(ns)} count{'' if len(ns) == 1 else 's'} for "
                                 f"{len(points)} components: give one count per component, "
                                 f"or one total count to share by length")
        else:
            ns = _split_count(points, check_number("n", n, integer=True))
        check_memory(_RESAMPLE_BYTES * sum(ns), f"resampling to {sum(ns)} vertices",
                     _FEWER_VERTICES)
        return [resample(p, k, closed) for p, k in zip(points, ns, strict=True)]
    P = real_array(points, "points")
    if P.ndim != 2 or P.shape[1] != 3:
        raise ValueError(f"points must be an (M, 3) array, got shape {P.shape}")
    if len(P) < 2:
        raise ValueError(f"points must hold at least 2 points of a polyline, got {len(P)}")
    if not np.all(np.isfinite(P)):
        raise ValueError("points contain NaN or infinite coordinates; remove or fix them first")
    n = check_number("n", n, integer=True)
    least = MIN_VERTICES if closed else MIN_OPEN_VERTICES
    if n < least:
        what = "a closed polygon" if closed else "an open polyline (closed=False)"
        raise ValueError(f"need at least {least} vertices for {what}, got {n}")
    check_memory(_RESAMPLE_BYTES * n, f"resampling to {n} vertices", _FEWER_VERTICES)
    k = unit_exponent(P)
    if k:  # a curve far larger or smaller than 1: resampled at a size near 1 (exact scaling)
        return np.ldexp(_resample_one(np.ldexp(P, -k), n, closed), k)
    return _resample_one(P, n, closed)


def subdivide(P, factor: int = 2, closed=True):
    """The same polygon with every edge split into ``factor`` equal edges.

    The curve as a point set is unchanged, so the result touches itself exactly where ``P``
    does and has its knot type; an equilateral polygon stays equilateral (edges ``1/factor`` of
    the old, to rounding). Vertex ``i`` of ``P`` is vertex ``factor · i`` of the result, with
    its coordinates' bits. This is how a run refines a jammed curve (``refine=`` of
    :func:`..flow.relax`), and how earlier iterates of a refined run are brought to its
    final vertex count.

    Parameters
    ----------
    P : (N, 3) array or list of arrays
        Polygon or link (one array per component).
    factor : int
        Edges each edge becomes, at least 1.
    closed : bool or sequence of bool
        False: an open polyline (N − 1 edges become ``factor · (N − 1)``, ``factor · (N − 1)
        + 1`` vertices); a link takes one flag per component, or one for all.

    Returns
    -------
    (factor · N, 3) array (closed) or list of arrays, as ``P``.
    """
    factor = check_number("factor", factor, 1, integer=True)  # int("2") and int(2.7) took both
    if isinstance(P, (list, tuple)):
        check_not_points(P, "P")
        flags = ([check_flag("closed", c) for c in closed] if np.ndim(closed)
                 else [check_flag("closed", closed)] * len(P))
        if len(flags) != len(P):
            raise ValueError(f"closed has {len(flags)} flags for {len(P)} components")
        return [subdivide(p, factor, c) for p, c in zip(P, flags, strict=True)]
    closed = check_flag("closed", closed)
    X = np.asarray(P, dtype=np.float64)
    if X.ndim != 2 or X.shape[1] != 3:
        raise ValueError(f"P must be an (N, 3) array, got shape {X.shape}")
    if factor == 1:
        return X.copy()
    ends = np.roll(X, -1, axis=0) if closed else X[1:]
    starts = X if closed else X[:-1]
    t = np.arange(factor) / factor
    out = starts[:, None, :] + t[None, :, None] * (ends - starts)[:, None, :]
    out[:, 0] = starts  # the old vertices keep their bits
    out = out.reshape(-1, 3)
    return out if closed else np.vstack([out, X[-1:]])


def _split_count(parts, n):
    """Distribute ``n`` vertices over link components proportionally to their lengths
    (largest remainder, so the counts add up to ``n``; at least 4 each). The lengths are
    taken at a size near 1 (one exact scale for all), as squares of 1e200 would overflow."""
    parts = [np.asarray(p, dtype=np.float64) for p in parts]
    k = unit_exponent(np.concatenate([p.ravel() for p in parts]))
    lengths = np.array([np.linalg.norm(np.diff(np.vstack([q, q[:1]]), axis=0), axis=1).sum()
                        for q in (np.ldexp(p, -k) for p in parts)])
    if n < MIN_VERTICES * len(parts):
        raise ValueError(f"{n} vertices cannot make {len(parts)} closed components of at "
                         f"least {MIN_VERTICES} vertices each: give at least "
                         f"{MIN_VERTICES * len(parts)}, or a count per component")
    share = n * lengths / lengths.sum()
    ns = np.floor(share).astype(int)
    ns[np.argsort(ns - share)[: n - ns.sum()]] += 1
    # a short component raised to the minimum takes its vertices from the longest ones (by
    # share per vertex), so that the counts still add up to n
    ns = np.maximum(MIN_VERTICES, ns)
    while ns.sum() > n:
        over = np.flatnonzero(ns > MIN_VERTICES)
        ns[over[np.argmin(share[over] / ns[over])]] -= 1
    return [int(c) for c in ns]


def contact_ratio(P, min_gap: int = CONTACT_GAP, closed=True) -> float:
    """Closest distance between vertices at least ``min_gap`` edges apart along the curve (or on
    different components), divided by the mean edge length. The start check wants >= 1.
    ``closed=False``: open polylines (distances along them do not wrap round the ends)."""
    min_gap = check_number("min_gap", min_gap, 1, integer=True)
    if isinstance(P, CheckedCurve) and min_gap == CONTACT_GAP:
        return P.ratio
    X, layout, _ = (P.X, P.layout, P.exponent) if isinstance(P, CheckedCurve) else (
        as_checked_layout(P, closed, touching=False))
    return layout_contact_ratio(X, layout, min_gap)


def layout_contact_ratio(X: np.ndarray, layout: Layout, min_gap: int = CONTACT_GAP) -> float:
    """:func:`contact_ratio` of vertices a run already holds (stacked and checked): the same
    number, without checking them again."""
    dv, _ = closest_vertices(X, layout, min_gap)
    return dv / _mean_edge(X, layout)


def _mean_edge(X, layout):
    ln = np.linalg.norm(X[layout.nxt] - X, axis=1)
    return float((ln[layout.real] if layout.has_open else ln).mean())


def suggest_edge_count(P, max_edges: int = 20000, start: int | None = None,
                       closed: bool = True) -> int | None:
    """Smallest edge count (total over a link) whose equilateral resampling of ``P`` passes the
    contact check, searched upward in steps of 10% from ``start`` (default: a guess above
    ``P``'s own count from its contact ratio); None if none up to ``max_edges``.
    ``closed=False``: open polylines (vertex counts, as the result counts them)."""
    closed = check_flag("closed", closed)
    max_edges = check_number("max_edges", max_edges, MIN_VERTICES, integer=True)
    X, layout, _ = as_checked_layout(P, closed, touching=False)
    parts = layout.split(X) if layout.is_link else X
    if start is None:
        n = layout.n
        ratio = contact_ratio(parts, closed=closed)
        # the ratio grows about linearly with the edge count near a true contact
        start = max(n + 1, int(np.ceil(n * CONTACT_RATIO / max(ratio, 1e-9) * 1.05)))
    k = start
    while k <= max_edges:
        Q = resample(parts, k, closed)
        if contact_ratio(Q, closed=closed) >= CONTACT_RATIO:
            return k
        k = int(np.ceil(k * 1.1))
    return None


class CheckedCurve(NamedTuple):
    """A start checked once at the door (:func:`check_curve`): what the checks found, kept so
    that nothing after them validates the vertices or searches their closest pairs again.
    Runs (:class:`..runs.base.Run`), :func:`contact_ratio` and :func:`check_polygon` take one
    in place of the vertices."""

    X: np.ndarray            #: the vertices scaled by ``2^-exponent`` (exact), stacked
    layout: Layout
    exponent: int
    mean_edge: float         #: of the real edges, at the scaled size
    vertex_gap: float        #: closest vertices ``CONTACT_GAP`` apart along the curve
    vertices: tuple          #: those two vertices
    coarse_checked: bool     #: whether the coarseness rule was checked (and passed)

    @property
    def ratio(self) -> float:
        """The contact ratio (:func:`contact_ratio`)."""
        return self.vertex_gap / self.mean_edge


def check_curve(P, *, coarseness: bool = True, name: str = "the curve",
                closed=True) -> CheckedCurve:
    """:func:`check_polygon`, returning what it found (:class:`CheckedCurve`). A curve
    already checked is not checked again: only the coarseness rule, if it was left out."""
    coarseness = check_flag("coarseness", coarseness)
    if isinstance(P, CheckedCurve):
        if coarseness and not P.coarse_checked:
            _check_coarseness(P, name)
            return P._replace(coarse_checked=True)
        return P
    X, layout, e2 = as_unit_layout(P, closed)
    return check_layout(X, layout, e2, coarseness=coarseness, name=name)


def check_layout(X: np.ndarray, layout: Layout, e2: int, *,
                 coarseness: bool = True, name: str = "the curve") -> CheckedCurve:
    """:func:`check_curve` of a curve already stacked and scaled (:func:`.layout.as_unit_layout`:
    ``X``, ``layout``, ``e2``), as a run has it."""
    check_counts(layout, name)
    check_finite(X, layout, name)
    check_distinct(X, layout, name)
    edge = np.linalg.norm(X[layout.nxt] - X, axis=1)
    if layout.has_open:  # the dummy edges (.layout) are no edges
        edge = edge[layout.real]
    h = float(edge.mean())
    (dv, (vi, vj)), (de, (ei, ej), (s, t)) = closest_pairs(X, layout, CONTACT_GAP)
    if de <= 1e-6 * h:
        point = np.ldexp(X[ei] + s * (X[layout.nxt[ei]] - X[ei]), e2)
        raise ValueError(
            f"{name} intersects itself: the edges after {vertex_name(layout, ei)} and after "
            f"{vertex_name(layout, ej)} touch near ({point[0]:.6g}, {point[1]:.6g}, "
            f"{point[2]:.6g}); move the strands apart before relaxing"
        )
    checked = CheckedCurve(X, layout, e2, h, float(dv), (int(vi), int(vj)), False)
    if coarseness:
        _check_coarseness(checked, name)
        checked = checked._replace(coarse_checked=True)
    return checked


def _check_coarseness(c: CheckedCurve, name: str) -> None:
    """ValueError for vertices far apart along the curve that are closer than
    ``CONTACT_RATIO`` mean edges in space, naming the edge count that works."""
    layout, X, h = c.layout, c.X, c.mean_edge
    dv, (vi, vj) = c.vertex_gap, c.vertices
    if dv >= CONTACT_RATIO * h:
        return
    flags = [True] if layout.closed is None else list(layout.closed)
    try:
        k = suggest_edge_count(layout.split(X) if layout.is_link else X,
                               closed=flags[0]) if len(set(flags)) == 1 else None
    except ValueError:  # a resampling on the way failed: no count to suggest, the refusal
        k = None        # stands (an open cable's 'could not make … equilateral' hid it)
    fix = (
        f"resample with at least {k} edges"
        if k is not None
        else "move the strands apart or use a much finer polygon"
    )
    raise ValueError(
        f"{name} is too coarse for its shape: {vertex_name(layout, vi)} and "
        f"{vertex_name(layout, vj)} are {dv / h:.2f} edge lengths apart in space but far "
        f"apart along the curve "
        f"(need >= {CONTACT_RATIO}); the energy cannot keep the strands apart at this "
        f"resolution — {fix}"
    )


def check_polygon(P, *, coarseness: bool = True, name: str = "the curve",
                  closed=True) -> None:
    """Raise ``ValueError`` if ``P`` cannot start a flow; the message says what to do.

    Checks, in order: shapes, at least 4 vertices per component, finite coordinates, no
    repeated consecutive points, no self-intersection (disjoint edges touching, with where),
    and (``coarseness``) no near-contact closer than the resolution: vertices at least 4 edges
    apart must be at least one mean edge length apart, else the message names the edge count
    that works. Curves spanning more than 2^64 or less than 2^-64 are checked at a size near 1.
    ``closed=False``: open polylines (a link: one flag per component, or one for all), with at
    least 3 vertices, distances along them not wrapping round the ends.
    """
    check_curve(P, coarseness=coarseness, name=name, closed=closed)
