"""The options of a relaxation: which panel settings act on a method, the settings as keyword
arguments of a run, and the checks every door (operator, script, command line) makes before any
work.

No bpy: ``relax_settings`` reads any object with the attributes of ``scene.moebius``.
"""

from __future__ import annotations

import numpy as np

from .. import core
from .labels import AUTO_METHOD, DEFAULT_METHOD, DEFAULT_PENALTY, EXPLICIT_METHOD, PENALTY_METHODS

#: Above this many edges in total the conversion is refused: each iteration evaluates all
#: N² edge pairs of the energy and solves an N×N system, so ten times the edges cost about a
#: hundred times the time per iteration. ``allow_large=True`` lifts the limit for scripts.
EDGE_LIMIT = 5000


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
    """Keyword arguments for ``relax_object`` from the ``scene.moebius`` settings: those
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
