"""Knots and links as one vertex array plus index arrays (private).

A knot is an ``(N, 3)`` array, a link a list of them. The kernels see one contiguous ``(N, 3)``
array ``X`` and index arrays that encode the closed components: edge ``I`` joins vertex ``I`` to
``nxt[I]``, and vertex ``p`` is the end of edge ``prv[p]``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Layout:
    """Index arrays of a knot or link with ``N`` vertices in ``K`` components."""

    starts: np.ndarray  # (K+1,) first vertex of each component, then N
    nxt: np.ndarray  # (N,) next vertex along the component
    prv: np.ndarray  # (N,) previous vertex along the component
    comp: np.ndarray  # (N,) component of each vertex
    is_link: bool  # input was a list (results are returned as lists)

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


def layout_from_sizes(sizes, is_link: bool) -> Layout:
    sizes = np.asarray(sizes, dtype=np.int64)
    starts = np.concatenate(([0], np.cumsum(sizes))).astype(np.int64)
    n = int(starts[-1])
    idx = np.arange(n, dtype=np.int64)
    comp = np.repeat(np.arange(len(sizes), dtype=np.int64), sizes)
    nxt = idx + 1
    prv = idx - 1
    nxt[starts[1:] - 1] = starts[:-1]
    prv[starts[:-1]] = starts[1:] - 1
    return Layout(starts, nxt, prv, comp, is_link)


def as_layout(P) -> tuple[np.ndarray, Layout]:
    """Stack a knot ``(N, 3)`` or a link (list of arrays) into ``(X, layout)``.

    Shapes are checked here; finiteness and geometry in :func:`polygon.check_polygon`.
    """
    is_link = isinstance(P, (list, tuple))
    parts = list(P) if is_link else [P]
    if not parts:
        raise ValueError("empty link: give at least one closed polygon")
    arrays = []
    for c, part in enumerate(parts):
        a = np.asarray(part, dtype=np.float64)
        if a.ndim != 2 or a.shape[1] != 3:
            where = f"component {c}" if is_link else "the polygon"
            raise ValueError(f"{where} must be an (N, 3) array of vertices, got shape {a.shape}")
        arrays.append(a)
    X = np.ascontiguousarray(np.concatenate(arrays, axis=0))
    return X, layout_from_sizes([len(a) for a in arrays], is_link)
