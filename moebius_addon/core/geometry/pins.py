"""Pinned vertices: the caller's ``pinned=`` checked and turned into stacked vertex
indices, before anything runs.

A pinned vertex keeps its position exactly: the feasible methods eliminate its coordinates
from the saddle-point system and from the back-projection (its velocity is zero, see
:class:`.linalg.Factorization`), so every iterate has the same bits there. With pins the
constraints change (:class:`.constraints.Constraints`): an edge whose two ends are pinned
loses its length row (its length cannot change), and a component with a pin loses its
barycenter rows (the pins hold it in place).

What can be refused, each with its own message: a ``pinned`` that is not a sequence of whole
numbers (one per component for a link), an index out of range, an index given twice, every
vertex pinned, and a stretch of free vertices between two pins that cannot move while it keeps
its edge lengths (it is straight: too few free vertices between those pins).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .layout import Layout

#: A free stretch whose end-to-end distance reaches this fraction of its length is straight:
#: its edge-length rows are dependent and the saddle-point system singular. 1e-6 is the spread
#: of edge lengths an "equilateral" start may have (solvers.base): a stretch closer to straight
#: than that may be too short for its target lengths.
_TAUT = 1.0 - 1e-6


def count_pins(pinned) -> int:
    """How many indices ``pinned`` holds (0 for None and empty lists), without checking
    them: for a method that refuses pins before anything else is looked at."""
    if pinned is None:
        return 0
    if isinstance(pinned, (list, tuple)):
        return sum(count_pins(p) if isinstance(p, (list, tuple, np.ndarray)) else 1
                   for p in pinned)
    return int(np.size(pinned))


def _indices(value, where: str, size: int) -> np.ndarray:
    """``value`` as a 1-D int64 array of distinct indices in ``[0, size)``, else ValueError."""
    if isinstance(value, (str, bytes)) or not isinstance(value, (Sequence, np.ndarray)):
        raise ValueError(f"pinned{where} must be a sequence of vertex indices, got {value!r}")
    if len(value) == 0:
        return np.zeros(0, np.int64)
    arr = value if isinstance(value, np.ndarray) else np.asarray(value, dtype=object)
    if arr.ndim != 1:
        raise ValueError(f"pinned{where} must be a flat sequence of vertex indices")
    out = np.empty(len(arr), np.int64)
    for i, v in enumerate(arr):
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)):
            raise ValueError(f"pinned{where} must hold whole vertex indices (int), got {v!r}")
        if not 0 <= int(v) < size:  # before int64: 10**20 does not fit one
            raise ValueError(f"pinned index {int(v)}{where} is out of range: the "
                             f"{'component' if where else 'polygon'} has {size} vertices, "
                             f"indices 0 to {size - 1}")
        out[i] = int(v)
    uniq, counts = np.unique(out, return_counts=True)
    if np.any(counts > 1):
        raise ValueError(f"pinned index {int(uniq[counts > 1][0])}{where} is given more "
                         f"than once")
    return uniq


def check_pins(pinned, layout: Layout, X: np.ndarray, *, tangents: bool = False,
               edge_lengths: bool = True) -> np.ndarray | None:
    """The pinned vertices as sorted stacked indices into ``X``, or None when nothing is
    pinned (the run is then exactly the run without ``pinned=``).

    Parameters
    ----------
    pinned : sequence of int, or (link) a sequence of them per component
        Vertex indices of the polygon (0 to N−1); for a link, one list per component with
        indices into that component.
    layout : Layout
        The components of ``X``.
    X : (N, 3) array
        The start (stacked), for the test of straight free stretches.
    tangents : bool
        Also pin both neighbours of every pinned vertex, so that the two edges at a pin keep
        their directions (fixed tangents at the pins).
    edge_lengths : bool
        Whether the run keeps edge lengths (only then does a straight free stretch jam).

    Raises
    ------
    ValueError
        For anything but whole indices in range given once, every vertex pinned, or a free
        stretch between two pins that is straight (it cannot move with fixed edge lengths).
    """
    if pinned is None:
        return None
    if layout.is_link:
        if isinstance(pinned, (str, bytes)) or not isinstance(pinned, (Sequence, np.ndarray)) \
                or len(pinned) != layout.k or any(
                    not isinstance(p, (Sequence, np.ndarray)) for p in pinned):
            raise ValueError(f"pinned must hold one list of vertex indices per component of "
                             f"the link ({layout.k} lists; an empty list pins nothing there), "
                             f"got {pinned!r}")
        parts = [layout.starts[c] + _indices(p, f" of component {c}",
                                             int(layout.starts[c + 1] - layout.starts[c]))
                 for c, p in enumerate(pinned)]
        idx = np.concatenate(parts)
    else:
        idx = _indices(pinned, "", layout.n)
    if idx.size == 0:
        return None
    if tangents:
        before = layout.prv[idx]
        if layout.has_open:  # the first vertex of an open polyline has no neighbour before
            first = ~layout.closed[layout.comp[idx]] & (idx == layout.starts[layout.comp[idx]])
            before = np.where(first, idx, before)
        idx = np.unique(np.concatenate([idx, layout.nxt[idx], before]))
    if idx.size == layout.n:
        raise ValueError(f"every vertex is pinned{' (with their neighbours)' if tangents else ''}"
                         f": nothing can move; leave some vertices free")
    if edge_lengths:
        _check_stretches(idx, layout, X, tangents)
    return idx


def _check_stretches(idx: np.ndarray, layout: Layout, X: np.ndarray, tangents: bool) -> None:
    """Refuse a straight run of free vertices between two pins: with its edge lengths kept it
    cannot move, and its edge rows are dependent (the saddle-point system is singular)."""
    pinned = np.zeros(layout.n, bool)
    pinned[idx] = True
    ln = np.linalg.norm(X[layout.nxt] - X, axis=1)
    for c in range(layout.k):
        s0, s1 = int(layout.starts[c]), int(layout.starts[c + 1])
        pins = np.flatnonzero(pinned[s0:s1]) + s0
        m = s1 - s0
        for a, b in zip(pins, np.roll(pins, -1), strict=True):
            gap = (b - a - 1) % m  # free vertices from a to b along the component
            if gap == 0 or a == b:  # adjacent pins, or one pin: a loop that can move
                continue
            if b < a and layout.has_open and not layout.closed[c]:
                continue  # round the free ends of an open polyline: they can move
            edges = (np.arange(a, a + gap + 1) - s0) % m + s0
            if np.linalg.norm(X[b] - X[a]) >= _TAUT * ln[edges].sum():
                where = f" of component {c}" if layout.is_link else ""
                lo, hi = a - s0, b - s0
                raise ValueError(
                    f"the {gap} free vertices between pinned vertices {lo} and {hi}{where} lie "
                    f"on a straight segment: too few free vertices to move while keeping their "
                    f"edge lengths; pin fewer vertices there"
                    f"{' or drop pin_tangents' if tangents else ''}, or bend the curve there"
                )
