"""Constraint map, Jacobian (finite differences, adjoint) and the saddle-point solvers."""

import numpy as np
import pytest

from moebius_addon.core.geometry.constraints import jacobian, make_constraints, residual
from moebius_addon.core.geometry.layout import as_layout
from moebius_addon.core.metrics.gram import gram_x
from moebius_addon.core.metrics.saddle import (
    CholeskySolve,
    Factorization,
    SaddlePointSolver,
    field_product,
    spd_inverse,
)
from tests.conftest import ngon, trefoil


def _setup(P, rng, **kw):
    X, lay = as_layout(P)
    ln = np.linalg.norm(X[lay.nxt] - X, axis=1)
    con = make_constraints(X, lay, ln * (1 + 0.01 * rng.standard_normal(len(ln))), **kw)
    return X, lay, con


def dense_C(X, con):
    jac = jacobian(X, con)
    n = len(X)
    C = np.zeros((con.size, 3 * n))
    for k in range(3 * n):
        e = np.zeros(3 * n)
        e[k] = 1
        C[:, k] = jac.matvec(e.reshape(n, 3))
    return C


@pytest.mark.parametrize("link", [False, True])
def test_jacobian_matches_finite_differences(link, rng):
    P = trefoil(20) + 0.05 * rng.standard_normal((20, 3))
    if link:
        P = [P, ngon(6) * 0.5 + [4.0, 0.0, 0.0]]
    X, lay, con = _setup(P, rng)
    C = dense_C(X, con)
    h = 1e-6
    for k in rng.choice(X.size, 12, replace=False):
        Y = X.copy().ravel()
        Y[k] += h
        fp = residual(Y.reshape(X.shape), con)
        Y[k] -= 2 * h
        fm = residual(Y.reshape(X.shape), con)
        np.testing.assert_allclose(C[:, k], (fp - fm) / (2 * h), atol=1e-7)


def test_rmatvec_is_the_adjoint(rng):
    X, lay, con = _setup([trefoil(15), ngon(5) + [5.0, 0, 0]], rng)
    jac = jacobian(X, con)
    U = rng.standard_normal(X.shape)
    lam = rng.standard_normal(con.size)
    assert jac.matvec(U) @ lam == pytest.approx(np.sum(U * jac.rmatvec(lam)), rel=1e-12)


def test_barycenter_rows_are_scale_free():
    # translating by δ·L along x changes Σ l_I m_I by δ L², so the scaled row reads δ at any size
    for scale in (1e-3, 1.0, 1e3):
        X, lay = as_layout(scale * trefoil(25))
        ln = np.linalg.norm(X[lay.nxt] - X, axis=1)
        con = make_constraints(X, lay, ln)
        phi = residual(X + [1e-4 * ln.sum(), 0.0, 0.0], con)
        np.testing.assert_allclose(phi[:25], 0.0, atol=1e-12)
        np.testing.assert_allclose(phi[25:], [1e-4, 0.0, 0.0], rtol=1e-8, atol=1e-14)


@pytest.mark.parametrize("blocked", [False, True])
@pytest.mark.parametrize("n", [5, 256, 300, 700])  # one block, exactly one, partial, several
def test_blocked_cholesky_solve_and_spd_inverse(n, blocked, rng, monkeypatch):
    # the blocked substitution serves large systems, the plain one small ones: test both
    monkeypatch.setattr(CholeskySolve, "SEQUENTIAL_BELOW", 0 if blocked else 10**9)
    assert CholeskySolve(np.eye(n)).sequential is not blocked
    B = rng.standard_normal((n, n))
    A = B @ B.T + n * np.eye(n)
    F = np.linalg.cholesky(A) + np.triu(rng.standard_normal((n, n)), 1)  # upper part ignored
    v = rng.standard_normal(n)
    np.testing.assert_allclose(A @ CholeskySolve(F)(v), v, rtol=0, atol=1e-10 * np.abs(v).max())
    np.testing.assert_allclose(spd_inverse(A) @ A, np.eye(n), atol=1e-10)


@pytest.mark.parametrize("n", [1, 50, 51, 53])  # the kernel takes rows four at a time
def test_field_product_is_the_matrix_product(n, rng):
    M = rng.standard_normal((n, n))
    U = rng.standard_normal((n, 3))
    np.testing.assert_allclose(field_product(M, U), M @ U, rtol=1e-13, atol=1e-13)
    # a single-precision matrix is summed in double precision: exact products of its values
    M32 = M.astype(np.float32)
    np.testing.assert_allclose(field_product(M32, U), M32.astype(np.float64) @ U,
                               rtol=1e-13, atol=1e-13)


@pytest.mark.parametrize("metric", ["hs", "h1"])
def test_factorization_solves_the_saddle_point_system(metric, rng):
    P = trefoil(40) + 0.03 * rng.standard_normal((40, 3))
    X, lay, con = _setup([P, ngon(8) * 0.7 + [5, 0, 0]], rng)
    A = gram_x(metric, X, lay)
    jac = jacobian(X, con)
    n = len(X)
    G = np.kron(A, np.eye(3))
    C = dense_C(X, con)
    K = np.block([[G, C.T], [C, np.zeros((con.size, con.size))]])
    g = rng.standard_normal((n, 3))
    r = rng.standard_normal(con.size) * 1e-3
    ref = np.linalg.solve(K, np.concatenate([g.ravel(), r]))
    u, lam = Factorization(A, jac).solve(g, r)
    np.testing.assert_allclose(u.ravel(), ref[: 3 * n], rtol=1e-8, atol=1e-10 * np.abs(ref).max())
    np.testing.assert_allclose(lam, ref[3 * n :], rtol=1e-8, atol=1e-10 * np.abs(ref).max())


def test_reused_factorization_gives_the_current_solution(rng):
    """GMRES preconditioned with an older iterate's factorization solves the new system."""
    P = trefoil(60)
    X, lay, con = _setup(P, rng)
    solver = SaddlePointSolver(reuse=True, factor_cost=1e9)  # never refactor on cost
    solver.update(gram_x("hs", X, lay), jacobian(X, con))
    Y = X + 0.02 * rng.standard_normal(X.shape)
    A, jac = gram_x("hs", Y, lay), jacobian(Y, con)
    solver.update(A, jac)
    assert not solver.fresh
    g = rng.standard_normal(X.shape)
    u, lam = solver.solve(g, np.zeros(con.size))
    assert solver.krylov_its[-1] > 1
    u_ref, lam_ref = Factorization(A, jac).solve(g, np.zeros(con.size))
    np.testing.assert_allclose(u, u_ref, rtol=1e-7, atol=1e-9 * np.abs(u_ref).max())
    assert np.abs(jac.matvec(u)).max() < 1e-8 * np.abs(u).max()


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_lapack_and_numpy_fallback_agree(dtype, rng):
    from moebius_addon.core.metrics import _lapack
    from moebius_addon.core.metrics.saddle import _numpy_triangular_inverse

    n = 260
    B = rng.standard_normal((n, n))
    A = (B @ B.T + n * np.eye(n)).astype(dtype)
    L = np.linalg.cholesky(A)
    ref = _numpy_triangular_inverse(L)
    tol = 1e-12 if dtype == np.float64 else 1e-4
    np.testing.assert_allclose(ref @ L, np.eye(n), atol=tol * 10)
    np.testing.assert_allclose(spd_inverse(A), ref.T @ ref, atol=tol * np.abs(ref).max() ** 2)
    if _lapack.available():  # numpy's own OpenBLAS was found (PyPI wheels)
        with pytest.raises(np.linalg.LinAlgError):
            _lapack.spd_inverse(-A)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_lapack_cholesky_and_blocked_solve(dtype, rng, monkeypatch):
    from moebius_addon.core.metrics import _lapack

    if not _lapack.available():
        pytest.skip("numpy's OpenBLAS not found: the numpy fallback is used instead")
    n = 300  # odd block sizes and the 64-tile mirror of spd_inverse
    B = rng.standard_normal((n, n))
    A = (B @ B.T + n * np.eye(n)).astype(dtype)
    b = rng.standard_normal(n)
    F = _lapack.cholesky(A)  # LAPACK's factor, upper part not zeroed
    ref = np.linalg.solve(A.astype(np.float64), b)
    tol = 1e-12 if dtype == np.float64 else 1e-5
    for below in (0, 10**9):  # blocked and plain substitution
        monkeypatch.setattr(CholeskySolve, "SEQUENTIAL_BELOW", below)
        x = CholeskySolve(F)(b)
        np.testing.assert_allclose(x, ref, atol=tol * np.abs(ref).max())
    Ai = _lapack.spd_inverse(A)
    np.testing.assert_array_equal(Ai, Ai.T)
    np.testing.assert_allclose(Ai @ A.astype(np.float64), np.eye(n), atol=100 * tol)
    with pytest.raises(np.linalg.LinAlgError):
        _lapack.cholesky(-A)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_refactoring_reuses_the_old_arrays_without_changing_the_solution(dtype, rng):
    """A refactorization overwrites the previous factorization's arrays (no fresh page-faulted
    memory per iterate); the solves must equal those of a factorization built from scratch."""
    P = trefoil(80)
    X, lay, con = _setup(P, rng)
    solver = SaddlePointSolver(reuse=False, dtype=dtype)
    solver.update(gram_x("hs", X, lay), jacobian(X, con))
    first = solver.fac
    Y = X + 0.01 * rng.standard_normal(X.shape)
    A, jac = gram_x("hs", Y, lay), jacobian(Y, con)
    solver.update(A, jac)
    assert solver.fac.Ainv is first.Ainv  # the same memory, refilled
    g = rng.standard_normal(X.shape)
    u, lam = solver.fac.solve(g, np.zeros(con.size))
    u_ref, lam_ref = Factorization(A, jac, dtype).solve(g, np.zeros(con.size))
    np.testing.assert_array_equal(u, u_ref)
    np.testing.assert_array_equal(lam, lam_ref)


@pytest.mark.parametrize("link", [False, True])
def test_tangent_projector_is_the_euclidean_projection(link, rng):
    # I − Cᵀ(CCᵀ)⁻¹C against a dense solve
    from moebius_addon.core.geometry.constraints import TangentProjector
    from tests.conftest import ngon, trefoil

    P = [trefoil(40), ngon(17) * 3 + 10, trefoil(23) + 20] if link else trefoil(60)
    X, lay = as_layout(P)
    ln = np.linalg.norm(X[lay.nxt] - X, axis=1)  # not equilateral: lengths vary
    jac = jacobian(X, make_constraints(X, lay, ln))
    n = lay.n
    C = np.column_stack([jac.matvec(e.reshape(n, 3)) for e in np.eye(3 * n)])
    W = rng.standard_normal((n, 3))
    ref = W.ravel() - C.T @ np.linalg.solve(C @ C.T, C @ W.ravel())
    w = TangentProjector(jac)(W)
    assert np.allclose(w.ravel(), ref, rtol=0, atol=1e-12 * np.abs(ref).max())
    assert np.abs(jac.matvec(w)).max() < 1e-10
