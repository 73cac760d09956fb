"""hs and hs_pure of order s (docs/design.md, "Metrics"): the dense matrix against the
formula written out in numpy, its scaling, the tree's operator against it, order 3/2 as it
always was, and runs of the tangent-point energy in the metric of its order (β − 1)/α."""

import numpy as np
import pytest

from moebius_addon import core
from moebius_addon.core.energies.choice import EnergyChoice
from moebius_addon.core.geometry.layout import as_layout
from moebius_addon.core.metrics.gram import check_order, gram_x
from moebius_addon.core.metrics.open import _weights
from moebius_addon.core.tree import hs_metric as hs_tree
from tests.conftest import trefoil


def _link():
    t = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    ring = np.c_[np.cos(t), np.sin(t), 0 * t]
    return [ring, ring[:, [0, 2, 1]] + [1.2, 0, 0]]


CURVES = {
    "knot": lambda: trefoil(40) + 0.02 * np.random.default_rng(3).standard_normal((40, 3)),
    "link": _link,
}


def slow_gram(metric, comps, s):
    """docs/design.md's matrix of order ``s`` for closed components, literally: dense D and M,
    ``w = l l / |d|^(2s−1)``, ``v = w (1/|d|² − 1/ρ²)``, hs_pure's L² term over ``L^(2s)``,
    the barycenter term ``N b bᵀ / L^(2s+1)``."""
    X = np.vstack(comps)
    n = len(X)
    sizes = [len(c) for c in comps]
    starts = np.cumsum([0] + sizes)
    comp = np.repeat(np.arange(len(comps)), sizes)
    nxt = np.arange(n) + 1
    for c in range(len(comps)):
        nxt[starts[c + 1] - 1] = starts[c]
    prv = np.argsort(nxt)
    ln = np.linalg.norm(X[nxt] - X, axis=1)
    L = ln.sum()
    mid = (X + X[nxt]) / 2
    arc = np.empty(n)
    for c in range(len(comps)):
        sl = slice(starts[c], starts[c + 1])
        arc[sl] = np.cumsum(ln[sl]) - ln[sl] / 2
    D = np.zeros((n, n))
    M = np.zeros((n, n))
    for i in range(n):
        D[i, i], D[i, nxt[i]] = -1 / ln[i], 1 / ln[i]
        M[i, i], M[i, nxt[i]] = 0.5, 0.5
    W = np.zeros((n, n))
    V = np.zeros((n, n))
    for i in range(n):
        for j in range(n):
            if comp[i] == comp[j]:
                size = sizes[comp[i]]
                gap = abs(i - j) % size
                if min(gap, size - gap) < 2:
                    continue
                fwd = abs(arc[i] - arc[j])
                inv_rho2 = 1 / min(fwd, ln[comp == comp[i]].sum() - fwd) ** 2
            else:
                inv_rho2 = 0.0
            d = np.linalg.norm(mid[i] - mid[j])
            W[i, j] = ln[i] * ln[j] / d ** (2 * s - 1)
            V[i, j] = W[i, j] * (1 / d**2 - inv_rho2)
    A = 2 * D.T @ (np.diag(W.sum(1)) - W) @ D
    if metric == "hs":
        A += 2 * M.T @ (np.diag(V.sum(1)) - V) @ M
    else:
        mass = np.zeros((n, n))
        for i in range(n):
            j = nxt[i]
            mass[np.ix_([i, j], [i, j])] += ln[i] * np.array([[1 / 3, 1 / 6], [1 / 6, 1 / 3]])
        A += 1e-6 * mass / L ** (2 * s)
    b = (ln[prv] + ln) / 2
    for c in range(len(comps)):
        sl = slice(starts[c], starts[c + 1])
        A[sl, sl] += n * np.outer(b[sl], b[sl]) / L ** (2 * s + 1)
    return A


def _stacked(P):
    X, lay = as_layout(P)
    return X, lay


@pytest.mark.parametrize("name", list(CURVES))
@pytest.mark.parametrize("metric", ["hs", "hs_pure"])
@pytest.mark.parametrize("s", [1.25, 1.75])
def test_dense_matrix_is_the_formula(name, metric, s):
    P = CURVES[name]()
    comps = P if isinstance(P, list) else [P]
    X, lay = _stacked(P)
    A = gram_x(metric, X, lay, order=s)
    B = slow_gram(metric, comps, s)
    assert np.allclose(A, B, rtol=0, atol=1e-11 * np.abs(B).max())
    assert np.allclose(A, A.T, rtol=0, atol=1e-13 * np.abs(A).max())
    assert np.linalg.eigvalsh(A)[0] > 0
    # the order is in the matrix: not the one of order 3/2
    assert not np.allclose(A, gram_x(metric, X, lay), rtol=1e-3)


@pytest.mark.parametrize("closed", [True, False])
@pytest.mark.parametrize("s", [1.25, 1.75])
def test_matrix_scales_as_length_to_the_one_minus_2s(closed, s):
    P = trefoil(30)
    lam = 3.7
    A = core.gram_matrix("hs", P, closed=closed, order=s)
    B = core.gram_matrix("hs", lam * P, closed=closed, order=s)
    assert np.allclose(B, lam ** (1 - 2 * s) * A, rtol=1e-12, atol=0)
    assert np.linalg.eigvalsh(A)[0] > 0
    # far from size 1 (core.gram_matrix works at a power-of-two scale and maps back)
    C = core.gram_matrix("hs", 2.0**40 * P, closed=closed, order=s)
    assert np.allclose(C, 2.0 ** (40 * (1 - 2 * s)) * A, rtol=1e-12, atol=0)


def test_open_weights_carry_the_order():
    """The open-curve kernel's weights at order s are those of order 3/2 times
    ``|d|^(3−2s)`` (w and v alike)."""
    X, lay = as_layout(trefoil(30), closed=False)
    mid = 0.5 * (X[lay.nxt] + X)
    ln = np.linalg.norm(X[lay.nxt] - X, axis=1) * lay.real
    arc = np.cumsum(ln) - ln / 2
    args = (*np.ascontiguousarray(mid.T), ln, arc, np.array([ln.sum()]), lay.starts, lay.comp,
            lay.closed, lay.real, 1.0)
    W0, V0 = _weights(*args, None)
    W, V = _weights(*args, 1.75 - 0.5)
    d2 = np.sum((mid[:, None] - mid[None]) ** 2, axis=2)
    np.fill_diagonal(d2, 1.0)
    f = d2 ** (1.5 - 1.75)
    assert np.count_nonzero(W0) > 0 and np.array_equal(W0 != 0, W != 0)
    assert np.allclose(W, W0 * f, rtol=1e-13, atol=0)
    assert np.allclose(V, V0 * f, rtol=1e-12, atol=1e-12 * np.abs(V).max())


@pytest.mark.parametrize("metric", ["hs", "hs_pure"])
def test_order_three_halves_is_the_matrix_of_before(metric, rng):
    P = CURVES["knot"]()
    X, lay = _stacked(P)
    X = X / np.linalg.norm(X[lay.nxt] - X, axis=1).sum()
    default = gram_x(metric, X, lay)
    order = EnergyChoice("tangent_point", 2, 4).metric_order  # (4 − 1)/2
    assert np.array_equal(gram_x(metric, X, lay, order=order), default)
    assert np.array_equal(core.gram_matrix(metric, P, order=1.5), core.gram_matrix(metric, P))
    U = rng.standard_normal((lay.n, 3))
    a = hs_tree.HsOperator(X, lay, metric)
    b = hs_tree.HsOperator(X, lay, metric, order=order)
    assert np.array_equal(a.product(U), b.product(U))
    # the lower-order metrics ignore the order
    assert np.array_equal(gram_x("h2", X, lay, order=1.25), gram_x("h2", X, lay))


def test_orders_outside_one_to_two_are_refused():
    for bad in (1.0, 2.0, 0.5, "x", None, np.nan):
        with pytest.raises(ValueError, match="order"):
            check_order(bad)
    with pytest.raises(ValueError, match="order"):
        core.gram_matrix("hs", trefoil(20), order=2.5)


@pytest.mark.parametrize("metric", ["hs", "hs_pure"])
@pytest.mark.parametrize("s", [1.25, 1.75])
def test_tree_operator_against_the_dense_matrix(metric, s, rng):
    """As tests/core/test_hs_tree.py at order 3/2: every pair near gives the dense matrix to
    rounding; the default far field stays within 2e-2 on random fields."""
    P = core.resample(trefoil(300), 240)
    X, lay = _stacked(P)
    X = X / np.linalg.norm(X[lay.nxt] - X, axis=1).sum()
    A = gram_x(metric, X, lay, order=s)
    U = rng.standard_normal((lay.n, 3))
    exact = A @ U
    op = hs_tree.HsOperator(X, lay, metric, order=s, theta=1e-9)
    assert op.far_pairs == 0
    assert np.allclose(op.product(U), exact, rtol=0, atol=1e-11 * np.abs(exact).max())
    assert np.allclose(op.diagonal(), np.diag(A), rtol=1e-12)
    op = hs_tree.HsOperator(X, lay, metric, order=s)
    assert op.far_pairs > 0
    assert np.linalg.norm(op.product(U) - exact) / np.linalg.norm(exact) < 2e-2


@pytest.mark.parametrize("engine", ["exact", "tree"])
def test_tangent_point_run_uses_the_metric_of_its_order(engine, rng):
    P = core.resample(core.knots.named("3_1"), 120)
    r = core.relax(P, energy="tangent_point", alpha=3, beta=6, engine=engine, max_iter=10,
                   tol=0.0, refine=False)
    E = np.array(r.history["energy"])
    assert len(E) > 1 and E[-1] < E[0]
    run = core.make_run("projected_gradient", P, energy="tangent_point", alpha=3, beta=6,
                        engine=engine, max_iter=2, tol=0.0, refine=False)
    run.step()  # the engine holds the metric at the current iterate
    X, lay = run.X, run.layout
    U = rng.standard_normal((lay.n, 3))
    got = run.engine.metric_product(U)
    if engine == "exact":
        assert np.allclose(got, gram_x("hs", X, lay, order=5 / 3) @ U, rtol=1e-13,
                           atol=1e-13 * np.abs(got).max())
    else:
        want = hs_tree.HsOperator(X, lay, "hs", order=5 / 3).product(U)
        assert np.array_equal(got, want)
    # and not the metric of order 3/2
    other = gram_x("hs", X, lay) @ U
    assert np.linalg.norm(got - other) > 0.1 * np.linalg.norm(other)
