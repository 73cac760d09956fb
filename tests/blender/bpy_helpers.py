"""Helpers for the Blender tests (imported by name; ``conftest`` is ambiguous in this tree).

Import only after ``conftest.py`` has pointed ``BLENDER_USER_RESOURCES`` at a throw-away
directory (pytest loads the conftest first).
"""

import sys
from pathlib import Path

import bpy
import numpy as np

ROOT = Path(__file__).resolve().parents[2]
EXT_MODULE = "bl_ext.user_default.moebius_addon"
#: This Python's version, e.g. "3.11": the extension's wheels are built and shipped for it.
PYTHON = f"{sys.version_info.major}.{sys.version_info.minor}"


def build_extension():
    """``mk/build_extension.py`` as a module (build, build_repo, blender_ext)."""
    sys.path.insert(0, str(ROOT / "mk"))
    try:
        import build_extension as module
    finally:
        sys.path.pop(0)
    return module


def fcurves_of(idblock):
    """The F-curves of ``idblock``'s action as Blender stores them: in the channelbag of the
    assigned slot on Blender 4.4+ (slotted actions), in ``action.fcurves`` on 4.2-4.3."""
    adt = idblock.animation_data
    if bpy.app.version < (4, 4):
        return adt.action.fcurves
    from bpy_extras import anim_utils

    return anim_utils.action_get_channelbag_for_slot(adt.action, adt.action_slot).fcurves


def poly_curve(name: str, polygons, cyclic: bool = True, spline_type: str = "POLY"):
    """Link a new curve object with one spline per ``(n, 3)`` point array and select it."""
    curve = bpy.data.curves.new(name, "CURVE")
    curve.dimensions = "3D"
    for P in polygons:
        P = np.asarray(P, dtype=float)
        spline = curve.splines.new(spline_type)
        spline.points.add(len(P) - 1)
        spline.points.foreach_set("co", np.column_stack([P, np.ones(len(P))]).ravel())
        spline.use_cyclic_u = cyclic
    obj = bpy.data.objects.new(name, curve)
    bpy.context.scene.collection.objects.link(obj)
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    return obj


def world_mesh(obj):
    """(V, F) of a mesh object in world coordinates, triangulated."""
    me = obj.data
    me.calc_loop_triangles()
    V = np.array([obj.matrix_world @ v.co for v in me.vertices])
    F = np.array([t.vertices[:] for t in me.loop_triangles])
    return V, F


def scene_state() -> dict:
    """Everything a failed operator must leave alone: data-blocks, visibility, geometry."""
    state = {
        "objects": sorted(o.name for o in bpy.data.objects),
        "curves": sorted(c.name for c in bpy.data.curves),
        "meshes": sorted(m.name for m in bpy.data.meshes),
        "actions": sorted(a.name for a in bpy.data.actions),
        "hidden": sorted(o.name for o in bpy.data.objects if o.hide_get() or o.hide_render),
        "frames": (bpy.context.scene.frame_start, bpy.context.scene.frame_end),
    }
    for c in bpy.data.curves:
        for k, s in enumerate(c.splines):
            pts = s.bezier_points if s.type == "BEZIER" else s.points
            co = np.empty(len(pts) * (3 if s.type == "BEZIER" else 4))
            pts.foreach_get("co", co)
            # NaN as None: NaN != NaN would make equal states compare unequal
            state[f"{c.name}/{k}"] = [None if x != x else x for x in co.round(12).tolist()]
    return state


def points_at(obj, frame: int):
    """World-space spline points of ``obj`` at ``frame`` as one ``(N, 3)`` array."""
    bpy.context.scene.frame_set(frame)
    M = np.array(obj.matrix_world)
    return spline_points(obj) @ M[:3, :3].T + M[:3, 3]


def spline_points(obj):
    """Local-space points of all poly splines of ``obj`` as Blender shows them, one ``(N, 3)``
    array: the spline points, or under shape keys (a large flow) the vertices of the curve
    Blender evaluates (its centre line, the bevel switched off while it is read)."""
    if obj.data.shape_keys is not None:
        bevel = obj.data.bevel_depth
        obj.data.bevel_depth = 0.0
        try:
            evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
            mesh = evaluated.to_mesh()
            co = np.empty(3 * len(mesh.vertices))
            mesh.vertices.foreach_get("co", co)
            evaluated.to_mesh_clear()
        finally:
            obj.data.bevel_depth = bevel
        assert len(co) == 3 * sum(len(s.points) for s in obj.data.splines)
        return co.reshape(-1, 3)
    X = []
    for s in obj.data.splines:
        co = np.empty(4 * len(s.points))
        s.points.foreach_get("co", co)
        X.append(co.reshape(-1, 4)[:, :3])
    return np.concatenate(X)


def imported_points(frame):
    """World positions of the one imported curves object at ``frame``."""
    scene = bpy.context.scene
    scene.frame_set(frame)
    objs = [o for o in scene.objects if o.type == "CURVES"]
    assert len(objs) == 1, [(o.name, o.type) for o in scene.objects]
    (obj,) = objs
    depsgraph = bpy.context.evaluated_depsgraph_get()
    ev = obj.evaluated_get(depsgraph)
    assert obj.type == "CURVES"
    pos = ev.data.attributes["position"]
    X = np.empty(3 * len(pos.data))
    pos.data.foreach_get("vector", X)
    X = X.reshape(-1, 3)
    M = np.array(ev.matrix_world)
    return X @ M[:3, :3].T + M[:3, 3], ev.data


#: The torus of :func:`cable_scene`: major and minor radius, height.
R_TORUS, r_TORUS, Z_TORUS = 0.6, 0.08, 0.5


def _into(collection, obj):
    for c in obj.users_collection:
        c.objects.unlink(obj)
    collection.objects.link(obj)


def cable_scene(resample, cables: int = 10, edges: int = 40, seed: int = 7, twist: float = 0.2,
                spread: float = 0.05) -> list:
    """The artist's cable scene: two plates (below z = 0, above z = 1) and a torus about the
    z axis at mid-height, in the collection 'Obstacles', and ``cables`` cables around the axis
    from plate to plate, each its own curve object of ``edges`` equal edges (``resample``:
    the core's), wavy (``twist`` radians about the axis, ``spread`` sideways), their ends on
    the plates and leaving them straight up; the cables selected, the first active."""
    scene = bpy.context.scene
    obstacles = bpy.data.collections.new("Obstacles")
    scene.collection.children.link(obstacles)
    for name, z in (("Floor", -0.05), ("Ceiling", 1.05)):
        bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.0, 0.0, z), scale=(2.0, 2.0, 0.1))
        bpy.context.active_object.name = name
        _into(obstacles, bpy.context.active_object)
    bpy.ops.mesh.primitive_torus_add(major_radius=R_TORUS, minor_radius=r_TORUS,
                                     location=(0.0, 0.0, Z_TORUS))
    bpy.context.active_object.name = "Ring"
    _into(obstacles, bpy.context.active_object)
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, 600)
    bump = np.sin(np.pi * t) ** 2  # no sideways motion at the plates: the cables leave them
    objs = []                      # straight up
    for c in range(cables):
        a = 2 * np.pi * c / cables + twist * bump * np.sin(2 * np.pi * t + c)
        w = 0.25 + spread * bump * rng.uniform(-1, 1) * np.cos(3 * np.pi * t + c)
        P = resample(np.c_[w * np.cos(a), w * np.sin(a), t], edges + 1, closed=False)
        objs.append(poly_curve(f"Cable.{c:03d}", [P], cyclic=False))
    for obj in objs:
        obj.select_set(True)
    bpy.context.view_layer.objects.active = objs[0]
    return objs
