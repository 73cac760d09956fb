"""Scripting API of the Blender layer: what the buttons do, as plain functions.

Every operator in ``bpy.ops.moebius`` validates its input and calls one of these, so a
``blender --background --python`` script, the ``blender -c moebius`` command and the tests run
exactly the code the panel runs. Numerics come from :mod:`moebius_addon.core`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from pathlib import Path

import bpy
import numpy as np

from .. import core
from . import geometry, keyframes
from .keyframes import ENERGY_PROP

# Coordinates at or beyond this are Blender's clamped infinities (single precision: ±3.4e38).
_FLOAT_LIMIT = 1e38

#: Above this many edges in total the conversion is refused: each iteration evaluates all
#: N² edge pairs of the energy and solves an N×N system, so ten times the edges cost about a
#: hundred times the time per iteration. ``allow_large=True`` lifts the limit for scripts.
EDGE_LIMIT = 5000

#: Metrics offered for the flow, as ``(core name, label, description)``.
METRICS = (
    ("hs", "W^{3/2,2} (geometric)", "Geometric Sobolev metric of the paper: fastest, scale-aware"),
    ("hs_pure", "W^{3/2,2} (pure)", "Fractional Sobolev metric without the lower-order terms"),
    ("h2", "H²", "Second-order Sobolev metric (too strong: slow for fine polygons)"),
    ("h1", "H¹", "First-order Sobolev metric (too weak: step sizes shrink with N)"),
    ("l2", "L²", "Plain L² gradient descent (needs tiny steps; for comparison only)"),
)

#: The paper's explicit projected gradient (``core.Relaxation``): best on unknots.
EXPLICIT_METHOD = "projected_gradient"
#: The implicit projected gradient: best on knots.
KNOT_METHOD = "projected_gradient_implicit"
#: Default: :data:`KNOT_METHOD` for a curve its knot determinant proves knotted, else
#: :data:`EXPLICIT_METHOD` (:func:`choose_method`; measured in docs/benchmarks.md, "The
#: automatic method": the implicit one ended lower on 32 of the 36 table knots in the same
#: seconds, the explicit one is faster on the FHW unknot).
AUTO_METHOD = "auto"
DEFAULT_METHOD = AUTO_METHOD

#: Default weight α of the edge-stretch penalty of the penalty methods (the core's default).
DEFAULT_PENALTY = core.DEFAULT_PENALTY_WEIGHT

_METHOD_TEXT = {
    AUTO_METHOD: (
        "Automatic",
        "Implicit Gradient for a knotted curve (knot determinant above 1), Projected Gradient "
        "for unknots and links: the faster of the two on each, as measured (default)"),
    "projected_gradient": (
        "Projected Gradient",
        "The paper's explicit projected Sobolev gradient with Armijo steps: keeps edge lengths "
        "and barycenter exactly; the fastest on unknots"),
    "projected_gradient_implicit": (
        "Implicit Gradient",
        "Backward Euler on the projected flow, solved by Newton–Krylov: keeps edge lengths and "
        "barycenter exactly; fewer but costlier iterations"),
    "trust_region": (
        "Trust Region",
        "Subspace trust-region method with Hessian products: keeps edge lengths and barycenter "
        "exactly"),
    "ncg": (
        "Nonlinear CG (penalty)",
        "Polak–Ribière conjugate gradients; edge lengths held only by a penalty (they may "
        "stretch), barycenter free"),
    "lbfgs": (
        "L-BFGS (penalty)",
        "Limited-memory BFGS; edge lengths held only by a penalty (they may stretch), "
        "barycenter free"),
    "nesterov": (
        "Nesterov (penalty)",
        "Nesterov's accelerated gradient; edge lengths held only by a penalty (they may "
        "stretch), barycenter free"),
}

#: Optimizers offered for the flow, as ``(name, label, description)``: :data:`AUTO_METHOD`,
#: then exactly ``core.METHODS`` in its order (a method without a text here gets its name as
#: label).
METHODS = tuple(
    (m, *_METHOD_TEXT.get(m, (m.replace("_", " ").title(), f"core.solvers '{m}'")))
    for m in (AUTO_METHOD, *core.METHODS)
)

#: Methods that replace the edge-length constraints by a penalty of weight α.
PENALTY_METHODS = core.solvers.INFEASIBLE

#: Catalogue entries besides the named knots of ``core.knots.names()``.
SPECIAL_KNOTS = (
    ("fhw", "Freedman–He–Wang unknot", "The tangled unknot of Freedman, He and Wang"),
    ("helix", "Helix unknot", "A coiled unknot"),
    ("random", "Random unknot", "A seeded random unknot"),
    ("torus", "Torus knot (p, q)", "The (p, q) torus knot"),
    ("circle", "Circle", "A regular polygon (the energy minimiser)"),
    ("figure_eight", "Figure-eight knot", "The 4_1 knot"),
)

_REST = "moebius_rest"
# Whether a run reached its first iterate in this Blender session: the first one pays for the
# numerical kernels (numba compiles them once per installation, later sessions load them from
# its cache) before its first iterate; see docs/blender.md, Install, for the times measured.
_SESSION = {"warm": False}
_SOURCE = "moebius_source"


def _as_input(polygons: Sequence[np.ndarray]):
    """A single polygon as an array, a link as a list (the core takes both)."""
    return polygons[0] if len(polygons) == 1 else list(polygons)


def _as_link(x) -> list[np.ndarray]:
    if isinstance(x, np.ndarray) and x.ndim == 2:
        return [np.array(x, dtype=np.float64)]
    return [np.array(p, dtype=np.float64) for p in x]


def energy(polygons: Sequence[np.ndarray]) -> float:
    """Möbius energy of one polygon, or one total of a link (components and their cross
    energy, as ``core.moebius_energy``).

    Parameters
    ----------
    polygons : sequence of (n_i, 3) arrays

    Returns
    -------
    float
    """
    e = core.moebius_energy(_as_input(polygons))
    return float(np.sum(e))


def _set_rest(obj: bpy.types.Object, polygons: Sequence[np.ndarray]) -> None:
    obj.data[_REST] = np.concatenate(polygons).ravel().tolist()


def _rest(obj: bpy.types.Object) -> list[np.ndarray] | None:
    flat = obj.data.get(_REST)
    if flat is None:
        return None
    X = np.asarray(flat, dtype=np.float64).reshape(-1, 3)
    sizes = np.cumsum([len(s.points) for s in obj.data.splines])[:-1]
    if sizes.size and sizes[-1] >= len(X):
        return None
    return np.split(X, sizes)


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
                       close_open: bool = False, allow_large: bool = False) -> list[np.ndarray]:
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
    allow_large : bool
        Accept more than :data:`EDGE_LIMIT` edges in total.

    Returns
    -------
    list of (n_i, 3) float64 arrays
        Equilateral polygons, one per component, in object coordinates.

    Raises
    ------
    ValueError
        With the reason and the fix: unsupported object, open spline, fewer than 4 points,
        too many edges, a polygon that touches itself.
    """
    polylines = geometry.object_polylines(obj)
    many = len(polylines) > 1
    cleaned = []
    for k, (points, closed) in enumerate(polylines):
        where = f"'{obj.name}'" + (f" (component {k + 1} of {len(polylines)})" if many else "")
        if not closed and not close_open:
            raise ValueError(
                f"{where} is an open curve; close it (Edit Mode: Alt+C, or F on the end "
                "vertices of a mesh) or enable 'Close open splines'"
            )
        points = np.asarray(points, np.float64)
        # Blender keeps points in single precision and stores an infinity typed in the UI as
        # ±3.4e38 (its float limit): coordinates that large are infinite ones
        bad = ~(np.abs(points) < _FLOAT_LIMIT).all(axis=1)
        if bad.any():
            raise ValueError(
                f"{where} has NaN or infinite coordinates ({int(bad.sum())} of its "
                f"{len(points)} points, the first at index {int(np.flatnonzero(bad)[0])}; "
                "Blender shows an infinite one as ±3.4e38); fix or delete those points"
            )
        points = _dedupe(points, closed=True)
        if len(points) < 4:
            raise ValueError(
                f"{where} has only {len(points)} distinct points; a closed curve to relax needs "
                "at least 4 (subdivide it or draw more points)"
            )
        try:  # the drawn curve itself must not touch itself (resampling could hide it)
            core.check_polygon(points, coarseness=False)
        except ValueError as err:
            raise ValueError(f"{where}: {err}") from None
        cleaned.append(points)
    lengths = [float(np.linalg.norm(np.diff(np.vstack([p, p[:1]]), axis=0), axis=1).sum())
               for p in cleaned]
    if edge_length is not None:
        if not edge_length > 0:
            raise ValueError(f"edge length must be positive, got {edge_length}")
        counts = [max(4, round(L / edge_length)) for L in lengths]
    else:
        if int(edges) < 4:
            raise ValueError(f"{edges} edges is too few; a closed polygon needs at least 4")
        counts = [int(edges)] * len(cleaned)
    few = core.polygon.MIN_CHECKED_VERTICES
    if min(counts) < few:
        raise ValueError(
            f"'{obj.name}': {min(counts)} edges per component is too few: below {few} the "
            "start check cannot see strands that come too close, and a knot can come out "
            f"unknotted (the trefoil at 5 to 7 edges did); use at least {few}"
            + (" or a shorter edge length" if edge_length is not None else "")
        )
    total = sum(counts)
    if total > EDGE_LIMIT and not allow_large:
        raise ValueError(
            f"{total} edges is too many: the energy couples every pair of edges, so time and "
            f"memory per iteration grow as N² (10× the edges ≈ 100× slower). Use at most "
            f"{EDGE_LIMIT} edges (a few hundred are plenty to untangle a knot)"
            + (" or a longer edge length" if edge_length is not None else "")
        )
    polygons = [core.resample(p, n, closed=True) for p, n in zip(cleaned, counts, strict=True)]
    try:
        core.check_polygon(_as_input(polygons), coarseness=False)
    except ValueError as err:
        raise ValueError(f"'{obj.name}' after resampling to {counts} edges: {err}") from None
    if core.contact_ratio(_as_input(polygons)) < core.polygon.CONTACT_RATIO:
        raise ValueError(f"'{obj.name}' is too coarse at {counts} edges for its shape: strands "
                         f"far apart along the curve come closer than one edge length, and the "
                         f"energy cannot keep them apart — "
                         f"{_finer_conversion(cleaned, counts, edge_length)}")
    return polygons


def _finer_conversion(cleaned, counts, edge_length) -> str:
    """The fix for a too coarse conversion, in the unit of the field the user set: the
    smallest count per component (or the largest edge length) in 10% steps that passes the
    contact check, or a plain advice when none does up to EDGE_LIMIT edges."""
    factor = 1.1
    while sum(counts) * factor <= EDGE_LIMIT:
        finer = [max(4, int(np.ceil(n * factor))) for n in counts]
        polygons = [core.resample(p, n, closed=True) for p, n in zip(cleaned, finer, strict=True)]
        if core.contact_ratio(_as_input(polygons)) >= core.polygon.CONTACT_RATIO:
            if edge_length is not None:
                return f"use an edge length of at most {edge_length / factor:.4g}"
            return f"use at least {finer[0]} edges per component (the Edges field)"
        factor *= 1.1
    return f"move the strands apart; no conversion up to {EDGE_LIMIT} edges resolves them"


def _link_like(new: bpy.types.Object, like: bpy.types.Object | None,
               context: bpy.types.Context) -> None:
    collections = list(like.users_collection) if like is not None else []
    if not collections:
        collections = [context.collection or context.scene.collection]
    for coll in collections:
        coll.objects.link(new)


def _deselect_all(context: bpy.types.Context) -> None:
    for o in context.view_layer.objects:
        if o is not None and o.select_get():
            o.select_set(False)


def _copy_transform(src: bpy.types.Object, dst: bpy.types.Object) -> None:
    """Copy parent and transform channels exactly (no round trip through a matrix)."""
    dst.parent = src.parent
    dst.parent_type = src.parent_type
    dst.matrix_parent_inverse = src.matrix_parent_inverse.copy()
    dst.rotation_mode = src.rotation_mode
    for attr in ("location", "rotation_euler", "rotation_quaternion", "rotation_axis_angle",
                 "scale", "delta_location", "delta_rotation_euler",
                 "delta_rotation_quaternion", "delta_scale"):
        setattr(dst, attr, getattr(src, attr))


def _select_only(context: bpy.types.Context, obj: bpy.types.Object) -> None:
    _deselect_all(context)
    obj.select_set(True)
    context.view_layer.objects.active = obj


def make_curve_object(name: str, polygons: Sequence[np.ndarray],
                      like: bpy.types.Object | None = None,
                      context: bpy.types.Context | None = None) -> bpy.types.Object:
    """Create and select a curve object with one cyclic poly spline per polygon.

    Parameters
    ----------
    name : str
    polygons : sequence of (n_i, 3) arrays
        Vertices in object coordinates.
    like : bpy.types.Object, optional
        Object whose transform, collections and (for curves) bevel and materials are copied.
    context : bpy.types.Context, optional
        Defaults to ``bpy.context``.

    Returns
    -------
    bpy.types.Object
    """
    context = context or bpy.context
    curve = geometry.new_curve(name, polygons)
    if like is not None and like.type == "CURVE":
        src = like.data
        curve.bevel_depth = src.bevel_depth
        curve.bevel_resolution = src.bevel_resolution
        curve.use_fill_caps = src.use_fill_caps
        for mat in src.materials:
            curve.materials.append(mat)
    obj = bpy.data.objects.new(name, curve)
    if like is not None:
        _copy_transform(like, obj)
    _deselect_all(context)
    _link_like(obj, like, context)
    _set_rest(obj, polygons)
    obj[ENERGY_PROP] = energy(polygons)
    obj.select_set(True)
    context.view_layer.objects.active = obj
    return obj


def convert_object(obj: bpy.types.Object, edges: int = 100, edge_length: float | None = None,
                   close_open: bool = False, allow_large: bool = False,
                   context: bpy.types.Context | None = None) -> bpy.types.Object:
    """Make an equal-edge poly curve from ``obj``; the original is kept, hidden.

    Parameters
    ----------
    obj : bpy.types.Object
        Curve (poly, Bezier, NURBS) or mesh made of closed edge loops.
    edges, edge_length, close_open, allow_large
        See :func:`prepare_conversion`.
    context : bpy.types.Context, optional
        Defaults to ``bpy.context``.

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
    polygons = prepare_conversion(obj, edges, edge_length, close_open, allow_large)
    return apply_conversion(obj, polygons, context)


def apply_conversion(obj: bpy.types.Object, polygons: Sequence[np.ndarray],
                     context: bpy.types.Context | None = None) -> bpy.types.Object:
    """Create the converted curve from :func:`prepare_conversion`'s polygons; hide ``obj``."""
    context = context or bpy.context
    new = make_curve_object(f"{obj.name}.moebius", polygons, like=obj, context=context)
    new[_SOURCE] = obj.name
    obj.hide_set(True)
    obj.hide_render = True
    return new


def choose_method(method: str, polygons: Sequence[np.ndarray]) -> tuple[str, str]:
    """The core method a run of ``method`` uses on ``polygons``, and why (empty unless
    ``method`` is :data:`AUTO_METHOD`): :data:`KNOT_METHOD` for one component whose knot
    determinant is above 1 (``core.knot_determinant``: certainly knotted), else
    :data:`EXPLICIT_METHOD` (unknots, links, and the rare knots of determinant 1)."""
    if method != AUTO_METHOD:
        return method, ""
    if len(polygons) != 1:
        return EXPLICIT_METHOD, f"a link of {len(polygons)} components"
    det = core.knot_determinant(polygons[0])
    if det > 1:
        return KNOT_METHOD, f"knotted, determinant {det}"
    return EXPLICIT_METHOD, "no knot detected"


def method_hint(method: str, result, polygons: Sequence[np.ndarray]) -> str:
    """Advice appended to the report of an explicit run that hit its iteration limit on a
    knotted curve (``polygons``: its start): the explicit flow's last stretch on a knot is
    slow (docs/benchmarks.md, "Knots of the table"). Decided by ``result.status``, never by
    the words of the message; unknots and links get none (the explicit method is the faster
    one on unknots)."""
    if method != EXPLICIT_METHOD or result.status != core.Status.MAX_ITER:
        return ""
    if len(polygons) != 1 or not core.is_knotted(polygons[0]):
        return ""
    label = _METHOD_TEXT[KNOT_METHOD][0]
    return f"; knots settle in fewer iterations with Advanced ▸ Method: {label}"


def acting_settings(method: str) -> frozenset:
    """Names of the ``scene.moebius`` line-search, back-projection and constraint settings
    that reach a run of ``method`` (the panel greys out the others): the Armijo constant and
    the step growth are the explicit method's (the implicit one keeps its own σ = 1e-4 and
    growth 1.5, see ``core.solvers``), the back-projection and constraint toggles belong to the
    methods that keep the constraints, the penalty weight to the penalty methods."""
    if method in PENALTY_METHODS:
        return frozenset({"penalty"})
    # the automatic choice passes them on to the explicit method (unknots and links)
    own = {"armijo", "growth"} if method in (EXPLICIT_METHOD, AUTO_METHOD) else set()
    return frozenset(own | {"backproject_iter", "backproject_digits", "keep_edge_lengths",
                            "keep_barycenter"})


def relax_settings(settings) -> dict:
    """Keyword arguments for :func:`relax_object` from the ``scene.moebius`` settings: those
    every method takes, and of the others only those that act on the chosen method
    (:func:`acting_settings`)."""
    method = settings.method
    acting = acting_settings(method)
    kwargs = dict(
        metric=settings.metric,
        method=method,
        max_iterations=settings.max_iterations,
        tolerance=settings.tolerance,
        frame_start=settings.frame_start,
        keyframe_stride=settings.keyframe_stride,
        initial_step=settings.initial_step,
    )
    if "armijo" in acting:
        kwargs["armijo"] = settings.armijo
    if "growth" in acting:
        kwargs["growth"] = settings.growth
    if "penalty" in acting:
        kwargs["penalty"] = settings.penalty
    if "backproject_iter" in acting:
        kwargs.update(
            backproject_iter=settings.backproject_iter,
            backproject_tol=10.0 ** -settings.backproject_digits,
            edge_lengths=settings.keep_edge_lengths,
            barycenter=settings.keep_barycenter,
        )
    if settings.use_energy_target:
        kwargs["energy_target"] = settings.energy_target
    if settings.max_seconds > 0:
        kwargs["max_seconds"] = settings.max_seconds
    return kwargs


def check_relax_options(max_iterations, tolerance, keyframe_stride, frame_start,
                        method: str = DEFAULT_METHOD, penalty: float | None = None):
    """The relax options checked under this layer's names (the core would say max_iter, tol):
    ``(max_iterations, tolerance, keyframe_stride, frame_start, method options)``, or
    ValueError. Every door (operator, script, command line) calls this before any work."""
    max_iterations = core.check_number("max_iterations", max_iterations, 0, integer=True)
    tolerance = core.check_number("tolerance", tolerance, 0)
    keyframe_stride = core.check_number("keyframe_stride", keyframe_stride, 1, integer=True)
    frame_start = core.check_number("frame_start", frame_start, integer=True)
    return max_iterations, tolerance, keyframe_stride, frame_start, _check_method(method, penalty)


def knot_names() -> list[str]:
    """Every name :func:`knot_polygons` takes: the generators, then the knot table."""
    from ..core import knots

    return [*_KNOT_MAKERS, *knots.names()]


_KNOT_MAKERS = ("fhw", "helix", "random", "torus", "circle", "figure_eight")


def check_knot(kind: str, n: int | None = None) -> None:
    """ValueError for a name :func:`knot_polygons` does not know (listing those it does) or
    more edges than a run takes (``EDGE_LIMIT``): the same refusal in every door, before any
    work."""
    if kind not in knot_names():
        raise ValueError(f"unknown knot '{kind}'; choose one of {', '.join(knot_names())}")
    if n and int(n) > EDGE_LIMIT:
        raise ValueError(f"{int(n)} edges is too many: runs above {EDGE_LIMIT} edges are "
                         f"refused (the cost per iteration grows as N²); use at most "
                         f"{EDGE_LIMIT} (a few hundred are plenty to untangle a knot)")


def _check_method(method: str, penalty: float | None) -> dict:
    """Validate ``method`` and ``penalty``; the extra options for ``core.make_run``."""
    if method not in (AUTO_METHOD, *core.METHODS):
        raise ValueError(f"unknown method '{method}'; choose one of "
                         f"{', '.join((AUTO_METHOD, *core.METHODS))}")
    if method not in PENALTY_METHODS:
        if penalty is not None:
            raise ValueError(
                f"a penalty weight applies only to the penalty methods "
                f"({', '.join(PENALTY_METHODS)}); method '{method}' keeps the edge lengths "
                f"exactly, so leave penalty unset"
            )
        return {}
    alpha = DEFAULT_PENALTY if penalty is None else penalty
    try:
        alpha = float(alpha)
    except (TypeError, ValueError):
        alpha = float("nan")
    if not (np.isfinite(alpha) and alpha > 0):
        raise ValueError(
            f"penalty weight must be a positive, finite number, got {penalty!r}; the default "
            f"is {DEFAULT_PENALTY:g} (larger keeps the edge lengths closer to their start)"
        )
    return {"alpha": alpha}


def solver_warm() -> bool:
    """Whether a relaxation has reached its first iterate in this session, so that the
    numerical kernels are ready (False: the next run prepares them first, see
    :attr:`ObjectRelaxation.first_run`)."""
    return _SESSION["warm"]


class ObjectRelaxation:
    """A relaxation of one curve object, stepped by a caller that may stop it at any time.

    The modal operator steps it on a timer; :func:`relax_object` steps it in a loop. The start
    and every ``keyframe_stride``-th accepted iterate (and always the last) are recorded and
    keyframed by :meth:`finish`.

    Parameters
    ----------
    obj : bpy.types.Object
        Curve of cyclic poly splines (see :func:`convert_object`); its shape at the current frame
        is the start. Earlier flow keyframes on it are replaced by this run's when it finishes.
    metric : str
        ``"hs"``, ``"hs_pure"``, ``"h2"``, ``"h1"`` or ``"l2"``.
    max_iterations : int
    tolerance : float
        Stop once the gradient norm in the metric is this small (``tol`` of ``core.relax``;
        projected onto the constraints for the feasible methods).
    frame_start : int
        Frame of the start shape.
    keyframe_stride : int
        Keyframe every this many iterates (1 = all).
    append : bool
        Continue the flow keyed on ``obj``: start from its last keyed iterate and key the new
        iterates on the frames after it, keeping the earlier keys (``frame_start`` is not
        used then). Without flow keys on ``obj`` this is a new run from the current shape.
    method : str
        ``"auto"`` (default; :func:`choose_method` decides from the start, the attributes
        ``method`` and ``why`` say what ran) or one of ``core.METHODS`` (run by
        ``core.make_run``); ``requested`` keeps what was asked.
    penalty : float, optional
        Weight α of the edge-stretch penalty, for the penalty methods ``"ncg"``, ``"lbfgs"``
        and ``"nesterov"`` only (None: the core's default, 1e4); positive and finite.
    **options
        Passed on to the core's run (``initial_step``, ``armijo``, ``growth``,
        ``backproject_iter``, ``backproject_tol``, ``edge_lengths``, ``barycenter``,
        ``energy_target``, ``ftol``, ``max_seconds``, and the method's own options); the
        penalty methods ignore the options that need hard constraints.

    Raises
    ------
    ValueError
        If the curve is not a closed poly curve, the core refuses it (touching itself, ...), or
        the method or penalty is invalid; nothing is changed then.
    """

    def __init__(self, obj: bpy.types.Object, metric: str = "hs", max_iterations: int = 200,
                 tolerance: float = 1e-6, frame_start: int = 1, keyframe_stride: int = 1,
                 method: str = DEFAULT_METHOD, penalty: float | None = None,
                 append: bool = False, **options) -> None:
        self.t0 = time.perf_counter()
        #: the first run of the session: it prepares the solver before its first iterate
        self.first_run = not _SESSION["warm"]
        #: seconds from the set-up to the first iterate (None before it)
        self.seconds_to_first: float | None = None
        max_iterations, tolerance, keyframe_stride, frame_start, extra = check_relax_options(
            max_iterations, tolerance, keyframe_stride, frame_start, method, penalty)
        options.update(extra)
        polygons = geometry.curve_polygons(obj)
        self._shown = [p.copy() for p in polygons]  # the shape at the current frame
        self._cuts = np.cumsum([len(p) for p in polygons])[:-1]
        # the earlier flow keys, continued from their last iterate (read by show() otherwise)
        self._prior = keyframes.read_flow_keyframes(obj) if append else None
        if self._prior is not None:
            frames, points, _ = self._prior
            polygons = np.split(points[-1], self._cuts)
            frame_start = int(frames[-1])
        total = sum(len(p) for p in polygons)
        if total > EDGE_LIMIT and not options.pop("allow_large", False):
            raise ValueError(
                f"'{obj.name}' has {total} edges; the cost per iteration grows as N², so runs "
                f"above {EDGE_LIMIT} edges are refused. Convert it again with fewer edges"
            )
        options.pop("allow_large", None)
        try:
            core.check_polygon(_as_input(polygons))
        except ValueError as err:
            raise ValueError(f"'{obj.name}': {err}") from None
        options.setdefault("target_lengths", "keep")
        self.obj = obj
        #: the method asked for (may be ``"auto"``), the core method run, and why
        self.requested = method
        self.method, self.why = choose_method(method, polygons)
        if method == AUTO_METHOD and self.method != EXPLICIT_METHOD:
            # the panel's Armijo constant and step growth are the explicit method's; the
            # implicit one keeps its own (core.solvers), but bad values are refused all the same
            core.solvers.projected.check_line_search(options.pop("armijo", 0.5),
                                                     options.pop("growth", 8.0))
        self.append = self._prior is not None
        self.frame_start = int(frame_start)
        self.stride = int(keyframe_stride)
        # make_run("projected_gradient", ...) is core.Relaxation itself: the default is the
        # same run as before methods existed
        self.run = core.make_run(self.method, _as_input(polygons), metric=metric,
                                 max_iter=max_iterations, tol=tolerance, **options)
        self.start = [p.copy() for p in polygons]
        self.x = [p.copy() for p in polygons]
        self.energy = float(np.sum(self.run.energy))
        self.nit = 0
        self.iterates = [self.start]
        self.energies = [self.energy]
        self._pending = None
        # the earlier run's keys stay until this run's are written (finish), so that a run
        # that fails before its first iterate leaves them; live display removes them first
        self._live = False

    def step(self) -> bool:
        """Advance by one accepted iterate; False once the run has finished."""
        before = self.run.nit
        more = self.run.step()
        if self.run.nit > before:  # an accepted iterate (the last one may come with False)
            if self.seconds_to_first is None:
                self.seconds_to_first = time.perf_counter() - self.t0
                _SESSION["warm"] = True
            self.nit += 1
            x = _as_link(self.run.x)
            self.x = x
            self.energy = float(np.sum(self.run.energy))
            if self.nit % self.stride == 0:
                self.iterates.append(x)
                self.energies.append(self.energy)
                self._pending = None
            else:
                self._pending = (x, self.energy)
        return more

    def stop(self, message: str) -> None:
        """Stop the run (e.g. the user pressed Esc); :meth:`finish` still keyframes it."""
        self.run.stop(message)

    def show(self) -> None:
        """Put the current iterate on the curve (for live display while running; the earlier
        run's keys are removed at the first call, or they would pull the curve back)."""
        if not self._live:
            if self._prior is None:  # kept to be put back by restore() after a failure
                try:
                    self._prior = keyframes.read_flow_keyframes(self.obj)
                except ValueError:  # keys edited by hand: a new run replaces them anyway
                    pass
            keyframes.remove_flow_keyframes(self.obj)
            self._live = True
        geometry.write_polygons(self.obj.data, self.x)

    def restore(self) -> None:
        """Undo :meth:`show` after a failure: the earlier flow keys (removed for the live
        display) written back and the curve as it was shown before the run."""
        if self._live and self._prior is not None:
            frames, points, energies = self._prior
            keyframes.write_flow_keyframes(self.obj, [np.split(X, self._cuts) for X in points],
                                           list(energies), int(frames[0]))
        geometry.write_polygons(self.obj.data, self._shown)

    def finish(self, scene: bpy.types.Scene | None = None):
        """Keyframe the recorded iterates and return the core's result.

        Grows the scene frame range to include the keyed frames (it never shrinks it: other
        animation may need the rest), jumps to the last one and stores the statistics in
        ``scene.moebius`` (when the add-on is registered).

        Returns
        -------
        result
            The core run's ``result()`` (``x``, ``fun``, ``nit``, ``success``, ``message``,
            ``history``; the penalty methods' history also has ``penalized_energy``).
        """
        scene = scene or bpy.context.scene
        result = self.run.result()
        if self._pending is not None:
            self.iterates.append(self._pending[0])
            self.energies.append(self._pending[1])
            self._pending = None
        iterates, energies, first = self.iterates, self.energies, self.frame_start
        if self.append:  # the earlier keys, then this run's from the last of them on
            frames0, points, energies0 = self._prior
            iterates = [np.split(X, self._cuts) for X in points[:-1]] + iterates
            energies = list(energies0[:-1]) + energies
            first = int(frames0[0])
        else:
            _set_rest(self.obj, self.start)
        # the curve's own (unanimated) shape: the rest shape Clear Flow goes back to
        rest = _rest(self.obj)
        geometry.write_polygons(self.obj.data, iterates[0] if rest is None else rest)
        frames = keyframes.write_flow_keyframes(self.obj, iterates, energies, first)
        scene.frame_start = min(scene.frame_start, frames.start)
        scene.frame_end = max(scene.frame_end, frames.stop - 1)
        scene.frame_set(frames.stop - 1)
        refresh_gradients(self.obj)  # drawn at the start, they would show a stale field
        stats = getattr(scene, "moebius", None)
        if stats is not None:
            stats.store_run(self.obj.name, self.nit, self.energies[0], self.energies[-1],
                            time.perf_counter() - self.t0, str(result.message), len(frames),
                            self.method)
        return result


def relax_object(obj: bpy.types.Object, *, metric: str = "hs", max_iterations: int = 200,
                 tolerance: float = 1e-6, frame_start: int = 1, keyframe_stride: int = 1,
                 method: str = DEFAULT_METHOD, penalty: float | None = None,
                 append: bool = False, callback: Callable | None = None,
                 scene: bpy.types.Scene | None = None, **options):
    """Relax a converted curve by the Möbius-energy flow and keyframe its iterates (every
    ``keyframe_stride``-th and the last).

    Parameters
    ----------
    obj : bpy.types.Object
        Curve of cyclic poly splines (see :func:`convert_object`).
    metric, max_iterations, tolerance, frame_start, keyframe_stride, append, **options
        See :class:`ObjectRelaxation`; ``append=True`` continues the flow keyed on ``obj``.
    method : str
        ``"auto"`` (default: :func:`choose_method` picks the implicit gradient for a knotted
        curve, the paper's explicit projected gradient for unknots and links) or one of
        ``core.METHODS``.
    penalty : float, optional
        Penalty weight α of ``"ncg"``, ``"lbfgs"``, ``"nesterov"`` (None: 1e4); refused for
        the other methods.
    callback : callable, optional
        ``callback(run)`` after every accepted iterate, the last one included, with the
        :class:`ObjectRelaxation` (``run.nit``, ``run.x``, ``run.energy``); returning True stops
        the run cleanly.
    scene : bpy.types.Scene, optional
        Scene whose frame range grows to include the flow; defaults to ``bpy.context.scene``.

    Returns
    -------
    result
        The core's result object (``x``, ``fun``, ``nit``, ``success``, ``message``,
        ``history``).

    Raises
    ------
    ValueError
        If the curve cannot be relaxed or the method or penalty is invalid; nothing is changed
        then.
    BaseException
        Whatever interrupts the run (Ctrl+C, a failing callback) passes through, after the
        iterates computed so far are keyed (or, before the first one, the earlier animation is
        left as it was); a note on the exception says which.
    """
    run = ObjectRelaxation(obj, metric=metric, max_iterations=max_iterations, tolerance=tolerance,
                           frame_start=frame_start, keyframe_stride=keyframe_stride,
                           method=method, penalty=penalty, append=append, **options)
    more = True
    try:
        while more:
            before = run.nit
            more = run.step()
            # every accepted iterate reaches the callback, the last one of the run included (as
            # in core.relax); a True returned for the last one changes nothing
            if run.nit > before and callback is not None and callback(run):
                run.stop("stopped by callback")
                break
    except BaseException as err:  # Ctrl+C in a script, a failing callback: keep the work
        if run.nit == 0:
            err.add_note(f"moebius: no iterate was computed; the earlier animation of "
                         f"'{obj.name}' is kept")
        else:
            run.stop(f"interrupted by {type(err).__name__}")
            run.finish(scene)
            err.add_note(f"moebius: the {run.nit} iterates computed before the interruption "
                         f"are keyed on '{obj.name}' from frame {run.frame_start}")
        raise
    return run.finish(scene)


def clear_animation(obj: bpy.types.Object) -> None:
    """Remove the flow keyframes of ``obj`` and put the curve back to the start of the last run.

    Parameters
    ----------
    obj : bpy.types.Object
        A curve relaxed by :func:`relax_object`.
    """
    keyframes.remove_flow_keyframes(obj)
    rest = _rest(obj)
    if rest is not None:
        geometry.write_polygons(obj.data, rest)
        obj[ENERGY_PROP] = energy(rest)
    refresh_gradients(obj)


def apply_frame(obj: bpy.types.Object, frame: int | None = None,
                scene: bpy.types.Scene | None = None) -> list[np.ndarray]:
    """Make the shape at ``frame`` (default: the current frame) the curve's new rest shape.

    The flow keyframes are removed; a later relaxation starts from this shape.

    Returns
    -------
    list of (n_i, 3) arrays
        The new rest polygons.
    """
    scene = scene or bpy.context.scene
    if frame is not None:
        scene.frame_set(frame)
    polygons = geometry.curve_polygons(obj)
    keyframes.remove_flow_keyframes(obj)
    geometry.write_polygons(obj.data, polygons)
    _set_rest(obj, polygons)
    obj[ENERGY_PROP] = energy(polygons)
    refresh_gradients(obj)
    return polygons


def knot_polygons(kind: str, n: int | None = None, p: int = 2, q: int = 3,
                  seed: int = 0) -> list:
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

    Returns
    -------
    list of (n_i, 3) float64 arrays
    """
    from ..core import knots

    check_knot(kind, n)
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
        link = _as_link(makers[kind]())
    else:
        link = _as_link(knots.named(kind, n))
    out = []
    for P in link:
        e = np.linalg.norm(np.roll(P, -1, axis=0) - P, axis=1)
        out.append(P if np.ptp(e) <= 1e-9 * e.mean() else core.resample(P, len(P), closed=True))
    try:
        core.check_polygon(_as_input(out))
    except ValueError as err:
        raise ValueError(f"knot '{kind}' with {n or 'default'} edges: {err}") from None
    return out


def add_knot(kind: str = "fhw", n: int | None = None, p: int = 2, q: int = 3, seed: int = 0,
             size: float = 2.0, location: Sequence[float] = (0.0, 0.0, 0.0),
             context: bpy.types.Context | None = None) -> bpy.types.Object:
    """Add a catalogue knot as a curve object ready to relax.

    Parameters
    ----------
    kind, n, p, q, seed
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
    polygons = knot_polygons(kind, n, p, q, seed)
    X = np.concatenate(polygons)
    centre = X.mean(axis=0)
    scale = size / max(float(np.ptp(X, axis=0).max()), 1e-300)
    polygons = [(P - centre) * scale for P in polygons]
    label = {"torus": f"torus {p},{q}", "random": f"random {seed}"}.get(kind, kind)
    obj = make_curve_object(f"Knot {label}", polygons, context=context)
    obj.location = location
    obj.data.bevel_depth = 0.01 * size
    return obj


_GRADIENT_COLOURS = {"l2": (0.9, 0.2, 0.15, 1.0), "hs_pure": (0.2, 0.7, 0.2, 1.0),
                     "hs": (0.15, 0.35, 0.9, 1.0), "h1": (0.8, 0.6, 0.1, 1.0),
                     "h2": (0.6, 0.2, 0.8, 1.0)}


def show_gradients(obj: bpy.types.Object, metrics: Sequence[str] = ("l2", "hs_pure", "hs"),
                   length: float = 0.15, projected: bool = True,
                   context: bpy.types.Context | None = None) -> list[bpy.types.Object]:
    """Draw energy gradients of a curve as vector fields (the paper's Fig. 2).

    For each metric a mesh object ``"<curve>.grad.<metric>"`` is made with one edge per vertex,
    from the vertex along the gradient. Each field is scaled on its own so that its longest
    arrow is ``length`` times the curve's bounding-box diagonal (the fields differ by orders of
    magnitude); the factor is stored as ``["moebius_arrow_scale"]``. Earlier fields of the same
    curve and metric are replaced. The fields show the shape they were drawn at; a relaxation,
    *Clear Flow* and *Apply Frame* redraw them at the shape they leave (:func:`refresh_gradients`).

    Parameters
    ----------
    obj : bpy.types.Object
        Curve of cyclic poly splines.
    metrics : sequence of str
        Metric names of ``core.sobolev_gradient``.
    length : float
        Longest arrow as a fraction of the bounding-box diagonal.
    projected : bool
        Project onto the constraints' tangent space (what the flow uses).
    context : bpy.types.Context, optional

    Returns
    -------
    list of bpy.types.Object
        The gradient objects, parented to ``obj``.
    """
    context = context or bpy.context
    polygons = geometry.curve_polygons(obj)
    try:  # NaN or a self-intersection would give NaN arrows; coarseness is no obstacle here
        core.check_polygon(_as_input(polygons), coarseness=False)
    except ValueError as err:
        raise ValueError(f"'{obj.name}': {err}") from None
    X = np.concatenate(polygons)
    diagonal = float(np.linalg.norm(np.ptp(X, axis=0)))
    out = []
    for metric in metrics:
        G = np.concatenate(_as_link(core.sobolev_gradient(_as_input(polygons), metric=metric,
                                                          projected=projected)))
        longest = float(np.linalg.norm(G, axis=1).max())
        scale = length * diagonal / longest if longest > 0 else 0.0
        name = f"{obj.name}.grad.{metric}"
        old = bpy.data.objects.get(name)
        if old is not None:
            mesh_old = old.data
            bpy.data.objects.remove(old)
            if mesh_old.users == 0:
                bpy.data.meshes.remove(mesh_old)
        mesh = bpy.data.meshes.new(name)
        n = len(X)
        mesh.from_pydata(np.vstack([X, X + scale * G]).tolist(),
                         np.column_stack([np.arange(n), np.arange(n) + n]).tolist(), [])
        mesh.update()
        arrows = bpy.data.objects.new(name, mesh)
        _link_like(arrows, obj, context)
        arrows.parent = obj
        arrows.matrix_parent_inverse.identity()
        arrows.color = _GRADIENT_COLOURS.get(metric, (1, 1, 1, 1))
        arrows["moebius_gradient"] = metric
        arrows["moebius_arrow_scale"] = scale
        arrows["moebius_arrow_length"] = length
        arrows["moebius_projected"] = bool(projected)
        out.append(arrows)
    return out


def refresh_gradients(obj: bpy.types.Object,
                      context: bpy.types.Context | None = None) -> list[bpy.types.Object]:
    """Redraw the gradient fields of ``obj`` (:func:`show_gradients`) at its current shape,
    with the metrics, length and projection they were drawn with; a field that cannot be drawn
    there any more (the shape touches itself) is removed rather than left stale.

    Returns
    -------
    list of bpy.types.Object
        The redrawn fields (empty when ``obj`` has none).
    """
    fields = [c for c in obj.children if "moebius_gradient" in c]
    if not fields:
        return []
    metrics = [c["moebius_gradient"] for c in fields]
    length = float(fields[0].get("moebius_arrow_length", 0.15))
    projected = bool(fields[0].get("moebius_projected", True))
    try:
        return show_gradients(obj, metrics, length=length, projected=projected, context=context)
    except ValueError:
        for c in fields:
            mesh = c.data
            bpy.data.objects.remove(c)
            if mesh.users == 0:
                bpy.data.meshes.remove(mesh)
        return []


def export_suffix(filepath: str | Path) -> str:
    """The lower-case suffix of an export path :func:`export_flow` can write, else ValueError."""
    suffix = Path(filepath).suffix.lower()
    if suffix not in (".abc", ".usd", ".usda", ".usdc", ".usdz"):
        raise ValueError(f"unknown export format '{suffix}' ({filepath}); use .abc or "
                         ".usd/.usda/.usdc/.usdz")
    return suffix


def export_flow(obj: bpy.types.Object, filepath: str | Path,
                scene: bpy.types.Scene | None = None,
                frame_range: tuple[int, int] | None = None) -> Path:
    """Export the keyframed curve over its own keyed frames as Alembic or USD.

    The centre line is exported (one cyclic linear curve per spline, positions sampled on every
    frame); the bevel, which Blender 5.0's exporters would write as a second curve object, is
    switched off for the export and restored afterwards.

    Parameters
    ----------
    obj : bpy.types.Object
        The relaxed curve; only it is exported.
    filepath : str or Path
        ``.abc`` for Alembic, ``.usd``/``.usda``/``.usdc``/``.usdz`` for USD.
    scene : bpy.types.Scene, optional
    frame_range : (int, int), optional
        First and last frame to export; default: the frames the flow keyed on ``obj`` (the
        scene's range only where it has none). The scene's own range is left as it was.

    Returns
    -------
    Path
    """
    scene = scene or bpy.context.scene
    path = Path(filepath)
    suffix = export_suffix(path)
    if frame_range is None:
        frames = keyframes.keyed_frames(obj)
        frame_range = ((min(frames), max(frames)) if frames
                       else (scene.frame_start, scene.frame_end))
    start, end = (int(f) for f in frame_range)
    if end < start:
        raise ValueError(f"frame_range must run forward, got {frame_range}")
    path.parent.mkdir(parents=True, exist_ok=True)
    selected = [o for o in bpy.context.view_layer.objects if o.select_get()]
    active = bpy.context.view_layer.objects.active
    _select_only(bpy.context, obj)
    frame = scene.frame_current
    scene_range = scene.frame_start, scene.frame_end
    bevel = obj.data.bevel_depth
    obj.data.bevel_depth = 0.0
    try:
        if suffix == ".abc":
            bpy.ops.wm.alembic_export(filepath=str(path), start=start, end=end, selected=True)
        else:  # the USD exporter takes the scene's range
            scene.frame_start, scene.frame_end = start, end
            bpy.ops.wm.usd_export(filepath=str(path), export_animation=True,
                                  selected_objects_only=True)
    finally:
        scene.frame_start, scene.frame_end = scene_range
        obj.data.bevel_depth = bevel
        obj.select_set(False)
        for o in selected:
            o.select_set(True)
        bpy.context.view_layer.objects.active = active
        scene.frame_set(frame)
    return path
