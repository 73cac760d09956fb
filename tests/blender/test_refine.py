"""Adaptive resolution in Blender: a refined run is one animation at the final point count that
plays, exports and continues; a too-coarse curve is refined, or refused with refine off."""

import itertools
import re

import bpy
import numpy as np
import pytest
from bpy_helpers import imported_points, points_at, poly_curve, scene_state, spline_points

from tests.mesh_checks import segments_closest


def _coarse_trefoil(core):
    # the table's trefoil at 24 edges: 27 is the least count that passes the start check
    return poly_curve("Coarse", [core.knots.named("3_1", 24)])


@pytest.mark.lines
def test_a_too_coarse_curve_is_refined_into_one_animation(scene, mb, core, tmp_path):
    obj = _coarse_trefoil(core)
    start = spline_points(obj).copy()
    s = scene.moebius
    s.max_iterations, s.tolerance = 4, 0.0
    assert bpy.ops.moebius.relax() == {"FINISHED"}
    assert s.last_iterations == 4
    assert "24 → 48 edges at iteration 0 (start too coarse)" in s.last_refined
    assert "refined 24 → 48" in s.last_message
    assert [len(sp.points) for sp in obj.data.splines] == [48]
    frames = mb.keyed_frames(obj)
    assert frames == [1, 2, 3, 4, 5]
    # the first frame is the start, the same curve: its old points every second point, the
    # new ones on its edges
    first = points_at(obj, 1)
    np.testing.assert_allclose(first[::2], start, atol=1e-6)
    np.testing.assert_allclose(first[1::2], 0.5 * (start + np.roll(start, -1, 0)), atol=1e-6)
    assert np.abs(points_at(obj, 5) - first).max() > 1e-3
    # Clear Flow goes back to that start (48 points); the flow plays and exports at 48
    bpy.ops.moebius.clear_animation()
    np.testing.assert_allclose(spline_points(obj), first, atol=1e-6)


def test_refine_off_refuses_a_too_coarse_curve_and_leaves_the_scene(scene, mb, core):
    _coarse_trefoil(core)
    scene.moebius.refine = False
    before = scene_state()
    with pytest.raises(RuntimeError, match="too coarse"):
        bpy.ops.moebius.relax()
    assert scene_state() == before


@pytest.fixture
def jammed(scene, mb):
    # 5_2 at 180 edges with the explicit method: strands squeezed to half an edge length by
    # iteration 48, steps collapsed at 60 (tests/core/test_adaptive.py)
    bpy.ops.moebius.add_knot(kind="5_2", edges=180)
    obj = bpy.context.active_object
    s = scene.moebius
    s.method, s.max_iterations, s.tolerance = "projected_gradient", 70, 1e-4
    assert bpy.ops.moebius.relax() == {"FINISHED"}
    return obj


def test_a_jammed_run_is_one_animation_that_plays_exports_and_continues(jammed, scene, mb,
                                                                        tmp_path):
    obj, s = jammed, scene.moebius
    assert "jammed" in s.last_refined and "180 → 360 edges" in s.last_refined
    assert s.last_iterations == 70
    frames = mb.keyed_frames(obj)
    assert frames == list(range(1, 72)) and s.last_keyframes == 71
    shapes = [points_at(obj, f) for f in frames]
    assert {len(X) for X in shapes} == {360}
    # no jump where it was refined: the frames before it are the same curves split in two (a
    # mix-up of the points would move them across the knot), so the move into and out of the
    # refined iterate is no larger than the moves before it
    k = int(re.search(r"at iteration (\d+)", s.last_refined).group(1))
    moves = [np.abs(b - a).max() for a, b in itertools.pairwise(shapes)]
    assert 5 < k < 60 and max(moves[k - 1], moves[k]) <= max(moves[: k - 1])
    before = shapes[k - 1]  # a frame of the coarse run: its new points halve its edges
    np.testing.assert_allclose(before[1::2], 0.5 * (before[::2] + np.roll(before[::2], -1, 0)),
                               atol=1e-5)
    assert "5_2" in s.last_type and "kept" in s.last_type
    # Alembic: every frame at 360 points
    path = mb.export_flow(obj, tmp_path / "flow.abc")
    keep = {f: shapes[f - 1] for f in (1, 40, 71)}
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.wm.alembic_import(filepath=str(path))
    for f, X in keep.items():
        Y, _ = imported_points(f)
        np.testing.assert_allclose(Y, X, atol=1e-5)


def test_continue_after_a_refined_run(jammed, scene, mb):
    obj, s = jammed, scene.moebius
    s.max_iterations = 5
    assert bpy.ops.moebius.relax(append=True) == {"FINISHED"}
    assert mb.keyed_frames(obj) == list(range(1, 77))
    assert [len(sp.points) for sp in obj.data.splines] == [360]


def test_the_command_line_refines_and_says_so(scene, mb, core, tmp_path, capfd):
    from importlib import import_module

    cli = import_module(mb.__name__ + ".cli")
    _coarse_trefoil(core)
    blend = tmp_path / "coarse.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    capfd.readouterr()
    # a curve too coarse for its shape: refined to 48 edges by default, and the line says so
    assert cli.main(["--open", str(blend), "--object", "Coarse", "--max-iterations", "2"]) == 0
    out = capfd.readouterr().out
    assert "refined 24 -> 48 edges at iteration 0 (start too coarse" in out
    assert [len(sp.points) for sp in bpy.data.objects["Coarse"].data.splines] == [48]
    # --no-refine keeps the refusal; bad values of the new options are refused before any work
    for argv, words in (
            (["--no-refine"], "too coarse"),
            (["--max-edges", "0"], "--max-edges must be a positive whole number, got 0"),
            (["--restarts", "-1"], "--restarts must be 0 or more, got -1"),
            (["--restarts", "1", "--method", "lbfgs"], "--restarts needs a projected gradient")):
        assert cli.main(["--open", str(blend), "--object", "Coarse", "--max-iterations", "2",
                         *argv]) == 1, argv
        assert words in capfd.readouterr().err, argv
        assert [len(sp.points) for sp in bpy.data.objects["Coarse"].data.splines] == [24], argv
    # a restart runs after convergence, seeded: the same energy twice
    energies = []
    for _ in range(2):
        capfd.readouterr()
        assert cli.main(["--knot", "3_1", "--edges", "60", "--max-iterations", "300",
                         "--restarts", "1", "--seed", "3", "--tolerance", "1e-2"]) == 0
        assert "1 restarts, " in capfd.readouterr().out
        energies.append(bpy.data.objects["Knot 3_1"][mb.api.ENERGY_PROP])
    assert energies[0] == energies[1]


def _closest_edges(X):
    """Smallest distance between two edges of the closed polygon ``X`` at least 2 apart along
    it, in mean edge lengths (numpy alone, every pair)."""
    n = len(X)
    Y = np.roll(X, -1, axis=0)
    i, j = np.triu_indices(n, 2)
    keep = (j - i) <= n - 2
    i, j = i[keep], j[keep]
    h = np.linalg.norm(Y - X, axis=1).mean()
    return float(segments_closest(X[i], Y[i], X[j], Y[j]).min() / h)


def test_strands_pushed_apart_are_the_first_frames(scene, mb, core):
    # a braid-tangled trefoil whose edges pass 0.003 edge lengths apart (tests/core/
    # test_adaptive.py): its separation's steps are keyed as the first frames, at its own
    # point count, and no frame or straight move between two frames crosses
    P = core.tangle.tangled("3_1", 100, 149, "braid", pairs=10, conjugations=5)
    obj = poly_curve("Tangled", [P])
    s = scene.moebius
    s.max_iterations, s.tolerance = 80, 1e-4
    assert bpy.ops.moebius.relax() == {"FINISHED"}
    m = re.search(r"136 → 136 edges at iteration 0 \(start too coarse, strands pushed apart "
                  r"in (\d+) steps\)", s.last_refined)
    assert m and 0 < int(m.group(1)) < 80
    assert s.last_method == "projected_gradient_implicit"
    frames = mb.keyed_frames(obj)
    assert frames == list(range(1, 82))
    shapes = [points_at(obj, f) for f in frames]
    assert {len(X) for X in shapes} == {136}
    np.testing.assert_allclose(shapes[0], P, atol=1e-6)
    for a, b in itertools.pairwise(shapes):
        assert _closest_edges(b) > 1e-4 and _closest_edges(0.5 * (a + b)) > 1e-4
    assert "3_1" in s.last_type and "kept" in s.last_type
