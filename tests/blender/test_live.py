"""Live relax (blender.live.LiveSession, what the modal *Live* operator drives) with the real
bpy, headless: a scripted sequence of pin moves (written into the curve as a user's G does)
and obstacle moves, one of them pushing the cable through the obstacle — clipped, never
crossed, checked with the tests' own segment and triangle distances (tests/live_checks.py);
the recorded keys never cross; cancel restores the start exactly."""

import time
from importlib import import_module

import bpy
import numpy as np
import pytest
from bpy_helpers import poly_curve, scene_state, world_mesh

from tests.live_checks import certify_record, mesh_distance


def live(mb):
    return import_module(mb.__name__ + ".live")


def keyframes(mb):
    return import_module(mb.__name__ + ".keyframes")


def sync_for(session, seconds: float, until=None) -> None:
    """What the operator's timer does, for ``seconds`` (or until ``until()``)."""
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        session.sync()
        if until is not None and until():
            return
        time.sleep(0.01)


def running(session) -> None:
    """Wait for the run's first step (the first one in a process compiles kernels)."""
    sync_for(session, 600.0, until=lambda: session.frame.seq >= 1 or session.driver.error)
    assert session.driver.error is None and session.frame.seq >= 1


def set_point(obj, i, xyz) -> None:
    obj.data.splines[0].points[i].co = (*xyz, 1.0)


def point(obj, i) -> np.ndarray:
    return np.array(obj.data.splines[0].points[i].co)[:3]


@pytest.fixture
def cable_and_box(scene, core):
    """An open cable from (0, 0, 0) to (0, 0, 1), its two ends selected (the pins), and a box
    beside its middle in the collection 'Obstacles'."""
    t = np.linspace(0, 1, 400)
    P = core.resample(np.c_[0.05 * np.sin(np.pi * t), np.zeros_like(t), t], 31, closed=False)
    obj = poly_curve("Cable", [P], cyclic=False)
    for k, p in enumerate(obj.data.splines[0].points):
        p.select = k in (0, 30)
    coll = bpy.data.collections.new("Obstacles")
    scene.collection.children.link(coll)
    bpy.ops.mesh.primitive_cube_add(size=2.0, location=(0.25, 0.0, 0.5))
    box = bpy.context.active_object
    box.scale = (0.06, 0.4, 0.1)
    for c in box.users_collection:
        c.objects.unlink(box)
    coll.objects.link(box)
    bpy.context.view_layer.objects.active = obj
    bpy.context.view_layer.update()
    return obj, box, coll


def test_pins_and_obstacle_moves_are_followed_clipped_and_recorded(mb, cable_and_box):
    obj, box, coll = cable_and_box
    session = live(mb).LiveSession([obj], record=True, pin_selected=True, obstacles=coll)
    V0, F = world_mesh(box)
    try:
        running(session)
        # 1. the top pin dragged down in small moves: the cable follows, the pin lands there
        top = point(obj, 30)
        for k in range(1, 5):
            target = top + [0.0, 0.0, -0.03 * k]
            set_point(obj, 30, target)
            sync_for(session, 0.1)
        target32 = np.array(obj.data.splines[0].points[30].co)[:3]  # as Blender keeps it
        sync_for(session, 60.0, until=lambda: np.array_equal(
            session.frame.parts[0][30], target32))
        assert np.array_equal(session.frame.parts[0][30], target32)
        # 2. the box pushed into the cable: it stops short of it, and moves as the flow makes room
        box.location.x -= 0.8
        bpy.context.view_layer.update()
        sync_for(session, 60.0, until=lambda: "mesh move clipped" in session.driver.clipped)
        assert "mesh move clipped at contact" in session.status()
        sync_for(session, 0.3)
        assert box.location.x < 0.25  # the user's place; the run's is checked below
        # 3. both pins carried 0.7 across: the cable's middle would go through the box
        bottom = point(obj, 0)
        set_point(obj, 0, bottom + [0.7, 0, 0])
        set_point(obj, 30, target32 + [0.7, 0, 0])
        sync_for(session, 60.0, until=lambda: "pin move clipped" in session.driver.clipped)
        assert "pin move clipped at contact" in session.status()
        sync_for(session, 0.5)
        M = session.frame.placements[0]  # the box where the run has it (world = run here)
        assert mesh_distance(session.frame.parts, [False], V0 @ M[:3, :3].T + M[:3, 3], F) > 0
        # the curve shows the run's state but leaves the pins where the user put them
        assert np.array_equal(point(obj, 0), np.float32(bottom + [0.7, 0, 0]))
        sync_for(session, 0.3)
    except BaseException:
        session.cancel()
        raise
    done = session.finish()
    assert done["frames"] is not None and done["states"] >= 3
    # the box is where the run had it: moved, but short of the cable
    assert 0.25 - 0.8 < box.location.x < 0.25
    frames, points, _ = keyframes(mb).read_flow_keyframes(obj)
    assert len(frames) == done["states"]
    assert frames[0] == 1  # the frame current when Live began
    # the recorded animation as Blender plays it: curve and box at every keyed frame
    states, meshes = [], []
    for k, f in enumerate(frames):
        bpy.context.scene.frame_set(int(f))
        bpy.context.view_layer.update()
        M = np.array(obj.matrix_world)
        states.append([points[k] @ M[:3, :3].T + M[:3, 3]])
        meshes.append([world_mesh(box)])
    assert not np.array_equal(meshes[0][0][0], meshes[-1][0][0])  # the box moved, keyed
    least = certify_record(states, [False], meshes)
    assert least > 0.0


def test_cancel_restores_the_start_exactly(mb, scene, core):
    bpy.ops.moebius.add_knot(kind="3_1", edges=60)
    knot = bpy.context.active_object
    mb.relax_object(knot, max_iterations=3)  # flow keys that Live must give back
    before_keys = keyframes(mb).read_flow_keyframes(knot)
    start = np.array([tuple(p.co) for p in knot.data.splines[0].points])
    coll = bpy.data.collections.new("Obstacles")
    scene.collection.children.link(coll)
    bpy.ops.mesh.primitive_ico_sphere_add(radius=0.2, location=(0.0, 0.0, 3.0))
    ball = bpy.context.active_object
    for c in ball.users_collection:
        c.objects.unlink(ball)
    coll.objects.link(ball)
    ball_at = ball.matrix_world.copy()
    bpy.context.view_layer.objects.active = knot
    for k, p in enumerate(knot.data.splines[0].points):
        p.select = k in (0, 30)
    session = live(mb).LiveSession([knot], pin_selected=True, obstacles=coll)
    running(session)
    p0 = np.array(knot.data.splines[0].points[0].co)
    knot.data.splines[0].points[0].co = tuple(p0 + [0.2, 0.0, 0.0, 0.0])
    ball.location.z -= 0.5
    sync_for(session, 0.5)
    moved = np.array([tuple(p.co) for p in knot.data.splines[0].points])
    assert not np.array_equal(moved, start)  # the flow ran and was shown
    session.cancel()
    assert np.array_equal(np.array([tuple(p.co) for p in knot.data.splines[0].points]), start)
    assert ball.matrix_world == ball_at
    after = keyframes(mb).read_flow_keyframes(knot)
    for a, b in zip(before_keys, after, strict=True):
        assert np.array_equal(a, b)


def test_bad_input_is_refused_and_leaves_the_scene(mb, scene):
    bpy.ops.moebius.add_knot(kind="3_1", edges=60)
    knot = bpy.context.active_object
    for p in knot.data.splines[0].points:
        p.select = False
    state = scene_state()
    with pytest.raises(ValueError, match=f"no point of '{knot.name}' is selected"):
        live(mb).LiveSession([knot], pin_selected=True)
    assert scene_state() == state
    bpy.ops.mesh.primitive_cube_add()
    with pytest.raises(ValueError, match="not a curve"):
        live(mb).LiveSession([bpy.context.active_object])
    assert bpy.ops.moebius.live.poll() is False  # a mesh is active: greyed out


def test_grow_slider_lengthens_the_curve_and_records_it(mb, scene):
    """*Grow* while Live runs (the operator sets ``session.grow`` from the panel's slider on
    every tick): the knot grows to 1.25 times its length, the status says how far it is, and
    the recorded keys as Blender plays them reach that length and never cross."""
    bpy.ops.moebius.add_knot(kind="3_1", edges=60)
    knot = bpy.context.active_object
    bpy.context.scene.moebius.length_growth = 4.0  # percent per iteration
    kwargs = live(mb).live_settings(bpy.context.scene.moebius)
    assert kwargs["length_growth"] == pytest.approx(0.04)

    def length(P):
        return float(np.linalg.norm(np.diff(np.vstack([P, P[:1]]), axis=0), axis=1).sum())

    start = np.array([tuple(p.co) for p in knot.data.splines[0].points])[:, :3]
    L0 = length(start)
    session = live(mb).LiveSession([knot], record=True, **kwargs)
    try:
        running(session)
        session.grow = 1.25
        sync_for(session, 30.0, until=lambda: session.run.growth_schedule is not None)
        assert "of the target" in session.status() or session.run.growth_schedule.reached
        sync_for(session, 120.0, until=lambda: abs(length(session.frame.parts[0]) - 1.25 * L0)
                 < 1e-6 * L0)
        sync_for(session, 0.2)
    except BaseException:
        session.cancel()
        raise
    done = session.finish()
    assert done["length"] == pytest.approx(1.25 * L0, rel=1e-6)
    frames, points, _ = keyframes(mb).read_flow_keyframes(knot)
    lengths = [length(P) for P in points]
    assert lengths[0] == pytest.approx(L0, rel=1e-6)
    assert max(lengths) == pytest.approx(1.25 * L0, rel=1e-5)  # float32 points
    assert all(b <= a * 1.04 * (1 + 1e-5) for a, b in zip(lengths[:-1], lengths[1:], strict=True))
    certify_record([[P] for P in points], [True])


def test_live_takes_the_stiffness(mb, scene):
    """*Stiffness* reaches a live run as it reaches *Relax* (the energy's records' options)."""
    bpy.ops.moebius.add_knot(kind="3_1", edges=60)
    knot = bpy.context.active_object
    bpy.context.scene.moebius.stiffness = 0.5
    kwargs = live(mb).live_settings(bpy.context.scene.moebius)
    assert kwargs["stiffness"] == pytest.approx(0.5)
    session = live(mb).LiveSession([knot], **kwargs)
    try:
        running(session)
        assert "bending" in session.run.energy_choice.label
    finally:
        session.cancel()
