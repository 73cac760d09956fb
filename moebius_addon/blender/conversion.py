"""Conversion: a drawn, imported or catalogue curve made into equal-edge cyclic poly splines,
checked before anything in the scene changes."""

from __future__ import annotations

from collections.abc import Sequence

import bpy
import numpy as np

from .. import core
from ..core.compilation.notice import compiling
from . import geometry
from .keyframes import ENERGY_PROP
from .labels import DEFAULT_ENGINE, DEFAULT_METHOD
from .objects import copy_transform, deselect_all, link_like
from .options import EDGE_LIMIT, check_edge_count, edge_limit
from .polygons import as_input, energy
from .progress import Progress, reporter
from .rest import set_rest_shape

_SOURCE = "moebius_source"
#: Bevel depth of a new curve whose source has none, as a share of its largest extent (Add
#: Knot's 0.01 × its size).
BEVEL_SHARE = 0.01


class Prepared(list):
    """The polygons :func:`prepare_conversion` makes (a list of (n_i, 3) arrays) and whether
    each is closed (``closed``: open splines kept open with ``keep_open``)."""

    def __init__(self, polygons, closed):
        super().__init__(polygons)
        self.closed = list(closed)


def _closed_arg(flags):
    """The core's ``closed=`` for these components: a bool for one, a list for a link."""
    return bool(flags[0]) if len(flags) == 1 else [bool(f) for f in flags]


def _dedupe(points: np.ndarray, closed: bool) -> np.ndarray:
    """Drop repeated consecutive points (OBJ files and evaluated curves often repeat them)."""
    scale = max(float(np.ptp(points, axis=0).max()), 1e-300) if len(points) else 1.0
    keep = np.ones(len(points), bool)
    keep[1:] = np.linalg.norm(np.diff(points, axis=0), axis=1) > 1e-12 * scale
    points = points[keep]
    if closed and len(points) > 1 and np.linalg.norm(points[-1] - points[0]) <= 1e-12 * scale:
        points = points[:-1]
    return points


def prepare_conversion(obj: bpy.types.Object, edges: int = 100, edge_length: float | None = None,
                       close_open: bool = False, allow_large: bool = False, *,
                       metric: str = "hs", method: str = DEFAULT_METHOD,
                       engine: str = DEFAULT_ENGINE, keep_open: bool = False) -> Prepared:
    """Check ``obj`` and compute its equal-edge polygons without touching the scene.

    Parameters
    ----------
    obj : bpy.types.Object
        Curve (poly, Bezier, NURBS) or mesh made of closed edge loops.
    edges : int
        Edges per component (at least 4); ignored when ``edge_length`` is given.
    edge_length : float, optional
        Target edge length in object units; each component gets ``round(length / edge_length)``
        edges (at least 4).
    close_open : bool
        Join the ends of open splines/chains instead of refusing them.
    keep_open : bool
        Keep open splines/chains open, their two ends where they are (Relax takes open poly
        splines: the core's open curves); ``close_open`` wins when both are set. An open one
        gets ``edges`` points.
    allow_large : bool
        Accept more than :data:`~.options.EDGE_LIMIT` edges in total on the tree engine (the
        core's own size refusals stand).
    metric, method, engine : str
        The run the curve is converted for: its edge count is refused where that run would
        refuse it (:func:`~.options.check_edge_count`).

    Returns
    -------
    Prepared
        Equilateral polygons, one per component, in object coordinates (a list; its
        ``closed`` says which are closed).

    Raises
    ------
    ValueError
        With the reason and the fix: unsupported object, open spline, fewer than 4 points,
        too many edges, a polygon that touches itself.
    """
    polylines = geometry.object_polylines(obj)
    many = len(polylines) > 1
    cleaned, flags = [], []
    for k, (points, closed) in enumerate(polylines):
        where = f"'{obj.name}'" + (f" (component {k + 1} of {len(polylines)})" if many else "")
        if not closed and not (close_open or keep_open):
            raise ValueError(
                f"{where} is an open curve; close it (Edit Mode: Alt+C, or F on the end "
                "vertices of a mesh), enable 'Close open splines', or enable 'Keep open "
                "splines' to relax it as an open curve"
            )
        closed = bool(closed or close_open)
        points = np.asarray(points, np.float64)
        geometry.check_finite_points(points, where)
        points = _dedupe(points, closed=closed)
        if len(points) < 4:
            raise ValueError(
                f"{where} has only {len(points)} distinct points; a closed curve to relax needs "
                "at least 4 (subdivide it or draw more points)"
            )
        try:  # the drawn curve itself must not touch itself (resampling could hide it)
            core.check_polygon(points, coarseness=False, closed=closed)
        except ValueError as err:
            raise ValueError(f"{where}: {err}") from None
        cleaned.append(points)
        flags.append(closed)
    lengths = [float(np.linalg.norm(np.diff(np.vstack([p, p[:1]]) if c else p, axis=0),
                                    axis=1).sum()) for p, c in zip(cleaned, flags, strict=True)]
    if edge_length is not None:
        if not edge_length > 0:
            raise ValueError(f"edge length must be positive, got {edge_length}")
        counts = [max(4, round(L / edge_length)) for L in lengths]
    else:
        if int(edges) < 4:
            raise ValueError(f"{edges} edges is too few; a closed polygon needs at least 4")
        counts = [int(edges)] * len(cleaned)
    few = core.geometry.polygon.MIN_CHECKED_VERTICES
    if min(counts) < few:
        raise ValueError(
            f"'{obj.name}': {min(counts)} edges per component is too few: below {few} the "
            "start check cannot see strands that come too close, and a knot can come out "
            f"unknotted (the trefoil at 5 to 7 edges did); use at least {few}"
            + (" or a shorter edge length" if edge_length is not None else "")
        )
    try:  # before resampling: no size may crash the process
        check_edge_count(sum(counts), metric, method, engine, allow_large)
    except ValueError as err:
        raise ValueError(f"'{obj.name}': {err}"
                         + (" (or set a longer edge length)" if edge_length is not None else "")
                         ) from None
    polygons = [core.resample(p, n, closed=c)
                for p, n, c in zip(cleaned, counts, flags, strict=True)]
    try:
        core.check_polygon(as_input(polygons), coarseness=False, closed=_closed_arg(flags))
    except ValueError as err:
        raise ValueError(f"'{obj.name}' after resampling to {counts} edges: {err}") from None
    ratio = core.contact_ratio(as_input(polygons), closed=_closed_arg(flags))
    if ratio < core.geometry.polygon.CONTACT_RATIO:
        limit = EDGE_LIMIT if allow_large else edge_limit(metric, method, engine)
        raise ValueError(f"'{obj.name}' is too coarse at {counts} edges for its shape: strands "
                         f"far apart along the curve come closer than one edge length, and the "
                         f"energy cannot keep them apart — "
                         f"{_finer_conversion(cleaned, counts, edge_length, limit, flags, ratio)}")
    return Prepared(polygons, flags)


#: Finer conversions tried for the suggestion of a too coarse one (each a resampling): the
#: search in 10% steps up to the limit took 6-19 s, a freeze on every wrong Edges value typed.
SUGGEST_TRIALS = 4


def _finer_conversion(cleaned, counts, edge_length, limit: int, flags, ratio: float) -> str:
    """The fix for a too coarse conversion, in the unit of the field the user set: the first
    count per component (or edge length) that passes the contact check, tried from the count
    the contact ratio ``ratio`` suggests (it grows about in proportion to the edge count near
    a contact, as ``core.suggest_edge_count`` assumes) in at most :data:`SUGGEST_TRIALS` steps
    of 10%; else a plain advice (``limit``: the edges a run takes)."""
    def finer(factor):
        return [max(4, int(np.ceil(n * factor))) for n in counts]

    def passes(trial):
        polygons = [core.resample(p, n, closed=c)
                    for p, n, c in zip(cleaned, trial, flags, strict=True)]
        return (core.contact_ratio(as_input(polygons), closed=_closed_arg(flags))
                >= core.geometry.polygon.CONTACT_RATIO)

    top = limit / sum(counts)
    factor = max(1.1, 1.05 * core.geometry.polygon.CONTACT_RATIO / max(ratio, 1e-9))
    for _ in range(SUGGEST_TRIALS):
        if factor > top:
            return (f"move the strands apart: by their closest approach they need about "
                    f"{finer(factor)[0]} edges per component, more than the {limit} edges a "
                    "run takes")
        if passes(finer(factor)):
            if edge_length is not None:
                return f"use an edge length of at most {edge_length / factor:.4g}"
            return f"use at least {finer(factor)[0]} edges per component (the Edges field)"
        factor *= 1.1
    factor /= 1.1
    if edge_length is not None:
        return f"use an edge length well below {edge_length / factor:.4g} (still too coarse)"
    return (f"use more than {finer(factor)[0]} edges per component (the Edges field; that "
            "many were still too coarse)")


def make_curve_object(name: str, polygons: Sequence[np.ndarray],
                      like: bpy.types.Object | None = None,
                      context: bpy.types.Context | None = None,
                      closed=None) -> bpy.types.Object:
    """Create and select a curve object with one cyclic poly spline per polygon.

    Parameters
    ----------
    name : str
    polygons : sequence of (n_i, 3) arrays
        Vertices in object coordinates.
    like : bpy.types.Object, optional
        Object whose transform, collections and (for curves) materials are copied, and its
        bevel when it has one; without one the curve gets a visible thickness of its own
        (:data:`BEVEL_SHARE` of its largest extent, as *Add Knot* gives), else the first
        render of a drawn curve or an imported mesh showed nothing.
    context : bpy.types.Context, optional
        Defaults to ``bpy.context``.
    closed : bool or sequence of bool, optional
        Which splines are cyclic (default: ``polygons.closed`` of a :class:`Prepared`, else
        all).

    Returns
    -------
    bpy.types.Object
    """
    context = context or bpy.context
    if closed is None:
        closed = getattr(polygons, "closed", True)
    curve = geometry.new_curve(name, polygons, closed)
    src = like.data if like is not None and like.type == "CURVE" else None
    if src is not None and src.bevel_depth > 0:
        curve.bevel_depth = src.bevel_depth
        curve.bevel_resolution = src.bevel_resolution
        curve.use_fill_caps = src.use_fill_caps
    else:
        X = np.concatenate(polygons)
        curve.bevel_depth = BEVEL_SHARE * max(float(np.ptp(X, axis=0).max()), 1e-300)
    if src is not None:
        for mat in src.materials:
            curve.materials.append(mat)
    obj = bpy.data.objects.new(name, curve)
    if like is not None:
        copy_transform(like, obj)
    deselect_all(context)
    link_like(obj, like, context)
    set_rest_shape(obj, polygons)
    obj[ENERGY_PROP] = energy(polygons, closed)
    obj.select_set(True)
    context.view_layer.objects.active = obj
    return obj


def convert_object(obj: bpy.types.Object, edges: int = 100, edge_length: float | None = None,
                   close_open: bool = False, allow_large: bool = False,
                   context: bpy.types.Context | None = None, *, metric: str = "hs",
                   method: str = DEFAULT_METHOD, engine: str = DEFAULT_ENGINE,
                   keep_open: bool = False, progress: Progress = False) -> bpy.types.Object:
    """Make an equal-edge poly curve from ``obj``; the original is kept, hidden.

    Parameters
    ----------
    obj : bpy.types.Object
        Curve (poly, Bezier, NURBS) or mesh made of closed edge loops.
    edges, edge_length, close_open, allow_large, metric, method, engine, keep_open
        See :func:`prepare_conversion`.
    context : bpy.types.Context, optional
        Defaults to ``bpy.context``.
    progress : bool or callable
        True: print a line when numba compiles the kernels (the first use after installing
        or updating) and one when done; a callable receives those lines; False: silent.

    Returns
    -------
    bpy.types.Object
        The new curve object ``"<name>.moebius"`` (same transform and collections), selected
        and active; ``obj["moebius_source"]`` names the hidden original.

    Raises
    ------
    ValueError
        See :func:`prepare_conversion`; the scene is unchanged then.
    """
    say = reporter(progress)
    with compiling(say):
        polygons = prepare_conversion(obj, edges, edge_length, close_open, allow_large,
                                      metric=metric, method=method, engine=engine,
                                      keep_open=keep_open)
        new = apply_conversion(obj, polygons, context)
    if say is not None:
        say(f"converted '{obj.name}' to '{new.name}', "
            f"{' + '.join(str(len(p)) for p in polygons)} edges")
    return new


def apply_conversion(obj: bpy.types.Object, polygons: Sequence[np.ndarray],
                     context: bpy.types.Context | None = None) -> bpy.types.Object:
    """Create the converted curve from :func:`prepare_conversion`'s polygons; hide ``obj``."""
    context = context or bpy.context
    new = make_curve_object(f"{obj.name}.moebius", polygons, like=obj, context=context)
    new[_SOURCE] = obj.name
    obj.hide_set(True)
    obj.hide_render = True
    return new


