"""Energy and gradient against the facts of docs/design.md and a slow, obviously correct numpy
version."""

import numpy as np
import pytest

from moebius_addon.core import moebius_energy, moebius_gradient
from tests.conftest import ngon, random_rotation, trefoil


def slow_energy(P) -> float:
    """Double loop over ordered pairs of disjoint edges, literally docs/design.md's formula."""
    comps = P if isinstance(P, list) else [P]
    edges = []
    for c, Q in enumerate(comps):
        n = len(Q)
        for i in range(n):
            a, b = Q[i], Q[(i + 1) % n]
            edges.append((c, i, n, b - a, (a + b) / 2))
    total = 4.0 * len(comps)
    for ci, i, n, ei, mi in edges:
        li = np.linalg.norm(ei)
        for cj, j, _, ej, mj in edges:
            lj = np.linalg.norm(ej)
            d = mi - mj
            r2 = d @ d
            if ci != cj:
                total += li * lj / r2
                continue
            gap = min((i - j) % n, (j - i) % n)
            if gap < 2:
                continue
            ti, tj = ei / li, ej / lj
            F = ((ti - tj) @ (ti - tj) / (2 * r2) + 2 * (ti @ tj) / r2
                 - 2 * (d @ ti) * (d @ tj) / r2**2)
            total += li * lj * F
    return total


def central_differences(f, P, h=1e-6):
    G = np.zeros_like(P)
    for idx in np.ndindex(P.shape):
        Q = P.copy()
        Q[idx] += h
        fp = f(Q)
        Q[idx] -= 2 * h
        G[idx] = (fp - f(Q)) / (2 * h)
    return G


@pytest.mark.parametrize("n", [4, 5, 12, 101, 640])
def test_regular_polygon_has_energy_four(n, rng):
    P = ngon(n) @ random_rotation(rng).T * 3.7 + rng.standard_normal(3)
    assert moebius_energy(P) == pytest.approx(4.0, abs=1e-12)


def test_trefoil_reference_value():
    # docs/design.md: 75.99452256688987 for this curve at N = 200
    assert moebius_energy(trefoil(200)) == pytest.approx(75.99452256688987, rel=1e-13)


def test_matches_slow_formula_knot_and_link(rng):
    P = trefoil(23) + 0.05 * rng.standard_normal((23, 3))
    assert moebius_energy(P) == pytest.approx(slow_energy(P), rel=1e-13)
    link = [ngon(9), ngon(11)[:, [0, 2, 1]] + [1.0, 0.0, 0.0]]
    assert moebius_energy(link) == pytest.approx(slow_energy(link), rel=1e-13)


def test_invariances(rng):
    P = trefoil(150) + 0.02 * rng.standard_normal((150, 3))
    e = moebius_energy(P)
    R = random_rotation(rng)
    assert moebius_energy(P + [3.0, -2.0, 7.5]) == pytest.approx(e, rel=1e-12)
    assert moebius_energy(P @ R.T) == pytest.approx(e, rel=1e-12)
    assert moebius_energy(P * 1e-3) == pytest.approx(e, rel=1e-12)
    assert moebius_energy(P * 1e4) == pytest.approx(e, rel=1e-12)
    assert moebius_energy(P[::-1]) == pytest.approx(e, rel=1e-12)
    assert moebius_energy(np.roll(P, 17, axis=0)) == pytest.approx(e, rel=1e-12)
    # a reflection is an isometry too
    assert moebius_energy(P * [1, 1, -1]) == pytest.approx(e, rel=1e-12)


def test_gradient_matches_central_differences(rng):
    P = trefoil(30) + 0.03 * rng.standard_normal((30, 3))
    G = moebius_gradient(P)
    fd = central_differences(moebius_energy, P)
    assert G.shape == P.shape
    np.testing.assert_allclose(G, fd, rtol=1e-6, atol=1e-7 * np.abs(fd).max())


def test_link_gradient_matches_central_differences(rng):
    A = ngon(8) + 0.05 * rng.standard_normal((8, 3))
    B = ngon(7)[:, [0, 2, 1]] + [1.0, 0.1, 0.0] + 0.05 * rng.standard_normal((7, 3))
    G = moebius_gradient([A, B])
    assert isinstance(G, list) and len(G) == 2

    def f_a(Q):
        return moebius_energy([Q, B])

    def f_b(Q):
        return moebius_energy([A, Q])

    np.testing.assert_allclose(G[0], central_differences(f_a, A), rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(G[1], central_differences(f_b, B), rtol=1e-6, atol=1e-6)


def test_gradient_scales_inversely_and_sums_to_zero(rng):
    P = trefoil(80) + 0.02 * rng.standard_normal((80, 3))
    G = moebius_gradient(P)
    np.testing.assert_allclose(moebius_gradient(2.0 * P), G / 2.0, rtol=1e-10, atol=1e-14)
    # translation invariance: the gradient has no net force, rotation invariance: no torque
    np.testing.assert_allclose(G.sum(axis=0), 0.0, atol=1e-10 * np.abs(G).max())
    np.testing.assert_allclose(np.cross(P, G).sum(axis=0), 0.0, atol=1e-9 * np.abs(G).max())


def test_deterministic(rng):
    P = trefoil(333) + 0.01 * rng.standard_normal((333, 3))
    assert moebius_energy(P) == moebius_energy(P.copy())
    np.testing.assert_array_equal(moebius_gradient(P), moebius_gradient(P.copy()))


def test_bad_shapes_raise():
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        moebius_energy(np.zeros((5, 2)))
    with pytest.raises(ValueError, match="empty link"):
        moebius_energy([])


@pytest.mark.parametrize("k", [-900, -300, 300, 900])
def test_far_from_unit_size_gives_the_same_bits(rng, k):
    # below about 1e-100 and above 1e100 the kernels' fourth powers leave the float64 range
    # (the gradient was NaN there); curves that far from size 1 are computed at a size near 1,
    # scaled by a power of 4, which changes no rounding
    P = trefoil(80) + 0.02 * rng.standard_normal((80, 3))
    Q = np.ldexp(P, k)
    assert moebius_energy(Q) == moebius_energy(P)
    np.testing.assert_array_equal(np.ldexp(moebius_gradient(Q), k), moebius_gradient(P))
    link = moebius_gradient([Q, Q + np.ldexp(3.0, k)])
    np.testing.assert_allclose(np.ldexp(link[1], k), moebius_gradient([P, P + 3.0])[1],
                               rtol=1e-12, atol=0)
    for s in (1e-300, 1e300):
        assert moebius_energy(s * P) == pytest.approx(moebius_energy(P), rel=1e-13)
        np.testing.assert_allclose(s * moebius_gradient(s * P), moebius_gradient(P),
                                   rtol=1e-10, atol=1e-12 * np.abs(moebius_gradient(P)).max())
