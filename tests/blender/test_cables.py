"""The artist's cable scene: ten cables as ten curve objects hanging between two plates through
a torus, *Untangle Cables*, *Relax*. Every keyed frame and the straight moves between frames
are checked with the test's own distances: tubes (the bevel's radius) at least the sum of their
radii apart, at least a radius from the torus and the plates, ends and end tangents fixed."""

from importlib import import_module

import bpy
import numpy as np
import pytest
from bpy_helpers import poly_curve, scene_state

from tests.mesh_checks import segments_closest

CABLES, EDGES = 10, 40
R_TORUS, r_TORUS, Z_TORUS = 0.6, 0.08, 0.5


def _keys(mb, obj):
    return import_module(mb.__name__ + ".keyframes").read_flow_keyframes(obj)


def _into(collection, obj):
    for c in obj.users_collection:
        c.objects.unlink(obj)
    collection.objects.link(obj)


@pytest.fixture
def cable_scene(scene, core):
    """Two plates (z below 0 and above 1), a torus about the z axis at mid-height, all in the
    collection 'Obstacles', and ten cables around the axis from plate to plate, each its own
    object, wavy, their ends on the plates and leaving them straight up."""
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
    rng = np.random.default_rng(7)
    t = np.linspace(0.0, 1.0, 600)
    bump = np.sin(np.pi * t) ** 2  # no sideways motion at the plates: the cables leave them
    cables = []                    # straight up
    for c in range(CABLES):
        a = 2 * np.pi * c / CABLES + 0.2 * bump * np.sin(2 * np.pi * t + c)
        w = 0.25 + 0.05 * bump * rng.uniform(-1, 1) * np.cos(3 * np.pi * t + c)
        P = core.resample(np.c_[w * np.cos(a), w * np.sin(a), t], EDGES + 1, closed=False)
        cables.append(poly_curve(f"Cable.{c:03d}", [P], cyclic=False))
    for obj in cables:
        obj.select_set(True)
    bpy.context.view_layer.objects.active = cables[0]
    return cables


def _tube_radius(obj):
    return obj.data.bevel_depth * obj.matrix_world.to_scale()[0]


def _world(obj, X):
    M = np.array(obj.matrix_world)
    return X @ M[:3, :3].T + M[:3, 3]


def _gap_between(A, B):
    i, j = (g.ravel() for g in np.meshgrid(np.arange(len(A) - 1), np.arange(len(B) - 1),
                                           indexing="ij"))
    return float(segments_closest(A[i], A[i + 1], B[j], B[j + 1]).min())


def _torus_gap(P):
    """The least distance of the polyline (sampled at 9 points per edge) from the torus' smooth
    surface, which holds its mesh (vertices on it, faces inside)."""
    s = np.linspace(0.0, 1.0, 9)[:, None, None]
    Q = (P[:-1] + s * (P[1:] - P[:-1])).reshape(-1, 3)
    rho = np.hypot(Q[:, 0], Q[:, 1]) - R_TORUS
    return float((np.hypot(rho, Q[:, 2] - Z_TORUS) - r_TORUS).min())


def test_ten_cable_objects_untangle_as_tubes_that_never_meet(scene, mb, cable_scene):
    cables = cable_scene
    s = scene.moebius
    assert bpy.ops.moebius.apply_preset(preset="untangle_cables") == {"FINISHED"}
    assert s.pin_tangents and s.keep_thickness
    edge = float(np.linalg.norm(np.diff(_world(cables[0], np.array(
        [p.co[:3] for p in cables[0].data.splines[0].points])), axis=0), axis=1).mean())
    for obj in cables:  # the preset thickens the active one; the rest as an artist would
        obj.data.bevel_depth = cables[0].data.bevel_depth
        for p in obj.data.splines[0].points:
            p.select = False
        for k in (0, EDGES):
            obj.data.splines[0].points[k].select = True
    r = _tube_radius(cables[0])
    assert r == pytest.approx(0.3 * edge, rel=1e-3)
    s.max_iterations = 12
    assert bpy.ops.moebius.relax() == {"FINISHED"}
    assert s.last_object == "'Cable.000' and 9 other curves"
    keys = [_keys(mb, obj) for obj in cables]
    frames = keys[0][0]
    assert len(frames) >= 2 and all(np.array_equal(k[0], frames) for k in keys)
    paths = [np.stack([_world(obj, X) for X in k[1]]) for obj, k in zip(cables, keys,
                                                                         strict=True)]
    moved = max(np.abs(p[-1] - p[0]).max() for p in paths)
    assert moved > 1e-3  # they did relax
    for p in paths:  # ends and end tangents to the keys' single precision
        np.testing.assert_allclose(p[:, [0, 1, -2, -1]],
                                   np.broadcast_to(p[0, [0, 1, -2, -1]], p[:, :4].shape),
                                   atol=1e-6)
    for f in range(len(frames) - 1):
        for u in (0.0, 0.25, 0.5, 0.75):
            X = [p[f] + u * (p[f + 1] - p[f]) for p in paths]
            for a in range(CABLES):
                free = X[a][1:-1]  # the ends lie on the plates, with their fixed first edges
                assert free[:, 2].min() >= r * (1 - 1e-5) and free[:, 2].max() <= 1 - r * (
                    1 - 1e-5)
                assert _torus_gap(X[a]) >= r * (1 - 1e-3)
                for b in range(a):
                    assert _gap_between(X[a], X[b]) >= 2 * r * (1 - 1e-5), (f, u, a, b)


def test_tubes_that_meet_at_the_start_are_refused_by_name(scene, mb, cable_scene):
    cables = cable_scene
    assert bpy.ops.moebius.apply_preset(preset="untangle_cables") == {"FINISHED"}
    for obj in cables:
        obj.data.bevel_depth = 0.09  # tubes thicker than the cables are apart
    before = scene_state()
    with pytest.raises(RuntimeError, match=r"'Cable\.000' and 9 other curves: 'Cable\.\d+' and "
                                           r"'Cable\.\d+' are [\d.]+ apart .*below twice the "
                                           r"thickness 0\.18"):
        bpy.ops.moebius.relax()
    assert scene_state() == before
    scene.moebius.keep_thickness = False  # centre lines only: it runs
    scene.moebius.max_iterations = 1
    assert bpy.ops.moebius.relax() == {"FINISHED"}
