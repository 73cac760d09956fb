"""A container: a closed mesh object the curve stays inside, set in the panel."""

from importlib import import_module

import bmesh
import bpy
import numpy as np
import pytest
from bpy_helpers import poly_curve, scene_state, world_mesh

from tests.mesh_checks import crossings, ray_parity_inside


@pytest.fixture
def loop_in_sphere(scene, mb):
    """A UV sphere of radius 0.8 (moved: world coordinates matter) and a wavy loop inside it
    whose relaxed round shape (radius 1.02) would not fit."""
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.8, segments=24, ring_count=12,
                                         location=(0.3, 0.0, 0.0))
    sphere = bpy.context.active_object
    t = np.linspace(0, 2 * np.pi, 80, endpoint=False)
    core = import_module(mb.__name__.rsplit(".", 1)[0] + ".core")
    P = core.resample(np.stack([0.6 * np.cos(t), 0.6 * np.sin(t), 0.25 * np.sin(5 * t)], -1),
                      80)
    obj = poly_curve("Loop", [P])
    obj.location = (0.3, 0.0, 0.0)
    bpy.context.view_layer.objects.active = obj
    bpy.context.view_layer.update()
    return obj, sphere


def test_a_loop_relaxes_inside_a_sphere_and_every_frame_stays_in(scene, mb, loop_in_sphere):
    obj, sphere = loop_in_sphere
    V, F = world_mesh(sphere)
    M = np.array(obj.matrix_world)
    s = scene.moebius
    s.container = sphere
    s.method = "projected_gradient"
    s.max_iterations = 15
    assert bpy.ops.moebius.relax() == {"FINISHED"}
    frames, points, _ = import_module(mb.__name__ + ".keyframes").read_flow_keyframes(obj)
    assert len(frames) == 16
    rng = np.random.default_rng(0)
    world = [P @ M[:3, :3].T + M[:3, 3] for P in points]
    for P in world:
        assert ray_parity_inside(P, V, F, rng).all()
    for A, B in zip(world[:-1], world[1:], strict=True):  # the straight moves between keys
        assert not any(crossings(p, V, F, closed=False) for p in np.stack([A, B], 1))
        for t in np.linspace(0, 1, 5)[1:-1]:
            assert crossings(A + t * (B - A), V, F) == 0
    assert s.last_energy_end < s.last_energy_start


def test_bad_containers_are_refused_with_the_scene_unchanged(scene, mb, loop_in_sphere):
    obj, sphere = loop_in_sphere
    s = scene.moebius
    s.method = "projected_gradient"
    s.max_iterations = 2
    # a sphere with a hole: not closed
    me = sphere.data
    bm = bmesh.new()  # one face deleted, its edges kept: a hole
    bm.from_mesh(me)
    bm.faces.ensure_lookup_table()
    bmesh.ops.delete(bm, geom=[bm.faces[0]], context="FACES_ONLY")
    bm.to_mesh(me)
    bm.free()
    s.container = sphere
    before = scene_state()
    with pytest.raises(RuntimeError, match="the container is not closed"):
        bpy.ops.moebius.relax()
    assert scene_state() == before
    # a closed sphere beside the curve: the start is outside
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.8, location=(5.0, 0.0, 0.0))
    far = bpy.context.active_object
    bpy.context.view_layer.objects.active = obj
    before = scene_state()
    with pytest.raises(ValueError, match="the curve is outside the container"):
        mb.relax_object(obj, max_iterations=2, container=far)
    with pytest.raises(ValueError, match="the container 'Loop' is a curve object"):
        mb.relax_object(obj, max_iterations=2, container=obj)
    assert scene_state() == before
