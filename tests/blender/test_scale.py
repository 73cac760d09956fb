"""Blender at scale (issue 14): the engine and θ in every door, an edge limit that follows the
engine (no size may crash the process), and the flow of large curves."""

from importlib import import_module

import bpy
import numpy as np
import pytest
from bpy_helpers import poly_curve, scene_state

from moebius_addon.core import barnes_hut
from moebius_addon.core.solvers.base import DENSE_MAX_VERTICES


def _circle(n):
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.column_stack([np.cos(t), np.sin(t), 0.1 * np.sin(3 * t)])


@pytest.fixture
def trefoil(scene, mb):
    bpy.ops.moebius.add_knot(kind="3_1", edges=60)
    return bpy.context.active_object


def test_engine_enum_is_the_cores_list(mb):
    settings = bpy.types.Scene.bl_rna.properties["moebius"].fixed_type
    engine = settings.properties["engine"]
    assert [item.identifier for item in engine.enum_items] == list(barnes_hut.ENGINE_NAMES)
    assert engine.default == "auto"
    assert [e for e, *_ in mb.api.ENGINES] == list(barnes_hut.ENGINE_NAMES)
    assert settings.properties["theta"].default == pytest.approx(barnes_hut.THETA)


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
    s.theta = 0.0
    with pytest.raises(RuntimeError, match=r"theta must be a number in \(0, 2\), got 0.0"):
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
    s.engine = "auto"  # 60 edges: exact (the tree from barnes_hut.TREE_FROM edges on)
    assert mb.ObjectRelaxation(trefoil, **mb.relax_settings(s)).engine == "exact"
    cli = import_module(mb.__name__ + ".cli")
    capfd.readouterr()
    assert cli.main(["--knot", "3_1", "--edges", "60", "--max-iterations", "1", "--engine",
                     "tree", "--theta", "0.25"]) == 0
    assert ", tree engine, 1 iterations" in capfd.readouterr().out


def test_panel_shows_theta_only_where_the_tree_can_run(scene, mb):
    s = scene.moebius
    for engine in barnes_hut.ENGINE_NAMES:
        s.engine = engine
        acting = mb.api.acting_settings(s.method, engine)
        assert ("theta" in acting) == (engine != "exact")
        assert ("theta" in mb.relax_settings(s)) == ("theta" in acting)
        assert mb.relax_settings(s)["engine"] == engine


def test_edge_limit_follows_the_engine(mb, core):
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


def test_relax_refuses_sizes_the_engine_cannot_take_before_any_work(scene, mb):
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
