"""Every optimizer of ``core.METHODS`` through the Blender layer: the panel's enum, keyframes,
what each method guarantees about the energy and the edge lengths, stop/callback, bad penalty
weights, the CLI's ``--method``."""

from importlib import import_module

import bpy
import numpy as np
import pytest
from bpy_helpers import scene_state, spline_points

# the core's method table, written here so that the tests are collected in a Blender venv
# (the installed core is imported only once the zip is installed); the first test checks it
FEASIBLE = ("projected_gradient", "projected_gradient_implicit", "trust_region")
INFEASIBLE = ("ncg", "lbfgs", "nesterov")
METHODS = FEASIBLE + INFEASIBLE


def _edges(X):
    return np.linalg.norm(np.roll(X, -1, axis=0) - X, axis=1)


@pytest.fixture
def trefoil(scene, mb):
    bpy.ops.moebius.add_knot(kind="3_1", edges=100)
    return bpy.context.active_object


def test_method_enum_lists_auto_then_exactly_the_core_methods(mb, core):
    settings = bpy.types.Scene.bl_rna.properties["moebius"].fixed_type
    method = settings.properties["method"]
    assert (METHODS, FEASIBLE, INFEASIBLE) == (core.METHODS, core.runs.methods.FEASIBLE,
                                               core.runs.methods.INFEASIBLE)
    assert [item.identifier for item in method.enum_items] == ["auto", *core.METHODS]
    assert method.default == "auto"
    for item in method.enum_items:
        assert item.name and item.description
    assert settings.properties["penalty"].default == 1e4
    assert mb.api.DEFAULT_PENALTY == 1e4
    assert set(mb.api.PENALTY_METHODS) == set(INFEASIBLE)


def test_settings_pass_each_method_only_its_options(scene, mb, core):
    s = scene.moebius
    legacy = {"metric", "max_iterations", "tolerance", "frame_start", "keyframe_stride",
              "initial_step", "armijo", "growth", "backproject_iter", "backproject_tol",
              "edge_lengths", "barycenter", "settle", "thickness"}
    assert set(mb.relax_settings(s)) == legacy | {"method", "engine", "theta", "refine", "energy"}
    # refinement on by default, Max Edges 0 (the core's default) not passed; restarts only
    # when asked, and to the methods that keep the constraints
    assert mb.relax_settings(s)["refine"] is True
    s.max_edges, s.restarts, s.seed = 3000, 2, 5
    kwargs = mb.relax_settings(s)
    assert (kwargs["max_edges"], kwargs["restarts"], kwargs["seed"]) == (3000, 2, 5)
    s.refine = False
    assert mb.relax_settings(s)["refine"] is False and "max_edges" not in mb.relax_settings(s)
    s.refine, s.max_edges, s.restarts = True, 0, 0
    # the default run is the core's: θ 0 passes None, the energy's own default
    assert mb.relax_settings(s)["engine"] == "auto"
    assert mb.relax_settings(s)["theta"] is None
    # the tolerance is set as digits (a number field shows only six decimals)
    assert mb.relax_settings(s)["backproject_tol"] == pytest.approx(1e-10, rel=1e-12)
    s.backproject_digits = 8
    assert mb.relax_settings(s)["backproject_tol"] == pytest.approx(1e-8, rel=1e-12)
    s.method = "projected_gradient_implicit"
    # it keeps its own σ = 1e-4 and growth 1.5
    assert not {"armijo", "growth"} & set(mb.relax_settings(s))
    s.method = "trust_region"
    assert not {"armijo", "growth", "penalty"} & set(mb.relax_settings(s))
    s.method = "lbfgs"
    s.penalty = 2e4
    kwargs = mb.relax_settings(s)
    assert kwargs["penalty"] == 2e4 and kwargs["method"] == "lbfgs"
    assert not {"armijo", "growth", "backproject_iter", "edge_lengths", "barycenter"} & set(kwargs)
    s.restarts = 2
    assert "restarts" not in mb.relax_settings(s)


@pytest.mark.parametrize("method", METHODS)
def test_relax_each_method_keys_every_iterate(scene, mb, core, trefoil, method):
    start = spline_points(trefoil)
    s = scene.moebius
    s.method = method
    s.max_iterations = 3
    s.tolerance = 0.0
    assert bpy.ops.moebius.relax() == {"FINISHED"}
    assert s.last_method == method and s.last_iterations == 3 and s.last_keyframes == 4
    frames, E = mb.keyed_energies(trefoil)
    assert frames.tolist() == [1.0, 2.0, 3.0, 4.0] and E[-1] < E[0]
    shapes = []
    for f in range(1, 5):
        scene.frame_set(f)
        shapes.append(spline_points(trefoil))
    np.testing.assert_allclose(shapes[0], start, atol=1e-6)
    assert np.abs(shapes[-1] - start).max() > 1e-3
    l0 = _edges(start)
    if method in FEASIBLE:
        # edge lengths and barycenter exact (to float32), energy never rises
        assert np.all(np.diff(E) <= 0)
        for X in shapes:
            np.testing.assert_allclose(_edges(X), l0, atol=1e-5)
            np.testing.assert_allclose(X.mean(0), start.mean(0), atol=1e-5)
    else:
        # Hencky's penalty α Σ l0 log(l/l0)² (lengths as fractions of the total length 1) is
        # never negative and zero at the start, and the penalized energy never rises: so the
        # Möbius energy never exceeds the start's, and each edge's stretch is bounded by the
        # energy spent
        alpha = s.penalty
        w = l0 / l0.sum()
        f = []
        for X, Ek in zip(shapes, E, strict=True):
            phi = np.log(_edges(X) / l0)
            f.append(Ek + alpha * np.sum(w * phi * phi))
            assert Ek <= E[0] * (1 + 1e-6)
            assert np.all(alpha * w * phi * phi <= E[0] - Ek + 1e-3)
        assert np.all(np.diff(f) <= 1e-3)  # float32 points: φ to about 1e-6


@pytest.mark.parametrize("method", METHODS)
def test_callback_and_esc_stop_every_method(scene, mb, core, trefoil, method):
    start = mb.curve_polygons(trefoil)[0]
    seen = []

    def progress(run):
        seen.append((run.nit, run.energy))
        return run.nit >= 2

    kw = {"penalty": 5e4} if method in INFEASIBLE else {}
    result = mb.relax_object(trefoil, method=method, max_iterations=50, tolerance=0.0,
                             callback=progress, **kw)
    assert result.nit == 2 and result.success and "callback" in result.message
    assert [n for n, _ in seen] == [1, 2] and seen[-1][1] == pytest.approx(result.fun)
    assert mb.keyed_frames(trefoil) == [1.0, 2.0, 3.0]
    # the same iterates as the core run (the Blender layer keeps the stored edge lengths)
    opts = {"penalty": 5e4} if method in INFEASIBLE else {}
    ref = core.relax(start, max_iter=2, tol=0.0, method=method, target_lengths="keep", **opts)
    np.testing.assert_allclose(result.history["energy"], ref.history["energy"], rtol=1e-12)
    if method in INFEASIBLE:
        assert np.all(np.diff(result.history["penalized_energy"]) <= 0)
    else:
        assert np.all(np.diff(result.history["energy"]) <= 0)
    # progress reaches the iterate that ends the run too
    seen.clear()
    result = mb.relax_object(trefoil, method=method, max_iterations=2, tolerance=0.0,
                             callback=progress, **kw)
    assert [n for n, _ in seen] == [1, 2] and "maximum number of iterations" in result.message
    # what Esc does in the modal operator: stop(), then finish() keys the iterates so far
    scene.frame_set(3)
    mid = spline_points(trefoil)
    run = mb.ObjectRelaxation(trefoil, method=method, max_iterations=50, tolerance=0.0, **kw)
    assert run.step()
    run.stop("cancelled by the user (Esc)")
    assert not run.step()
    result = run.finish(scene)
    assert result.nit == 1 and result.message == "cancelled by the user (Esc)"
    assert mb.keyed_frames(trefoil) == [1.0, 2.0] and scene.moebius.last_method == method
    scene.frame_set(1)
    np.testing.assert_allclose(spline_points(trefoil), mid, atol=1e-6)


def test_bad_method_or_penalty_is_refused_leaving_the_scene(scene, mb, trefoil):
    s = scene.moebius
    s.max_iterations = 2
    bpy.ops.moebius.relax()
    frames = mb.keyed_frames(trefoil)
    before = scene_state()
    s.method = "nesterov"
    s.penalty = 0.0
    with pytest.raises(RuntimeError, match="penalty weight must be a positive, finite number"):
        bpy.ops.moebius.relax()
    for bad in (-1.0, float("nan"), float("inf"), "lots"):
        with pytest.raises(ValueError, match=r"penalty weight must be .*default is 10000"):
            mb.relax_object(trefoil, method="ncg", penalty=bad)
    with pytest.raises(ValueError, match="applies only to the penalty methods.*leave penalty"):
        mb.relax_object(trefoil, method="trust_region", penalty=1e4)
    with pytest.raises(ValueError, match="unknown method 'bfgs'; choose one of .*lbfgs"):
        mb.ObjectRelaxation(trefoil, method="bfgs")
    assert scene_state() == before and mb.keyed_frames(trefoil) == frames


def test_action_names_are_distinct(scene, mb, trefoil):
    scene.moebius.max_iterations = 1
    bpy.ops.moebius.relax()
    assert trefoil.name == trefoil.data.name  # so one pattern for both would clash
    assert trefoil.animation_data.action.name == f"{trefoil.name}Action"
    assert trefoil.data.animation_data.action.name == f"{trefoil.data.name}CurveAction"
    assert sorted(a.name for a in bpy.data.actions) == sorted(
        [f"{trefoil.name}Action", f"{trefoil.name}CurveAction"])


def test_cli_method_and_penalty(scene, mb):
    cli = import_module(mb.__name__ + ".cli")
    rc = cli.main(["--knot", "3_1", "--edges", "100", "--method", "lbfgs", "--penalty", "1e5",
                   "--max-iterations", "2", "--tolerance", "0"])
    # the command starts from a new empty scene: the fixture's scene is gone
    assert rc == 0 and bpy.context.scene.moebius.last_method == "lbfgs"
    assert mb.keyed_frames(bpy.data.objects["Knot 3_1"]) == [1.0, 2.0, 3.0]
    before = scene_state()
    assert cli.main(["--knot", "3_1", "--penalty", "1e5"]) == 1  # default method: no penalty
    assert cli.main(["--knot", "3_1", "--method", "ncg", "--penalty", "-1"]) == 1
    assert scene_state() == before  # refused before the knot was added
    assert cli.main(["--knot", "3_1", "--method", "bfgs"]) == 2


def test_panel_text_wraps_to_the_sidebar(mb):
    panel = import_module(mb.__name__ + ".panel")
    message = ("stalled at energy 747.1234567: the line search found no decrease while the "
               "gradient norm is still 0.0123; strands are probably jammed — use more edges")
    lines = panel.wrap_text(message, 220)
    assert len(lines) > 1 and " ".join(lines) == message
    assert max(map(len, lines)) <= 25  # what fits the default sidebar (about 220 px)
    assert panel.wrap_text(message, 440, ui_scale=2.0) == lines
    assert panel.wrap_text("", 220) == [""]


def test_panel_and_run_agree_on_which_settings_act(scene, mb):
    # Step Growth was shown active for the implicit method, which never received it
    s = bpy.context.scene.moebius
    api = mb.api
    for method in METHODS:
        s.method = method
        passed = set(api.relax_settings(s))
        acting = api.acting_settings(method)
        for setting, option in (("armijo", "armijo"), ("growth", "growth"),
                                ("penalty", "penalty"), ("backproject_iter", "backproject_iter"),
                                ("keep_edge_lengths", "edge_lengths")):
            assert (setting in acting) == (option in passed), (method, setting)
    assert {m for m in ("auto", *METHODS) if "growth" in api.acting_settings(m)} == {
        "auto", "projected_gradient"}


def test_automatic_method_follows_the_knot_type(scene, mb, core, trefoil):
    # measured (docs/lab/flows-and-methods.md): the implicit method is faster to the relaxed shape
    # on
    # knots, the explicit one on the FHW unknot
    s = scene.moebius
    s.max_iterations = 2
    s.armijo = 0.3  # the explicit method's; the implicit one keeps its own 1e-4
    run = mb.api.ObjectRelaxation(trefoil, **mb.relax_settings(s))
    assert (run.requested, run.method, run.why) == (
        "auto", "projected_gradient_implicit", "knotted, determinant 3")
    assert run.run.armijo == 1e-4
    assert bpy.ops.moebius.relax() == {"FINISHED"}
    assert s.last_method == "projected_gradient_implicit"
    bpy.ops.moebius.add_knot(kind="fhw", edges=600)
    run = mb.api.ObjectRelaxation(bpy.context.active_object, **mb.relax_settings(s))
    assert (run.method, run.why) == ("projected_gradient", "no knot detected")
    assert run.run.armijo == pytest.approx(0.3)  # a float32 property
    hopf = core.knots.braid_closure([1, 1])
    assert mb.api.choose_method("auto", hopf) == ("projected_gradient_implicit",
                                                  "a link of 2 components")
    assert mb.api.choose_method("trust_region", hopf) == ("trust_region", "")
