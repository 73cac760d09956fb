"""Objects in the scene: link a new one where another lives, copy a transform, select."""

from __future__ import annotations

import bpy


def link_like(new: bpy.types.Object, like: bpy.types.Object | None,
              context: bpy.types.Context) -> None:
    """Link ``new`` into the collections of ``like`` (else the context's collection)."""
    collections = list(like.users_collection) if like is not None else []
    if not collections:
        collections = [context.collection or context.scene.collection]
    for coll in collections:
        coll.objects.link(new)


def deselect_all(context: bpy.types.Context) -> None:
    for o in context.view_layer.objects:
        if o is not None and o.select_get():
            o.select_set(False)


def copy_transform(src: bpy.types.Object, dst: bpy.types.Object) -> None:
    """Copy parent and transform channels exactly (no round trip through a matrix)."""
    dst.parent = src.parent
    dst.parent_type = src.parent_type
    dst.matrix_parent_inverse = src.matrix_parent_inverse.copy()
    dst.rotation_mode = src.rotation_mode
    for attr in ("location", "rotation_euler", "rotation_quaternion", "rotation_axis_angle",
                 "scale", "delta_location", "delta_rotation_euler",
                 "delta_rotation_quaternion", "delta_scale"):
        setattr(dst, attr, getattr(src, attr))


def select_only(context: bpy.types.Context, obj: bpy.types.Object) -> None:
    """Select ``obj`` alone and make it active."""
    deselect_all(context)
    obj.select_set(True)
    context.view_layer.objects.active = obj
