"""Polygons as this layer holds them (a list of ``(n_i, 3)`` arrays, one per spline) and as the
core takes them (one array for a knot, a list for a link), and their energy."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .. import core


def as_input(polygons: Sequence[np.ndarray]):
    """A single polygon as an array, a link as a list (the core takes both)."""
    return polygons[0] if len(polygons) == 1 else list(polygons)


def as_link(x) -> list[np.ndarray]:
    """The core's polygon or link as a list of float64 ``(n_i, 3)`` arrays."""
    if isinstance(x, np.ndarray) and x.ndim == 2:
        return [np.array(x, dtype=np.float64)]
    return [np.array(p, dtype=np.float64) for p in x]


def energy(polygons: Sequence[np.ndarray], closed=True) -> float:
    """Möbius energy of one polygon, or one total of a link (components and their cross
    energy, as ``core.moebius_energy``).

    Parameters
    ----------
    polygons : sequence of (n_i, 3) arrays
    closed : bool or sequence of bool
        Whether each is closed (``core.moebius_energy``'s ``closed``).

    Returns
    -------
    float
    """
    flags = [closed] * len(polygons) if isinstance(closed, bool) else list(closed)
    if all(flags):  # the closed energy, as before open curves existed
        e = core.moebius_energy(as_input(polygons))
    else:
        e = core.moebius_energy(as_input(polygons),
                                closed=flags if len(polygons) > 1 else flags[0])
    return float(np.sum(e))
