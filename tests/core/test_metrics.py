"""Every Gram matrix against a slow numpy version of docs/design.md's formula."""

import numpy as np
import pytest

from moebius_addon.core import METRICS, gram_matrix, resample, sobolev_gradient
from tests.conftest import ngon, trefoil


def _ops(comps):
    """Dense D, M, lengths, midpoints, arc positions for a list of closed polygons."""
    X = np.vstack(comps)
    n = len(X)
    sizes = [len(c) for c in comps]
    starts = np.cumsum([0] + sizes)
    nxt = np.arange(n) + 1
    comp = np.repeat(np.arange(len(comps)), sizes)
    for c in range(len(comps)):
        nxt[starts[c + 1] - 1] = starts[c]
    e = X[nxt] - X
    ln = np.linalg.norm(e, axis=1)
    D = np.zeros((n, n))
    M = np.zeros((n, n))
    for i in range(n):
        D[i, i], D[i, nxt[i]] = -1 / ln[i], 1 / ln[i]
        M[i, i], M[i, nxt[i]] = 0.5, 0.5
    return X, nxt, comp, starts, ln, (X + X[nxt]) / 2, D, M


def slow_gram(metric, comps):
    X, nxt, comp, starts, ln, mid, D, M = _ops(comps)
    n = len(X)
    L = ln.sum()
    prv = np.argsort(nxt)
    if metric in ("hs", "hs_pure"):
        arc = np.zeros(n)
        clen = {}
        for c in range(len(comps)):
            s = slice(starts[c], starts[c + 1])
            cum = np.cumsum(ln[s])
            arc[s] = cum - ln[s] / 2
            clen[c] = cum[-1]
        W = np.zeros((n, n))
        V = np.zeros((n, n))
        for i in range(n):
            for j in range(n):
                if comp[i] == comp[j]:
                    size = starts[comp[i] + 1] - starts[comp[i]]
                    gap = abs(i - j) % size
                    if min(gap, size - gap) < 2:
                        continue
                    fwd = abs(arc[i] - arc[j])
                    inv_rho2 = 1 / min(fwd, clen[comp[i]] - fwd) ** 2
                else:
                    inv_rho2 = 0.0
                r2 = np.sum((mid[i] - mid[j]) ** 2)
                W[i, j] = ln[i] * ln[j] / r2
                V[i, j] = ln[i] * ln[j] * (1 / r2 - inv_rho2) / r2
        A = 2 * D.T @ (np.diag(W.sum(1)) - W) @ D
        if metric == "hs":
            A += 2 * M.T @ (np.diag(V.sum(1)) - V) @ M
    # P1 mass matrix: ∫ u² over each edge
    mass = np.zeros((n, n))
    for i in range(n):
        j = nxt[i]
        mass[np.ix_([i, j], [i, j])] += ln[i] * np.array([[1 / 3, 1 / 6], [1 / 6, 1 / 3]])
    h1 = (D.T @ np.diag(ln) @ D + mass / L**2) / L
    if metric == "hs_pure":
        A += 1e-6 * mass / L**3
    elif metric == "l2":
        A = mass / L**3
    elif metric == "h1":
        A = h1
    elif metric == "h2":
        dual = (ln[prv] + ln) / 2
        D2 = np.diag(1 / dual) @ (D - D[prv])
        A = L * D2.T @ np.diag(dual) @ D2 + h1
    b = (ln[prv] + ln) / 2 * np.sqrt(n) / L**2
    for c in range(len(comps)):
        s = slice(starts[c], starts[c + 1])
        A[s, s] += np.outer(b[s], b[s])
    return A


@pytest.fixture
def wobbly(rng):
    return trefoil(31) + 0.05 * rng.standard_normal((31, 3))


@pytest.mark.parametrize("metric", METRICS)
def test_gram_matches_slow_formula(metric, wobbly):
    A = gram_matrix(metric, wobbly)
    B = slow_gram(metric, [wobbly])
    np.testing.assert_allclose(A, B, rtol=1e-12, atol=1e-13 * np.abs(B).max())


@pytest.mark.parametrize("metric", METRICS)
def test_gram_of_link_matches_slow_formula(metric, rng):
    comps = [ngon(9) + 0.02 * rng.standard_normal((9, 3)),
             ngon(12)[:, [0, 2, 1]] * 0.8 + [1.0, 0.0, 0.1]]
    np.testing.assert_allclose(gram_matrix(metric, comps), slow_gram(metric, comps),
                               rtol=1e-12, atol=1e-13 * np.abs(slow_gram(metric, comps)).max())


@pytest.mark.parametrize("metric", ["hs", "hs_pure"])
def test_gram_of_smallest_components_matches_slow_formula(metric, rng):
    # 4 and 5 edges: the neighbours excluded from the disjoint pairs wrap around the component
    comps = [ngon(4) + 0.05 * rng.standard_normal((4, 3)),
             ngon(5)[:, [0, 2, 1]] * 0.7 + [1.5, 0.0, 0.2] + 0.05 * rng.standard_normal((5, 3))]
    for P in (comps[0], comps[1], comps):
        B = slow_gram(metric, P if isinstance(P, list) else [P])
        np.testing.assert_allclose(gram_matrix(metric, P), B, rtol=1e-12,
                                   atol=1e-13 * np.abs(B).max())


@pytest.mark.parametrize("metric", METRICS)
def test_gram_symmetric_definite_and_scales_like_inverse_square(metric, wobbly):
    A = gram_matrix(metric, wobbly)
    np.testing.assert_allclose(A, A.T, atol=1e-12 * np.abs(A).max())
    assert np.linalg.eigvalsh(A).min() > 0
    np.testing.assert_allclose(gram_matrix(metric, 5.0 * wobbly), A / 25.0, rtol=1e-11,
                               atol=1e-14 * np.abs(A).max())


def test_geometric_term_is_nonnegative_and_penalises_near_contact():
    # the low-order weights v_IJ are >= 0 (chord <= arc) so A_hs - A_pure is PSD
    P = trefoil(60)
    diff = gram_matrix("hs", P) - gram_matrix("hs_pure", P)
    assert np.linalg.eigvalsh(diff).min() > -1e-10 * np.abs(diff).max()


def test_unknown_metric():
    with pytest.raises(ValueError, match="unknown metric"):
        gram_matrix("h3", ngon(10))


@pytest.mark.parametrize("metric", METRICS)
def test_far_from_unit_size(metric):
    # curves spanning more than 2^64 are computed at a size near 1 and scaled back exactly
    P = resample(trefoil(300), 60)
    k = 100  # a power of 4: the same bits
    np.testing.assert_array_equal(np.ldexp(gram_matrix(metric, np.ldexp(P, k)), 2 * k),
                                  gram_matrix(metric, P))
    np.testing.assert_array_equal(np.ldexp(sobolev_gradient(np.ldexp(P, k), metric), -k),
                                  sobolev_gradient(P, metric))
    u = sobolev_gradient(P, metric, projected=False)
    np.testing.assert_allclose(sobolev_gradient(1e200 * P, metric, projected=False) / 1e200, u,
                               rtol=0, atol=1e-8 * np.abs(u).max())  # h2: κ(A) ~ 1e8
    with pytest.raises(ValueError, match="outside the float64 range"):
        gram_matrix(metric, 1e300 * P)  # entries of 1e-600


@pytest.mark.parametrize("metric", ["hs", "h1"])
def test_sobolev_gradient_of_the_tangent_point_energy(metric):
    # the field of the energy asked for (Show Gradients drew the Möbius one whatever the
    # energy): G u = ∇E with the metric of the order that fits it, (β − 1)/α = 7/4 for hs
    from moebius_addon import core

    P = resample(trefoil(300), 60)
    _, g = core.energy_gradient(P, energy="tangent_point", engine="exact")
    order = 1.75 if metric == "hs" else 1.5
    A = gram_matrix(metric, P, order=order)
    u = sobolev_gradient(P, metric, projected=False, energy="tangent_point")
    np.testing.assert_allclose(A @ u, g, rtol=0, atol=1e-9 * np.abs(g).max())
    moebius = sobolev_gradient(P, metric, projected=False)
    assert np.abs(u / np.abs(u).max() - moebius / np.abs(moebius).max()).max() > 1e-2
    # projected: on the constraints' tangent space (edge lengths and barycenter kept)
    w = sobolev_gradient(P, metric, energy="tangent_point", alpha=2, beta=4)
    e = np.roll(P, -1, axis=0) - P
    assert np.abs(np.sum(e * (np.roll(w, -1, axis=0) - w), axis=1)).max() < 1e-9 * np.abs(
        w).max() * np.abs(e).max()
    assert np.abs(w.sum(axis=0)).max() < 1e-9 * np.abs(w).max() * len(w)
    # far from unit size, computed near 1 and scaled back: u(λP) = λ^p u(P), p from the energy's
    # and the metric's scaling (λ^(2 + α − β − 1) and λ^(1 − 2s) or λ^-2)
    k = 100
    p = (2 + 2 - 4.5) - 1 - ((1 - 2 * order) if metric == "hs" else -2)
    far = sobolev_gradient(np.ldexp(P, k), metric, projected=False, energy="tangent_point")
    np.testing.assert_allclose(far / 2.0 ** (k * p), u, rtol=0, atol=1e-9 * np.abs(u).max())
