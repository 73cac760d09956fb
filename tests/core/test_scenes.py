"""bench/scenes.py: its independent path check, and two small scenes run through
the same code as the demos — cables past a torus, a loop grown inside a sphere — with every
move between consecutive iterates certified free of contact."""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))

import scenes  # noqa: E402

from moebius_addon import core  # noqa: E402
from tests.core.test_container import uv_sphere  # noqa: E402
from tests.core.test_obstacles import torus  # noqa: E402
from tests.mesh_checks import crossings, segments_closest  # noqa: E402


def brute_segment_triangle(p, q, a, b, c, k=400):
    """Distance by dense sampling of the segment against the plane-or-sides distance (an
    upper bound that converges to the true one; 0 where the segment crosses)."""
    s = np.linspace(0.0, 1.0, k)[:, None]
    X = p + s * (q - p)
    n = len(X)
    return float(scenes.point_triangle(X, np.repeat(a[None], n, 0), np.repeat(b[None], n, 0),
                                       np.repeat(c[None], n, 0)).min())


def test_segment_triangle_against_sampling_and_crossings():
    rng = np.random.default_rng(1)
    p, q = rng.normal(size=(300, 3)), rng.normal(size=(300, 3))
    a, b, c = (rng.normal(size=(300, 3)) for _ in range(3))
    d = scenes.segment_triangle(p, q, a, b, c)
    ref = np.array([brute_segment_triangle(*x) for x in zip(p, q, a, b, c, strict=True)])
    hit = d == 0
    assert 0 < hit.sum() < len(d)  # both kinds occur
    # sampling is an upper bound, within the sample spacing of the truth
    step = np.linalg.norm(q - p, axis=1) / 399
    assert np.all(d <= ref + 1e-12) and np.all(ref - d <= step)
    # the crossings agree with tests/mesh_checks.py's all-pairs count, one pair at a time
    assert hit.sum() == sum(crossings(np.array([x, y]), np.array([u, v, w]),
                                      np.array([[0, 1, 2]]), closed=False)
                            for x, y, u, v, w in zip(p, q, a, b, c, strict=True))


def test_gaps_find_the_same_least_distance_as_all_pairs():
    """The k-d tree's candidates miss no pair closer than the cap."""
    rng = np.random.default_rng(2)
    parts = [np.cumsum(rng.normal(scale=0.1, size=(40, 3)), axis=0) + rng.normal(size=3)
             for _ in range(3)]
    closed = [True, False, False]
    p, q, a, b = scenes._edges(parts, closed)
    i, j = np.triu_indices(len(p), 1)
    keep = (a[i] != a[j]) & (a[i] != b[j]) & (b[i] != a[j]) & (b[i] != b[j])
    ref = segments_closest(p[i[keep]], q[i[keep]], p[j[keep]], q[j[keep]]).min()
    assert scenes.curve_gap(p, q, a, b, 10.0) == pytest.approx(ref, rel=1e-12)
    assert scenes.curve_gap(p, q, a, b, 0.5 * ref) == 0.5 * ref
    V, F = torus(0.5, 0.1, 16, 8)
    mesh = scenes.Mesh(V + 0.3, F)
    ii, jj = np.meshgrid(np.arange(len(p)), np.arange(len(F)), indexing="ij")
    ref = scenes.segment_triangle(p[ii.ravel()], q[ii.ravel()], mesh.a[jj.ravel()],
                                  mesh.b[jj.ravel()], mesh.c[jj.ravel()]).min()
    assert scenes.mesh_gap(p, q, mesh, 10.0) == pytest.approx(ref, rel=1e-12)


def small_cables():
    return scenes.cables_torus(cables=4, edges=40, R=0.07, r=0.012, clear=0.03)


def test_the_checker_catches_a_move_through_the_obstacle_and_through_a_cable():
    sc = small_cables()
    checker = scenes.PathChecker(sc)
    rng = np.random.default_rng(0)
    checker.start(sc.parts, rng)
    assert checker.failures == []
    # the whole bundle shifted rigidly sideways, past the torus: neither the start nor the end
    # meets it (nor do the cables meet each other), but the straight move sweeps through its
    # tube, which the check of the iterates alone would not see
    V, F = sc.obstacles[0]
    moved = [P + np.array([0.15, 0.0, 0.0]) for P in sc.parts]
    assert all(crossings(X, V, F, closed=False) == 0 for X in sc.parts + moved)
    assert scenes.PathChecker(sc).gaps(moved, 1.0)[1] > 0.01
    assert not checker.step(sc.parts, moved, "through")
    assert any("contact" in f for f in checker.failures)
    assert not checker.pins_exact  # the pinned ends moved as well
    # a cable moved straight through its neighbour, the torus out of the way
    sc2 = small_cables()
    sc2.obstacles = []
    ch2 = scenes.PathChecker(sc2)
    swap = [sc2.parts[1], sc2.parts[0]] + sc2.parts[2:]
    assert not ch2.step(sc2.parts, swap, "swap")
    # and a small, harmless move passes
    ch3 = scenes.PathChecker(sc2)
    nudged = [P + 1e-4 * np.sin(np.arange(len(P)))[:, None] for P in sc2.parts]
    for P, Q in zip(sc2.parts, nudged, strict=True):
        Q[[0, -1]] = P[[0, -1]]
    assert ch3.step(sc2.parts, nudged, "nudge") and ch3.failures == []


def test_split_like_is_the_refinement():
    rng = np.random.default_rng(3)
    P = rng.normal(size=(7, 3))
    for closed in (True, False):
        for f in (2, 4):
            n = 7 * f if closed else 6 * f + 1
            assert np.allclose(scenes.split_like(P, n, closed),
                               core.subdivide(P, f, closed=closed))


def test_cables_past_a_torus_never_touch_it_nor_each_other():
    sc = small_cables()
    out = scenes.run(sc, iterations=6, engine="exact", say=lambda *_: None)
    assert out["failures"] == [] and out["pins_exact"]
    assert out["checked_steps"] == out["iterations"] >= 3
    assert out["energy_end"] < out["energy_start"]


def test_a_loop_grown_in_a_sphere_stays_inside():
    t = np.linspace(0, 2 * np.pi, 400, endpoint=False)
    P = core.resample(np.c_[np.cos(t), np.sin(t), 0.3 * np.sin(3 * t)] * 0.5, 40)
    L = scenes.total_length([P], [True])
    sc = scenes.Scene("sphere", [P], [True], container=uv_sphere(1.0, 24, 12),
                      options={"length_target": 2.5 * L, "length_growth": 0.1})
    out = scenes.run(sc, iterations=14, engine="exact", say=lambda *_: None)
    assert out["failures"] == []
    assert out["length_end"] == pytest.approx(2.5 * L, rel=1e-8)
    assert out["edges_end"] > 40  # split on the way: the check went through a refinement
    assert out["checked_steps"] == out["iterations"]
