"""Several curve objects relaxed together as one system (an artist's cables are separate
objects): each keeps its own data, keys and pins; no strand of one meets another at any keyed
frame or between frames; Continue, Clear and Export act on the group; refusals name the
object."""

from importlib import import_module

import bpy
import mathutils
import numpy as np
import pytest
from bpy_helpers import poly_curve, scene_state, spline_points

from tests.mesh_checks import segments_closest


def _keys(mb, obj):
    return import_module(mb.__name__ + ".keyframes").read_flow_keyframes(obj)


def _world(obj, points):
    M = np.array(obj.matrix_world)
    return points @ M[:3, :3].T + M[:3, 3]


def _gap(A, B):
    """The least distance between a segment of closed polygon A and one of closed polygon B."""
    i, j = np.meshgrid(np.arange(len(A)), np.arange(len(B)), indexing="ij")
    i, j = i.ravel(), j.ravel()
    return float(segments_closest(A[i], A[(i + 1) % len(A)], B[j], B[(j + 1) % len(B)]).min())


@pytest.fixture
def hopf_as_two_objects(scene, core):
    """The two rings of a Hopf link as two curve objects, the second moved, turned and scaled
    (its points in its own coordinates), both selected, 'Ring A' active."""
    A, B = core.knots.named("L2a1", 100)
    a = poly_curve("Ring A", [A])
    M = mathutils.Matrix.LocRotScale(mathutils.Vector((0.4, -0.2, 0.3)),
                                     mathutils.Euler((0.3, -0.5, 0.8)),
                                     mathutils.Vector((1.5, 1.5, 1.5)))
    Mi = np.array(M.inverted())
    b = poly_curve("Ring B", [B @ Mi[:3, :3].T + Mi[:3, 3]])
    b.matrix_world = M
    bpy.context.view_layer.update()
    a.select_set(True)
    b.select_set(True)
    bpy.context.view_layer.objects.active = a
    return a, b, [A, B]


@pytest.mark.lines
def test_selected_curves_relax_together_each_keeping_its_keys_and_pins(scene, mb,
                                                                     hopf_as_two_objects):
    a, b, (A, B) = hopf_as_two_objects
    pts = b.data.splines[0].points
    for i in (0, 30):
        pts[i].select = True
    b_start = spline_points(b).copy()
    s = scene.moebius
    s.pin_selected = True
    s.method = "projected_gradient"
    s.max_iterations = 8
    assert bpy.ops.moebius.relax() == {"FINISHED"}
    (fa, pa, ea), (fb, pb, eb) = _keys(mb, a), _keys(mb, b)
    assert len(fa) == 9 and np.array_equal(fa, fb) and np.array_equal(ea, eb)
    # each object keyed in its own coordinates; the pinned points of B never moved
    np.testing.assert_allclose(_world(a, pa[0]), A, atol=1e-5)
    np.testing.assert_allclose(_world(b, pb[0]), B, atol=1e-5)
    np.testing.assert_allclose(pb[:, [0, 30]], np.broadcast_to(b_start[[0, 30]], (9, 2, 3)),
                               atol=1e-6)
    assert np.abs(pa[-1] - pa[0]).max() > 1e-2 and np.abs(pb[-1] - pb[0]).max() > 1e-2
    # never closer than the run's contact distance (1e-3 of an edge) at a keyed frame or on the
    # straight path between frames, checked with the test's own segment distances
    edge = float(np.linalg.norm(A[1] - A[0]))
    worlds = [(_world(a, x), _world(b, y)) for x, y in zip(pa, pb, strict=True)]
    for (A0, B0), (A1, B1) in zip(worlds[:-1], worlds[1:], strict=True):
        for t in (0.0, 0.25, 0.5, 0.75):
            assert _gap(A0 + t * (A1 - A0), B0 + t * (B1 - B0)) > 1e-3 * edge
    assert s.last_object == "'Ring A' and 1 other curve"
    # Continue carries both on; Clear clears both
    assert bpy.ops.moebius.relax(append=True) == {"FINISHED"}
    (fa2, _, _), (fb2, _, _) = _keys(mb, a), _keys(mb, b)
    assert len(fa2) == 17 and np.array_equal(fa2, fb2)
    assert bpy.ops.moebius.clear_animation() == {"FINISHED"}
    assert _keys(mb, a) is None and _keys(mb, b) is None


@pytest.mark.lines
def test_a_group_export_holds_every_curve(scene, mb, hopf_as_two_objects, tmp_path):
    a, b, _ = hopf_as_two_objects
    scene.moebius.max_iterations = 2
    assert bpy.ops.moebius.relax() == {"FINISHED"}
    path = tmp_path / "hopf.usda"
    assert bpy.ops.moebius.export_flow(filepath=str(path)) == {"FINISHED"}
    text = path.read_text()
    assert "Ring_A" in text and "Ring_B" in text


def test_a_group_is_refused_by_object_name_with_the_scene_unchanged(scene, mb,
                                                                     hopf_as_two_objects):
    a, b, _ = hopf_as_two_objects
    b.scale = (1.5, 1.5, 3.0)
    bpy.context.view_layer.update()
    before = scene_state()
    with pytest.raises(RuntimeError, match="'Ring B' is scaled unevenly against 'Ring A'"):
        bpy.ops.moebius.relax()
    assert scene_state() == before
    # a third ring through the first (the same ring, turned a little about one of its
    # points): the start meets itself across the objects
    b.scale = (1.5, 1.5, 1.5)
    A = spline_points(a)
    turn = np.array(mathutils.Matrix.Rotation(0.3, 3, "X"))
    c = poly_curve("Ring C", [(A - A[0]) @ turn.T + A[0]])
    for o in (a, b, c):
        o.select_set(True)
    bpy.context.view_layer.objects.active = a
    before = scene_state()
    with pytest.raises(RuntimeError, match="'Ring A' and 2 other curves: "):
        bpy.ops.moebius.relax()
    assert scene_state() == before
