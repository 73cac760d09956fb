"""Continuous collision bound: analytic contact times, planar motions, conservativeness."""

import numpy as np
import pytest

from moebius_addon.core import max_collision_free_step
from moebius_addon.core.geometry.collision import closest_pairs, segment_distance2
from moebius_addon.core.geometry.layout import as_layout
from tests.conftest import ngon


def square(z=0.0, angle=0.0):
    c = np.array([[0.5, 0.5], [-0.5, 0.5], [-0.5, -0.5], [0.5, -0.5]])
    r = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    c = c @ r.T
    return np.c_[c, np.full(4, z)]


def test_segment_distance_cases():
    d2, s, t = segment_distance2(0, 0, 0, 1, 0, 0, 0.5, -1, 1, 0.5, 1, 1)  # skew, 1 apart
    assert d2 == pytest.approx(1.0) and s == pytest.approx(0.5) and t == pytest.approx(0.5)
    d2, *_ = segment_distance2(0, 0, 0, 1, 0, 0, 2, 0, 0, 3, 0, 0)  # collinear, gap 1
    assert d2 == pytest.approx(1.0)
    d2, *_ = segment_distance2(0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0)  # parallel, 1 apart
    assert d2 == pytest.approx(1.0)
    d2, *_ = segment_distance2(0, 0, 0, 1, 1, 0, 1, 0, 0, 0, 1, 0)  # crossing
    assert d2 == pytest.approx(0.0, abs=1e-30)


def test_falling_square_hits_at_the_analytic_time():
    # square B (rotated 45°) falls from z = 2 onto square A at z = 0: contact at τ = 2
    A, B = square(0.0), square(2.0, np.pi / 4)
    U = [np.zeros((4, 3)), np.tile([0.0, 0.0, 1.0], (4, 1))]
    tau = max_collision_free_step([A, B], U, tau_max=10.0, eps=1e-6)
    assert 2.0 - 2e-6 <= tau <= 2.0


def test_no_contact_before_the_bound_returns_the_bound():
    A, B = square(0.0), square(2.0, np.pi / 4)
    U = [np.zeros((4, 3)), np.tile([0.0, 0.0, 1.0], (4, 1))]
    assert max_collision_free_step([A, B], U, tau_max=1.5) == 1.5
    assert max_collision_free_step([A, B], [U[0], -U[1]], tau_max=100.0) == 100.0


def test_planar_squeeze():
    # a flat rectangle whose long sides move toward each other in their own plane (the
    # classical coplanarity cubic vanishes identically here): contact at τ = 1
    n = 60
    top = np.c_[np.linspace(0, 10, n), np.ones(n), np.zeros(n)]
    P = np.vstack([top[::-1][:-1], np.c_[np.linspace(0, 10, n), np.zeros(n), np.zeros(n)][:-1]])
    P = np.vstack([np.c_[np.linspace(0, 10, n), np.zeros(n), np.zeros(n)],
                   np.c_[np.linspace(10, 0, n), np.ones(n), np.zeros(n)]])
    U = np.zeros_like(P)
    U[:, 1] = P[:, 1] - 0.5
    tau = max_collision_free_step(P, U, tau_max=5.0, eps=1e-4)
    assert 1.0 - 1e-3 <= tau <= 1.0


def test_step_is_conservative_on_random_motions(rng):
    for _ in range(5):
        P = ngon(40) + 0.02 * rng.standard_normal((40, 3))
        U = rng.standard_normal((40, 3))
        X, lay = as_layout(P)
        eps = 1e-3 * np.linalg.norm(np.roll(P, -1, 0) - P, axis=1).mean()
        tau = max_collision_free_step(P, U, tau_max=1.0, eps=eps)
        assert 0 < tau <= 1.0
        for s in np.linspace(0, tau, 50):
            (_, _), (de, _, _) = closest_pairs(X - s * U, lay)
            assert de >= 0.999 * eps


def test_step_is_the_first_contact(rng):
    """The pruned search returns a time of real contact, not just some safe step: a thin long
    loop sweeps through a trefoil (translation + linearized rotation about z). At the returned τ two
    edges are eps apart; before it none are closer (sampled); and it agrees with the
    conservative advancement of every pair without pruning."""
    from moebius_addon.core.geometry.collision import _pair_contact
    from tests.conftest import trefoil

    A = trefoil(150)
    eps = 1e-3 * np.linalg.norm(np.roll(A, -1, 0) - A, axis=1).mean()
    y = np.linspace(-10.0, 10.0, 50)
    for _ in range(3):
        z0 = rng.uniform(-0.8, 0.8)
        B = np.r_[np.c_[np.full(50, 7.0), y, np.full(50, z0)],
                  np.c_[np.full(50, 7.0), y[::-1], np.full(50, z0 + 0.02)]]
        # rotation about z keeps B in its planes z0, z0 + 0.02, which the trefoil crosses
        omega = [0.0, 0.0, 0.01 * rng.standard_normal()]
        UB = np.array([1.0, 0.05 * rng.standard_normal(), 0.0]) + np.cross(omega, B)
        P, U = [A, B], [np.zeros_like(A), UB]
        X, lay = as_layout(P)
        Ux, _ = as_layout(U)
        tau = max_collision_free_step(P, U, tau_max=20.0, eps=eps)
        assert tau < 20.0
        assert closest_pairs(X - tau * Ux, lay)[1][0] <= 1.0011 * eps
        for s in np.linspace(0.0, tau, 200, endpoint=False):
            assert closest_pairs(X - s * Ux, lay)[1][0] >= 0.999 * eps
        nxt = lay.nxt
        ref = min(
            _pair_contact(X, Ux, i, nxt[i], j, nxt[j], 0.0, 20.0, eps)
            for i in range(len(X)) for j in range(i + 1, len(X))
            if j != nxt[i] and i != nxt[j]
        )
        assert tau == pytest.approx(ref, rel=1e-6)


def test_contact_time_far_from_unit_size():
    P = ngon(40)
    U = np.zeros_like(P)
    U[10] = P[10]  # vertex 10 moves through the centre, towards the far side
    tau = max_collision_free_step(P, U, 5.0)
    assert 0.0 < tau < 2.5
    for k in (-500, 500):  # P, U and eps at 2^k: the same contact time, to the bit
        assert max_collision_free_step(np.ldexp(P, k), np.ldexp(U, k), 5.0) == tau
