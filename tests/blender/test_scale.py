"""Blender at scale: the engine and θ in every door, an edge limit that follows the
engine (no size may crash the process), and the flow of large curves."""

from importlib import import_module

import bpy
import numpy as np
import pytest
from bpy_helpers import (
    fcurves_of,
    imported_points,
    points_at,
    poly_curve,
    scene_state,
    spline_points,
)


def _core_names(core):
    """``engine`` and ``DENSE_MAX_VERTICES`` of the installed extension's core (the
    repository's core needs numba in the venv, which the Blender lines' venvs leave to the
    extension)."""
    return (import_module(core.__name__ + ".runs.engine"),
            import_module(core.__name__ + ".runs.base").DENSE_MAX_VERTICES)


def _circle(n):
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.column_stack([np.cos(t), np.sin(t), 0.1 * np.sin(3 * t)])


@pytest.fixture
def trefoil(scene, mb):
    bpy.ops.moebius.add_knot(kind="3_1", edges=60)
    return bpy.context.active_object


def test_engine_enum_is_the_cores_list(mb, core):
    engines, _ = _core_names(core)
    settings = bpy.types.Scene.bl_rna.properties["moebius"].fixed_type
    engine = settings.properties["engine"]
    assert [item.identifier for item in engine.enum_items] == list(engines.ENGINE_NAMES)
    assert engine.default == "auto"
    assert [e for e, *_ in mb.api.ENGINES] == list(engines.ENGINE_NAMES)
    assert settings.properties["theta"].default == 0.0  # the energy's own (its record's)


def test_bad_engine_and_theta_are_refused_by_name_in_every_door(scene, mb, trefoil, capfd):
    cli = import_module(mb.__name__ + ".cli")
    before = scene_state()
    with pytest.raises(ValueError, match="unknown engine 'warp'; choose one of auto, exact, tree"):
        mb.relax_object(trefoil, engine="warp")
    for theta in (0, 2.0, -1, float("nan"), "x"):
        with pytest.raises(ValueError, match=r"theta must be a number in \(0, 2\)"):
            mb.relax_object(trefoil, theta=theta)
    assert scene_state() == before
    # the panel: θ is refused where it acts, and passed on only there
    s = scene.moebius
    s.theta = 2.0
    with pytest.raises(RuntimeError, match=r"theta must be a number in \(0, 2\), got 2.0"):
        bpy.ops.moebius.relax()
    assert scene_state() == before
    s.engine = "exact"  # θ hidden: the tree never runs
    assert "theta" not in mb.relax_settings(s)
    s.max_iterations = 1
    assert bpy.ops.moebius.relax() == {"FINISHED"}
    # the command line: before anything is added
    objects = len(bpy.data.objects)
    capfd.readouterr()
    assert cli.main(["--knot", "3_1", "--theta", "3", "--no-relax"]) == 1
    assert "moebius: error: theta must be a number in (0, 2), got 3.0" in capfd.readouterr().err
    assert cli.main(["--knot", "3_1", "--engine", "warp"]) == 2
    assert "invalid choice: 'warp'" in capfd.readouterr().err
    assert len(bpy.data.objects) == objects


def test_theta_and_engine_reach_the_run_and_the_report_names_the_engine(scene, mb, trefoil,
                                                                       capfd):
    s = scene.moebius
    s.max_iterations = 2
    s.tolerance = 0.0
    for engine in ("exact", "tree"):
        s.engine = engine
        s.theta = 0.3
        run = mb.ObjectRelaxation(trefoil, **mb.relax_settings(s))
        assert run.engine == engine
        assert run.run.engine.name == engine
        if engine == "tree":
            assert run.run.engine.theta == pytest.approx(0.3)
        capfd.readouterr()
        assert bpy.ops.moebius.relax() == {"FINISHED"}
        assert f", {engine} engine: 2 iterations" in capfd.readouterr().out
        assert s.last_engine == engine
    s.engine = "auto"  # 60 edges: exact (the tree from core.runs.engine.AUTO_TREE_FROM edges on)
    assert mb.ObjectRelaxation(trefoil, **mb.relax_settings(s)).engine == "exact"
    cli = import_module(mb.__name__ + ".cli")
    capfd.readouterr()
    assert cli.main(["--knot", "3_1", "--edges", "60", "--max-iterations", "1", "--engine",
                     "tree", "--theta", "0.25"]) == 0
    assert ", tree engine, 1 iterations" in capfd.readouterr().out


def test_panel_shows_theta_only_where_the_tree_can_run(scene, mb, core):
    engines, _ = _core_names(core)
    s = scene.moebius
    for engine in engines.ENGINE_NAMES:
        s.engine = engine
        acting = mb.api.acting_settings(s.method, engine)
        assert ("theta" in acting) == (engine != "exact")
        assert ("theta" in mb.relax_settings(s)) == ("theta" in acting)
        assert mb.relax_settings(s)["engine"] == engine


def test_edge_limit_follows_the_engine(mb, core):
    _, DENSE_MAX_VERTICES = _core_names(core)
    check, limit = mb.api.check_edge_count, mb.api.EDGE_LIMIT
    # the exact engine holds every metric densely: the core's bound and words
    n = DENSE_MAX_VERTICES + 1
    with pytest.raises(ValueError, match=f"{n} vertices are more than the dense metric's "
                                         f"factorization handles \\({DENSE_MAX_VERTICES}"):
        check(n, "h2", "auto", "exact")
    assert mb.api.edge_limit("h2", "auto", "exact") <= DENSE_MAX_VERTICES
    # the tree with a banded metric: Blender's cap, which allow_large lifts
    check(limit, "h2", "auto", "tree")
    check(limit, "h1", "projected_gradient", "auto")
    with pytest.raises(ValueError, match=f"{limit + 1} edges are more than a run in Blender "
                                         f"takes \\({limit}, on the tree engine"):
        check(limit + 1, "h2", "auto", "tree")
    check(limit + 1, "h2", "auto", "tree", allow_large=True)
    assert mb.api.edge_limit("h2", "auto", "tree") == limit
    # the penalty methods hold the metric densely on every engine
    with pytest.raises(ValueError, match="dense metric"):
        check(n, "h2", "lbfgs", "tree", allow_large=True)
    # whatever the core decides for hs on the tree (dense today), Blender refuses exactly
    # what it refuses, in its words, and caps the rest
    for size in (n, limit, limit + 1):
        try:
            core.check_size(size, "hs", "projected_gradient", "auto")
        except ValueError as err:
            with pytest.raises(ValueError, match=str(err)[:60].replace("(", r"\(")):
                check(size, "hs", "auto", "auto")
        else:
            if size <= limit:
                check(size, "hs", "auto", "auto")
            else:
                with pytest.raises(ValueError, match="more than a run in Blender takes"):
                    check(size, "hs", "auto", "auto")
    for bad, word in ((("nope", "auto", "auto"), "metric"), (("hs", "nope", "auto"), "method"),
                      (("hs", "auto", "nope"), "engine")):
        with pytest.raises(ValueError, match=f"unknown {word}"):
            check(100, *bad)


def test_relax_refuses_sizes_the_engine_cannot_take_before_any_work(scene, mb, core):
    _, DENSE_MAX_VERTICES = _core_names(core)
    # the exact engine's dense factorization crashed the process from about 16 000 vertices
    obj = poly_curve("Big", [_circle(DENSE_MAX_VERTICES + 1)])
    before = scene_state()
    with pytest.raises(ValueError, match=f"'Big': {DENSE_MAX_VERTICES + 1} vertices are more "
                                         "than the dense metric's factorization handles"):
        mb.relax_object(obj, metric="h2", engine="exact")
    with pytest.raises(RuntimeError, match="dense metric"):  # the panel's door
        scene.moebius.engine = "exact"
        bpy.ops.moebius.relax()
    assert scene_state() == before
    obj = poly_curve("Huge", [_circle(mb.api.EDGE_LIMIT + 1)])
    with pytest.raises(ValueError, match="'Huge': 100001 edges are more than a run in Blender"):
        mb.relax_object(obj, metric="h2", engine="tree")
    assert obj.data.animation_data is None and obj.data.shape_keys is None
    # converting for the tree with a banded metric: the same cap, before resampling
    bpy.ops.curve.primitive_bezier_circle_add()
    s = scene.moebius
    s.metric, s.engine, s.edges = "h2", "tree", mb.api.EDGE_LIMIT + 1
    before = scene_state()
    with pytest.raises(RuntimeError, match="100001 edges are more than a run in Blender"):
        bpy.ops.moebius.convert()
    assert scene_state() == before


# ---- the flow of large curves: shape keys ------------------------------------------------------
# Curves above keyframes.PER_POINT_MAX points key their flow as shape keys. The behaviour is
# tested on small curves with the threshold lowered (fast), and end to end on a 10 000-point
# curve. spline_points reads what Blender shows (its own evaluation of the keys).


@pytest.fixture
def shape_keys(mb, monkeypatch):
    """Key every flow as shape keys, whatever its size."""
    monkeypatch.setattr(import_module(mb.__name__ + ".keyframes"), "PER_POINT_MAX", 0)


def _blocks(obj):
    key = obj.data.shape_keys
    out = []
    for block in key.key_blocks:
        co = np.empty(3 * len(block.data), dtype=np.float32)
        block.data.foreach_get("co", co)
        out.append(co.reshape(-1, 3))
    return np.array(out)


@pytest.mark.lines
def test_shape_keys_hold_every_iterate_and_play_linearly(scene, mb, core, trefoil, shape_keys):
    start = spline_points(trefoil)
    s = scene.moebius
    s.max_iterations, s.tolerance, s.frame_start = 4, 0.0, 10
    assert bpy.ops.moebius.relax() == {"FINISHED"}
    key = trefoil.data.shape_keys
    assert not key.use_relative and len(key.key_blocks) == 5
    assert {b.interpolation for b in key.key_blocks} == {"KEY_LINEAR"}
    # no point F-curves; one F-curve, LINEAR, drives the keys; the energy as before
    assert trefoil.data.animation_data is None
    (fc,) = fcurves_of(key)
    assert fc.data_path == "eval_time" and {k.interpolation for k in fc.keyframe_points} == {
        "LINEAR"}
    assert key.animation_data.action.name == f"{trefoil.data.name}KeyAction"
    assert mb.keyed_frames(trefoil) == [10, 11, 12, 13, 14]
    # every keyed frame shows its iterate (Blender's own evaluation, and curve_polygons)
    ref = core.relax(start, max_iter=4, tol=0.0, target_lengths="keep",
                     method="projected_gradient_implicit")
    blocks = _blocks(trefoil)
    np.testing.assert_allclose(blocks[0], start, atol=1e-6)
    np.testing.assert_allclose(blocks[-1], ref.x, atol=1e-6)
    for k, frame in enumerate(range(10, 15)):
        scene.frame_set(frame)
        np.testing.assert_array_equal(spline_points(trefoil), blocks[k])
        np.testing.assert_array_equal(mb.curve_polygons(trefoil)[0], blocks[k])
    # in between: the straight segment between two iterates (the collision-free one)
    scene.frame_set(12, subframe=0.25)
    half = 0.75 * blocks[2].astype(float) + 0.25 * blocks[3]
    np.testing.assert_allclose(spline_points(trefoil), half, atol=1e-6)
    np.testing.assert_allclose(mb.curve_polygons(trefoil)[0], half, atol=1e-6)
    frames, points, energies = import_module(mb.__name__ + ".keyframes").read_flow_keyframes(
        trefoil)
    assert frames.tolist() == list(range(10, 15))
    np.testing.assert_array_equal(points, blocks)
    assert energies[-1] == pytest.approx(ref.fun, rel=1e-6)


@pytest.mark.lines
def test_shape_keys_continue_clear_and_apply(scene, mb, core, trefoil, shape_keys):
    start = spline_points(trefoil)
    s = scene.moebius
    s.max_iterations, s.tolerance = 3, 0.0
    bpy.ops.moebius.relax()
    before = _blocks(trefoil)
    scene.frame_set(2)  # the current frame does not matter for Continue
    assert bpy.ops.moebius.relax(append=True) == {"FINISHED"}
    assert mb.keyed_frames(trefoil) == list(range(1, 8))
    after = _blocks(trefoil)
    np.testing.assert_array_equal(after[:4], before)  # the earlier keys are untouched
    ref = core.relax(before[-1].astype(np.float64), max_iter=3, tol=0.0,
                     target_lengths="keep", method="projected_gradient_implicit")
    scene.frame_set(7)
    np.testing.assert_allclose(spline_points(trefoil), ref.x, atol=1e-6)
    # keys edited by hand are refused by Continue, nothing changed
    trefoil.shape_key_add(name="mine", from_mix=False)
    state = scene_state()
    with pytest.raises(RuntimeError, match="were edited"):
        bpy.ops.moebius.relax(append=True)
    assert scene_state() == state
    trefoil.shape_key_remove(trefoil.data.shape_keys.key_blocks["mine"])
    # Clear Flow: back to the start of the first run, keys and their action gone
    assert bpy.ops.moebius.clear_animation() == {"FINISHED"}
    assert trefoil.data.shape_keys is None and mb.keyed_frames(trefoil) == []
    assert len(bpy.data.actions) == 0
    np.testing.assert_allclose(spline_points(trefoil), start, atol=1e-6)
    # Apply Frame, at an in-between frame too
    bpy.ops.moebius.relax()
    scene.frame_set(3, subframe=0.5)
    mid = spline_points(trefoil)
    assert bpy.ops.moebius.apply_frame() == {"FINISHED"}
    assert trefoil.data.shape_keys is None and mb.keyed_frames(trefoil) == []
    scene.frame_set(1)
    np.testing.assert_allclose(spline_points(trefoil), mid, atol=1e-7)


def test_shape_keys_survive_a_failed_or_interrupted_run(scene, mb, trefoil, shape_keys):
    scene.moebius.max_iterations = 2
    bpy.ops.moebius.relax()
    keyed = _blocks(trefoil)
    # the live display removes the keys; a failure puts them back as they were
    run = mb.ObjectRelaxation(trefoil, max_iterations=5, tolerance=0.0)
    run.step()
    run.show()
    assert trefoil.data.shape_keys is None
    np.testing.assert_allclose(spline_points(trefoil), run.x[0], atol=1e-6)
    run.restore()
    np.testing.assert_array_equal(_blocks(trefoil), keyed)
    assert mb.keyed_frames(trefoil) == [1, 2, 3]
    # an exception before the first iterate keeps them; after it, the iterates so far are keyed

    def interrupt(run):
        if run.nit == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        mb.relax_object(trefoil, max_iterations=50, tolerance=0.0, callback=interrupt)
    assert mb.keyed_frames(trefoil) == [1, 2, 3] and len(_blocks(trefoil)) == 3
    assert not np.array_equal(_blocks(trefoil)[1:], keyed[1:])


def test_export_button_needs_a_keyed_flow(scene, mb, trefoil, tmp_path):
    with pytest.raises(RuntimeError, match="no flow keys; press Relax first"):
        bpy.ops.moebius.export_flow(filepath=str(tmp_path / "x.abc"))
    scene.moebius.max_iterations = 1
    bpy.ops.moebius.relax()
    with pytest.raises(RuntimeError, match=r"unknown export format '\.obj'"):
        bpy.ops.moebius.export_flow(filepath=str(tmp_path / "x.obj"))
    assert not (tmp_path / "x.obj").exists()


def test_a_curve_with_shape_keys_of_its_own_is_refused_before_the_run(scene, mb, trefoil,
                                                                     shape_keys):
    trefoil.shape_key_add(name="Basis")
    before = scene_state()
    with pytest.raises(RuntimeError, match="has shape keys of its own .*remove them first"):
        bpy.ops.moebius.relax()
    assert scene_state() == before


@pytest.mark.lines
@pytest.mark.parametrize("suffix", [".abc", ".usda"])
def test_shape_keys_export_round_trip(scene, mb, trefoil, shape_keys, tmp_path, suffix):
    trefoil.location = (0.5, -1.0, 2.0)  # the transform too
    scene.moebius.max_iterations, scene.moebius.tolerance = 4, 0.0
    bpy.ops.moebius.relax()
    frames = [1, 3, 5]
    expected = {f: points_at(trefoil, f) for f in frames}
    assert np.abs(expected[1] - expected[5]).max() > 1e-3
    below = [P.copy() for P, _ in mb.object_polylines(trefoil)]
    path = tmp_path / f"flow{suffix}"
    if suffix == ".abc":
        mb.export_flow(trefoil, path)
    else:  # the panel's button (Keyframes ▸ Export Flow…)
        assert bpy.ops.moebius.export_flow(filepath=str(path)) == {"FINISHED"}
    # the points under the keys are put back
    for (P, _), Q in zip(mb.object_polylines(trefoil), below, strict=True):
        np.testing.assert_array_equal(P, Q)
    bpy.ops.wm.read_homefile(use_empty=True)
    if suffix == ".abc":
        bpy.ops.wm.alembic_import(filepath=str(path))
    else:
        bpy.ops.wm.usd_import(filepath=str(path))
    for f in frames:
        X, curves = imported_points(f)
        np.testing.assert_allclose(X, expected[f], atol=1e-5)
    assert bool(curves.attributes["cyclic"].data[0].value)


def test_a_large_curve_keys_plays_and_exports_its_flow(scene, mb, core, tmp_path, capfd):
    # 10 000 points: refused before the tree engine (EDGE_LIMIT 5 000); per-point keys would be
    # 30 000 F-curves
    P = core.resample(core.knots.named("7_2"), 10_000)
    obj = mb.make_curve_object("Big", [2.0 * (P - P.mean(0)) / np.ptp(P, axis=0).max()])
    obj.data.bevel_depth = 0.01
    start = spline_points(obj)
    s = scene.moebius
    s.metric, s.engine, s.method = "h2", "tree", "projected_gradient"
    s.max_iterations, s.tolerance = 2, 0.0
    capfd.readouterr()
    assert bpy.ops.moebius.relax() == {"FINISHED"}
    assert ", tree engine: 2 iterations" in capfd.readouterr().out
    key = obj.data.shape_keys
    assert len(key.key_blocks) == 3 and obj.data.animation_data is None
    assert mb.keyed_frames(obj) == [1, 2, 3]
    # it plays: each frame shows its iterate, the last one the run's end
    shown = {}
    for frame in (1, 2, 3):
        scene.frame_set(frame)
        shown[frame] = spline_points(obj)
        np.testing.assert_array_equal(mb.curve_polygons(obj)[0], shown[frame])
    np.testing.assert_allclose(shown[1], start, atol=1e-6)
    assert np.abs(shown[3] - shown[1]).max() > 1e-4
    # and exports (Alembic, the default interchange): the positions of every frame
    expected = {f: points_at(obj, f) for f in (1, 3)}
    path = mb.export_flow(obj, tmp_path / "big.abc")
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.wm.alembic_import(filepath=str(path))
    for f in (1, 3):
        X, _ = imported_points(f)
        np.testing.assert_allclose(X, expected[f], atol=1e-5)
