"""The catalogue: knots, unknots and links by name, as polygons or as curve objects."""

from __future__ import annotations

from collections.abc import Sequence

import bpy
import numpy as np

from .. import core
from .conversion import make_curve_object
from .labels import DEFAULT_ENGINE, DEFAULT_METHOD, SPECIAL_KNOTS
from .options import check_edge_count
from .polygons import as_input, as_link


def knot_names() -> list[str]:
    """Every name :func:`knot_polygons` takes: the generators, then the knot table."""
    from ..core import knots

    return [*(key for key, *_ in SPECIAL_KNOTS), *knots.names()]


def check_knot(kind: str, n: int | None = None, metric: str = "hs",
               method: str = DEFAULT_METHOD, engine: str = DEFAULT_ENGINE) -> None:
    """ValueError for a name :func:`knot_polygons` does not know (listing those it does) or
    more edges than a run of ``method`` in ``metric`` on ``engine`` takes
    (:func:`~.options.check_edge_count`): the same refusal in every door, before any work."""
    if kind not in knot_names():
        raise ValueError(f"unknown knot '{kind}'; choose one of {', '.join(knot_names())}")
    if n:
        check_edge_count(n, metric, method, engine)


def knot_polygons(kind: str, n: int | None = None, p: int = 2, q: int = 3,
                  seed: int = 0, *, metric: str = "hs", method: str = DEFAULT_METHOD,
                  engine: str = DEFAULT_ENGINE) -> list:
    """Polygons of a catalogue entry, equilateral and ready to relax.

    Parameters
    ----------
    kind : str
        ``"fhw"``, ``"helix"``, ``"random"``, ``"torus"``, ``"circle"``, ``"figure_eight"`` or a
        name from ``core.knots.names()`` such as ``"7_2"``.
    n : int, optional
        Edges in total (split over the components of a link); None or 0 takes the catalogue's
        default for the entry, which is fine enough for its shape.
    p, q : int
        Torus knot parameters.
    seed : int
        Seed of the random unknot.
    metric, method, engine : str
        The run the knot is made for: more edges than it takes are refused before any work
        (:func:`check_knot`).

    Returns
    -------
    list of (n_i, 3) float64 arrays
    """
    from ..core import knots

    check_knot(kind, n, metric, method, engine)
    n = n or None
    makers = {
        "fhw": lambda: knots.freedman_unknot(*(n,) if n else ()),
        "helix": lambda: knots.helix_unknot(*(n,) if n else ()),
        "random": lambda: knots.random_unknot(*(n,) if n else (), seed=seed),
        "torus": lambda: knots.torus_knot(p, q, n),
        "circle": lambda: knots.circle(*(n,) if n else ()),
        "figure_eight": lambda: knots.figure_eight(*(n,) if n else ()),
    }
    if kind in makers:
        link = as_link(makers[kind]())
    else:
        link = as_link(knots.named(kind, n))
    out = []
    for P in link:
        e = np.linalg.norm(np.roll(P, -1, axis=0) - P, axis=1)
        out.append(P if np.ptp(e) <= 1e-9 * e.mean() else core.resample(P, len(P), closed=True))
    try:
        core.check_polygon(as_input(out))
    except ValueError as err:
        raise ValueError(f"knot '{kind}' with {n or 'default'} edges: {err}") from None
    return out


def add_knot(kind: str = "fhw", n: int | None = None, p: int = 2, q: int = 3, seed: int = 0,
             size: float = 2.0, location: Sequence[float] = (0.0, 0.0, 0.0),
             context: bpy.types.Context | None = None, *, metric: str = "hs",
             method: str = DEFAULT_METHOD, engine: str = DEFAULT_ENGINE) -> bpy.types.Object:
    """Add a catalogue knot as a curve object ready to relax.

    Parameters
    ----------
    kind, n, p, q, seed, metric, method, engine
        See :func:`knot_polygons`.
    size : float
        Largest extent of the bounding box, in scene units (the energy is scale invariant).
    location : 3 floats
        Where the object origin (the curve's barycenter) goes.
    context : bpy.types.Context, optional

    Returns
    -------
    bpy.types.Object
        The new, selected and active curve object.
    """
    polygons = knot_polygons(kind, n, p, q, seed, metric=metric, method=method, engine=engine)
    X = np.concatenate(polygons)
    centre = X.mean(axis=0)
    scale = size / max(float(np.ptp(X, axis=0).max()), 1e-300)
    polygons = [(P - centre) * scale for P in polygons]
    label = {"torus": f"torus {p},{q}", "random": f"random {seed}"}.get(kind, kind)
    obj = make_curve_object(f"Knot {label}", polygons, context=context)
    obj.location = location
    obj.data.bevel_depth = 0.01 * size
    return obj


