"""Knots and links as one vertex array plus index arrays (private).

A knot is an ``(N, 3)`` array, a link a list of them. The kernels see one contiguous ``(N, 3)``
array ``X`` and index arrays that encode the components: edge ``I`` joins vertex ``I`` to
``nxt[I]``, and vertex ``p`` is the end of edge ``prv[p]``.

Open components (``closed=False``, docs/api.md "Open curves") keep the same arrays with one
change: the last vertex ``v`` of an open component has ``nxt[v] = v``, so its edge slot holds
a *dummy edge* of length 0 (edge vector 0, midpoint at the vertex), and ``prv`` of the first
vertex still points at that dummy. Then every per-vertex weight built from the edge lengths
(``(l_prv + l) / 2``, ``Σ l m``, totals) is already right for the polyline, and the kernels
that need it skip the dummy edge (``Layout.real``). ``closed`` is None when every component is
closed: those layouts, and every kernel run on them, are exactly as before open curves.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .prechecks import equal_rows_possible, extent, short_edge_possible


@dataclass(frozen=True)
class Layout:
    """Index arrays of a knot or link with ``N`` vertices in ``K`` components."""

    starts: np.ndarray  # (K+1,) first vertex of each component, then N
    nxt: np.ndarray  # (N,) next vertex along the component
    prv: np.ndarray  # (N,) previous vertex along the component
    comp: np.ndarray  # (N,) component of each vertex
    is_link: bool  # input was a list (results are returned as lists)
    closed: np.ndarray | None = None  # (K,) bool per component, None: every one closed

    @property
    def has_open(self) -> bool:
        """Whether some component is an open polyline."""
        return self.closed is not None

    @property
    def closed_flags(self) -> np.ndarray:
        """(K,) bool: closed per component (``closed`` as the kernels take it)."""
        return np.ones(self.k, np.bool_) if self.closed is None else self.closed.astype(np.bool_)

    @property
    def real(self) -> np.ndarray:
        """(N,) bool: edge slots that hold an edge (False: the dummy of an open component)."""
        return self.nxt != np.arange(self.n)

    @property
    def n(self) -> int:
        return int(self.starts[-1])

    @property
    def k(self) -> int:
        return len(self.starts) - 1

    def split(self, X: np.ndarray):
        """Return ``X`` (rows per vertex) in the caller's shape: array or list per component."""
        if not self.is_link:
            return X
        return [X[self.starts[c] : self.starts[c + 1]].copy() for c in range(self.k)]


def layout_from_sizes(sizes, is_link: bool, closed=None) -> Layout:
    """``closed``: None (every component closed) or one bool per component."""
    sizes = np.asarray(sizes, dtype=np.int64)
    starts = np.concatenate(([0], np.cumsum(sizes))).astype(np.int64)
    n = int(starts[-1])
    idx = np.arange(n, dtype=np.int64)
    comp = np.repeat(np.arange(len(sizes), dtype=np.int64), sizes)
    nxt = idx + 1
    prv = idx - 1
    nxt[starts[1:] - 1] = starts[:-1]
    prv[starts[:-1]] = starts[1:] - 1
    if closed is not None:
        closed = np.asarray(closed, dtype=bool)
        if closed.all():
            closed = None
        else:
            last = starts[1:][~closed] - 1
            nxt[last] = last  # the dummy edge of an open component (module docstring)
    return Layout(starts, nxt, prv, comp, is_link, closed)


#: Fewest vertices of an open component (two edges; with fewer there is no curve to relax).
MIN_OPEN_VERTICES = 3


#: Fewest vertices of a closed component (with fewer, no two edges are disjoint).
MIN_CLOSED_VERTICES = 4


def real_array(a, what: str = "the polygon") -> np.ndarray:
    """``a`` as a float64 array, or TypeError unless it holds real numbers (floats or
    integers): complex, boolean, text and object arrays are refused rather than cast (a
    complex array lost its imaginary part, an object array was taken as it came)."""
    arr = np.asarray(a)
    if arr.dtype.kind not in "iuf":
        fix = ("take the real part (P.real) if that is what you mean"
               if arr.dtype.kind == "c" else "convert it with np.asarray(P, dtype=float)")
        raise TypeError(f"{what} must hold real numbers (float or int), got an array of "
                        f"{arr.dtype}; {fix}")
    return arr.astype(np.float64, copy=False)


def check_not_points(parts: list, what: str = "the polygon") -> None:
    """ValueError for a list of points (``[[x, y, z], …]``) where a list means a link, one
    (N, 3) array per component: numpy's own error for it (a shape or concatenation error)
    named neither the cause nor the fix."""
    if parts and np.ndim(parts[0]) == 1 and np.shape(parts[0]) == (3,):
        raise ValueError(f"{what} is a list of {len(parts)} points, but a list is read as a "
                         f"link, one (N, 3) array per component: give one curve as an array, "
                         f"np.asarray(P), or a link as a list of such arrays")


def check_closed(closed, k: int, is_link: bool) -> list[bool]:
    """``closed`` as one bool per component, or ValueError: a bool for a knot, a bool or one
    bool per component for a link."""
    if isinstance(closed, (bool, np.bool_)):
        return [bool(closed)] * k
    if is_link and isinstance(closed, (list, tuple, np.ndarray)) and len(closed) == k and all(
            isinstance(c, (bool, np.bool_)) for c in closed):
        return [bool(c) for c in closed]
    if is_link:
        raise ValueError(f"closed must be a bool or one bool per component of the link "
                         f"({k} components), got {closed!r}")
    raise ValueError(f"closed must be a bool (True: a closed polygon, False: an open "
                     f"polyline), got {closed!r}")


def as_layout(P, closed=True) -> tuple[np.ndarray, Layout]:
    """Stack a knot ``(N, 3)`` or a link (list of arrays) into ``(X, layout)``.

    Shapes (and ``closed``: a bool, or one per component of a link; an open component needs
    ``MIN_OPEN_VERTICES``) are checked here; finiteness and geometry in
    :func:`polygon.check_polygon`.
    """
    is_link = isinstance(P, (list, tuple))
    parts = list(P) if is_link else [P]
    if not parts:
        raise ValueError("empty link: give at least one closed polygon")
    if is_link:
        check_not_points(parts)
    arrays = []
    for c, part in enumerate(parts):
        where = f"component {c}" if is_link else "the polygon"
        a = real_array(part, where)
        if a.ndim != 2 or a.shape[1] != 3:
            raise ValueError(f"{where} must be an (N, 3) array of vertices, got shape {a.shape}")
        if len(a) == 0:
            raise ValueError(f"{where} has no vertices: give an (N, 3) array of N >= "
                             f"{MIN_CLOSED_VERTICES} vertices (a closed polygon)")
        arrays.append(a)
    X = np.ascontiguousarray(np.concatenate(arrays, axis=0))
    sizes = [len(a) for a in arrays]
    if closed is True:  # the default: no flags, the layout of closed components
        return X, layout_from_sizes(sizes, is_link)
    flags = check_closed(closed, len(arrays), is_link)
    for c, (size, cl) in enumerate(zip(sizes, flags, strict=True)):
        if not cl and size < MIN_OPEN_VERTICES:
            where = f"component {c}" if is_link else "the polyline"
            raise ValueError(f"{where} has {size} vertices; an open polyline (closed=False) "
                             f"needs at least {MIN_OPEN_VERTICES}")
    return X, layout_from_sizes(sizes, is_link, flags)


# Spans of coordinates inside [2^-_SPAN_BITS, 2^_SPAN_BITS] are used as they are; the kernels'
# intermediate terms reach the fourth power of lengths and their inverses (the gradient is NaN
# from spans of about 1e100 or 1e-100), so far larger or smaller curves are scaled first.
_SPAN_BITS = 64


def unit_exponent(X: np.ndarray) -> int:
    """``k`` such that ``X · 2^-k`` spans about 1, for coordinates spanning more than ``2^64``
    or less than ``2^-64`` (0 otherwise, and for arrays that are empty, flat or not finite:
    the checks report those). ``k`` is even, so that ``np.ldexp(X, -k)`` is exact and every
    rounding of the homogeneous formulas (sums, products, quotients, square roots) is the same
    as at the original size: results scaled back are the same bits."""
    if X.size == 0 or not np.all(np.isfinite(X)):
        return 0
    return _span_exponent(float((X.max(axis=0) / 2 - X.min(axis=0) / 2).max()))


def _span_exponent(span: float) -> int:
    """:func:`unit_exponent` of a curve of half-range ``span`` (half-range: no overflow)."""
    if span == 0.0:
        return 0
    e = int(np.frexp(span)[1])
    if abs(e) <= _SPAN_BITS:
        return 0
    return e + (e & 1)


def as_unit_layout(P, closed=True) -> tuple[np.ndarray, Layout, int]:
    """:func:`as_layout` with the vertices scaled by ``2^-k`` (:func:`unit_exponent`):
    ``(X · 2^-k, layout, k)``."""
    X, layout = as_layout(P, closed)
    # unit_exponent in one pass (its max and min along columns: 0.07 s at 10^6 vertices)
    finite, span = extent(X)
    k = _span_exponent(span) if finite else 0
    return (np.ldexp(X, -k) if k else X), layout, k


# ---------------------------------------------------------------------------------------------
# What every public function checks of its vertices before any kernel sees them: O(N) numpy
# checks (and two sorts), so that no kernel divides by zero or returns NaN for bad input. A
# curve that passes is let through by one-pass screens (._screens); the numpy code runs
# where a screen cannot tell, and so decides and words every refusal as it did alone.


def vertex_name(layout: Layout, v: int) -> str:
    """``"vertex 7"``, or ``"vertex 7 of component 1"`` for a link."""
    if layout.k == 1:
        return f"vertex {v}"
    c = int(layout.comp[v])
    return f"vertex {v - layout.starts[c]} of component {c}"


def check_counts(layout: Layout, name: str = "the curve") -> None:
    """ValueError for a closed component of fewer than :data:`MIN_CLOSED_VERTICES` vertices
    (open ones were checked by :func:`as_layout`)."""
    for c in range(layout.k):
        size = int(layout.starts[c + 1] - layout.starts[c])
        if size < MIN_CLOSED_VERTICES and (layout.closed is None or layout.closed[c]):
            where = f"component {c} of {name}" if layout.is_link else name
            raise ValueError(f"{where} has {size} {'vertex' if size == 1 else 'vertices'}; a "
                             f"closed polygon needs at least {MIN_CLOSED_VERTICES}")


def check_finite(X: np.ndarray, layout: Layout, name: str = "the curve") -> None:
    """ValueError naming the first vertex with a NaN or infinite coordinate."""
    if np.isfinite(X).all():  # without the reduction per row below (0.02 s at 10^6 vertices)
        return
    bad = ~np.isfinite(X).all(axis=1)
    if bad.any():
        v = int(np.flatnonzero(bad)[0])
        raise ValueError(
            f"{name} has NaN or infinite coordinates ({int(bad.sum())} vertices, first at "
            f"{vertex_name(layout, v)}); fix or delete those points"
        )


def check_distinct(X: np.ndarray, layout: Layout, name: str = "the curve") -> None:
    """ValueError for a vertex equal to the next one (an edge of length 0, relative to the
    curve's size; the dummy edges of open components are no such edges)."""
    if short_edge_possible(X, layout.nxt, layout.has_open):  # else every edge is long enough
        _distinct_by_numpy(X, layout, name)


def _distinct_by_numpy(X: np.ndarray, layout: Layout, name: str) -> None:
    """:func:`check_distinct` without its screen (what decides and words a refusal)."""
    edge = np.linalg.norm(X[layout.nxt] - X, axis=1)
    scale = float(np.abs(X - X.mean(axis=0)).max()) or 1.0
    rep = edge <= 1e-12 * scale
    if layout.has_open:
        rep &= layout.real
    if rep.any():
        v = int(np.flatnonzero(rep)[0])
        raise ValueError(
            f"{name} repeats a point: {vertex_name(layout, v)} and the next vertex coincide "
            f"({int(rep.sum())} repeated in all); merge duplicates (Blender: Merge by Distance) "
            f"or resample the curve"
        )


def _equal_rows(R: np.ndarray) -> tuple[int, int] | None:
    """Indices of two equal rows of ``R`` (the first pair in sorted order), or None."""
    order = np.lexsort(R.T[::-1])
    S = R[order]
    same = np.flatnonzero((S[1:] == S[:-1]).all(axis=1))
    if not len(same):
        return None
    a, b = sorted((int(order[same[0]]), int(order[same[0] + 1])))
    return a, b


def check_not_touching(X: np.ndarray, layout: Layout, name: str = "the curve") -> None:
    """ValueError for two vertices in the same place, or two edges that are not neighbours
    with the same midpoint: the kernels divide by those distances (an exact coincidence; a
    near one is the start check's business, :func:`..polygon.check_polygon`)."""
    # the sorts only where a screen saw (or could not rule out) equal vertices or midpoints:
    # they took 0.4 s at 10^6 vertices, the screens 0.04 s
    if (equal_rows_possible(X, layout.nxt, False, False)
            or equal_rows_possible(X, layout.nxt, True, layout.has_open)):
        _not_touching_by_sorting(X, layout, name)


def _not_touching_by_sorting(X: np.ndarray, layout: Layout, name: str) -> None:
    """:func:`check_not_touching` without its screens (what decides and words a refusal)."""
    pair = _equal_rows(X)
    if pair is not None:
        a, b = pair
        raise ValueError(f"{name} touches itself: {vertex_name(layout, a)} and "
                         f"{vertex_name(layout, b)} are the same point; move the strands apart")
    real = np.flatnonzero(layout.real) if layout.has_open else np.arange(layout.n)
    M = 0.5 * (X[real] + X[layout.nxt[real]])
    order = np.lexsort(M.T[::-1])
    S = M[order]
    same = np.flatnonzero((S[1:] == S[:-1]).all(axis=1))
    for k in same:  # neighbouring edges share a midpoint only where the curve turns back
        i, j = int(real[order[k]]), int(real[order[k + 1]])
        if layout.nxt[i] != j and layout.nxt[j] != i:
            i, j = min(i, j), max(i, j)
            raise ValueError(f"{name} touches itself: the edges after {vertex_name(layout, i)} "
                             f"and after {vertex_name(layout, j)} have the same midpoint; move "
                             f"the strands apart")


def as_checked_layout(P, closed=True, *, name: str = "the curve",
                      touching: bool = True) -> tuple[np.ndarray, Layout, int]:
    """:func:`as_unit_layout` of a curve whose vertices passed the checks of every public
    door: real numbers in (N, 3) arrays, no empty component, at least
    :data:`MIN_CLOSED_VERTICES` vertices per closed component, finite coordinates, no vertex
    equal to the next, and (``touching``) no two vertices or midpoints of disjoint edges in
    one place. ValueError (TypeError for the type) says which and where."""
    X, layout, k = as_unit_layout(P, closed)
    check_counts(layout, name)
    check_finite(X, layout, name)
    check_distinct(X, layout, name)
    if touching:
        check_not_touching(X, layout, name)
    return X, layout, k
