"""Live relaxation (core.runs.live): pins and meshes that move while the flow runs. Every move is
checked with the tests' own geometry (tests/live_checks.py), never the core's: no strand
passes through another or through a mesh, a move that would is cut at contact, pins land on
their targets to the bit when nothing is in the way."""

import time

import numpy as np
import pytest

from moebius_addon import core
from moebius_addon.core.runs.live import LiveDriver, LiveRelaxation, drag_field
from tests.live_checks import certify_move, certify_record, mesh_distance


def box(centre, half):
    """A closed box mesh (8 vertices, 12 triangles facing outwards)."""
    c, h = np.asarray(centre, float), np.asarray(half, float)
    V = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float) * h + c
    F = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    return V, F


def cable(n=30):
    """An open cable from (0, 0, 0) to (0, 0, 1), gently bowed, equilateral."""
    t = np.linspace(0, 1, 400)
    P = np.c_[0.05 * np.sin(np.pi * t), np.zeros_like(t), t]
    return core.resample(P, n + 1, closed=False)


def slow_drag(layout_sizes, closed, pinned, moves):
    """drag_field written out vertex by vertex: walk from each vertex to the pins on either
    side along its component and interpolate by the steps walked."""
    out = []
    start = 0
    for n, cl in zip(layout_sizes, closed, strict=True):
        pins = [p - start for p in pinned if start <= p < start + n]
        D = np.zeros((n, 3))
        for i in range(n):
            if not pins:
                continue
            if cl:
                back = min(pins, key=lambda p: (i - p) % n)
                ahead = min(pins, key=lambda p: (p - i) % n)
                db, da = (i - back) % n, (ahead - i) % n
                mb, ma = moves[pinned.index(back + start)], moves[pinned.index(ahead + start)]
                D[i] = mb if da + db == 0 else (da * mb + db * ma) / (da + db)
            else:
                before = [p for p in pins if p <= i]
                after = [p for p in pins if p >= i]
                if not before:
                    D[i] = moves[pinned.index(after[0] + start)]
                elif not after:
                    D[i] = moves[pinned.index(before[-1] + start)]
                else:
                    b, a = before[-1], after[0]
                    mb, ma = moves[pinned.index(b + start)], moves[pinned.index(a + start)]
                    D[i] = mb if a == b else ((a - i) * mb + (i - b) * ma) / (a - b)
        out.append(D)
        start += n
    return np.concatenate(out)


def test_drag_field_is_the_interpolation_along_each_component():
    from moebius_addon.core.geometry.layout import layout_from_sizes

    rng = np.random.default_rng(1)
    sizes, closed = [12, 9, 7], [True, False, True]
    lay = layout_from_sizes(sizes, True, closed)
    pinned = [2, 7, 14, 18]  # two on the first, two on the open one, none on the last
    moves = rng.standard_normal((4, 3))
    D = drag_field(lay, np.array(pinned), moves)
    assert np.allclose(D, slow_drag(sizes, closed, pinned, list(moves)))
    assert not D[21:].any()  # a component without pins stays
    one = drag_field(layout_from_sizes([10], False), np.array([3]), moves[:1])
    assert np.allclose(one, moves[0])  # one pin on a closed curve: a rigid move


def test_pin_move_lands_on_the_target_and_never_crosses():
    P = core.resample(core.knots.named("3_1", 200), 60)
    run = LiveRelaxation(P, pinned=[0, 30])
    for _ in range(3):
        run.step()
    before = run.x.copy()
    T = run.pin_positions + np.array([[0.25, 0.1, 0.0], [0.0, 0.0, 0.0]])
    res = run.move_pins(T)
    assert res.share == 1.0 and not res.clipped
    assert np.array_equal(run.x[[0, 30]], T)  # the caller's bits
    e = np.linalg.norm(np.roll(run.x, -1, axis=0) - run.x, axis=1)
    e0 = np.linalg.norm(np.roll(before, -1, axis=0) - before, axis=1)
    assert np.abs(e / e0 - 1).max() < 1e-8  # the edge lengths kept
    certify_move([before], [run.x], [True])
    # the flow goes on from there, pins held
    for _ in range(3):
        run.step()
    assert np.array_equal(run.x[[0, 30]], T)


def test_pin_pushing_a_strand_through_an_obstacle_is_clipped():
    P = cable()
    V, F = box((0.25, 0.0, 0.5), (0.06, 0.4, 0.1))
    run = LiveRelaxation(P, pinned=[0, len(P) - 1], closed=False, obstacles=[(V, F)])
    before = run.x.copy()
    T = run.pin_positions.copy()
    T += [0.7, 0.0, 0.0]  # both ends: the cable would be carried through the box
    res = run.move_pins(T)
    assert res.clipped and 0.0 <= res.share < 1.0
    assert "through a mesh" in res.reason
    certify_move([before], [run.x], [False], [(V, V, F)])
    assert mesh_distance([run.x], [False], V, F) > 0.0
    # asked again and again with steps between (what the live thread does): never through
    states = [run.x.copy()]
    for _ in range(15):
        run.move_pins(T)
        states.append(run.x.copy())
        run.step()
        states.append(run.x.copy())
    certify_record([[s] for s in states], [False], [[(V, F)]] * len(states))


def test_mesh_moved_into_the_curve_stops_short_of_it():
    P = cable()
    V, F = box((0.4, 0.0, 0.5), (0.06, 0.4, 0.1))
    run = LiveRelaxation(P, pinned=[0, len(P) - 1], closed=False, obstacles={"Box": (V, F)})
    M = np.eye(4)
    M[0, 3] = -0.6  # through the cable and beyond
    res = run.move_meshes({"Box": M})
    assert res.clipped and 0.0 < res.share < 1.0
    placed = run.placements[0]
    V1 = V @ placed[:3, :3].T + placed[:3, 3]
    certify_move([run.x], [run.x], [False], [(V, V1, F)])  # the box's path misses the cable
    assert V1[:, 0].min() < V[:, 0].min()  # it did move
    with pytest.raises(ValueError, match="no mesh 'Ball'"):
        run.move_meshes({"Ball": M})
    with pytest.raises(ValueError, match="4 × 4"):
        run.move_meshes({"Box": np.eye(3)})


def test_rested_run_goes_on_after_a_move():
    P = core.resample(core.knots.named("3_1", 200), 48)
    run = LiveRelaxation(P, pinned=[0, 24], tol=1e-2)
    while run.step():
        pass
    assert run.done
    T = run.pin_positions + [[0.05, 0.0, 0.0], [0.0, 0.0, 0.0]]
    assert run.move_pins(T).share == 1.0
    assert not run.done and run.step()


def test_bad_targets_are_refused():
    P = core.resample(core.knots.named("3_1", 200), 48)
    run = LiveRelaxation(P, pinned=[0, 24])
    with pytest.raises(ValueError, match="one row"):
        run.move_pins(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="finite"):
        run.move_pins(np.full((2, 3), np.nan))
    free = LiveRelaxation(P)
    with pytest.raises(ValueError, match="nothing is pinned"):
        free.move_pins(np.zeros((2, 3)))


def test_driver_follows_a_scripted_drag_and_records_a_crossing_free_run():
    P = cable()
    V, F = box((0.25, 0.0, 0.5), (0.06, 0.4, 0.1))
    run = LiveRelaxation(P, pinned=[0, len(P) - 1], closed=False, obstacles={"Box": (V, F)})
    start = run.pin_positions.copy()
    drv = LiveDriver(run, record=True)
    try:
        # the top pin dragged down in small moves (reachable: it lands exactly there),
        # then the box pushed into the cable
        for k in range(1, 6):
            T = start + [[0, 0, 0], [0.0, 0.0, -0.04 * k]]
            drv.post(pins=T)
            time.sleep(0.05)
        assert _wait(lambda: drv.latest(new_only=False).parts[0][-1].tolist() == T[1].tolist())
        M = np.eye(4)
        M[0, 3] = -0.5
        drv.post(placements={"Box": M})
        assert _wait(lambda: "clipped" in drv.clipped or drv.error is not None)
        time.sleep(0.2)
    finally:
        drv.close()
    assert drv.error is None
    frames = drv.record
    assert [f.seq for f in frames] == list(range(len(frames)))
    kinds = {f.kind for f in frames}
    assert {"start", "pins", "meshes"} <= kinds
    assert np.array_equal(frames[-1].parts[0][-1], T[1])
    meshes = [[(V @ f.placements[0][:3, :3].T + f.placements[0][:3, 3], F)] for f in frames]
    certify_record([f.parts for f in frames], [False], meshes)


def _wait(cond, timeout=20.0):
    end = time.perf_counter() + timeout
    while time.perf_counter() < end:
        if cond():
            return True
        time.sleep(0.01)
    return False


def test_tangent_point_energy_runs_live():
    P = core.resample(core.knots.named("3_1", 200), 48)
    run = LiveRelaxation(P, pinned=[0, 24], energy="tangent_point")
    assert run.energy_choice.label.startswith("tangent_point")
    before = run.x.copy()
    T = run.pin_positions + [[0.1, 0.0, 0.0], [0.0, 0.0, 0.0]]
    assert run.move_pins(T).share == 1.0
    assert run.step()
    certify_move([before], [run.x], [True])


def _total_length(parts, closed):
    return sum(float(np.linalg.norm(np.diff(np.vstack([P, P[:1]]) if closed else P, axis=0),
                                    axis=1).sum()) for P in parts)


def test_grow_lengthens_then_shrinks_back_never_crossing():
    """The Grow slider: the length reaches factor × the start's (measured here from the
    coordinates), shrinks back when the factor is lowered, and the driver's record of the
    whole run passes the crossing certificate."""
    P = core.resample(core.knots.named("3_1", 200), 48)
    run = LiveRelaxation(P, pinned=[0, 24], length_growth=0.05)
    L0 = _total_length([run.x], True)
    drv = LiveDriver(run, record=True)
    try:
        drv.post(grow=1.3)
        assert _wait(lambda: abs(_total_length(drv.latest(new_only=False).parts, True)
                                 - 1.3 * L0) < 1e-6 * L0)
        high = drv.latest(new_only=False).seq
        drv.post(grow=1.1)
        assert _wait(lambda: abs(_total_length(drv.latest(new_only=False).parts, True)
                                 - 1.1 * L0) < 1e-6 * L0)
        time.sleep(0.1)
    finally:
        drv.close()
    assert drv.error is None
    assert run.length_factor == 1.1
    lengths = [_total_length(f.parts, True) for f in drv.record]
    assert max(lengths) == pytest.approx(1.3 * L0, rel=1e-6)
    # growth by at most 5 % per state, and the shrink after the high point
    assert all(b <= a * 1.05 * (1 + 1e-9) for a, b in zip(lengths[:-1], lengths[1:], strict=True))
    assert min(lengths[high:]) == pytest.approx(1.1 * L0, rel=1e-6)
    certify_record([f.parts for f in drv.record], [True], None)


def test_grow_refusals():
    P = core.resample(core.knots.named("3_1", 200), 48)
    run = LiveRelaxation(P, pinned=[0, 24])
    with pytest.raises(ValueError, match="factor"):
        run.grow(0.5)
    with pytest.raises(ValueError, match="grow"):
        LiveDriver.post(LiveDriver.__new__(LiveDriver), grow=float("nan"))
    with pytest.raises(ValueError, match="length_growth"):
        LiveRelaxation(P, length_growth=0.0)
    # a cable pinned at every vertex has nothing that can grow: the driver says so and runs on
    C = cable(8)
    every = LiveRelaxation([C, C + [0.5, 0.0, 0.0]], pinned=[list(range(len(C))), [0]],
                           closed=False)
    drv = LiveDriver(every)
    try:
        drv.post(grow=1.5)
        assert _wait(lambda: "grow refused" in drv.refused)
        assert "component 0 cannot grow" in drv.refused
        assert drv.error is None and drv.alive
    finally:
        drv.close()
    assert every.growth_schedule is None and every.length_factor == 1.0
