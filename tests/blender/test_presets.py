"""Presets of the panel and length growth in Blender: each preset sets what it says;
a growth run inside a container keys frames that stay inside and whose length grows; bad input
is refused with the scene unchanged."""

from importlib import import_module

import bmesh
import bpy
import numpy as np
import pytest
from bpy_helpers import poly_curve, scene_state, world_mesh

from tests.mesh_checks import crossings, ray_parity_inside


def _options(mb):
    return import_module(mb.__name__ + ".options")


def polyline_length(P, closed):
    P = np.vstack([P, P[:1]]) if closed else P
    return float(np.linalg.norm(np.diff(P, axis=0), axis=1).sum())


def _core(mb):
    return import_module(mb.__name__.rsplit(".", 1)[0] + ".core")


def _cables(mb):
    """Two open cables side by side (equal edges: as converted) and a collection 'Obstacles'
    with a cube between them."""
    t = np.linspace(0, 1, 200)
    resample = _core(mb).resample
    a = resample(np.c_[4 * t, 0.3 * np.sin(3 * np.pi * t), 0 * t], 30, closed=False)
    b = resample(np.c_[4 * t, 1.0 + 0.2 * np.sin(2 * np.pi * t), 0.1 + 0 * t], 30,
                 closed=False)
    obstacles = bpy.data.collections.new("Obstacles")
    bpy.context.scene.collection.children.link(obstacles)
    bpy.ops.mesh.primitive_cube_add(size=0.3, location=(2.0, 0.5, 1.0))
    cube = bpy.context.active_object
    for c in cube.users_collection:
        c.objects.unlink(cube)
    obstacles.objects.link(cube)
    return poly_curve("Cables", [a, b], cyclic=False), obstacles


def test_untangle_cables_keeps_them_open_pins_the_ends_and_takes_the_obstacles(scene, mb):
    obj, obstacles = _cables(mb)
    s = scene.moebius
    s.close_open = True  # the preset turns what contradicts it off
    assert bpy.ops.moebius.apply_preset(preset="untangle_cables") == {"FINISHED"}
    assert s.keep_open and not s.close_open and s.pin_selected and not s.use_length_target
    assert s.method == "projected_gradient" and s.obstacles == obstacles
    assert s.theta == pytest.approx(0.3)  # the tree's far field looser than for knots
    for spline in obj.data.splines:  # exactly the two ends of each cable selected
        sel = [p.select for p in spline.points]
        assert sel[0] and sel[-1] and not any(sel[1:-1])
    pts = [np.array([p.co[:3] for p in sp.points]) for sp in obj.data.splines]
    mean_edge = sum(polyline_length(P, False) for P in pts) / sum(len(P) - 1 for P in pts)
    assert obj.data.bevel_depth == pytest.approx(
        _options(mb).BEVEL_EDGES * mean_edge, rel=1e-5)  # the result renders as a tube
    # the settings are the user's again: a change sticks, and the cables relax with them
    s.max_iterations = 3
    assert bpy.ops.moebius.relax() == {"FINISHED"}
    for spline, P in zip(obj.data.splines, pts, strict=True):
        Q = np.array([p.co[:3] for p in spline.points])
        assert not spline.use_cyclic_u
        assert np.allclose(Q[[0, -1]], P[[0, -1]], atol=1e-6)  # the ends stay
    assert s.last_iterations == 3


def test_pack_in_volume_grows_and_relax_knot_restores_the_defaults(scene, mb):
    t = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    obj = poly_curve("Loop", [np.c_[np.cos(t), np.sin(t), 0.2 * np.sin(3 * t)]])
    L = polyline_length(np.array([p.co[:3] for p in obj.data.splines[0].points]), True)
    s = scene.moebius
    s.pin_selected = True
    assert bpy.ops.moebius.apply_preset(preset="pack_in_volume") == {"FINISHED"}
    opts = _options(mb)
    assert s.use_length_target and s.length_growth == pytest.approx(1.0)
    assert s.length_target == pytest.approx(opts.PACK_LENGTH_FACTOR * L, rel=1e-5)
    assert s.method == "projected_gradient" and not s.pin_selected and s.max_iterations == 400
    assert obj.data.bevel_depth == pytest.approx(opts.BEVEL_EDGES * L / 60, rel=1e-5)
    kwargs = mb.relax_settings(s)  # what Relax passes on: the percent as the core's fraction
    assert kwargs["length_target"] == pytest.approx(s.length_target)
    assert kwargs["length_growth"] == pytest.approx(0.01)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=3.0)
    s.container = bpy.context.active_object
    bpy.context.view_layer.objects.active = obj
    assert bpy.ops.moebius.apply_preset(preset="relax_knot") == {"FINISHED"}
    props = type(s).bl_rna.properties
    for key in opts.PRESET_SETTINGS:
        if props[key].type == "POINTER":
            assert getattr(s, key) is None, key
        else:
            assert getattr(s, key) == pytest.approx(props[key].default), key
    assert not s.use_length_target and s.container is None


def test_a_preset_in_edit_mode_is_refused_with_nothing_changed(scene, mb):
    _cables(mb)
    bpy.ops.object.mode_set(mode="EDIT")
    s = scene.moebius
    with pytest.raises(RuntimeError, match="is in Edit Mode"):
        bpy.ops.moebius.apply_preset(preset="untangle_cables")
    assert not s.keep_open and not s.pin_selected
    bpy.ops.object.mode_set(mode="OBJECT")


@pytest.fixture
def loop_in_sphere(scene, mb):
    """A wavy loop (60 edges) inside a UV sphere of radius 0.8, both moved off the origin."""
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.8, segments=24, ring_count=12,
                                         location=(0.3, 0.0, 0.0))
    sphere = bpy.context.active_object
    t = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    P = _core(mb).resample(np.stack([0.6 * np.cos(t), 0.6 * np.sin(t), 0.25 * np.sin(5 * t)], -1),
                      60)
    obj = poly_curve("Loop", [P])
    obj.location = (0.3, 0.0, 0.0)
    bpy.context.view_layer.objects.active = obj
    bpy.context.view_layer.update()
    return obj, sphere, polyline_length(P, True)


def test_a_growth_run_inside_a_container_keys_frames_inside_that_grow(scene, mb,
                                                                      loop_in_sphere):
    obj, sphere, L0 = loop_in_sphere
    V, F = world_mesh(sphere)
    s = scene.moebius
    assert bpy.ops.moebius.apply_preset(preset="pack_in_volume") == {"FINISHED"}
    s.container = sphere
    s.length_target = 1.5 * L0  # more than the sphere's great circle (5.03): it must fold
    s.length_growth = 4.0
    s.max_iterations = 20
    assert bpy.ops.moebius.relax() == {"FINISHED"}
    frames, points, _ = import_module(mb.__name__ + ".keyframes").read_flow_keyframes(obj)
    assert len(frames) == 21
    M = np.array(obj.matrix_world)
    world = [P @ M[:3, :3].T + M[:3, 3] for P in points]
    lengths = np.array([polyline_length(P, True) for P in points])
    # keyed in single precision: lengths to about 1e-6
    assert np.all(np.diff(lengths) >= -1e-5 * L0)
    assert lengths[-1] == pytest.approx(1.5 * L0, rel=1e-5)
    assert lengths[-1] > 2 * np.pi * 0.8
    rng = np.random.default_rng(0)
    for P in world:
        assert ray_parity_inside(P, V, F, rng).all()
    for A, B in zip(world[:-1], world[1:], strict=True):  # the straight moves between keys
        assert not any(crossings(p, V, F, closed=False) for p in np.stack([A, B], 1))
        for u in np.linspace(0, 1, 5)[1:-1]:
            assert crossings(A + u * (B - A), V, F) == 0


def test_bad_growth_input_is_refused_with_the_scene_unchanged(scene, mb, loop_in_sphere):
    obj, sphere, L0 = loop_in_sphere
    s = scene.moebius
    s.method = "projected_gradient"
    s.max_iterations = 2
    s.use_length_target = True
    s.length_target = 2 * L0
    s.container = sphere
    s.length_growth = 0.0
    before = scene_state()
    with pytest.raises(RuntimeError, match="length_growth must be a finite number > 0"):
        bpy.ops.moebius.relax()
    assert scene_state() == before
    s.length_growth = 1.0
    s.length_target = 0.5 * L0
    with pytest.raises(RuntimeError, match="below the curve's length at the start"):
        bpy.ops.moebius.relax()
    assert scene_state() == before
    s.length_target = 2 * L0
    for method, label in (("trust_region", "Trust Region"),
                          ("projected_gradient_implicit", "Implicit Gradient")):
        s.method = method  # refused by the panel's names, not the core's
        with pytest.raises(RuntimeError, match=f"Method: {label} cannot grow the curve's "
                           r"length \(Length Target\): choose Projected Gradient"):
            bpy.ops.moebius.relax()
        assert scene_state() == before
    s.method = "projected_gradient"
    bm = bmesh.new()  # a hole in the container
    bm.from_mesh(sphere.data)
    bm.faces.ensure_lookup_table()
    bmesh.ops.delete(bm, geom=[bm.faces[0]], context="FACES_ONLY")
    bm.to_mesh(sphere.data)
    bm.free()
    before = scene_state()
    with pytest.raises(RuntimeError, match="the container is not closed"):
        bpy.ops.moebius.relax()
    assert scene_state() == before


def test_pins_on_every_point_of_a_cable_are_refused_with_the_scene_unchanged(scene, mb):
    t = np.linspace(0, 1, 200)
    P = _core(mb).resample(np.c_[3 * t, 0.3 * np.sin(3 * np.pi * t), 0 * t], 20, closed=False)
    obj = poly_curve("Cable", [P], cyclic=False)
    s = scene.moebius
    assert bpy.ops.moebius.apply_preset(preset="untangle_cables") == {"FINISHED"}
    for p in obj.data.splines[0].points:
        p.select = True
    before = scene_state()
    with pytest.raises(RuntimeError, match="every vertex is pinned"):
        bpy.ops.moebius.relax()
    assert scene_state() == before
    assert s.pin_selected


def test_the_command_line_grows_inside_a_container_and_pins_cable_ends(scene, mb, tmp_path,
                                                                          loop_in_sphere, capfd):
    # the scene constraints the panel has, from the command line (it had none)
    cli = import_module(mb.__name__ + ".cli")
    obj, sphere, L0 = loop_in_sphere
    ball = sphere.name
    blend, out = tmp_path / "scene.blend", tmp_path / "grown.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    rc = cli.main(["--open", str(blend), "--object", "Loop", "--container", ball,
                   "--length-target", str(1.3 * L0), "--length-growth", "0.05",
                   "--max-iter", "8", "--save", str(out)])
    assert rc == 0, capfd.readouterr().err
    assert "length growth" in capfd.readouterr().out  # Automatic took the explicit method
    bpy.ops.wm.open_mainfile(filepath=str(out))
    obj, sphere = bpy.data.objects["Loop"], bpy.data.objects[ball]
    V, F = world_mesh(sphere)
    frames, points, _ = import_module(mb.__name__ + ".keyframes").read_flow_keyframes(obj)
    lengths = [polyline_length(P, True) for P in points]
    assert len(frames) == 9 and lengths[-1] == pytest.approx(1.3 * L0, rel=1e-5)
    M = np.array(obj.matrix_world)
    rng = np.random.default_rng(1)
    for P in points:
        assert ray_parity_inside(P @ M[:3, :3].T + M[:3, 3], V, F, rng).all()
    # a cable with its ends pinned; names that are not there, and growth without a target,
    # refused before anything is added or saved
    bpy.ops.wm.read_homefile(use_empty=True)
    cable = poly_curve("Cable", [np.c_[np.linspace(-1, 1, 41), 0.1 * np.sin(np.linspace(
        0, 9, 41)), np.zeros(41)]], cyclic=False)
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    rc = cli.main(["--open", str(blend), "--object", cable.name, "--keep-open", "--edges",
                   "40", "--pin-ends", "--max-iter", "3", "--save", str(out)])
    assert rc == 0, capfd.readouterr().err
    bpy.ops.wm.open_mainfile(filepath=str(out))
    frames, points, _ = import_module(mb.__name__ + ".keyframes").read_flow_keyframes(
        bpy.data.objects["Cable.moebius"])  # the converted copy (the original is kept)
    assert len(frames) == 4 and np.abs(points[-1] - points[0]).max() > 1e-3
    for P in points:  # the ends never moved (keyed in single precision)
        np.testing.assert_allclose(P[[0, -1]], points[0][[0, -1]], atol=1e-6)
    capfd.readouterr()
    for argv, words in ((["--container", "Nope"], "--container 'Nope': no such object"),
                        (["--obstacles", "Nope"], "--obstacles 'Nope': no such object"),
                        (["--length-growth", "0.1"], "--length-growth needs --length-target")):
        assert cli.main(["--open", str(blend), "--object", "Cable", "--keep-open",
                         "--save", str(tmp_path / "never.blend"), *argv]) == 1
        assert words in capfd.readouterr().err
        assert not (tmp_path / "never.blend").exists()
