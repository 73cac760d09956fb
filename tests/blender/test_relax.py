"""moebius.relax: keyframes on the splines and the energy, frame range, stride, stop, undo."""

from importlib import import_module

import bpy
import numpy as np
import pytest
from bpy_helpers import fcurves_of, poly_curve, scene_state, spline_points


@pytest.fixture
def trefoil(scene, mb):
    bpy.ops.moebius.add_knot(kind="3_1", edges=60)
    return bpy.context.active_object


@pytest.mark.lines
def test_relax_keyframes_every_iterate(scene, mb, trefoil):
    start = spline_points(trefoil)
    s = scene.moebius
    s.max_iterations = 6
    s.frame_start = 10
    scene.frame_start, scene.frame_end = 10, 11  # the range grows to hold the flow
    assert bpy.ops.moebius.relax() == {"FINISHED"}
    nit = s.last_iterations
    assert 1 <= nit <= 6 and s.last_keyframes == nit + 1
    assert (scene.frame_start, scene.frame_end) == (10, 10 + nit)
    assert scene.frame_current == 10 + nit
    # one channelbag of a slotted action (4.4+; action.fcurves before), 3 F-curves per point,
    # LINEAR keys
    fcurves = fcurves_of(trefoil.data)
    assert len(fcurves) == 3 * 60
    fc = fcurves.find("splines[0].points[7].co", index=2)
    co = np.empty(2 * len(fc.keyframe_points))
    fc.keyframe_points.foreach_get("co", co)
    np.testing.assert_array_equal(co[0::2], np.arange(10, 11 + nit))
    assert {k.interpolation for k in fc.keyframe_points} == {"LINEAR"}
    assert {f.group.name for f in fcurves} == {"Möbius flow"}
    assert co[1] == pytest.approx(start[7, 2], abs=1e-6)
    # frame_start shows the start; the current (last) frame the final iterate
    scene.frame_set(10)
    np.testing.assert_allclose(spline_points(trefoil), start, atol=1e-6)
    scene.frame_set(10 + nit)
    final = spline_points(trefoil)
    assert np.abs(final - start).max() > 1e-3
    # energy keyed on the object, strictly decreasing, matching the core's energy
    efc = fcurves_of(trefoil).find('["moebius_energy"]')
    energies = np.array([k.co[1] for k in efc.keyframe_points])
    assert len(energies) == nit + 1 and np.all(np.diff(energies) < 0)
    assert trefoil["moebius_energy"] == pytest.approx(energies[-1], rel=1e-6)
    assert s.last_energy_end == pytest.approx(mb.energy([final]), rel=1e-4)
    assert s.last_energy_start == pytest.approx(energies[0], rel=1e-6)
    # the flow kept the edge lengths and the barycenter (to float32)
    e0 = np.linalg.norm(np.roll(start, -1, 0) - start, axis=1)
    e1 = np.linalg.norm(np.roll(final, -1, 0) - final, axis=1)
    np.testing.assert_allclose(e1, e0, atol=1e-5)
    np.testing.assert_allclose(final.mean(0), start.mean(0), atol=1e-5)


def test_invoke_without_window_runs_blocking(scene, mb, trefoil):
    scene.moebius.max_iterations = 3
    assert bpy.ops.moebius.relax("INVOKE_DEFAULT") == {"FINISHED"}
    assert scene.moebius.last_keyframes == scene.moebius.last_iterations + 1


def test_keyframe_stride_keeps_the_last_iterate(scene, mb, trefoil):
    s = scene.moebius
    s.max_iterations = 7
    s.tolerance = 0.0
    s.keyframe_stride = 3
    bpy.ops.moebius.relax()
    nit = s.last_iterations
    assert nit == 7
    assert s.last_keyframes == 4  # iterates 0, 3, 6 and 7
    assert mb.keyed_frames(trefoil) == [1, 2, 3, 4]
    assert "maximum number of iterations" in s.last_message


def test_relax_api_matches_core_relax(scene, mb, core, trefoil):
    start = mb.curve_polygons(trefoil)[0]
    # the default method on a knot is the implicit one (api.choose_method)
    for method in ("projected_gradient", "auto"):
        scene.frame_set(1)  # a run starts from the shape shown
        result = mb.relax_object(trefoil, max_iterations=4, tolerance=0.0, method=method)
        ref = core.relax(start, max_iter=4, tol=0.0, target_lengths="keep",
                         method=mb.api.choose_method(method, [start])[0])
        assert result.nit == ref.nit == 4
        np.testing.assert_allclose(result.x, ref.x, atol=1e-12)
        np.testing.assert_allclose(spline_points(trefoil), ref.x, atol=1e-6)  # last shown
        assert result.history["energy"] == ref.history["energy"]


def test_stopping_keeps_iterates_so_far_and_the_start(scene, mb, trefoil):
    """What Esc does in the modal operator: stop(), then finish() keyframes what was done."""
    start = spline_points(trefoil)
    run = mb.ObjectRelaxation(trefoil, max_iterations=50, tolerance=0.0)
    for _ in range(3):
        assert run.step()
    run.stop("cancelled by the user (Esc)")
    assert not run.step()
    result = run.finish(scene)
    assert result.nit == 3 and result.message == "cancelled by the user (Esc)"
    assert mb.keyed_frames(trefoil) == [1.0, 2.0, 3.0, 4.0]
    scene.frame_set(1)
    np.testing.assert_allclose(spline_points(trefoil), start, atol=1e-6)
    # clear_animation goes back to the start shape
    scene.frame_set(4)
    assert bpy.ops.moebius.clear_animation() == {"FINISHED"}
    assert mb.keyed_frames(trefoil) == [] and trefoil.data.animation_data.action is None
    np.testing.assert_allclose(spline_points(trefoil), start, atol=1e-6)


def test_callback_stops_the_run(scene, mb, trefoil):
    result = mb.relax_object(trefoil, max_iterations=50, tolerance=0.0,
                             callback=lambda run: run.nit >= 2)
    assert result.nit == 2 and result.success and "callback" in result.message
    assert len(mb.keyed_frames(trefoil)) == 3


@pytest.mark.lines
def test_apply_frame_then_relax_again(scene, mb, trefoil):
    scene.moebius.max_iterations = 4
    bpy.ops.moebius.relax()
    scene.frame_set(3)
    mid = spline_points(trefoil)
    assert bpy.ops.moebius.apply_frame() == {"FINISHED"}
    assert mb.keyed_frames(trefoil) == []
    scene.frame_set(1)  # no animation any more: the frame-3 shape stays
    np.testing.assert_allclose(spline_points(trefoil), mid, atol=1e-7)
    assert trefoil["moebius_energy"] == pytest.approx(mb.energy([mid]), rel=1e-9)
    bpy.ops.moebius.relax()
    scene.frame_set(scene.frame_start)
    np.testing.assert_allclose(spline_points(trefoil), mid, atol=1e-6)


@pytest.mark.lines
def test_other_animation_is_left_alone(scene, mb, trefoil):
    trefoil.keyframe_insert("location", frame=1)
    scene.moebius.max_iterations = 2
    bpy.ops.moebius.relax()
    bpy.ops.moebius.clear_animation()
    fcurves = fcurves_of(trefoil)
    assert sorted(fc.data_path for fc in fcurves) == ["location"] * 3


def test_link_relaxes_both_components(scene, mb):
    t = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    a = np.column_stack([np.cos(t), np.sin(t), 0 * t])
    b = np.column_stack([1 + np.cos(t), 0 * t, np.sin(t)])
    poly_curve("Hopf", [a, b])
    scene.moebius.edges = 40
    bpy.ops.moebius.convert()
    link = bpy.context.active_object
    scene.moebius.max_iterations = 3
    assert bpy.ops.moebius.relax() == {"FINISHED"}
    assert len(fcurves_of(link.data)) == 3 * 80
    assert scene.moebius.last_energy_end < scene.moebius.last_energy_start
    # Automatic runs the implicit method on links and knots, the explicit one on unknots
    assert scene.moebius.last_method == "projected_gradient_implicit"


@pytest.mark.lines
def test_new_user_relaxes_the_fhw_unknot_into_keyframes(scene, mb):
    # new user: Add Knot ▸ Freedman–He–Wang (its default edges), Relax
    assert bpy.ops.moebius.add_knot(kind="fhw") == {"FINISHED"}
    fhw = bpy.context.active_object
    n = len(spline_points(fhw))
    s = scene.moebius
    s.max_iterations = 5
    assert bpy.ops.moebius.relax() == {"FINISHED"}
    assert (s.last_method, s.last_iterations, s.last_keyframes) == ("projected_gradient", 5, 6)
    assert s.last_energy_end < s.last_energy_start
    assert len(fcurves_of(fhw.data)) == 3 * n
    assert mb.keyed_frames(fhw) == [float(f) for f in range(1, 7)]


def test_failed_setup_keeps_the_previous_flow(scene, mb, trefoil):
    scene.moebius.max_iterations = 2
    bpy.ops.moebius.relax()
    before = scene_state()
    frames = mb.keyed_frames(trefoil)
    with pytest.raises(ValueError, match="armijo must lie"):
        mb.ObjectRelaxation(trefoil, armijo=1.5)
    assert scene_state() == before and mb.keyed_frames(trefoil) == frames


@pytest.mark.lines
def test_failure_while_keyframing_restores_the_curve(scene, mb, trefoil, monkeypatch):
    """The end of a run (writing the keyframes) can fail too, e.g. when the object was
    deleted during a modal run: the operator restores the curve and reports, like any
    other failure, instead of raising out of the operator."""
    import sys

    keyframes = sys.modules[mb.__name__ + ".keyframes"]

    def broken(*args, **kwargs):
        raise ReferenceError("StructRNA of type Object has been removed")

    monkeypatch.setattr(keyframes, "write_flow_keyframes", broken)
    scene.moebius.max_iterations = 3
    before = scene_state()
    with pytest.raises(RuntimeError, match="Relaxation failed, curve restored: StructRNA"):
        bpy.ops.moebius.relax()
    assert scene_state() == before
    assert trefoil.data.animation_data is None or trefoil.data.animation_data.action is None


def test_iteration_limit_report_suggests_the_implicit_method_for_knots(scene, mb, capfd):
    mb.api.add_knot("4_1", None)
    scene.moebius.max_iterations = 3
    scene.moebius.method = "projected_gradient"
    bpy.ops.moebius.relax()
    out, _ = capfd.readouterr()
    assert ("(maximum number of iterations (3) reached; knots settle in fewer iterations with "
            "Advanced ▸ Method: Implicit Gradient)") in out
    assert "Info: " in out and "Warning" not in out  # the limit set is an ordinary end
    scene.moebius.method = "projected_gradient_implicit"
    bpy.ops.moebius.relax()
    out, _ = capfd.readouterr()
    assert "maximum number of iterations (3) reached)" in out and "settle" not in out
    scene.moebius.method = "auto"  # the default: the implicit method on a knot, named
    bpy.ops.moebius.relax()
    out, _ = capfd.readouterr()
    assert "(projected_gradient_implicit: knotted, determinant 5)" in out
    assert "settle" not in out
    # an unknot: the explicit method is the faster one there, no advice
    mb.api.add_knot("fhw", 600)
    scene.moebius.method = "projected_gradient"
    bpy.ops.moebius.relax()
    out, _ = capfd.readouterr()
    assert "maximum number of iterations (3) reached)" in out and "settle" not in out


def test_method_hint_follows_the_status_not_the_words(mb, core):
    def result(status, message):
        return core.RelaxResult(x=None, fun=0.0, nit=3, success=False, message=message,
                                status=status)

    def hint(method, result):
        return mb.api.method_hint(method, result, [core.knots.named("5_2")])

    assert "Implicit Gradient" in hint("projected_gradient", result(core.Status.MAX_ITER, ""))
    # a growing run (Pack in Volume) is not sent to a method that refuses growth
    assert mb.api.method_hint("projected_gradient", result(core.Status.MAX_ITER, ""),
                              [core.knots.named("5_2")], grows=True) == ""
    # the words alone decide nothing: a time budget that mentions an iteration limit
    assert hint("projected_gradient", result(core.Status.TIME, "maximum number of")) == ""
    assert hint("projected_gradient_implicit", result(core.Status.MAX_ITER, "")) == ""
    # nor for an unknot or a link
    unknot = mb.api.method_hint("projected_gradient", result(core.Status.MAX_ITER, ""),
                                [core.knots.freedman_unknot(600)])
    assert unknot == ""


@pytest.mark.parametrize("error", [KeyboardInterrupt, RuntimeError])
def test_interrupted_script_keeps_the_work(scene, mb, error):
    # a callback that raised (Ctrl+C in a script) deleted the earlier run's keys and the new
    # iterates: the curve was left unanimated
    bpy.ops.moebius.add_knot(kind="3_1", edges=60)
    obj = bpy.context.active_object
    mb.relax_object(obj, max_iterations=4, tolerance=0.0)
    assert mb.keyed_frames(obj) == [1, 2, 3, 4, 5]

    def interrupt(run):
        if run.nit == 2:
            raise error("stop")

    with pytest.raises(error) as info:
        mb.relax_object(obj, max_iterations=50, tolerance=0.0, callback=interrupt)
    assert mb.keyed_frames(obj) == [1, 2, 3]  # the start and the two iterates computed
    assert "the 2 iterates computed before the interruption are keyed" in "".join(
        getattr(info.value, "__notes__", []))


def _flow_keys(obj):
    """Every flow F-curve's keys (frame, value) by channel."""
    out = {}
    for idblock in (obj.data, obj):
        for fc in fcurves_of(idblock):
            co = np.empty(2 * len(fc.keyframe_points))
            fc.keyframe_points.foreach_get("co", co)
            out[fc.data_path, fc.array_index] = co.reshape(-1, 2)
    return out


@pytest.mark.lines
def test_continue_appends_after_the_last_keyed_frame(scene, mb, core, trefoil):
    # Relax replaced the previous run and restarted at frame 1 from the current shape; Continue
    # starts from the last keyed iterate and keys the new iterates after it
    start = spline_points(trefoil)
    s = scene.moebius
    s.max_iterations = 4
    s.tolerance = 0.0
    assert bpy.ops.moebius.relax() == {"FINISHED"}
    assert mb.keyed_frames(trefoil) == [1, 2, 3, 4, 5]
    before = _flow_keys(trefoil)
    scene.frame_set(5)
    last = spline_points(trefoil)
    scene.frame_set(2)  # the current frame does not matter for Continue
    s.max_iterations = 3
    assert bpy.ops.moebius.relax(append=True) == {"FINISHED"}
    assert mb.keyed_frames(trefoil) == list(range(1, 9))
    after = _flow_keys(trefoil)
    assert after.keys() == before.keys()
    for channel, keys in before.items():  # the earlier keys are untouched
        np.testing.assert_array_equal(after[channel][:5], keys, err_msg=str(channel))
    # the new iterates are the core's run from the last keyed iterate
    ref = core.relax(last.astype(np.float64), max_iter=3, tol=0.0, target_lengths="keep",
                     method="projected_gradient_implicit")  # the default's choice on a knot
    scene.frame_set(8)
    np.testing.assert_allclose(spline_points(trefoil), ref.x, atol=1e-6)
    assert s.last_iterations == 3 and s.last_energy_start == pytest.approx(ref.history["energy"][0])
    frames, energies = mb.keyed_energies(trefoil)
    assert np.all(np.diff(energies) < 0)
    # Clear Flow still goes back to the start of the first run
    bpy.ops.moebius.clear_animation()
    np.testing.assert_allclose(spline_points(trefoil), start, atol=1e-6)


def test_continue_without_keys_is_a_new_run_and_edited_keys_are_refused(scene, mb, trefoil):
    scene.moebius.max_iterations = 2
    assert bpy.ops.moebius.relax(append=True) == {"FINISHED"}
    assert mb.keyed_frames(trefoil) == [1, 2, 3]
    fcurves_of(trefoil.data)[0].keyframe_points.insert(10, 0.5)  # a key edited by hand
    before = scene_state()
    with pytest.raises(RuntimeError, match="were edited"):
        bpy.ops.moebius.relax(append=True)
    assert scene_state() == before


def test_relax_only_grows_the_scene_range(scene, mb, trefoil):
    # a relax overwrote the scene range: the user's location animation to frame 50 was left
    # with a range of 1-17
    scene.frame_start, scene.frame_end = 1, 50
    trefoil.keyframe_insert("location", frame=50)
    s = scene.moebius
    s.max_iterations = 3
    s.tolerance = 0.0
    bpy.ops.moebius.relax()
    assert mb.keyed_frames(trefoil) == [1, 2, 3, 4]
    assert (scene.frame_start, scene.frame_end) == (1, 50) and scene.frame_current == 4
    s.frame_start = 48
    bpy.ops.moebius.relax()
    assert (scene.frame_start, scene.frame_end) == (1, 51)
    scene.frame_start, scene.frame_end = 40, 45
    bpy.ops.moebius.relax(append=True)  # frames 48-54
    assert (scene.frame_start, scene.frame_end) == (40, 54)


def test_first_run_of_a_session_says_it_prepares_the_solver(scene, mb, trefoil, capfd,
                                                            monkeypatch):
    # the first use compiled for seconds with no word of why nothing moved
    import sys

    monkeypatch.setitem(sys.modules[mb.__name__ + ".relaxation"]._SESSION, "warm", False)
    # the kernels are compiled by now: a note however short the preparation
    monkeypatch.setattr(sys.modules[mb.__name__ + ".operators"], "PREPARE_NOTE_FROM", 0.0)
    scene.moebius.max_iterations = 2
    capfd.readouterr()
    bpy.ops.moebius.relax()
    out = capfd.readouterr().out
    assert "; first run in this session: " in out
    assert " s to the first iterate, preparing the solver (later runs start at once)" in out
    assert mb.api.solver_warm()
    bpy.ops.moebius.relax()
    assert "first run" not in capfd.readouterr().out


def test_the_kernels_are_prepared_in_the_background(scene, mb, trefoil):
    # what the modal Relax waits on, in a thread, when a session's first run starts (the window
    # stays responsive while numba compiles or loads the kernels)
    assert mb.api.solver_paths(trefoil) == ["exact"]
    assert mb.api.solver_paths(trefoil, "tree") == ["tree"]
    trefoil.data.splines[0].use_cyclic_u = False
    assert mb.api.solver_paths(trefoil) == ["open"]
    prep = mb.api.Preparation(["exact"])
    assert prep.wait(600) and prep.error is None and prep.done
    assert prep.kernels >= 0 and 0 < prep.seconds == prep.seconds  # stops counting when done


def test_the_default_run_ends_when_the_shape_stops_changing(scene, mb):
    # Stop When Still (0.1 % of an edge, 5 iterations in a row): the keys end where the motion
    # ends; off, the same run goes on to the tolerance
    s = scene.moebius
    assert s.settle == pytest.approx(0.1)
    bpy.ops.moebius.add_knot(kind="3_1", edges=60)
    knot = bpy.context.active_object
    s.max_iterations = 300
    s.tolerance = 0.0  # this trefoil meets the default tolerance first
    s.method = "projected_gradient"  # the implicit one stalls on rounding first
    assert bpy.ops.moebius.relax() == {"FINISHED"}
    assert s.last_message.startswith("settled: no vertex moved more than 0.001 of an edge")
    settled = s.last_iterations
    frames, points, _ = import_module(mb.__name__ + ".keyframes").read_flow_keyframes(knot)
    assert len(frames) == settled + 1 < 301
    edge = np.linalg.norm(np.roll(points[0], -1, 0) - points[0], axis=1).mean()
    assert np.linalg.norm(points[-1] - points[-6], axis=1).max() <= 5e-3 * edge * 1.001
    s.settle = 0.0
    scene.frame_set(1)  # from the same start
    assert bpy.ops.moebius.relax() == {"FINISHED"}
    assert s.last_iterations > settled and not s.last_message.startswith("settled")
