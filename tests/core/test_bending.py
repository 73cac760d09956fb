"""core.energies.bending: the discrete elastic rod's bending energy and its weight ``stiffness=``.

Against a slow numpy version of the formula (turning angles by arccos), the regular polygon's
closed form, central differences, and runs: the weight 0 changes no bit, a positive one is
added once by both engines, and a bent cable between pins comes out straighter with it.
"""

from __future__ import annotations

import numpy as np
import pytest

from moebius_addon import core
from moebius_addon.core.energies import bending
from moebius_addon.core.energies.choice import check_energy
from moebius_addon.core.geometry.layout import as_layout
from moebius_addon.core.runs.engine import DenseEngine, TreeEngine


def _slow(P, closed=True) -> float:
    """Σ over interior vertices of 4 tan²(φ/2) / ((|a| + |b|)/2), φ by arccos."""
    P = np.asarray(P, float)
    n = len(P)
    idx = range(n) if closed else range(1, n - 1)
    E = 0.0
    for i in idx:
        a = P[i] - P[i - 1]
        b = P[(i + 1) % n] - P[i]
        la, lb = np.linalg.norm(a), np.linalg.norm(b)
        phi = np.arccos(np.clip(a @ b / (la * lb), -1.0, 1.0))
        E += 4.0 * np.tan(phi / 2.0) ** 2 / ((la + lb) / 2.0)
    return E


def _wobbly(n=40, seed=0, closed=True):
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=not closed)
    P = np.c_[np.cos(t), np.sin(t), 0.3 * np.sin(3 * t)]
    return P + 0.05 * rng.standard_normal(P.shape)


def _turning(P) -> np.ndarray:
    a, b = P[1:-1] - P[:-2], P[2:] - P[1:-1]
    c = np.sum(a * b, 1) / np.linalg.norm(a, axis=1) / np.linalg.norm(b, axis=1)
    return np.arccos(np.clip(c, -1.0, 1.0))


def test_against_the_slow_formula_closed_open_and_links():
    P = _wobbly()
    assert core.energy(P, energy="bending") == pytest.approx(_slow(P), rel=1e-12)
    Q = _wobbly(closed=False, seed=1)
    assert core.energy(Q, energy="bending", closed=False) == pytest.approx(
        _slow(Q, closed=False), rel=1e-12)
    # a link: per component; an open and a closed one
    E = core.energy([P, Q + 5.0], energy="bending", closed=[True, False])
    assert E == pytest.approx(_slow(P) + _slow(Q, closed=False), rel=1e-12)


def test_regular_polygon_and_its_limit():
    # N · 4 tan²(π/N) / (2 R sin(π/N)), → 2π/R = ∫κ² ds of the circle
    for n, R in ((12, 1.0), (200, 0.5)):
        t = 2.0 * np.pi * np.arange(n) / n
        P = R * np.c_[np.cos(t), np.sin(t), 0 * t]
        want = n * 4.0 * np.tan(np.pi / n) ** 2 / (2.0 * R * np.sin(np.pi / n))
        assert core.energy(P, energy="bending") == pytest.approx(want, rel=1e-12)
    assert core.energy(P, energy="bending") == pytest.approx(2.0 * np.pi / R, rel=1e-3)
    # a straight open line bends nowhere; its ends never count
    line = np.c_[np.linspace(0, 1, 7), np.zeros(7), np.zeros(7)]
    assert core.energy(line, energy="bending", closed=False) == 0.0
    corner = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0]])  # one interior vertex, φ = 90°
    assert core.energy(corner, energy="bending", closed=False) == pytest.approx(4.0)


@pytest.mark.parametrize("closed", [True, False])
def test_gradient_by_central_differences(closed):
    P = _wobbly(30, seed=2, closed=closed)
    _, G = core.energy_gradient(P, energy="bending", closed=closed)
    h = 1e-6
    worst = 0.0
    for i in range(len(P)):
        for c in range(3):
            Q, R = P.copy(), P.copy()
            Q[i, c] += h
            R[i, c] -= h
            fd = (core.energy(Q, energy="bending", closed=closed)
                  - core.energy(R, energy="bending", closed=closed)) / (2 * h)
            worst = max(worst, abs(fd - G[i, c]))
    assert worst <= 1e-6 * np.abs(G).max()
    if not closed:  # the ends have no term of their own, only their neighbours'
        assert np.any(G[0] != 0.0)


def test_scaling():
    # E_b(λP) = E_b(P)/λ, its gradient as 1/λ²; also far from size 1 (the evaluators scale)
    P = _wobbly()
    E, G = core.energy_gradient(P, energy="bending")
    for lam in (3.0, 2.0**70, 2.0**-70):
        El, Gl = core.energy_gradient(lam * P, energy="bending")
        assert El == pytest.approx(E / lam, rel=1e-12)
        np.testing.assert_allclose(Gl, G / lam**2, rtol=1e-10, atol=1e-12 * np.abs(G).max()
                                   / lam**2)
    # added to the Möbius energy: each term keeps its own scaling
    w = 0.3
    for lam in (1.0, 2.0**70):
        got = core.energy(lam * P, stiffness=w)
        assert got == pytest.approx(core.energy(lam * P) + w * E / lam, rel=1e-12)
        _, g = core.energy_gradient(lam * P, stiffness=w)
        want = core.moebius_gradient(lam * P) + w * G / lam**2
        np.testing.assert_allclose(g, want, rtol=1e-9, atol=1e-12 * np.abs(want).max())


def test_checks():
    with pytest.raises(ValueError, match="stiffness must be"):
        core.energy(_wobbly(), stiffness=-1.0)
    with pytest.raises(ValueError, match="cannot minimize it alone.*stiffness="):
        core.relax(_wobbly(), energy="bending", max_iter=1)
    with pytest.raises(ValueError, match="has it already"):
        core.energy(_wobbly(), energy="bending", stiffness=1.0)
    with pytest.raises(ValueError, match="unknown energy option"):
        core.energy(_wobbly(), stiffnes=1.0)
    assert "bending" in core.ENERGY_NAMES


@pytest.mark.parametrize("engine_class", [DenseEngine, TreeEngine])
@pytest.mark.parametrize("name", ["moebius", "tangent_point"])
def test_both_engines_add_the_term_once(engine_class, name):
    X, layout = as_layout(_wobbly(60))
    X = X / np.linalg.norm(X - np.roll(X, -1, 0), axis=1).sum()
    w = 0.2
    plain = engine_class(layout, "hs", energy=check_energy(name))
    stiff = engine_class(layout, "hs", energy=check_energy(name, stiffness=w))
    Eb, Gb = bending.bending_gradient_x(X, layout)
    E0, G0 = plain.energy_gradient(X)
    E1, G1 = stiff.energy_gradient(X)
    assert E1 == pytest.approx(E0 + w * Eb, rel=1e-13)
    np.testing.assert_allclose(G1, G0 + w * Gb, rtol=1e-12, atol=1e-14 * np.abs(G0).max())
    # energy-only calls (the line search's) too
    assert stiff.energy(X) == pytest.approx(plain.energy(X) + w * Eb, rel=1e-13)
    assert stiff.trial_energy(1.0001 * X) == pytest.approx(
        plain.trial_energy(1.0001 * X) + w * bending.bending_x(1.0001 * X, layout), rel=1e-12)
    assert stiff.result_energy(X, E1) == pytest.approx(plain.result_energy(X, E0) + w * Eb,
                                                       rel=1e-12)
    assert stiff.theta == plain.theta == check_energy(name).default_theta


def test_zero_stiffness_changes_no_bit():
    P = core.knots.named("3_1", 60)
    for energy in ("moebius", "tangent_point"):
        a = core.relax(P, max_iter=4, energy=energy)
        b = core.relax(P, max_iter=4, energy=energy, stiffness=0.0)
        assert a.history["energy"] == b.history["energy"]
        np.testing.assert_array_equal(a.x, b.x)
        assert b.energy == a.energy


def _bent_cable(n=40):
    # a tent: a sharp kink in the middle, its ends held
    t = np.linspace(-1.0, 1.0, 401)
    return core.resample(np.c_[t, 0.8 * (1.0 - np.abs(t)), 0.05 * np.sin(3 * t)], n + 1,
                         closed=False)


def test_a_bent_cable_between_pins_straightens_with_stiffness():
    P = _bent_cable()
    pins = [0, len(P) - 1]
    out = {}
    for w in (0.0, 1.0):
        r = core.relax(P, closed=False, pinned=pins, stiffness=w, max_iter=60)
        assert r.nit == 60
        assert r.energy == f"moebius + bending({w:g})" if w else r.energy == "moebius"
        out[w] = r.x
        np.testing.assert_array_equal(r.x[pins], P[pins])  # the pins held
        core.check_polygon(r.x, closed=False)  # never crossed itself
    # the Möbius flow alone smooths the kink too (bending 39.1 at the start, 2.54 after 60
    # iterations); with stiffness the cable bends less, and most where it bent most
    bend = {w: core.energy(x, energy="bending", closed=False) for w, x in out.items()}
    assert bend[1.0] < 0.8 * bend[0.0]  # seen: 1.81 against 2.54
    assert _turning(out[1.0]).max() < 0.75 * _turning(out[0.0]).max()  # 4.5° against 7.2°


def test_a_stiff_knot_run_keeps_its_type_on_both_engines():
    P = core.knots.named("3_1", 80)
    for engine in ("exact", "tree"):
        r = core.relax(P, stiffness=0.5, max_iter=15, engine=engine)
        assert r.energy == "moebius + bending(0.5)"
        assert r.stats["engine"] == engine
        core.check_polygon(r.x)
        assert core.knot_determinant(r.x) == 3
        assert r.history["energy"][-1] < r.history["energy"][0]


def test_stiffness_is_scale_free_in_a_run():
    # a run works at total length 1: the same iterates for a scaled copy of the curve
    P = core.knots.named("3_1", 60)
    a = core.relax(P, stiffness=0.3, max_iter=4)
    b = core.relax(7.0 * P, stiffness=0.3, max_iter=4)
    np.testing.assert_allclose(a.history["energy"], b.history["energy"], rtol=1e-9)
    np.testing.assert_allclose(7.0 * a.x, b.x, rtol=1e-7, atol=1e-9)
    # the run's energy is that of the curve scaled to total length 1: E_m + w · L · E_b(P)
    L = np.linalg.norm(P - np.roll(P, -1, 0), axis=1).sum()
    assert a.history["energy"][0] == pytest.approx(
        core.energy(P) + 0.3 * L * core.energy(P, energy="bending"), rel=1e-10)
