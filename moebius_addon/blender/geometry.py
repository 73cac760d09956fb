"""Curve and mesh objects <-> polygons (``(N, 3)`` float64 arrays in object coordinates).

Reading accepts poly, Bezier and NURBS curves (the last two through Blender's own evaluation) and
meshes made only of edge loops, which is what OBJ polyline import produces. Writing makes one
cyclic ``POLY`` spline per component.
"""

from __future__ import annotations

from collections.abc import Sequence

import bpy
import numpy as np

from .. import core
from . import keyframes

#: Samples per Bezier segment (or per NURBS control point) when reading a smooth curve; the
#: result is resampled to equal edges afterwards, so this only sets how faithfully the shape
#: is followed.
READ_RESOLUTION = 24
#: Coordinates at or beyond this are infinite ones: Blender keeps points in single precision and
#: stores an infinity typed in the UI as ±3.4e38 (its float limit), a finite number to numpy.
FLOAT_LIMIT = 1e38


def check_finite_points(points: np.ndarray, where: str) -> None:
    """ValueError for NaN, infinite or clamped-infinite coordinates (:data:`FLOAT_LIMIT`):
    ``where`` names the curve ("'Knot'", "'Knot' (component 2 of 3)")."""
    bad = ~(np.abs(points) < FLOAT_LIMIT).all(axis=1)
    if bad.any():
        raise ValueError(
            f"{where} has NaN or infinite coordinates ({int(bad.sum())} of its {len(points)} "
            f"points, the first at index {int(np.flatnonzero(bad)[0])}; Blender shows an "
            "infinite one as ±3.4e38); fix or delete those points"
        )


def _mesh_polylines(vertices: np.ndarray, edges: np.ndarray, name: str) -> list[tuple]:
    """Split an edge graph into closed loops and open chains.

    Parameters
    ----------
    vertices : (V, 3) float array
    edges : (E, 2) int array
    name : str
        Object name used in error messages.

    Returns
    -------
    list of (points, closed)
        ``points`` is ``(n, 3)`` in walking order; ``closed`` says whether it is a loop.
    """
    nv = len(vertices)
    degree = np.bincount(edges.ravel(), minlength=nv) if len(edges) else np.zeros(nv, int)
    if np.any(degree > 2):
        v = int(np.flatnonzero(degree > 2)[0])
        raise ValueError(
            f"'{name}' is not made of separate curves: vertex {v} has {degree[v]} edges. "
            "Use a mesh whose vertices each have exactly two edges (closed edge loops), "
            "e.g. from an OBJ polyline, or a curve object"
        )
    neighbours = [[] for _ in range(nv)]
    for a, b in edges:
        neighbours[a].append(b)
        neighbours[b].append(a)
    seen = np.zeros(nv, bool)
    seen[degree == 0] = True  # loose vertices carry no curve
    out = []
    # open chains first (start at an end), then whatever is left are loops
    starts = [int(v) for v in np.flatnonzero(degree == 1)] + list(range(nv))
    for start in starts:
        if seen[start]:
            continue
        order, prev, cur = [start], -1, start
        seen[start] = True
        while True:
            nxt = [v for v in neighbours[cur] if v != prev and not seen[v]]
            if not nxt:
                break
            prev, cur = cur, nxt[0]
            seen[cur] = True
            order.append(cur)
        closed = bool(degree[start] == 2)
        out.append((vertices[order].astype(np.float64), closed))
    return out


def _curve_polylines(obj: bpy.types.Object) -> list[tuple]:
    curve = obj.data
    if all(s.type == "POLY" for s in curve.splines):
        out = []
        for s in curve.splines:
            co = np.empty(4 * len(s.points))
            s.points.foreach_get("co", co)
            out.append((co.reshape(-1, 4)[:, :3].copy(), bool(s.use_cyclic_u)))
        return out
    # Bezier/NURBS: let Blender evaluate the splines on a bare copy (no bevel, extrusion or
    # modifiers, so the evaluated mesh is just the centre line), then read its edges. The copy
    # lives in a scratch scene: adding and removing objects in the user's view layer leaves its
    # object list stale for the rest of the operator (and iterating it then crashes Blender 5.0).
    tmp_curve = curve.copy()
    tmp_obj = None
    tmp_scene = bpy.data.scenes.new("_moebius_read")
    try:
        tmp_curve.dimensions = "3D"
        tmp_curve.bevel_depth = 0.0
        tmp_curve.bevel_mode = "ROUND"
        tmp_curve.bevel_object = None
        tmp_curve.taper_object = None
        tmp_curve.extrude = 0.0
        tmp_curve.offset = 1.0
        tmp_curve.resolution_u = max(curve.resolution_u, READ_RESOLUTION)
        tmp_obj = bpy.data.objects.new("_moebius_read", tmp_curve)
        tmp_scene.collection.objects.link(tmp_obj)
        with bpy.context.temp_override(scene=tmp_scene, view_layer=tmp_scene.view_layers[0]):
            depsgraph = bpy.context.evaluated_depsgraph_get()
        evaluated = tmp_obj.evaluated_get(depsgraph)
        mesh = evaluated.to_mesh()
        try:
            vertices, edges = _mesh_arrays(mesh)
        finally:
            evaluated.to_mesh_clear()
    finally:
        if tmp_obj is not None:
            bpy.data.objects.remove(tmp_obj)
        bpy.data.curves.remove(tmp_curve)
        bpy.data.scenes.remove(tmp_scene)
    return _mesh_polylines(vertices, edges, obj.name)


def _mesh_arrays(mesh: bpy.types.Mesh) -> tuple[np.ndarray, np.ndarray]:
    vertices = np.empty(3 * len(mesh.vertices))
    mesh.vertices.foreach_get("co", vertices)
    edges = np.empty(2 * len(mesh.edges), dtype=np.int64)
    mesh.edges.foreach_get("vertices", edges)
    return vertices.reshape(-1, 3), edges.reshape(-1, 2)


def object_polylines(obj: bpy.types.Object) -> list[tuple[np.ndarray, bool]]:
    """Read the centre lines of a curve or edge-loop mesh object.

    Parameters
    ----------
    obj : bpy.types.Object
        A ``CURVE`` object (poly, Bezier or NURBS splines) or a ``MESH`` object without faces.

    Returns
    -------
    list of (points, closed)
        One entry per spline or edge component: ``points`` an ``(n, 3)`` float64 array in object
        coordinates, ``closed`` whether the component is cyclic.

    Raises
    ------
    ValueError
        For other object types, meshes with faces or branching vertices, and empty objects.
    """
    if obj.type == "CURVE":
        if len(obj.data.splines) == 0:
            raise ValueError(f"curve '{obj.name}' has no splines; draw or add a curve first")
        return _curve_polylines(obj)
    if obj.type == "MESH":
        mesh = obj.data
        if len(mesh.polygons):
            raise ValueError(
                f"mesh '{obj.name}' has {len(mesh.polygons)} faces, so it is not a curve; "
                "select a curve object or a mesh made only of closed edge loops "
                "(e.g. an imported OBJ polyline)"
            )
        if len(mesh.edges) == 0:
            raise ValueError(f"mesh '{obj.name}' has no edges; it holds no curve to convert")
        vertices, edges = _mesh_arrays(mesh)
        return _mesh_polylines(vertices, edges, obj.name)
    raise ValueError(
        f"'{obj.name}' is a {obj.type.lower()} object; select a curve object "
        "or a mesh made of closed edge loops"
    )


def curve_closed(obj: bpy.types.Object) -> list[bool]:
    """Whether each spline of ``obj`` is closed (cyclic)."""
    return [bool(s.use_cyclic_u) for s in obj.data.splines]


def curve_polygons(obj: bpy.types.Object, allow_open: bool = False) -> list[np.ndarray]:
    """Polygons of a curve made of cyclic poly splines, as shown at the current frame (for a
    flow keyed as shape keys: their mix, see :func:`.keyframes.flow_shape_at`).

    Parameters
    ----------
    obj : bpy.types.Object
        A curve object whose splines are all cyclic ``POLY`` splines (what
        :func:`~moebius_addon.blender.convert_object` and ``moebius.add_knot`` make).
    allow_open : bool
        Take open ``POLY`` splines too (what Relax takes: :func:`curve_closed` says which).

    Returns
    -------
    list of (n_i, 3) float64 arrays
        One polygon per spline, in object coordinates.

    Raises
    ------
    ValueError
        If ``obj`` is not such a curve, saying how to make it one.
    """
    if obj is None or obj.type != "CURVE":
        kind = "nothing" if obj is None else f"a {obj.type.lower()} object"
        raise ValueError(f"the active object is {kind}; select a converted Möbius curve "
                         "(Möbius ▸ Polygon ▸ Convert)")
    splines = obj.data.splines
    if len(splines) == 0:
        raise ValueError(f"curve '{obj.name}' has no splines")
    for s in splines:
        if s.type != "POLY" or not (s.use_cyclic_u or allow_open):
            what = "an open" if s.type == "POLY" else f"a {s.type.title()}"
            raise ValueError(
                f"curve '{obj.name}' has {what} spline; convert it to equal-edge closed "
                "polygons first (Möbius ▸ Polygon ▸ Convert)"
            )
    scene = bpy.context.scene
    mixed = keyframes.flow_shape_at(obj, scene.frame_current + scene.frame_subframe)
    if mixed is not None:  # a flow keyed as shape keys: what they show, not the points below
        polygons = np.split(mixed, np.cumsum([len(s.points) for s in splines])[:-1])
    else:
        polygons = [p for p, _ in _curve_polylines(obj)]
    for k, P in enumerate(polygons):  # ±3.4e38 read as "repeats a point" in the core
        check_finite_points(P, f"'{obj.name}'" + (f" (component {k + 1} of {len(polygons)})"
                                                  if len(polygons) > 1 else ""))
    return polygons


def write_polygons(curve: bpy.types.Curve, polygons: Sequence[np.ndarray]) -> None:
    """Overwrite the point positions of a curve whose splines match ``polygons`` in size.

    Parameters
    ----------
    curve : bpy.types.Curve
        Curve data with one poly spline per polygon.
    polygons : sequence of (n_i, 3) arrays
    """
    for spline, P in zip(curve.splines, polygons, strict=True):
        co = np.ones((len(P), 4))
        co[:, :3] = P
        spline.points.foreach_set("co", co.ravel())
    curve.update_tag()


def grow_splines(curve: bpy.types.Curve, sizes: Sequence[int]) -> None:
    """Give spline ``s`` of ``curve`` ``sizes[s]`` points, a whole multiple of its edges (a
    refined run's count, ``core.subdivide``): the new points are placed on its edges, and their
    radius, tilt and soft-body weight are interpolated between the old points'.

    Blender's spline points can be added, not removed: a curve is only ever grown."""
    for spline, size in zip(curve.splines, sizes, strict=True):
        n = len(spline.points)
        if size == n:
            continue
        closed = spline.use_cyclic_u
        edges = n if closed else n - 1
        factor, rest = divmod(size if closed else size - 1, edges)
        if rest or factor < 1:
            raise ValueError(f"a spline of {n} points cannot grow to {size} by splitting edges")
        co = np.empty(4 * n)
        spline.points.foreach_get("co", co)
        attrs = np.empty((n, 3))
        for k, name in enumerate(("radius", "tilt", "weight_softbody")):
            spline.points.foreach_get(name, attrs[:, k])
        new_co = core.subdivide(co.reshape(n, 4)[:, :3], factor, closed)
        new_attrs = core.subdivide(attrs, factor, closed)
        spline.points.add(size - n)
        full = np.ones((size, 4))
        full[:, :3] = new_co
        spline.points.foreach_set("co", full.ravel())
        for k, name in enumerate(("radius", "tilt", "weight_softbody")):
            spline.points.foreach_set(name, np.ascontiguousarray(new_attrs[:, k]))
    curve.update_tag()


def new_curve(name: str, polygons: Sequence[np.ndarray], closed=True) -> bpy.types.Curve:
    """Make curve data with one ``POLY`` spline per polygon, cyclic where ``closed``.

    Parameters
    ----------
    name : str
    polygons : sequence of (n_i, 3) arrays
        Vertices in object coordinates.
    closed : bool or sequence of bool
        Whether each spline is cyclic (an open one keeps its two ends).

    Returns
    -------
    bpy.types.Curve
    """
    curve = bpy.data.curves.new(name, "CURVE")
    curve.dimensions = "3D"
    curve.twist_mode = "MINIMUM"
    flags = [closed] * len(polygons) if isinstance(closed, bool) else list(closed)
    for P, cyclic in zip(polygons, flags, strict=True):
        spline = curve.splines.new("POLY")
        spline.points.add(len(P) - 1)
        spline.use_cyclic_u = bool(cyclic)
    write_polygons(curve, polygons)
    return curve
