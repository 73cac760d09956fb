"""What the scene adds to a relaxation: obstacles (mesh objects the curve never crosses), a
container (a closed mesh object the curve stays inside) and pins (points of the curve selected
in Edit Mode that stay where they are).

``resolve(obj, options)`` turns the Blender forms of these options into the core's:
``obstacles`` given as a collection or a list of objects become ``(V, F)`` triangle arrays in
the curve's object coordinates (modifiers applied, as shown), so does a ``container`` given as
a mesh object (the core checks that it is closed and holds the curve), ``pin_selected=True`` becomes
``pinned=`` with the selected points' indices (one list per spline for a link).
"""

from __future__ import annotations

from collections.abc import Sequence

import bpy
import numpy as np

from .group import group_name


def obstacle_meshes(source, curve: bpy.types.Object,
                    depsgraph: bpy.types.Depsgraph | None = None) -> dict[str, tuple]:
    """``(V, F)`` of every mesh object of ``source`` (a collection, its child collections
    included, or a list of objects), triangulated, in ``curve``'s object coordinates, by
    object name (the core's messages name them so).

    Raises
    ------
    ValueError
        ``source`` holds no mesh object, or the curve itself is among them.
    """
    if isinstance(source, bpy.types.Collection):
        objects, what = list(source.all_objects), f"collection '{source.name}'"
    else:
        objects, what = list(source), "the obstacles given"
    meshes = [o for o in objects if o.type == "MESH"]
    if not meshes:
        kinds = sorted({o.type.lower() for o in objects})
        has = f" (it has {', '.join(kinds)} objects)" if kinds else " (it is empty)"
        raise ValueError(f"{what} holds no mesh object to use as an obstacle{has}")
    if depsgraph is None:
        depsgraph = bpy.context.evaluated_depsgraph_get()
    return {o.name: _triangles(o, curve, depsgraph, "obstacle") for o in meshes}


def _triangles(o: bpy.types.Object, curve: bpy.types.Object, depsgraph, role: str) -> tuple:
    """``(V, F)`` of mesh object ``o`` as shown, triangulated, in ``curve``'s coordinates."""
    ev = o.evaluated_get(depsgraph)
    mesh = ev.to_mesh()
    try:
        mesh.calc_loop_triangles()
        V = np.empty(3 * len(mesh.vertices))
        mesh.vertices.foreach_get("co", V)
        F = np.empty(3 * len(mesh.loop_triangles), dtype=np.int32)
        mesh.loop_triangles.foreach_get("vertices", F)
    finally:
        ev.to_mesh_clear()
    if len(F) == 0:
        raise ValueError(f"{role} '{o.name}' has no faces (a mesh without faces cannot be "
                         f"{'an obstacle' if role == 'obstacle' else 'a container'})")
    M = np.array(curve.matrix_world.inverted(), dtype=np.float64) @ np.array(
        o.matrix_world, dtype=np.float64)
    V = V.reshape(-1, 3) @ M[:3, :3].T + M[:3, 3]
    return V, F.reshape(-1, 3).astype(np.int64)


def container_mesh(o: bpy.types.Object, curve: bpy.types.Object,
                   depsgraph: bpy.types.Depsgraph | None = None) -> tuple:
    """``(V, F)`` of the container object ``o`` (modifiers applied), triangulated, in
    ``curve``'s object coordinates.

    Raises
    ------
    ValueError
        ``o`` is not a mesh object, or is the curve itself.
    """
    if o == curve or o.type != "MESH":
        raise ValueError(f"the container '{o.name}' is a {o.type.lower()} object; choose a "
                         "closed mesh object around the curve")
    if depsgraph is None:
        depsgraph = bpy.context.evaluated_depsgraph_get()
    return _triangles(o, curve, depsgraph, "container")


def selected_points(obj: bpy.types.Object):
    """Indices of the selected points of each spline of ``obj`` (Edit Mode's selection, read
    in either mode): a list for a one-spline curve, a list per spline otherwise; None when no
    point is selected."""
    if obj.mode == "EDIT":
        obj.update_from_editmode()
    per = []
    for s in obj.data.splines:
        sel = np.zeros(len(s.points), dtype=bool)
        s.points.foreach_get("select", sel)
        per.append(np.flatnonzero(sel).tolist())
    if not any(per):
        return None
    return per[0] if len(per) == 1 else per


def resolve(objects: Sequence[bpy.types.Object], options: dict) -> dict:
    """``options`` with their Blender forms turned into the core's (see the module text), for
    a run on the curve ``objects`` in the first one's coordinates; ``pin_selected`` is
    consumed: the selected points of every spline of every object, one list per spline (one
    list for a single spline).

    Raises
    ------
    ValueError
        ``pin_selected`` with no point selected; obstacles or a container that are not meshes.
    """
    options = dict(options)
    obj = objects[0]
    if isinstance(options.get("container"), bpy.types.Object):  # named in the core's messages
        container = options["container"]
        options["container"] = {container.name: container_mesh(container, obj)}
    source = options.get("obstacles")
    if source is not None and (isinstance(source, bpy.types.Collection) or (
            isinstance(source, (list, tuple)) and source
            and all(isinstance(o, bpy.types.Object) for o in source))):
        options["obstacles"] = obstacle_meshes(source, obj)
    if options.pop("pin_selected", False):
        per = []
        for o in objects:
            sel = selected_points(o)
            per += ([[] for _ in o.data.splines] if sel is None
                    else [sel] if len(o.data.splines) == 1 else sel)
        if not any(per):
            raise ValueError(f"Pin Selected Points is on, but no point of {group_name(objects)} "
                             "is selected: select the points to pin in Edit Mode (or turn it "
                             "off)")
        if options.get("pinned") is not None:
            raise ValueError("give pinned= or pin_selected=True, not both")
        options["pinned"] = per[0] if len(per) == 1 else per
    return options
