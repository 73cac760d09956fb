"""The catalogue: knots, unknots and links by name or notation, as polygons or as curve objects
(a link's components each in its own colour)."""

from __future__ import annotations

from collections.abc import Sequence

import bpy
import numpy as np

from .. import core
from .conversion import make_curve_object
from .identification import KNOT_TYPE_PROP
from .labels import DEFAULT_ENGINE, DEFAULT_METHOD, SPECIAL_KNOTS
from .options import check_edge_count
from .polygons import as_input, as_link


def knot_names() -> list[str]:
    """Every name :func:`knot_polygons` takes as it is listed: the generators, then the knot
    table (``core.knots.names()``: 7 166 knots and links); aliases and mirror images
    (``"trefoil"``, ``"m3_1"``) are taken too (:func:`check_knot`)."""
    from ..core.topology import knots

    return [*(key for key, *_ in SPECIAL_KNOTS), *knots.names()]


def search_knots(text: str, limit: int = 100) -> list[tuple[str, str]]:
    """``(name, description)`` of the catalogue entries matching ``text``, best first: the
    generators whose name or label contain it, then ``core.knots.search`` (names, aliases,
    mirror images, descriptions). What *Add Knot*'s search field lists."""
    from ..core.topology import knots, table

    low = text.strip().lower()
    out = [(key, label) for key, label, _ in SPECIAL_KNOTS
           if not low or low in key or low in label.lower()]
    for name in knots.search(text, limit=limit):
        out.append((name, table.entry(name).description))
    return out[:limit]


def check_knot(kind: str, n: int | None = None, metric: str = "hs",
               method: str = DEFAULT_METHOD, engine: str = DEFAULT_ENGINE) -> None:
    """ValueError for a name :func:`knot_polygons` does not know (naming close matches) or
    more edges than a run of ``method`` in ``metric`` on ``engine`` takes
    (:func:`~.options.check_edge_count`): the same refusal in every door, before any work."""
    from ..core.topology import table

    if kind not in _SPECIAL and table.lookup(kind) is None:
        near = [name for name, _ in search_knots(kind, 8)] or table.close_matches(
            kind, extra=tuple(_SPECIAL))
        hint = (f"did you mean {', '.join(near)}?" if near else
                "names look like 3_1, 10_161, 12n_888, L6a4{0,0}, 'trefoil', 'Borromean "
                "rings', or fhw, helix, random, torus, circle")
        raise ValueError(f"unknown knot '{kind}'; {hint}")
    if n:
        check_edge_count(n, metric, method, engine)


_SPECIAL = {key for key, *_ in SPECIAL_KNOTS}


def knot_polygons(kind: str, n: int | None = None, p: int = 2, q: int = 3,
                  seed: int = 0, *, metric: str = "hs", method: str = DEFAULT_METHOD,
                  engine: str = DEFAULT_ENGINE) -> list:
    """Polygons of a catalogue entry, equilateral and ready to relax.

    Parameters
    ----------
    kind : str
        ``"fhw"``, ``"helix"``, ``"random"``, ``"torus"``, ``"circle"``, ``"figure_eight"`` or a
        knot or link of the table by name, alias or mirror image (``"7_2"``, ``"10_161"``,
        ``"L6a4{0,0}"``, ``"Borromean rings"``, ``"m3_1"``; ``core.knots.named``).
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
    from ..core.topology import knots

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
    label = {"torus": f"torus {p},{q}", "random": f"random {seed}"}.get(kind, kind)
    obj = _place(f"Knot {label}", polygons, size, location, context)
    if kind not in _SPECIAL:
        from ..core.topology import table

        obj[KNOT_TYPE_PROP] = table.lookup(kind)
    elif kind in ("fhw", "helix", "random", "circle"):
        obj[KNOT_TYPE_PROP] = "0_1"
    return obj


def _place(name: str, polygons: list, size: float, location, context) -> bpy.types.Object:
    """A curve object of the polygons scaled to ``size``, at ``location``, each component of
    a link in its own colour."""
    X = np.concatenate(polygons)
    centre = X.mean(axis=0)
    scale = size / max(float(np.ptp(X, axis=0).max()), 1e-300)
    polygons = [(P - centre) * scale for P in polygons]
    obj = make_curve_object(name, polygons, context=context)
    obj.location = location  # the bevel: 1% of the size (make_curve_object's default)
    if len(polygons) > 1:
        colour_components(obj)
    return obj


#: Viewport colours of a link's components (Blender's default palette hues, distinct in
#: Solid mode with Material colours).
COMPONENT_COLOURS = ((0.80, 0.16, 0.12, 1.0), (0.13, 0.45, 0.80, 1.0), (0.95, 0.65, 0.10, 1.0),
                     (0.20, 0.65, 0.25, 1.0), (0.60, 0.25, 0.70, 1.0), (0.10, 0.70, 0.70, 1.0))


def colour_components(obj: bpy.types.Object) -> None:
    """Give each spline of a curve its own material (``Möbius component k``, viewport colour
    and base colour from :data:`COMPONENT_COLOURS`), so a link's components are told apart
    in the viewport and in renders."""
    curve = obj.data
    curve.materials.clear()
    for k, spline in enumerate(curve.splines):
        name = f"Möbius component {k + 1}"
        mat = bpy.data.materials.get(name)
        if mat is None:
            mat = bpy.data.materials.new(name)
            colour = COMPONENT_COLOURS[k % len(COMPONENT_COLOURS)]
            mat.diffuse_color = colour
            if hasattr(mat, "base_color"):  # pragma: no cover - newer Blender
                mat.base_color = colour[:3]
        curve.materials.append(mat)
        spline.material_index = k


def notation_polygons(text: str, n: int | None = None, *, metric: str = "hs",
                      method: str = DEFAULT_METHOD, engine: str = DEFAULT_ENGINE) -> list:
    """Polygons of a knot or link typed as a braid word or PD code
    (``core.knots.from_notation``), equilateral and checked like :func:`knot_polygons`."""
    from ..core.topology import knots, notation, pd

    if not str(text).strip():
        raise ValueError("type a braid word (1 -2 1 -2) or a PD code "
                         "([[1,5,2,4],[3,1,4,6],[5,3,6,2]]) first")
    kind, value = notation.parse_notation(text)
    if kind == "pd" and pd.simplify(value).crossings == 0:
        # PD[X[1,1,2,2]] was added as "Knot PD code of 1 crossings", a plain circle
        k = len(value.components()) + value.loops
        what = "the unknot" if k == 1 else f"an unlink of {k} components"
        raise ValueError(
            f"this PD code of {value.crossings} crossing{'' if value.crossings == 1 else 's'} "
            f"is {what}: kinks and bigons (Reidemeister I and II moves) remove every crossing, "
            f"and the drawing would be {'a plain circle' if k == 1 else 'plain circles'}; "
            f"check the code, or add the unknot (0_1) to relax a circle")
    if n:
        check_edge_count(n, metric, method, engine)
    elif kind == "braid":  # its default count, before any work ("99 -99": 106 810 edges)
        default = knots.braid_edges(*value)
        try:
            check_edge_count(default, metric, method, engine)
        except ValueError as err:
            raise ValueError(f"'{text}' takes {default} edges by default (3.3 per strand "
                             f"spacing): {err}; give fewer edges (Edges in the Add from "
                             f"Notation dialog) or type a braid word on fewer strands") from None
    link = as_link(knots.from_notation(text, n or None))
    if not n:  # a PD code's default count comes from its drawing
        check_edge_count(sum(len(p) for p in link), metric, method, engine)
    try:
        core.check_polygon(as_input(link))
    except ValueError as err:
        raise ValueError(f"'{text}' with {n or 'default'} edges: {err}") from None
    return link


def add_notation(text: str, n: int | None = None, size: float = 2.0,
                 location: Sequence[float] = (0.0, 0.0, 0.0),
                 context: bpy.types.Context | None = None, *, metric: str = "hs",
                 method: str = DEFAULT_METHOD, engine: str = DEFAULT_ENGINE
                 ) -> bpy.types.Object:
    """Add the knot or link of a braid word (``"1 -2 1 -2"``) or PD code as a curve object
    ready to relax (:func:`notation_polygons`); the text is kept in the object's
    ``moebius_notation`` property, and a link's components get their own colours."""
    from ..core.topology import notation

    polygons = notation_polygons(text, n, metric=metric, method=method, engine=engine)
    kind, value = notation.parse_notation(text)
    obj = _place(f"Knot {notation.describe(kind, value)}"[:60], polygons, size, location,
                 context)
    obj["moebius_notation"] = str(text)
    return obj


