"""Export of the keyed flow as Alembic or USD."""

from __future__ import annotations

from pathlib import Path

import bpy
import numpy as np

from . import geometry, keyframes
from .objects import select_only


def export_suffix(filepath: str | Path) -> str:
    """The lower-case suffix of an export path :func:`export_flow` can write, else ValueError."""
    suffix = Path(filepath).suffix.lower()
    if suffix not in (".abc", ".usd", ".usda", ".usdc", ".usdz"):
        raise ValueError(f"unknown export format '{suffix}' ({filepath}); use .abc or "
                         ".usd/.usda/.usdc/.usdz")
    return suffix


def export_flow(obj, filepath: str | Path,
                scene: bpy.types.Scene | None = None,
                frame_range: tuple[int, int] | None = None) -> Path:
    """Export the keyframed curve over its own keyed frames as Alembic or USD.

    The centre line is exported (one cyclic linear curve per spline, positions sampled on every
    frame); the bevel, which Blender 5.0's exporters would write as a second curve object, is
    switched off for the export and restored afterwards. The exporters read the curve's points,
    not its shape keys: for a flow keyed as shape keys (large curves, see :mod:`.keyframes`)
    the points follow the keys' mix while the export runs and are put back afterwards.

    Parameters
    ----------
    obj : bpy.types.Object or sequence of them
        The relaxed curve, or the curves relaxed together; only they are exported.
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
    objs = [obj] if isinstance(obj, bpy.types.Object) else list(obj)
    path = Path(filepath)
    suffix = export_suffix(path)
    if frame_range is None:
        frames = sorted({f for o in objs for f in keyframes.keyed_frames(o)})
        frame_range = ((min(frames), max(frames)) if frames
                       else (scene.frame_start, scene.frame_end))
    start, end = (int(f) for f in frame_range)
    if end < start:
        raise ValueError(f"frame_range must run forward, got {frame_range}")
    path.parent.mkdir(parents=True, exist_ok=True)
    selected = [o for o in bpy.context.view_layer.objects if o.select_get()]
    active = bpy.context.view_layer.objects.active
    select_only(bpy.context, objs[0])
    for o in objs[1:]:
        o.select_set(True)
    frame = scene.frame_current
    scene_range = scene.frame_start, scene.frame_end
    bevels = [o.data.bevel_depth for o in objs]
    follows = [_points_follow_shape_keys(o) for o in objs]
    for o in objs:
        o.data.bevel_depth = 0.0
    try:
        if suffix == ".abc":
            bpy.ops.wm.alembic_export(filepath=str(path), start=start, end=end, selected=True)
        else:  # the USD exporter takes the scene's range
            scene.frame_start, scene.frame_end = start, end
            bpy.ops.wm.usd_export(filepath=str(path), export_animation=True,
                                  selected_objects_only=True)
    finally:
        for follow in follows:
            follow()
        scene.frame_start, scene.frame_end = scene_range
        for o, bevel in zip(objs, bevels, strict=True):
            o.data.bevel_depth = bevel
            o.select_set(False)
        for o in selected:
            o.select_set(True)
        bpy.context.view_layer.objects.active = active
        scene.frame_set(frame)
    return path


def _points_follow_shape_keys(obj: bpy.types.Object):
    """For a flow keyed as shape keys, make the curve's points follow the keys on every frame
    change (a handler run before each frame is evaluated, the exporters' included); returns
    the function that stops it and puts the points back."""
    if keyframes.flow_shape_at(obj, 0.0) is None:
        return lambda: None
    below = [p for p, _ in geometry.object_polylines(obj)]  # the points under the keys
    cuts = np.cumsum([len(p) for p in below])[:-1]

    def follow(scene, depsgraph=None):
        X = keyframes.flow_shape_at(obj, scene.frame_current + scene.frame_subframe)
        geometry.write_polygons(obj.data, np.split(X, cuts))

    bpy.app.handlers.frame_change_pre.append(follow)

    def stop():
        bpy.app.handlers.frame_change_pre.remove(follow)
        geometry.write_polygons(obj.data, below)

    return stop
