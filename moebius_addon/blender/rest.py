"""The rest shape of a relaxed curve (its own, unanimated shape: where *Clear Flow* goes back to)
and the two operations on it, *Clear Flow* and *Apply Frame*."""

from __future__ import annotations

from collections.abc import Sequence

import bpy
import numpy as np

from . import geometry, keyframes
from .gradients import refresh_gradients
from .keyframes import ENERGY_PROP
from .polygons import energy

_REST = "moebius_rest"


def set_rest_shape(obj: bpy.types.Object, polygons: Sequence[np.ndarray]) -> None:
    """Store ``polygons`` as the rest shape of ``obj`` (on its curve data)."""
    obj.data[_REST] = np.concatenate(polygons).ravel().tolist()


def rest_shape(obj: bpy.types.Object) -> list[np.ndarray] | None:
    """The rest shape stored on ``obj``, one array per spline (None without one, or when it no
    longer fits the splines)."""
    flat = obj.data.get(_REST)
    if flat is None:
        return None
    X = np.asarray(flat, dtype=np.float64).reshape(-1, 3)
    sizes = np.cumsum([len(s.points) for s in obj.data.splines])[:-1]
    if sizes.size and sizes[-1] >= len(X):
        return None
    return np.split(X, sizes)


def clear_animation(obj: bpy.types.Object) -> None:
    """Remove the flow keyframes of ``obj`` and put the curve back to the start of the last run.

    Parameters
    ----------
    obj : bpy.types.Object
        A curve relaxed by :func:`relax_object`.
    """
    keyframes.remove_flow_keyframes(obj)
    rest = rest_shape(obj)
    if rest is not None:
        geometry.write_polygons(obj.data, rest)
        obj[ENERGY_PROP] = energy(rest, geometry.curve_closed(obj))
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
    polygons = geometry.curve_polygons(obj, allow_open=True)
    keyframes.remove_flow_keyframes(obj)
    geometry.write_polygons(obj.data, polygons)
    set_rest_shape(obj, polygons)
    obj[ENERGY_PROP] = energy(polygons, geometry.curve_closed(obj))
    refresh_gradients(obj)
    return polygons


