"""Alembic/USD round trips of the keyframed flow, the gradient fields, the CLI command, panel."""

import bpy
import numpy as np
import pytest
from bpy_helpers import imported_points as _imported_points
from bpy_helpers import points_at


@pytest.fixture
def relaxed(scene, mb):
    bpy.ops.moebius.add_knot(kind="3_1", edges=60)
    obj = bpy.context.active_object
    obj.location = (0.5, -1.0, 2.0)  # exports must carry the transform too
    obj.rotation_euler = (0.2, 0.0, 0.4)
    scene.moebius.max_iterations = 5
    scene.moebius.tolerance = 0.0
    bpy.ops.moebius.relax()
    assert mb.keyed_frames(obj) == [1, 2, 3, 4, 5, 6]
    return obj


@pytest.mark.lines
@pytest.mark.parametrize("suffix", [".abc", ".usda"])
def test_export_round_trip(relaxed, mb, tmp_path, suffix):
    keyed = mb.keyed_frames(relaxed)
    frames = [keyed[0], keyed[2], keyed[-1]]
    expected = {f: points_at(relaxed, f) for f in frames}
    assert np.abs(expected[frames[0]] - expected[frames[-1]]).max() > 1e-3
    path = mb.export_flow(relaxed, tmp_path / f"flow{suffix}")
    assert path.stat().st_size > 0
    bpy.ops.wm.read_homefile(use_empty=True)
    if suffix == ".abc":
        bpy.ops.wm.alembic_import(filepath=str(path))
    else:
        bpy.ops.wm.usd_import(filepath=str(path))
    for f in frames:
        X, curves = _imported_points(f)
        assert len(X) == 60
        np.testing.assert_allclose(X, expected[f], atol=1e-5)
    assert bool(curves.attributes["cyclic"].data[0].value)


def test_unknown_export_format_is_refused_before_any_change(relaxed, mb, tmp_path):
    target = tmp_path / "new_dir" / "flow.obj"
    with pytest.raises(ValueError, match=r"unknown export format '\.obj'.*use \.abc"):
        mb.api.export_flow(relaxed, target)
    assert not target.parent.exists()  # the folder was created before the refusal


def test_show_gradient_arrows(scene, mb, core):
    bpy.ops.moebius.add_knot(kind="3_1", edges=60)
    knot = bpy.context.active_object
    assert bpy.ops.moebius.show_gradient(length=0.2) == {"FINISHED"}
    P = mb.curve_polygons(knot)[0]
    diagonal = np.linalg.norm(np.ptp(P, axis=0))
    for metric in ("l2", "hs_pure", "hs"):
        arrows = bpy.data.objects[f"{knot.name}.grad.{metric}"]
        mesh = arrows.data
        assert arrows.parent == knot and len(mesh.edges) == 60 and len(mesh.vertices) == 120
        V = np.array([v.co[:] for v in mesh.vertices])
        D = V[60:] - V[:60]
        G = core.sobolev_gradient(P, metric=metric, projected=True)
        scale = arrows["moebius_arrow_scale"]
        np.testing.assert_allclose(D, scale * G, atol=1e-5 * diagonal)
        assert np.linalg.norm(D, axis=1).max() == pytest.approx(0.2 * diagonal, rel=1e-5)
    # running it again replaces, not duplicates
    bpy.context.view_layer.objects.active = knot
    bpy.ops.moebius.show_gradient(l2=False, hs_pure=False)
    assert len([o for o in bpy.data.objects if ".grad." in o.name]) == 3


def _field(knot, metric):
    arrows = bpy.data.objects[f"{knot.name}.grad.{metric}"]
    V = np.array([v.co[:] for v in arrows.data.vertices])
    n = len(V) // 2
    return V[:n], V[n:] - V[:n], arrows["moebius_arrow_scale"]


def test_gradient_fields_follow_the_relaxed_curve(scene, mb, core):
    # the arrows stayed at the start after a relax, showing a stale field
    bpy.ops.moebius.add_knot(kind="3_1", edges=60)
    knot = bpy.context.active_object
    start = mb.curve_polygons(knot)[0]
    bpy.ops.moebius.show_gradient(l2=False, hs_pure=False, length=0.2, projected=False)
    scene.moebius.max_iterations = 3
    scene.moebius.tolerance = 0.0
    assert bpy.ops.moebius.relax() == {"FINISHED"}
    for shape in ("relaxed", "cleared"):
        P = mb.curve_polygons(knot)[0]
        assert np.abs(P - start).max() > 1e-3 if shape == "relaxed" else np.allclose(P, start)
        tails, D, scale = _field(knot, "hs")
        np.testing.assert_allclose(tails, P, atol=1e-6)
        G = core.sobolev_gradient(P, metric="hs", projected=False)  # as it was drawn
        np.testing.assert_allclose(D, scale * G, atol=1e-5 * np.abs(scale * G).max())
        assert np.linalg.norm(D, axis=1).max() == pytest.approx(
            0.2 * np.linalg.norm(np.ptp(P, axis=0)), rel=1e-5)
        assert [o.name for o in knot.children] == [f"{knot.name}.grad.hs"]
        bpy.context.view_layer.objects.active = knot
        bpy.ops.moebius.clear_animation()


@pytest.mark.lines
def test_cli_command(scene, mb, tmp_path, capfd):
    from importlib import import_module

    cli = import_module(mb.__name__ + ".cli")
    assert cli._handle is not None  # registered with bpy.utils.register_cli_command
    blend, abc = tmp_path / "knot.blend", tmp_path / "knot.abc"
    bpy.ops.mesh.primitive_cube_add()  # the scene the command starts in is not saved
    capfd.readouterr()
    rc = cli.main(["--knot", "3_1", "--edges", "60", "--max-iterations", "3",
                   "--save", str(blend), "--export", str(abc)])
    assert rc == 0 and blend.stat().st_size > 0 and abc.stat().st_size > 0
    out = capfd.readouterr().out
    # the keyed frames (was the scene's range, "frames 1-250"), no line per iterate by default
    assert "3 iterations" in out and "keyed frames 1-4 (" in out and "iteration 1/" not in out
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    assert [o.name for o in bpy.data.objects] == ["Knot 3_1"]  # no Cube, Camera or Light
    bpy.ops.wm.read_homefile(use_empty=True)
    # both spellings of the limit; a line per iterate with --verbose
    rc = cli.main(["--open", str(blend), "--object", "Knot 3_1", "--max-iter", "2",
                   "--frame-start", "5", "--save", str(blend), "--verbose"])
    assert rc == 0
    out = capfd.readouterr().out
    assert "moebius: 'Knot 3_1' iteration 1/2, energy" in out and "iteration 2/2" in out
    assert "keyed frames 5-7 (maximum number of iterations (2) reached)" in out
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    assert mb.keyed_frames(bpy.data.objects["Knot 3_1"]) == [5.0, 6.0, 7.0]
    assert cli.main(["--knot", "3_1", "--edges", "60", "--max-iterations", "1", "--quiet"]) == 0
    assert "moebius" not in capfd.readouterr().out
    assert cli.main(["--help"]) == 0
    out = " ".join(capfd.readouterr().out.split())
    assert "(default 200)" in out and "(default 1e-06)" in out and "--verbose" in out
    assert bpy.context.scene.frame_start <= 5 and bpy.context.scene.frame_end >= 7
    assert cli.main(["--object", "Nope"]) == 1
    assert cli.main(["--knot", "no_such_knot"]) == 1
    assert cli.main(["--bogus"]) == 2
    # options named as the command line names them (was "tol must be …" for --tolerance)
    capfd.readouterr()
    assert cli.main(["--knot", "3_1", "--tolerance", "nan"]) == 1
    err = capfd.readouterr().err
    assert "moebius: error: tolerance must be a finite number >= 0, got nan" in err
    with pytest.raises(ValueError, match="tolerance must be a finite number >= 0, got nan"):
        mb.api.relax_object(bpy.context.active_object, tolerance=float("nan"))
    with pytest.raises(ValueError, match="keyframe_stride must be a finite number >= 1"):
        mb.api.relax_object(bpy.context.active_object, keyframe_stride=0)
    # an unknown export format is refused before the knot is added or anything is saved
    objects = len(bpy.data.objects)
    other = tmp_path / "other.blend"
    assert cli.main(["--knot", "3_1", "--save", str(other), "--export", "x.obj"]) == 1
    assert len(bpy.data.objects) == objects and not other.exists()


@pytest.mark.lines
def test_panels_registered(mb):
    for name in ("VIEW3D_PT_moebius", "VIEW3D_PT_moebius_polygon", "VIEW3D_PT_moebius_flow",
                 "VIEW3D_PT_moebius_keyframes", "VIEW3D_PT_moebius_advanced"):
        panel = getattr(bpy.types, name)
        assert panel.bl_category == "Möbius" and panel.bl_space_type == "VIEW_3D"
    settings = bpy.types.Scene.bl_rna.properties["moebius"].fixed_type
    for prop in ("metric", "method", "penalty", "edges", "max_iterations", "tolerance",
                 "frame_start", "keyframe_stride", "initial_step", "armijo", "backproject_iter",
                 "backproject_digits", "keep_edge_lengths", "keep_barycenter"):
        assert prop in settings.properties, prop
    for stat in ("last_iterations", "last_energy_start", "last_energy_end", "last_message",
                 "last_method"):
        assert settings.properties[stat].is_readonly, stat


@pytest.mark.parametrize("suffix", [".abc", ".usda"])
def test_export_takes_the_objects_keyed_range(relaxed, mb, tmp_path, suffix):
    # another run (or the user) shrank the scene range: the export still holds every iterate
    scene = bpy.context.scene
    first, last = mb.keyed_frames(relaxed)[0], mb.keyed_frames(relaxed)[-1]
    expected = points_at(relaxed, last)
    scene.frame_start, scene.frame_end = first, first + 2
    path = mb.export_flow(relaxed, tmp_path / f"flow{suffix}")
    assert (scene.frame_start, scene.frame_end) == (first, first + 2)  # the scene is untouched
    bpy.ops.wm.read_homefile(use_empty=True)
    if suffix == ".abc":
        bpy.ops.wm.alembic_import(filepath=str(path))
    else:
        bpy.ops.wm.usd_import(filepath=str(path))
    X, _ = _imported_points(last)
    np.testing.assert_allclose(X, expected, atol=1e-5)


def test_keyed_frames_are_whole_numbers(relaxed, mb):
    frames, energies = mb.keyed_energies(relaxed)
    bpy.context.scene.frame_set(frames[-1])  # a float frame raised TypeError here
    assert bpy.context.scene.frame_current == frames[-1] and len(energies) == len(frames)


def test_one_set_of_limits_in_every_door(scene, mb, capfd):
    from importlib import import_module

    cli = import_module(mb.__name__ + ".cli")
    limit = mb.api.EDGE_LIMIT
    assert limit == 100_000
    objects = len(bpy.data.objects)
    # the script door: was clamped to the limit by the operator, made as asked by add_knot
    too_many = f"{limit + 1000} edges are more than a run in Blender takes .*at most {limit}"
    with pytest.raises(ValueError, match=too_many):
        mb.add_knot("3_1", limit + 1000, metric="h2", engine="tree")
    bpy.context.scene.moebius.metric = "h2"
    with pytest.raises(RuntimeError, match=too_many):
        bpy.ops.moebius.add_knot(kind="3_1", edges=limit + 1000)
    bpy.context.scene.moebius.metric = "hs"
    # the command line: refused before adding anything (was a 6000-edge knot, then refused by
    # Relax), and a bad --tolerance before the knot is added
    capfd.readouterr()
    assert cli.main(["--knot", "3_1", "--edges", str(limit + 1000), "--metric", "h2",
                     "--no-relax"]) == 1
    assert cli.main(["--knot", "3_1", "--tolerance", "nan", "--no-relax"]) == 1
    assert cli.main(["--knot", "no_such_knot"]) == 1
    err = capfd.readouterr().err
    assert f"{limit + 1000} edges are more than" in err and "tolerance must be" in err
    assert "unknown knot 'no_such_knot'; " in err and "10_161" in err and "fhw, helix" in err
    assert len(bpy.data.objects) == objects
    # --help names the catalogue (the generators, and how table names look: not all 7 166)
    assert cli.main(["--help"]) == 0
    out = " ".join(capfd.readouterr().out.split())
    assert "figure_eight" in out and "10_161" in out and "--braid WORD" in out
    assert "8_21" not in out
