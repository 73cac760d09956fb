"""Which knot or link a curve object is (``core.identify``), stored on the object; whether a
relaxation kept it."""

from __future__ import annotations

from collections.abc import Sequence

import bpy
import numpy as np

from .. import core
from ..core.compilation.notice import compiling
from . import geometry
from .polygons import as_input
from .progress import Progress, reporter

#: Custom property holding the knot or link type found by :func:`identify_object` (or given by
#: *Add Knot*): a table name ("3_1", "m3_1", "L6a4{0,0}"), a link without its orientation when
#: the orientations share their invariants ("L6a4"), names joined by " | " when several share
#: them, or "" when none has them.
KNOT_TYPE_PROP = "moebius_knot_type"


def object_curves(obj: bpy.types.Object) -> list[np.ndarray]:
    """The closed curves of a curve or edge-loop mesh object as shown (a converted curve at the
    current frame, flow included), in world coordinates: a mirrored object (negative scale)
    shows the mirror image, and that is what is identified.

    ``ValueError`` (with the fix) for objects that are not curves, open splines or chains,
    invalid coordinates and components of fewer than 4 distinct points."""
    try:
        polylines = [(P, True) for P in geometry.curve_polygons(obj)]
    except ValueError:
        polylines = geometry.object_polylines(obj)
    many = len(polylines) > 1
    M = np.array(obj.matrix_world)
    out = []
    for k, (points, closed) in enumerate(polylines):
        where = f"'{obj.name}'" + (f" (component {k + 1} of {len(polylines)})" if many else "")
        if not closed:
            raise ValueError(f"{where} is an open curve, which has no knot type; close it "
                             "(Edit Mode: Alt+C, or F on the end vertices of a mesh)")
        points = np.asarray(points, np.float64)
        geometry.check_finite_points(points, where)
        keep = np.linalg.norm(np.roll(points, -1, axis=0) - points, axis=1) > 0
        points = points[keep]
        if len(points) < 4:
            raise ValueError(f"{where} has only {len(points)} distinct points; a closed curve "
                             "needs at least 4")
        out.append(points @ M[:3, :3].T + M[:3, 3])
    return out


def type_label(result: core.Identification) -> str:
    """What :data:`KNOT_TYPE_PROP` stores for an identification."""
    if result.name:
        return result.name
    if result.link:
        return result.link
    return " | ".join(result.names)


def identify_object(obj: bpy.types.Object, progress: Progress = False) -> core.Identification:
    """Identify the knot or link a curve or edge-loop mesh object shows (``core.identify``) and
    store it on the object (:data:`KNOT_TYPE_PROP`). ``progress``: True prints a line when
    numba compiles the kernels (the first use after installing or updating) and the result; a
    callable receives those lines; False (default): silent.

    Raises ``ValueError`` saying what to fix: not a curve, an open curve, fewer than 4 points,
    a curve that touches itself, or one too tangled to read (relax it first)."""
    say = reporter(progress)
    curves = object_curves(obj)
    try:
        with compiling(say):
            result = core.identify(as_input(curves))
    except ValueError as err:
        raise ValueError(f"'{obj.name}': {err}") from None
    obj[KNOT_TYPE_PROP] = type_label(result)
    if say is not None:
        say(f"'{obj.name}' is {result.message}" if result.names else
            f"'{obj.name}': {result.message}")
    return result


def type_kept(start: Sequence[np.ndarray], end: Sequence[np.ndarray]) -> tuple[bool | None, str]:
    """Whether a run kept the knot type: the same invariants (``core.identify``'s fingerprint)
    before and after. ``(True, "knot type kept: 3_1 (trefoil)")``; ``(None, why)`` when the
    invariants could not be read."""
    try:
        a = core.identify(as_input([np.asarray(p, np.float64) for p in start]))
        b = core.identify(as_input([np.asarray(p, np.float64) for p in end]))
    except ValueError as err:
        return None, f"knot type not checked ({err})"
    what = "link" if a.fingerprint.components > 1 else "knot"
    if a.fingerprint != b.fingerprint:
        return False, (f"the {what}'s invariants changed ({type_label(a) or 'not in the table'}"
                       f" → {type_label(b) or 'not in the table'}): please report this")
    label = (a.message if a.status == core.Match.UNIQUE and a.fingerprint.jones is not None
             else type_label(a) or "not in the table")
    return True, f"{what} type kept: {label} (same invariants before and after)"
