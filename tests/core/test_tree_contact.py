"""Contact queries through the edge hierarchy (core/tree_contact.py) give the all-pairs answers
bit for bit: random knots, links and motions, and adversarial ones."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from moebius_addon import core
from moebius_addon.core.geometry import collision
from moebius_addon.core.geometry.layout import as_layout
from tests.conftest import ngon, trefoil

ROOT = Path(__file__).resolve().parents[2]


def _both_contacts(P, U, tau_max, eps):
    X, layout = as_layout(P)
    Ux, _ = as_layout(U)
    a = collision.contact_time_x(X, Ux, layout, tau_max, eps, search="pairs")
    b = collision.contact_time_x(X, Ux, layout, tau_max, eps, search="tree")
    return a, b


def _both_closest(P, min_gap=4):
    X, layout = as_layout(P)
    a = collision.closest_pairs(X, layout, min_gap, search="pairs")
    b = collision.closest_pairs(X, layout, min_gap, search="tree")
    # the vertices alone, searched without the edges: the same pair
    assert collision.closest_vertices(X, layout, min_gap, search="tree") == b[0]
    return a, b


def _mean_edge(P):
    X, layout = as_layout(P)
    return float(np.linalg.norm(X[layout.nxt] - X, axis=1).mean())


def _random_curve(rng):
    n = int(rng.integers(12, 500))
    kind = rng.integers(3)
    if kind == 0:
        return core.resample(trefoil(200), max(n, 30)) + 0.03 * rng.standard_normal(
            (max(n, 30), 3))
    if kind == 1:
        m = int(rng.integers(8, 120))
        return [ngon(n) + 0.4 * rng.standard_normal(3), ngon(m)[:, [0, 2, 1]] * 0.8 + [0.9, 0, 0]]
    return rng.standard_normal((n, 3)).cumsum(axis=0)  # a random closed walk


def test_random_inputs_same_bits(rng):
    for _ in range(40):
        P = _random_curve(rng)
        X, layout = as_layout(P)
        U = layout.split(rng.standard_normal(X.shape) * 10 ** rng.uniform(-2, 1))
        eps = 1e-3 * _mean_edge(P)
        for tau_max in (1e-3, 0.1, 10.0):
            a, b = _both_contacts(P, U, tau_max, eps)
            assert a == b
        (va, ea), (vb, eb) = _both_closest(P)
        assert va[0] == vb[0] and ea[0] == eb[0]
        (va, ea), (vb, eb) = _both_closest(P, min_gap=2)
        assert va[0] == vb[0] and ea[0] == eb[0]


def _two_strands(gap, n=80, angle=0.0):
    """Two long flat loops whose straight sides pass ``gap`` apart (crossing at ``angle``)."""
    t = np.linspace(0, 1, n // 2, endpoint=False)
    side = np.c_[10 * t, 0 * t, 0 * t]
    A = np.vstack([side, side[::-1] + [0, 1.0, 0]])
    c, s = np.cos(angle), np.sin(angle)
    B = (A - [5.0, 0, 0]) @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T + [5.0, 0, gap]
    return [A, B]


@pytest.mark.parametrize("angle", [0.0, 1e-3, 0.7, np.pi / 2])
@pytest.mark.parametrize("gap", [1e-9, 1e-4, 0.05])
def test_near_contacts_parallel_and_crossing(gap, angle):
    P = _two_strands(gap, angle=angle)
    h = _mean_edge(P)
    (va, ea), (vb, eb) = _both_closest(P)
    assert va[0] == vb[0] and ea[0] == eb[0]
    # the upper loop moves down through the lower one: contact at about gap
    U = [np.zeros_like(P[0]), np.tile([0, 0, 1.0], (len(P[1]), 1))]
    for eps in (1e-3 * h, 1e-12):
        a, b = _both_contacts(P, U, 10.0, eps)
        assert a == b
        assert a <= gap


def test_coincident_boxes_interleaved_rings_and_collinear_edges():
    ring = ngon(64)
    P = [ring, ring @ np.diag([1.0, 1.0, -1.0]) + [0, 0, 1e-7]]  # congruent, boxes coincide
    (va, ea), (vb, eb) = _both_closest(P)
    assert va[0] == vb[0] and ea[0] == eb[0]
    line = np.c_[np.linspace(0, 1, 50), np.zeros(50), np.zeros(50)]
    Q = [np.vstack([line, line[::-1] + [0, 1, 0]]), np.vstack([line, line[::-1] + [0, 1, 0]])
         + [1.0 + 1e-6, 0, 0]]  # collinear edges end to end
    U = [np.tile([-1.0, 0, 0], (100, 1)), np.tile([1.0, 0, 0], (100, 1))]
    a, b = _both_contacts(Q, U, 1.0, 1e-9)
    assert a == b and a < 1e-6


def test_zero_velocity_and_ties():
    P = ngon(300)  # every vertex pair at one gap is a tie
    (va, ea), (vb, eb) = _both_closest(P)
    assert va[0] == vb[0] and ea[0] == eb[0]
    assert _both_contacts(P, np.zeros_like(P), 3.0, 1e-3) == (3.0, 3.0)


@pytest.mark.parametrize("scale", [1e-30, 1e30])
def test_tiny_and_huge(scale, rng):
    P = core.resample(trefoil(300), 1500) + 0.01 * rng.standard_normal((1500, 3))
    U = rng.standard_normal(P.shape)
    a, b = _both_contacts(P * scale, U * scale, 0.5, 1e-3 * _mean_edge(P) * scale)
    assert a == b
    (va, ea), (vb, eb) = _both_closest(P * scale)
    assert va[0] == vb[0] and ea[0] == eb[0]


def test_check_polygon_messages_the_same(monkeypatch):
    P = trefoil(1200)
    P[700] = P[100] + [0.0, 0.0, 1e-9]  # a self-intersection
    messages = []
    for crossover in (10**9, 0):
        monkeypatch.setattr(collision, "CLOSEST_TREE_FROM", crossover)
        with pytest.raises(ValueError, match="intersects itself") as err:
            core.check_polygon(P)
        messages.append(str(err.value))
    assert messages[0] == messages[1]


def test_bad_search_refused():
    X, layout = as_layout(ngon(20))
    with pytest.raises(ValueError, match="search"):
        collision.closest_pairs(X, layout, 4, search="fast")


CODE = """
import json, numpy as np
from moebius_addon import core
from moebius_addon.core.geometry import collision
from moebius_addon.core.geometry.layout import as_layout
rng = np.random.default_rng(3)
P = core.resample(core.knots.named("8_17"), 6000)
X, layout = as_layout(P)
U = rng.standard_normal(X.shape)
t = collision.contact_time_x(X, U, layout, 0.05, 1e-6, search="tree")
(v, vi), (e, ei, st) = collision.closest_pairs(X, layout, 4, search="tree")
print(json.dumps([t.hex(), v.hex(), e.hex(), vi, ei, [x.hex() for x in st]]))
"""


def test_same_bits_for_every_thread_count():
    outs = []
    for threads in ("1", "2"):
        env = {**os.environ, "NUMBA_NUM_THREADS": threads}
        out = subprocess.run([sys.executable, "-c", CODE], env=env, cwd=ROOT,
                             capture_output=True, text=True, check=True, timeout=600)
        outs.append(json.loads(out.stdout.strip().splitlines()[-1]))
    assert outs[0] == outs[1]


def test_an_engine_builds_the_hierarchy_once_per_polygon(monkeypatch, rng):
    # the step's bound and its trials' paths search from the same iterate: one build, the
    # all-pairs answers; a new polygon, or one changed in place, is built anew
    from moebius_addon.core.runs import engine as engine_module
    P = core.resample(core.knots.named("5_2"), 2000)
    X, layout = as_layout(P)
    eng = engine_module.make_engine("tree", layout, "hs")
    builds = []
    build = engine_module.contact_bvh.build
    monkeypatch.setattr(engine_module.contact_bvh, "build",
                        lambda *a, **k: builds.append(1) or build(*a, **k))
    h = _mean_edge(P)
    for _ in range(3):
        U = rng.standard_normal(X.shape) * h
        got = eng.contact_time(X, U, 50.0, 0.01 * h)
        assert got == collision.contact_time_x(X, U, layout, 50.0, 0.01 * h, search="pairs")
    assert len(builds) == 1
    Y = X.copy()
    eng.contact_time(Y, U, 50.0, 0.01 * h)
    assert len(builds) == 1  # equal values: the same hierarchy
    Y[7] += 0.5 * h
    assert eng.contact_time(Y, U, 50.0, 0.01 * h) == collision.contact_time_x(
        Y, U, layout, 50.0, 0.01 * h, search="pairs")
    assert len(builds) == 2
