"""Pins from the points selected in Edit Mode and obstacles from a collection of meshes,
through the panel's settings and the script functions."""

from importlib import import_module

import bpy
import numpy as np
import pytest
from bpy_helpers import poly_curve, scene_state, spline_points, world_mesh

from tests.mesh_checks import crossings


def keyed(mb, obj):
    """(frames, points per frame) of the flow keyed on ``obj``."""
    frames, points, _ = import_module(mb.__name__ + ".keyframes").read_flow_keyframes(obj)
    return frames, points


@pytest.fixture
def trefoil(scene, mb):
    bpy.ops.moebius.add_knot(kind="3_1", edges=60)
    return bpy.context.active_object


@pytest.fixture
def ring_and_torus(scene, mb):
    """A torus in a collection 'Obstacles' (moved and scaled: world coordinates matter) and a
    converted ring around its tube (a curve object with its own transform)."""
    coll = bpy.data.collections.new("Obstacles")
    scene.collection.children.link(coll)
    bpy.ops.mesh.primitive_torus_add(major_radius=1.0, minor_radius=0.3, major_segments=24,
                                     minor_segments=10, location=(0.5, 0.0, 0.0))
    torus = bpy.context.active_object
    torus.scale = (1.2, 1.2, 1.2)
    for c in torus.users_collection:
        c.objects.unlink(torus)
    coll.objects.link(torus)
    t = np.linspace(0, 2 * np.pi, 80, endpoint=False)
    ring = np.stack([1.7 + 0.65 * np.cos(t) + 0.1 * np.cos(3 * t), 0.15 * np.sin(5 * t),
                     0.65 * np.sin(t)], -1)
    # the curve object sits at +1 in x, its points 1 less: the same place in the world
    mb_core = import_module(mb.__name__.rsplit(".", 1)[0] + ".core")
    ring = mb_core.resample(ring, 80) - np.array([1.0, 0.0, 0.0])
    obj = poly_curve("Ring", [ring])
    obj.location = (1.0, 0.0, 0.0)
    bpy.context.view_layer.update()
    return obj, torus, coll


def test_selected_points_stay_where_they_are(scene, mb, trefoil):
    pts = trefoil.data.splines[0].points
    for p in pts:
        p.select = False
    for i in (0, 1, 20, 41):
        pts[i].select = True
    start = spline_points(trefoil).copy()
    s = scene.moebius
    s.pin_selected = True
    s.method = "projected_gradient"
    s.max_iterations = 6
    assert bpy.ops.moebius.relax() == {"FINISHED"}
    frames, points = keyed(mb, trefoil)
    assert len(frames) == 7
    moved = np.linalg.norm(points[-1] - start, axis=1)
    assert np.all(moved[[0, 1, 20, 41]] == 0.0)  # exact
    assert moved.max() > 1e-3  # the rest relaxed
    assert s.last_energy_end < s.last_energy_start


def test_pins_without_a_selection_or_with_a_penalty_method_are_refused(scene, mb, trefoil):
    for p in trefoil.data.splines[0].points:
        p.select = False
    before = scene_state()
    with pytest.raises(ValueError, match="Pin Selected Points is on, but no point of '.+' is "
                                         "selected: select the points to pin in Edit Mode"):
        mb.relax_object(trefoil, max_iterations=2, pin_selected=True)
    trefoil.data.splines[0].points[3].select = True
    with pytest.raises(ValueError, match="projected_gradient"):
        mb.relax_object(trefoil, max_iterations=2, pin_selected=True, method="lbfgs")
    assert scene_state() == before


def test_the_ring_never_enters_the_torus(scene, mb, ring_and_torus):
    ring, torus, coll = ring_and_torus
    V, F = world_mesh(torus)
    M = np.array(ring.matrix_world)
    world = lambda P: P @ M[:3, :3].T + M[:3, 3]  # noqa: E731
    # in the ring's own coordinates (1 less in x) the tube would cut it: the obstacle must be
    # mapped into them, or this start would be refused
    assert crossings(world(spline_points(ring)), V, F) == 0
    assert crossings(spline_points(ring), V, F) > 0
    s = scene.moebius
    s.obstacles = coll
    s.method = "projected_gradient"
    s.max_iterations = 12
    assert bpy.ops.moebius.relax() == {"FINISHED"}
    frames, points = keyed(mb, ring)
    assert len(frames) == 13
    for P in points:
        assert crossings(world(P), V, F) == 0
    assert s.last_energy_end < s.last_energy_start
    # the ring still goes around the tube: it meets the plane y = 0 on both sides of the
    # tube's core point (1.7, 0, 0)
    P = world(points[-1])
    Q = np.roll(P, -1, axis=0)
    cross = (P[:, 1] <= 0) != (Q[:, 1] <= 0)
    x = P[cross, 0] + (Q[cross, 0] - P[cross, 0]) * (-P[cross, 1]) / (Q[cross, 1] - P[cross, 1])
    assert np.any(x < 1.7) and np.any(x > 1.7)


def test_obstacles_as_objects_and_bad_obstacles(scene, mb, ring_and_torus):
    ring, torus, coll = ring_and_torus
    r = mb.relax_object(ring, max_iterations=3, method="projected_gradient", obstacles=[torus])
    assert r.nit == 3
    empty = bpy.data.collections.new("Empty")
    before = scene_state()
    with pytest.raises(ValueError, match="collection 'Empty' holds no mesh object"):
        mb.relax_object(ring, max_iterations=2, obstacles=empty)
    # a torus moved onto the ring: the start crosses it, refused naming where, the obstacle
    # by its object's name
    torus.location = (1.7, 0.0, 0.0)
    torus.scale = (0.65, 0.65, 2.0)
    bpy.context.view_layer.update()
    with pytest.raises(ValueError, match=r"crosses an obstacle: edge \d+ passes through "
                                         rf"triangle \d+ of obstacle '{torus.name}'; move the "
                                         rf"curve or obstacle '{torus.name}'"):
        mb.relax_object(ring, max_iterations=2, obstacles=coll)
    after = scene_state()
    assert after["curves"] == before["curves"] and after["Ring/0"] == before["Ring/0"]


def test_an_open_spline_relaxes_with_its_ends_pinned(scene, mb):
    # an open coil of two turns: Relax takes open poly splines (the core's closed=False)
    t = np.linspace(0, 4 * np.pi, 60)
    P = np.stack([np.cos(t), np.sin(t), 0.25 * t], -1)
    obj = poly_curve("Cable", [P], cyclic=False)
    for i, p in enumerate(obj.data.splines[0].points):
        p.select = i in (0, len(P) - 1)
    start = spline_points(obj).copy()
    settings = scene.moebius
    settings.pin_selected = True
    settings.max_iterations = 15
    before = scene_state()
    with pytest.raises(RuntimeError, match="lbfgs.* cannot (keep pinned|relax open)"):
        settings.method = "lbfgs"
        bpy.ops.moebius.relax()
    assert scene_state() == before
    settings.method = "auto"
    assert bpy.ops.moebius.relax() == {"FINISHED"}
    assert settings.last_method == "projected_gradient" and settings.last_engine == "exact"
    assert "open curve" in settings.last_type
    frames, points = keyed(mb, obj)
    assert len(frames) == 16 and not obj.data.splines[0].use_cyclic_u
    ends = [0, len(P) - 1]
    assert all(np.array_equal(Q[ends], start[ends]) for Q in points)  # exact
    assert np.abs(points[-1] - start).max() > 1e-2
    assert settings.last_energy_end < settings.last_energy_start
    core = import_module(mb.__name__.rsplit(".", 1)[0] + ".core")
    for Q in points:  # no frame touches itself (the start check of an open curve)
        core.check_polygon(Q.astype(np.float64), closed=False, coarseness=False)


def test_convert_keeps_an_open_spline_open_with_its_ends(scene, mb):
    # a drawn open Bezier curve: refused as before unless 'Keep Open Splines' is on; then an
    # open equal-edge poly spline whose two ends are the drawn ends
    curve = bpy.data.curves.new("Drawn", "CURVE")
    curve.dimensions = "3D"
    s = curve.splines.new("BEZIER")
    s.bezier_points.add(3)
    for p, co in zip(s.bezier_points, [(0, 0, 0), (1, 1, 0.3), (2, -1, -0.3), (3, 0, 0)],
                     strict=True):
        p.co = co
        p.handle_left_type = p.handle_right_type = "AUTO"
    obj = bpy.data.objects.new("Drawn", curve)
    scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    obj.select_set(True)
    settings = scene.moebius
    settings.edges = 40
    before = scene_state()
    with pytest.raises(RuntimeError, match="enable 'Keep open splines'"):
        bpy.ops.moebius.convert()
    assert scene_state() == before
    settings.keep_open = True
    assert bpy.ops.moebius.convert() == {"FINISHED"}
    new = bpy.context.active_object
    spline = new.data.splines[0]
    assert spline.type == "POLY" and not spline.use_cyclic_u and len(spline.points) == 40
    X = spline_points(new)
    assert np.allclose(X[0], (0, 0, 0), atol=1e-6) and np.allclose(X[-1], (3, 0, 0), atol=1e-6)
    lengths = np.linalg.norm(np.diff(X, axis=0), axis=1)
    assert np.ptp(lengths) < 1e-5 * lengths.mean()  # equal edges, no closing edge
    energy = new["moebius_energy"]
    r = mb.relax_object(new, max_iterations=5, pinned=[0, 39])
    assert r.nit == 5 and r.fun < energy
    assert np.array_equal(spline_points(new)[[0, 39]], X[[0, 39]])


def test_cli_keeps_and_relaxes_an_open_curve(scene, mb, tmp_path, capfd):
    cli = import_module(mb.__name__ + ".cli")
    t = np.linspace(0, 4 * np.pi, 80)
    P = np.stack([np.cos(t), np.sin(t), 0.25 * t], -1)
    poly_curve("Coil", [P], cyclic=False)
    blend = tmp_path / "coil.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    capfd.readouterr()
    assert cli.main(["--open", str(blend), "--object", "Coil", "--max-iterations", "2"]) == 1
    assert "enable 'Keep open splines'" in capfd.readouterr().err
    assert cli.main(["--open", str(blend), "--object", "Coil", "--keep-open", "--edges", "60",
                     "--max-iterations", "4"]) == 0
    out = capfd.readouterr().out
    assert "projected_gradient (an open curve), exact engine, 4 iterations" in out
    assert "an open curve has no knot type" in out
    new = bpy.context.active_object
    assert not new.data.splines[0].use_cyclic_u and len(new.data.splines[0].points) == 60
