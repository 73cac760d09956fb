"""moebius.convert on real curve and mesh objects, and the Add ▸ Curve ▸ Knot catalogue."""

import bpy
import numpy as np
import pytest
from bpy_helpers import points_at, poly_curve


def _edge_lengths(P):
    return np.linalg.norm(np.roll(P, -1, axis=0) - P, axis=1)


def _assert_equilateral(P, what=""):
    # Blender stores curve points in float32: lengths agree to float32 rounding of coordinates
    e = _edge_lengths(P)
    assert np.ptp(e) < 1e-6 * np.abs(P).max(), what


def _converted(obj):
    assert obj.type == "CURVE"
    return [np.array([p.co[:3] for p in s.points]) for s in obj.data.splines]


@pytest.mark.lines
@pytest.mark.parametrize("add", ["bezier", "nurbs"])
def test_convert_smooth_curve(scene, mb, add):
    if add == "bezier":
        bpy.ops.curve.primitive_bezier_circle_add(radius=1.5, location=(1, 2, 3),
                                                  rotation=(0.3, 0.2, 0.1))
    else:
        bpy.ops.curve.primitive_nurbs_circle_add(radius=1.5, location=(1, 2, 3),
                                                 rotation=(0.3, 0.2, 0.1))
    src = bpy.context.active_object
    scene.moebius.edges = 48
    assert bpy.ops.moebius.convert() == {"FINISHED"}
    new = bpy.context.active_object
    assert new is not src and new.name == f"{src.name}.moebius"
    assert new["moebius_source"] == src.name
    (P,) = _converted(new)
    spline = new.data.splines[0]
    assert spline.type == "POLY" and spline.use_cyclic_u and len(P) == 48
    _assert_equilateral(P)
    # same transform; the circle lies on radius 1.5 in object space (NURBS circles lie inside
    # their control polygon, Bézier circles are within 0.1 % of round)
    np.testing.assert_allclose(np.array(new.matrix_world), np.array(src.matrix_world))
    r = np.linalg.norm(P[:, :2], axis=1)
    assert np.all(np.abs(P[:, 2]) < 1e-6)
    assert np.all(np.abs(r - r.mean()) < 0.01 * r.mean()) and 1.0 < r.mean() <= 1.51
    # original kept, hidden in viewport and render
    assert src.name in bpy.data.objects and src.hide_get() and src.hide_render
    assert 3.99 < new["moebius_energy"] < 4.01  # a round circle has energy 4


def test_convert_poly_curve_keeps_vertices_on_the_polyline(scene, mb):
    square = np.array([[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0]], float)
    poly_curve("Square", [square])
    scene.moebius.edges = 16
    bpy.ops.moebius.convert()
    (P,) = _converted(bpy.context.active_object)
    assert len(P) == 16
    np.testing.assert_allclose(_edge_lengths(P), 0.5, rtol=2e-6)
    on_side = np.isclose(P, 0, atol=1e-6) | np.isclose(P, 2, atol=1e-6)
    assert (on_side[:, 0] | on_side[:, 1]).all()


def test_convert_sharp_cornered_poly_curve_gives_equal_edges(scene, mb):
    # a ten-pointed star has no equal-chord polygon on it at 97 edges: the conversion came back
    # with one edge 2.27 times the others, which the flow then kept to the end
    ang = np.arange(10) * 2 * np.pi / 10
    r = np.where(np.arange(10) % 2 == 0, 1.0, 0.4)
    poly_curve("Star", [np.c_[r * np.cos(ang), r * np.sin(ang), 0.05 * np.cos(3 * ang)]])
    scene.moebius.edges = 97
    assert bpy.ops.moebius.convert() == {"FINISHED"}
    (P,) = _converted(bpy.context.active_object)
    assert len(P) == 97
    _assert_equilateral(P)


@pytest.mark.lines
def test_convert_mesh_edge_loop_and_edge_length(scene, mb):
    bpy.ops.mesh.primitive_circle_add(vertices=32, radius=1.0, fill_type="NOTHING")
    scene.moebius.use_edge_length = True
    scene.moebius.edge_length = 2 * np.pi / 40
    assert bpy.ops.moebius.convert() == {"FINISHED"}
    (P,) = _converted(bpy.context.active_object)
    assert 38 <= len(P) <= 40  # the 32-gon is a little shorter than the circle


@pytest.mark.lines
def test_convert_two_splines_gives_a_link(scene, mb):
    t = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    a = np.column_stack([np.cos(t), np.sin(t), 0 * t])
    b = np.column_stack([1 + np.cos(t), 0 * t, np.sin(t)])  # Hopf link
    poly_curve("Hopf", [a, b])
    scene.moebius.edges = 30
    bpy.ops.moebius.convert()
    link = _converted(bpy.context.active_object)
    assert [len(P) for P in link] == [30, 30]


@pytest.mark.lines
def test_convert_obj_polyline_import(scene, mb, core, tmp_path):
    from importlib import import_module

    knots = import_module(core.__name__ + ".topology.knots")
    objio = import_module(core.__name__ + ".geometry.objio")
    P = knots.torus_knot(2, 3, 90)
    path = tmp_path / "trefoil.obj"
    objio.write_obj(path, P)
    bpy.ops.wm.obj_import(filepath=str(path))
    mesh = bpy.context.selected_objects[0]
    assert mesh.type == "MESH" and len(mesh.data.polygons) == 0
    scene.moebius.edges = 90
    assert bpy.ops.moebius.convert() == {"FINISHED"}
    new = bpy.context.active_object
    Q = points_at(new, scene.frame_current)
    # the OBJ importer turns Y-up into Z-up; compare in the world frame
    M = np.array(mesh.matrix_world)
    P_world = P @ M[:3, :3].T + M[:3, 3]
    assert np.abs(np.sort(np.linalg.norm(Q - Q.mean(0), axis=1))
                  - np.sort(np.linalg.norm(P_world - P_world.mean(0), axis=1))).max() < 0.05


def test_converted_curves_are_visible_in_a_render(scene, mb):
    # a drawn curve has no bevel, and the converted one copied it: the first F12 showed nothing
    bpy.ops.curve.primitive_bezier_circle_add(radius=3.0)
    assert bpy.context.active_object.data.bevel_depth == 0.0
    assert bpy.ops.moebius.convert() == {"FINISHED"}
    new = bpy.context.active_object
    assert new.data.bevel_depth == pytest.approx(0.01 * 6.0, rel=1e-3)  # 1% of its extent
    # a source with a bevel of its own keeps it
    bpy.ops.curve.primitive_nurbs_circle_add()
    bpy.context.active_object.data.bevel_depth = 0.123
    assert bpy.ops.moebius.convert() == {"FINISHED"}
    assert bpy.context.active_object.data.bevel_depth == pytest.approx(0.123)


def test_close_open_splines_option(scene, mb):
    t = np.linspace(0, 1.5 * np.pi, 20)
    arc = np.column_stack([np.cos(t), np.sin(t), 0 * t])
    poly_curve("Arc", [arc], cyclic=False)
    scene.moebius.close_open = True
    scene.moebius.edges = 24
    assert bpy.ops.moebius.convert() == {"FINISHED"}
    assert bpy.context.active_object.data.splines[0].use_cyclic_u


def test_add_knot_catalogue_entries(scene, mb, core):
    # every generator, and a seeded sample of the 7 166 table entries (tests/blender/
    # test_catalogue.py has more; tools/verify_knot_table.py checks every curve in the core)
    from importlib import import_module

    knots = import_module(core.__name__ + ".topology.knots")
    rng = np.random.default_rng(3)
    table = knots.names()
    kinds = ["fhw", "helix", "random", "torus", "circle", "figure_eight", "3_1", "m3_1",
             "L6a4{0,0}", *(table[i] for i in rng.choice(len(table), 6, replace=False))]
    for kind in kinds:
        assert bpy.ops.moebius.add_knot(kind=kind) == {"FINISHED"}, kind
        obj = bpy.context.active_object
        polys = mb.curve_polygons(obj)
        for P in polys:
            _assert_equilateral(P, kind)
        core.check_polygon(polys[0] if len(polys) == 1 else polys)
        size = np.ptp(np.concatenate(polys), axis=0).max()
        assert abs(size - 2.0) < 1e-6, kind
        assert obj["moebius_energy"] >= 4.0 - 1e-9


@pytest.mark.lines
def test_add_knot_menu_entry(mb):
    draw_funcs = bpy.types.VIEW3D_MT_curve_add.draw._draw_funcs
    assert any(f.__module__.endswith("moebius_addon.blender.operators") for f in draw_funcs)
