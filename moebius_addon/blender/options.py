"""The options of a relaxation: which panel settings act on a method, the settings as keyword
arguments of a run, and the checks every door (operator, script, command line) makes before any
work.

No bpy: ``relax_settings`` reads any object with the attributes of ``scene.moebius``.
"""

from __future__ import annotations

import numpy as np

from .. import core
from ..core.runs.engine import engine_class
from ..core.tree import moebius as barnes_hut
from .labels import (
    AUTO_METHOD,
    DEFAULT_ENERGY,
    DEFAULT_ENGINE,
    DEFAULT_METHOD,
    DEFAULT_PENALTY,
    ENERGY_PARAMETERS,
    EXPLICIT_METHOD,
    KNOT_METHOD,
    PENALTY_METHODS,
)

#: Most edges in total a run takes where the tree engine serves it (``allow_large=True`` lifts
#: this for scripts). Where the metric is a dense matrix the core's own bound is lower
#: (``core.check_size``: the exact engine, and the metrics the tree holds densely).
EDGE_LIMIT = 100_000


def acting_settings(method: str, engine: str = DEFAULT_ENGINE) -> frozenset:
    """Names of the ``scene.moebius`` line-search, back-projection, constraint and engine
    settings that reach a run of ``method`` on ``engine`` (the panel greys out or hides the
    others): the Armijo constant and the step growth are the explicit method's (the implicit
    one keeps its own σ = 1e-4 and growth 1.5, see ``core.runs.methods``), the back-projection and
    constraint toggles and the thickness belong to the methods that keep the constraints, the
    penalty weight to the penalty methods, θ to the engines that can run the tree ("auto" and
    "tree")."""
    tree = {"theta"} if engine != "exact" else set()
    if method in PENALTY_METHODS:
        return frozenset({"penalty"} | tree)
    # the automatic choice passes them on to the explicit method (unknots)
    own = {"armijo", "growth"} if method in (EXPLICIT_METHOD, AUTO_METHOD) else set()
    return frozenset(own | tree | {"backproject_iter", "backproject_digits",
                                   "keep_edge_lengths", "keep_barycenter", "keep_thickness"})


def energy_settings(settings) -> dict:
    """``energy=`` and its options from the ``scene.moebius`` settings, by the core's records:
    the chosen energy's own parameters (α, β of the tangent-point energy), and each added
    energy's weight (``stiffness``) where it is above 0; as typed (float32 properties)."""
    name = getattr(settings, "energy", DEFAULT_ENERGY)
    out = {"energy": name}
    for record, p in ENERGY_PARAMETERS:
        value = getattr(settings, p.setting, p.default)
        if record.name == name and p in record.parameters:
            out[p.name] = round(value, 6)
        elif p is record.weight and value > 0.0:
            out[p.name] = round(value, 6)
    return out


def relax_settings(settings) -> dict:
    """Keyword arguments for ``relax_object`` from the ``scene.moebius`` settings: those
    every method takes, and of the others only those that act on the chosen method
    (:func:`acting_settings`)."""
    method = settings.method
    acting = acting_settings(method, settings.engine)
    kwargs = dict(
        **energy_settings(settings),
        metric=settings.metric,
        method=method,
        engine=settings.engine,
        max_iterations=settings.max_iterations,
        tolerance=settings.tolerance,
        settle=settings.settle / 100.0,
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
    if "theta" in acting:  # as typed: the float32 property's 0.17499999701976776 is 0.175;
        # 0: the energy's own (None, the core's default for the energy run)
        kwargs["theta"] = round(settings.theta, 6) if settings.theta > 0.0 else None
    if "backproject_iter" in acting:
        kwargs.update(
            backproject_iter=settings.backproject_iter,
            backproject_tol=10.0 ** -settings.backproject_digits,
            edge_lengths=settings.keep_edge_lengths,
            barycenter=settings.keep_barycenter,
        )
    if "keep_thickness" in acting:  # the curves' bevel, or centre lines only
        kwargs["thickness"] = "bevel" if settings.keep_thickness else 0.0
        if settings.keep_thickness and settings.push_apart:
            kwargs["push_apart"] = True
    if getattr(settings, "pin_selected", False):
        kwargs.update(pin_selected=True, pin_tangents=settings.pin_tangents)
    if getattr(settings, "obstacles", None) is not None:
        kwargs.update(obstacles=settings.obstacles, obstacle_weight=settings.obstacle_weight)
    if getattr(settings, "container", None) is not None:
        kwargs.update(container=settings.container, obstacle_weight=settings.obstacle_weight)
    kwargs["refine"] = bool(getattr(settings, "refine", True))
    if kwargs["refine"] and getattr(settings, "max_edges", 0):
        kwargs["max_edges"] = settings.max_edges
    if getattr(settings, "restarts", 0) and "backproject_iter" in acting:  # feasible methods
        kwargs.update(restarts=settings.restarts, seed=settings.seed)
    if getattr(settings, "use_length_target", False):  # the panel's percent, the core's fraction
        kwargs.update(length_target=settings.length_target,
                      length_growth=settings.length_growth / 100.0)
    if settings.use_energy_target:
        kwargs["energy_target"] = settings.energy_target
    if settings.max_seconds > 0:
        kwargs["max_seconds"] = settings.max_seconds
    return kwargs


#: The panel's presets: key -> (label, description, settings of ``scene.moebius``). A preset
#: sets these (the user can change any afterwards); :mod:`.presets` adds what it does to the
#: scene. Relax Knot sets every setting any preset sets back to its default (empty here: the
#: defaults are the properties' own).
PRESETS = {
    "untangle_cables": (
        "Untangle Cables",
        "Open splines kept open, their end points selected and pinned, obstacles from a "
        "collection (Advanced ▸ Obstacles; one named 'Obstacles' is taken if none is set), "
        "the tree's θ 0.3; a thickness set on the curve",
        {"keep_open": True, "close_open": False, "pin_selected": True, "pin_tangents": True,
         "keep_thickness": True,
         "use_length_target": False, "method": EXPLICIT_METHOD, "refine": True,
         "theta": 0.3},
    ),
    "pack_in_volume": (
        "Pack in Volume",
        "Grow the curve to three times its length at 1 % per iteration inside the Container "
        "(Advanced ▸ Container: a closed mesh around the curve); a thickness set on the curve",
        {"use_length_target": True, "length_growth": 1.0, "method": EXPLICIT_METHOD,
         "keep_thickness": True,
         "keep_open": False, "pin_selected": False, "refine": True, "max_iterations": 400},
    ),
    "relax_knot": (
        "Relax Knot",
        "The default settings: a closed knot or link relaxed to its low-energy shape (no "
        "pins, obstacles, container or growth); a thickness set on the curve",
        {},
    ),
}
# Untangle Cables' θ 0.3 (default 0.175): on the 100 cables with the torus its energy and
# gradient err 1.9e-5 / 5.4e-4 against the exact sums (default: 1.4e-6 / 1.0e-4; on knots the
# default errs up to 1e-5 / 7e-4), for 0.86-0.91 s against 1.04-1.20 s per iteration
# (docs/lab/cables-and-obstacles.md, alternated in one run).
#: The settings the presets set: Relax Knot puts each back to its default.
PRESET_SETTINGS = tuple(sorted({k for _, _, d in PRESETS.values() for k in d}
                               | {"obstacles", "container"}))
#: Pack in Volume's Length Target, in multiples of the active curve's length.
PACK_LENGTH_FACTOR = 3.0
#: The thickness a preset gives the curve (bevel depth, the tube's radius), in mean edge
#: lengths: strands the flow keeps about an edge apart stay visibly apart.
BEVEL_EDGES = 0.3


def check_relax_options(max_iterations, tolerance, keyframe_stride, frame_start,
                        method: str = DEFAULT_METHOD, penalty: float | None = None,
                        engine: str = DEFAULT_ENGINE, theta: float | None = None):
    """The relax options checked under this layer's names (the core would say max_iter, tol):
    ``(max_iterations, tolerance, keyframe_stride, frame_start, method options)``, or
    ValueError. Every door (operator, script, command line) calls this before any work.

    The method options are the extra keywords of ``core.make_run``: ``penalty`` of a penalty
    method, ``engine`` and ``theta`` (refused by name as the core would: an engine not in
    ``core.runs.engine.ENGINE_NAMES``, a θ outside (0, 2); None is the core's default θ)."""
    max_iterations = core.check_number("max_iterations", max_iterations, 0, integer=True)
    tolerance = core.check_number("tolerance", tolerance, 0)
    keyframe_stride = core.check_number("keyframe_stride", keyframe_stride, 1, integer=True)
    frame_start = core.check_number("frame_start", frame_start, integer=True)
    extra = _check_method(method, penalty)
    engine_class(engine, 0)  # ValueError naming the engines for an unknown one
    extra.update(engine=engine,
                 theta=None if theta is None else barnes_hut.check_theta(theta))
    return max_iterations, tolerance, keyframe_stride, frame_start, extra


def check_edge_count(n: int, metric: str = "hs", method: str = DEFAULT_METHOD,
                     engine: str = DEFAULT_ENGINE, allow_large: bool = False, *,
                     edge_lengths: bool = True, barycenter: bool = True) -> None:
    """Refuse ``n`` edges in total for a run of ``method`` in ``metric`` on ``engine`` before any
    work: the core's refusal where it holds the metric as a dense matrix (``core.check_size``,
    whose message names the way out; its sizes crash or exhaust the machine), else more than
    :data:`EDGE_LIMIT` edges where the tree serves the run (unless ``allow_large``).

    Raises
    ------
    ValueError
        Also for an unknown metric, method or engine.
    """
    n = int(n)
    # "auto" picks one of two methods by the curve's knot type; both hold the metric alike
    for m in (EXPLICIT_METHOD, KNOT_METHOD) if method == AUTO_METHOD else (method,):
        core.check_size(n, metric, m, engine, edge_lengths=edge_lengths,
                        barycenter=barycenter)
    tree = issubclass(engine_class(engine, n), core.ENGINES["tree"])
    if n > EDGE_LIMIT and not allow_large and tree:
        raise ValueError(
            f"{n} edges are more than a run in Blender takes ({EDGE_LIMIT}, on the tree "
            f"engine, where an iteration at that size takes seconds): use at most {EDGE_LIMIT} "
            f"edges (a few hundred are plenty to untangle a knot)")


def edge_limit(metric: str = "hs", method: str = DEFAULT_METHOD,
               engine: str = DEFAULT_ENGINE) -> int:
    """The most edges :func:`check_edge_count` lets a run of ``method`` in ``metric`` on
    ``engine`` have (the sizes it refuses are all above the sizes it takes)."""
    def takes(n):
        try:
            check_edge_count(n, metric, method, engine)
        except ValueError:
            return False
        return True

    check_edge_count(4, metric, method, engine)  # unknown names refused by name
    lo, hi = 4, EDGE_LIMIT  # takes(lo); the answer is in [lo, hi]
    if takes(hi):
        return hi
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (mid, hi) if takes(mid) else (lo, mid)
    return lo


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
    return {"penalty": alpha}
