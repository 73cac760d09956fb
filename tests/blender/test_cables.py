"""The artist's cable scene: ten cables as ten curve objects hanging between two plates through
a torus, *Untangle Cables*, *Relax*. Every keyed frame and the straight moves between frames
are checked with the test's own distances: tubes (the bevel's radius) at least the sum of their
radii apart, at least a radius from the torus and the plates, ends and end tangents fixed."""

from importlib import import_module

import bpy
import numpy as np
import pytest
from bpy_helpers import R_TORUS, Z_TORUS, r_TORUS, scene_state
from bpy_helpers import cable_scene as cable_scene_of

from tests.mesh_checks import segments_closest

CABLES, EDGES = 10, 40


def _keys(mb, obj):
    return import_module(mb.__name__ + ".keyframes").read_flow_keyframes(obj)


@pytest.fixture
def cable_scene(scene, core):
    """Ten cables as ten curve objects between two plates through a torus
    (``bpy_helpers.cable_scene``), all selected, the first active."""
    return cable_scene_of(core.resample, CABLES, EDGES)


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
    for obj in cables:  # the preset thickens every selected cable and selects its two ends
        X = _world(obj, np.array([p.co[:3] for p in obj.data.splines[0].points]))
        edge = float(np.linalg.norm(np.diff(X, axis=0), axis=1).mean())
        assert _tube_radius(obj) == pytest.approx(0.3 * edge, rel=1e-5)
        assert [p.select for p in obj.data.splines[0].points] == [True] + [False] * (
            EDGES - 1) + [True]
    r = max(_tube_radius(obj) for obj in cables)
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
                                           r"thickness 0\.09"):
        bpy.ops.moebius.relax()
    assert scene_state() == before
    for obj in cables:  # a radius in world units on the object counts instead of the bevel
        obj.data.bevel_depth = 0.001
        obj["moebius_thickness"] = 0.09
    with pytest.raises(RuntimeError, match=r"below twice the thickness 0\.09"):
        bpy.ops.moebius.relax()
    assert scene_state() == before
    s = scene.moebius
    s.push_apart = True  # or pushed apart first: the tubes it allows, thickened as it goes
    s.max_iterations = 2
    assert bpy.ops.moebius.relax() == {"FINISHED"}
    s.push_apart = False
    s.keep_thickness = False  # or centre lines only
    assert bpy.ops.moebius.relax() == {"FINISHED"}
