"""Length growth: ``length_target=`` reached at ``length_growth=`` per iteration,
monotonically, then held; inside a container never left (independent numpy checks of every
iterate and every straight move between iterates)."""

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from moebius_addon import core
from tests.core.test_container import left_on_the_way, uv_sphere, wall_distance, wavy_loop

# lengths agree with their targets to the back-projection's tolerance (1e-10 per log length)
ROUND = 1e-9
ROOT = Path(__file__).resolve().parents[2]


def length(X, closed=True):
    """Total length of a polygon (numpy, independent of the run's bookkeeping)."""
    X = np.asarray(X)
    E = (np.roll(X, -1, 0) - X) if closed else np.diff(X, axis=0)
    return float(np.linalg.norm(E, axis=1).sum())


def trefoil(n=60):
    t = np.linspace(0, 2 * np.pi, 600, endpoint=False)
    P = np.stack([np.sin(t) + 2 * np.sin(2 * t), np.cos(t) - 2 * np.cos(2 * t),
                  -np.sin(3 * t)], -1)
    return core.resample(P, n)


def split(A):
    """Every edge of the closed polygon ``A`` split in two at its midpoint (the same point
    set: what a refinement makes)."""
    out = np.empty((2 * len(A), 3))
    out[0::2] = A
    out[1::2] = 0.5 * (A + np.roll(A, -1, 0))
    return out


def test_growth_reaches_its_target_monotonically_and_holds_it():
    P = trefoil()
    L0 = length(P)
    target, rate = 1.5 * L0, 0.05
    xs = [P]
    r = core.relax(P, max_iter=16, length_target=target, length_growth=rate, engine="exact",
                   refine=False, callback=lambda s: xs.append(s.x.copy()))
    L = np.array(r.history["length"])
    assert L[0] == pytest.approx(L0, rel=ROUND)
    # the history's lengths are the iterates' own
    assert np.allclose(L, [length(X) for X in xs], rtol=ROUND, atol=0)
    assert np.all(np.diff(L) >= -ROUND * target)  # never shorter
    assert np.all(L[1:] / L[:-1] <= 1 + rate + ROUND)  # never faster than the rate
    # the Möbius energy is scale-invariant: nothing blocks, every iteration grows by the rate
    reached = int(np.argmax(L >= target * (1 - ROUND)))
    assert reached == math.ceil(math.log(target / L0) / math.log(1 + rate))
    assert np.allclose(L[reached:], target, rtol=ROUND, atol=0)  # held from there
    assert r.nit == 16 and len(L) == 17  # no convergence test while growing


def test_the_target_is_held_by_a_run_that_then_converges():
    P = trefoil(48)
    target = 1.2 * length(P)
    r = core.relax(P, max_iter=300, length_target=target, length_growth=0.1, engine="exact",
                   tol=1e-3)
    assert r.status == core.Status.CONVERGED
    assert length(r.x) == pytest.approx(target, rel=ROUND)
    # edges equal, each grown by the same factor
    ln = np.linalg.norm(np.roll(r.x, -1, 0) - r.x, axis=1)
    assert np.allclose(ln, target / len(P), rtol=1e-8)


def test_growth_inside_a_container_never_leaves_it(rng):
    V, F = uv_sphere(0.8)
    P = wavy_loop(60)
    L0 = length(P)
    target = 1.6 * L0  # longer than the largest circle of the sphere (5.03): it must fold
    assert target > 2 * np.pi * 0.8
    xs = [P]
    r = core.relax(P, max_iter=20, container=(V, F), length_target=target,
                   length_growth=0.05, engine="exact",
                   callback=lambda s: xs.append(s.x.copy()))
    L = np.array(r.history["length"])
    assert np.all(np.diff(L) >= -ROUND * target)
    assert length(r.x) == pytest.approx(target, rel=ROUND)
    # a split iterate is the same point set: compare the moves at the finer count
    moves = [xs[0]]
    for X in xs[1:]:
        moves.append(X)
        if len(X) == 2 * len(moves[-2]):
            moves[-2] = split(moves[-2])
    assert all(len(A) == len(B) for A, B in zip(moves[:-1], moves[1:], strict=True))
    assert not left_on_the_way(moves, V, F, rng)
    assert wall_distance(r.x, V, F) > 0


def test_growth_with_no_room_left_stops_stalled_and_says_so(rng):
    # a flat round circle has no direction to fold in (its energy gradient is zero): it grows
    # until the next growth would touch the wall (weight 0: nothing pushes it off), then stops
    V, F = uv_sphere(0.8)
    t = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    P = np.c_[0.6 * np.cos(t), 0.6 * np.sin(t), 0 * t]
    xs = [P]
    r = core.relax(P, container=(V, F), obstacle_weight=0.0, max_iter=80,
                   length_target=3 * length(P), length_growth=0.05, engine="exact",
                   refine=False, callback=lambda s: xs.append(s.x.copy()))
    assert r.status == core.Status.STALLED and not r.success
    assert r.message.startswith("growth blocked at length")
    L = np.array(r.history["length"])
    assert np.all(np.diff(L) >= -ROUND * L[-1]) and L[-1] > 1.2 * L[0]
    assert L[-1] < 2 * np.pi * 0.8  # the sphere's great circle: it cannot be longer, round
    assert not left_on_the_way(xs, V, F, rng)


_NO_ROOM = """
import numpy as np
from moebius_addon import core
from tests.core.test_container import uv_sphere
V, F = uv_sphere(0.8)
t = np.linspace(0, 2 * np.pi, 40, endpoint=False)
P = np.c_[0.6 * np.cos(t), 0.6 * np.sin(t), 0 * t]
r = core.relax(P, container=(V, F), obstacle_weight=0.0, max_iter=80,
               length_target=3 * 2 * np.pi * 0.6, length_growth=0.05, engine="exact",
               refine=False)
OUT = [int(r.status), r.nit, r.message]
"""


def test_growth_blocked_ends_the_run_whatever_the_blas_threads():
    # the round circle's gradient is rounding noise: with one BLAS thread a descent step was
    # still found at every iteration and the run went on, not growing, to max_iter (80); it
    # now ends after projected._GROWTH_PATIENCE iterations whose growth was blocked
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    out = subprocess.run([sys.executable, "-c", _NO_ROOM + "\nimport json\nprint(json.dumps(OUT))"],
                         env=env, cwd=ROOT, capture_output=True, text=True, check=True,
                         timeout=600)
    status, nit, message = json.loads(out.stdout.strip().splitlines()[-1])
    assert status == int(core.Status.STALLED), message
    assert message.startswith("growth blocked at length 4.9788")
    assert nit < 80


def test_growth_splits_edges_grown_past_twice_their_start():
    P = trefoil(40)
    L0 = length(P)
    r = core.relax(P, max_iter=20, length_target=2.5 * L0, length_growth=0.1, engine="exact")
    (ref,) = r.refinements
    assert (ref["edges_before"], ref["edges_after"]) == (40, 80)
    edges = np.array(r.history["edges"])
    L = np.array(r.history["length"])
    # split at the first iterate whose edges were more than twice the start's
    first = int(np.argmax(L / L0 > 2.0))
    assert np.all(edges[:first] == 40) and np.all(edges[first:] == 80)
    assert length(r.x) == pytest.approx(2.5 * L0, rel=ROUND)
    assert np.all(np.diff(L) >= -ROUND * L0)


def test_the_tree_engine_grows_too():
    P = trefoil(120)
    L0 = length(P)
    r = core.relax(P, engine="tree", max_iter=12, length_target=1.5 * L0, length_growth=0.05,
                   refine=False)
    assert r.stats["engine"] == "tree"
    L = np.array(r.history["length"])
    assert np.all(np.diff(L) >= -ROUND * L0)
    assert length(r.x) == pytest.approx(1.5 * L0, rel=ROUND)


def test_growth_keeps_the_ratios_of_kept_lengths():
    t = np.linspace(0, 2 * np.pi, 50, endpoint=False)
    P = np.stack([np.cos(t + 0.2 * np.sin(t)), np.sin(t + 0.2 * np.sin(t)),
                  0.3 * np.sin(2 * t)], -1)  # edges of different lengths
    l0 = np.linalg.norm(np.roll(P, -1, 0) - P, axis=1)
    r = core.relax(P, max_iter=8, length_target=1.3 * l0.sum(), length_growth=0.05,
                   target_lengths="keep", engine="exact", refine=False)
    ln = np.linalg.norm(np.roll(r.x, -1, 0) - r.x, axis=1)
    assert np.allclose(ln / l0, 1.3, rtol=1e-8)


def test_a_link_grows_each_component_to_its_own_target():
    t = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    a = np.c_[np.cos(t), np.sin(t), 0 * t]
    b = np.c_[1.0 + 0.7 * np.cos(t), 0 * t, 0.7 * np.sin(t)]
    La, Lb = length(a), length(b)
    r = core.relax([a, b], max_iter=12, length_target=[1.1 * La, 1.4 * Lb],
                   length_growth=0.05, engine="exact", refine=False)
    assert length(r.x[0]) == pytest.approx(1.1 * La, rel=ROUND)
    assert length(r.x[1]) == pytest.approx(1.4 * Lb, rel=ROUND)
    # one number: the whole link, each component alike; 1 % per iteration by default
    r = core.relax([a, b], max_iter=25, length_target=1.2 * (La + Lb), engine="exact",
                   refine=False)
    assert length(r.x[0]) / La == pytest.approx(1.2, rel=ROUND)
    assert length(r.x[1]) / Lb == pytest.approx(1.2, rel=ROUND)


def test_an_open_cable_between_pinned_ends_grows():
    t = np.linspace(0, 1, 200)
    P = core.resample(np.c_[4 * t, 0.3 * np.sin(3 * np.pi * t), 0 * t], 40, closed=False)
    L0 = length(P, closed=False)
    r = core.relax(P, closed=False, pinned=[0, 39], max_iter=20, length_target=1.25 * L0,
                   length_growth=0.05, engine="exact")
    assert np.array_equal(r.x[[0, 39]], P[[0, 39]])  # the ends stay, bit for bit
    # nearly straight between its ends, the cable first grows by halved rates (the
    # back-projection of a full 5 % does not converge there), then at the full rate
    L = np.array(r.history["length"])
    assert np.all(np.diff(L) >= -ROUND * L0) and np.all(L[1:] / L[:-1] <= 1.05 + ROUND)
    assert length(r.x, closed=False) == pytest.approx(1.25 * L0, rel=ROUND)


def test_the_tangent_point_energy_grows_too():
    P = trefoil(48)
    target = 1.3 * length(P)
    r = core.relax(P, energy="tangent_point", max_iter=10, length_target=target,
                   length_growth=0.05, engine="exact", refine=False)
    assert length(r.x) == pytest.approx(target, rel=ROUND)
    L = np.array(r.history["length"])
    assert np.all(np.diff(L) >= -ROUND * target)


@pytest.mark.parametrize("options, message", [
    ({"length_target": 10.0, "length_growth": 0.0}, "length_growth must be a finite number > 0"),
    ({"length_target": 10.0, "length_growth": -0.1}, "length_growth must be a finite number > 0"),
    ({"length_target": 10.0, "length_growth": float("nan")}, "length_growth must be a finite"),
    ({"length_target": float("nan")}, "length_target must be a finite number > 0"),
    ({"length_target": "20"}, "length_target must be a number"),
    ({"length_target": 1.0}, "length_target 1 is below the curve's length at the start"),
    ({"length_target": [20.0, 30.0]}, r"one per component \(1\)"),
    ({"length_growth": 0.01}, "length_growth needs length_target="),
    ({"length_target": 20.0, "method": "trust_region"}, "cannot grow the curve's length"),
    ({"length_target": 20.0, "method": "lbfgs"}, "cannot grow the curve's length"),
    ({"length_target": 20.0, "edge_lengths": False}, "edge_lengths=False"),
])
def test_bad_growth_options_are_refused(options, message):
    P = trefoil(48)
    before = P.copy()
    with pytest.raises(ValueError, match=message):
        core.relax(P, max_iter=1, engine="exact", **options)
    assert np.array_equal(P, before)
