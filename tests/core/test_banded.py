"""The O(N) saddle-point solver of the banded metrics (core/banded.py) against the dense one."""

from __future__ import annotations

import numpy as np
import pytest

from moebius_addon import core
from moebius_addon.core.geometry.constraints import jacobian, make_constraints
from moebius_addon.core.geometry.layout import as_unit_layout
from moebius_addon.core.metrics import banded
from moebius_addon.core.metrics import gram as metrics
from moebius_addon.core.metrics.saddle import Factorization
from moebius_addon.core.runs.base import DENSE_MAX_VERTICES
from moebius_addon.core.tree import hs_metric
from tests.conftest import out_here_and_in_one_thread


def _ring(n):
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.c_[np.cos(t), np.sin(t), 0 * t]


CURVES = {
    "trefoil": lambda: core.resample(core.knots.named("3_1"), 200),
    "fhw": lambda: core.knots.freedman_unknot(300),
    "link": lambda: core.resample([_ring(60), _ring(60)[:, [0, 2, 1]] + [1.2, 0, 0],
                                   _ring(60) + [2.4, 0, 0]], [40, 50, 60]),
    # not equilateral, as the flow's iterates between back-projections are not exactly
    "noneq": lambda: core.resample(core.knots.named("4_1"), 150)
    + 0.05 / 150 * np.random.default_rng(3).standard_normal((150, 3)),
}


def _system(name):
    X, lay, _ = as_unit_layout(CURVES[name]())
    X = X / np.linalg.norm(X[lay.nxt] - X, axis=1).sum()
    ln = np.linalg.norm(X[lay.nxt] - X, axis=1)
    con = make_constraints(X, lay, ln)
    return X, lay, con, jacobian(X, con)


@pytest.mark.parametrize("split", [False, True])
@pytest.mark.parametrize("name", sorted(CURVES))
@pytest.mark.parametrize("metric", banded.BANDED_METRICS)
def test_same_solution_as_the_dense_solver(name, metric, split, monkeypatch):
    # split: every block of 20 vertices or more in two halves and a separator, as from
    # SPLIT_FROM vertices on (the link: three blocks split, each a component)
    if split:
        monkeypatch.setattr(banded, "SPLIT_FROM", 20)
    X, lay, con, jac = _system(name)
    A = metrics.gram_x(metric, X, lay)
    solver = banded.BandedSaddle(metrics.banded_parts(metric, X, lay), jac)
    assert (solver.part >= 0).any() == split
    dense = Factorization(A, jac, np.float64)
    rng = np.random.default_rng(1)
    V = rng.standard_normal((lay.n, 3))
    assert np.allclose(solver.metric_product(V), A @ V, rtol=0, atol=1e-13 * np.abs(A @ V).max())
    g = rng.standard_normal((lay.n, 3))
    r = 1e-3 * rng.standard_normal(con.size)
    u0, lam0 = dense.solve(g, r)
    u1, lam1 = solver.solve(g, r)
    assert np.linalg.norm(u1 - u0) <= 1e-8 * np.linalg.norm(u0)
    assert np.linalg.norm(lam1 - lam0) <= 1e-7 * np.linalg.norm(lam0)
    # its own residuals in the true system: G u + Cᵀλ = g, C u = r
    assert np.linalg.norm(A @ u1 + jac.rmatvec(lam1) - g) <= 1e-9 * np.linalg.norm(g)
    assert np.linalg.norm(jac.matvec(u1) - r) <= 1e-7 * np.linalg.norm(r)
    p0 = dense.pseudo_inverse(r)
    assert np.linalg.norm(solver.pseudo_inverse(r) - p0) <= 1e-8 * np.linalg.norm(p0)


def test_band_lu_pivots_like_a_dense_solve():
    # a saddle-like band with zeros on the diagonal: no solve without row exchanges
    rng = np.random.default_rng(0)
    n, kl, ku = 60, 3, 3
    M = np.zeros((n, n))
    for i in range(n):
        for j in range(max(0, i - kl), min(n, i + ku + 1)):
            M[i, j] = rng.standard_normal()
    M[np.arange(0, n, 2), np.arange(0, n, 2)] = 0.0
    ab = np.zeros((n, kl + ku + 1))
    for i in range(n):
        for j in range(max(0, i - kl), min(n, i + ku + 1)):
            ab[i, j - i + kl] = M[i, j]
    piv, mult, bad = banded.band_lu(ab, kl, ku)
    assert bad == -1
    b = rng.standard_normal((n, 2))
    x = b.copy()
    banded.band_solve(ab, mult, piv, kl, ku, x)
    assert np.allclose(x, np.linalg.solve(M, b), rtol=1e-9, atol=1e-9)
    # the same bits as the elimination on LAPACK's wide layout (room for the fill-in in every
    # row), written out here in plain Python: the window changes where rows live, not the sums
    wide = np.zeros((n, 2 * kl + ku + 1))
    wide[:, :kl + ku + 1] = [[M[i, j] if 0 <= j < n else 0.0 for j in range(i - kl, i + ku + 1)]
                             for i in range(n)]
    mult0 = np.zeros((n, kl))
    for k in range(n):
        last = min(n - 1, k + kl)
        p = k + int(np.argmax([abs(wide[r, k - r + kl]) for r in range(k, last + 1)]))
        assert p == piv[k]
        jmax = min(n - 1, k + kl + ku)
        for j in range(k, jmax + 1):
            wide[k, j - k + kl], wide[p, j - p + kl] = wide[p, j - p + kl], wide[k, j - k + kl]
        for r in range(k + 1, last + 1):
            f = wide[r, k - r + kl] / wide[k, kl]
            mult0[k, r - k - 1] = f
            for j in range(k + 1, jmax + 1):
                wide[r, j - r + kl] -= f * wide[k, j - k + kl]
    assert np.array_equal(mult, mult0)
    assert np.array_equal(ab, wide[:, kl:])  # row k of U: the columns k … k + kl + ku


def test_zigzag_order_makes_every_closed_loop_a_band():
    _, lay, _, _ = _system("link")
    pos = banded.zigzag_positions(lay)
    assert sorted(pos) == list(range(lay.n))
    assert np.abs(pos[lay.nxt] - pos).max() <= 2
    assert np.abs(pos[lay.nxt[lay.nxt]] - pos).max() <= 4


def test_not_a_banded_metric_refused():
    X, lay, _, _ = _system("trefoil")
    with pytest.raises(ValueError, match="hs"):
        metrics.banded_parts("hs", X, lay)


def test_tree_engine_with_a_banded_metric_runs_past_the_dense_limit():
    n = DENSE_MAX_VERTICES + 1000
    P = core.knots.freedman_unknot(n)
    with pytest.raises(ValueError, match="engine='tree'"):
        core.relax(P, metric="h2", max_iter=1, engine="exact")
    with pytest.raises(ValueError, match="penalty methods"):
        core.relax(P, metric="h2", max_iter=1, engine="tree", method="lbfgs")
    r = core.relax(P, metric="h2", max_iter=2, engine="tree")
    assert r.nit == 2
    assert r.history["energy"][-1] < r.history["energy"][0]
    assert max(r.history["constraint_residual"]) < 1e-8
    assert r.stats["engine"] == "tree"


def test_banded_tree_flow_follows_the_exact_flow():
    # the same metric solved two ways; the energies differ only by the tree's approximation
    P = core.knots.freedman_unknot(600)
    exact = core.relax(P, metric="h2", max_iter=15, engine="exact")
    tree = core.relax(P, metric="h2", max_iter=15, engine="tree")
    assert tree.nit == exact.nit == 15
    assert tree.fun == pytest.approx(exact.fun, rel=1e-3)


def test_packed_factors_keep_every_nonzero_and_solve_the_blocks():
    """pack_factors drops only the zeros past each row's last nonzero (rows end at their
    block's end), and each block's packed solve solves its system."""
    rng = np.random.default_rng(1)
    n, kl, ku = 80, 4, 4
    M = np.zeros((n, n))
    for i in range(n):
        for j in range(max(0, i - kl), min(n, i + ku + 1)):
            M[i, j] = rng.standard_normal() if (i + j) % 3 else 0.0  # zeros inside the band
        M[i, i] += 8.0
    M[40:, :40] = M[:40, 40:] = 0.0  # two blocks
    ab = np.zeros((n, kl + ku + 1))
    for i in range(n):
        for j in range(max(0, i - kl), min(n, i + ku + 1)):
            ab[i, j - i + kl] = M[i, j]
    cuts = np.array([0, 40, n], np.int64)
    piv, mult, bad = banded.band_lu_blocks(ab, kl, ku, cuts)
    assert bad == -1
    band, mult0 = ab.copy(), mult.copy()
    U, L, uw, lw, uoff, loff = banded.pack_factors(ab, mult, kl, ku, cuts)
    assert uw.sum() == U.size < band.size and lw.sum() == L.size < mult0.size
    for b in range(2):
        lo, hi = cuts[b], cuts[b + 1]
        pu, pl = uoff[b], loff[b]
        for k in range(lo, hi):
            row = band[k, :min(kl + ku + 1, hi - k)]
            assert np.array_equal(U[pu:pu + uw[k]], row[:uw[k]]) and not np.any(row[uw[k]:])
            mrow = mult0[k, :min(kl, hi - 1 - k)]
            assert np.array_equal(L[pl:pl + lw[k]], mrow[:lw[k]]) and not np.any(mrow[lw[k]:])
            pu, pl = pu + uw[k], pl + lw[k]
    b = rng.standard_normal(n)
    x = b.copy()
    banded._solve_range(U, L, uw, lw, uoff[1], loff[0], piv, x[:40], 0, 40)
    banded._solve_range(U, L, uw, lw, uoff[2], loff[1], piv, x[40:], 40, n)
    assert np.allclose(x, np.linalg.solve(M, b), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("name", ["fhw", "link"])
def test_compacted_band_solves_the_same_bits(name, monkeypatch):
    """From COMPACT_FROM vertices on the band keeps only its packed U (the array shrunk in
    place): the same solutions to the bit, the room given back, nothing left to recycle."""
    X, lay, con, jac = _system(name)
    parts = metrics.banded_parts("h1", X, lay)
    rng = np.random.default_rng(2)
    g = rng.standard_normal((lay.n, 3))
    r = 1e-3 * rng.standard_normal(con.size)
    kept = banded.BandedSaddle(parts, jac)
    again = banded.BandedSaddle(parts, jac, recycle=kept)  # takes kept's band over
    full = (4 * lay.n, again.kl + again.ku + 1)
    assert again.ab is not None and again.ab.shape == full
    again.release()
    monkeypatch.setattr(banded, "COMPACT_FROM", lay.n)
    small = banded.BandedSaddle(parts, jac, recycle=again)
    assert small.ab is None
    U = small.factors[0]
    assert U.ndim == 1 and U.flags.owndata and U.size < 0.7 * full[0] * full[1]
    # `again` was recycled (its band overwritten): build the reference anew
    monkeypatch.setattr(banded, "COMPACT_FROM", lay.n + 1)
    ref = banded.BandedSaddle(parts, jac)
    for a, b in zip(small.solve(g, r), ref.solve(g, r), strict=True):
        assert np.array_equal(a, b)
    assert np.array_equal(small.pseudo_inverse(r), ref.pseudo_inverse(r))
    small.release()
    monkeypatch.setattr(banded, "COMPACT_FROM", lay.n)
    fresh = banded.BandedSaddle(parts, jac, recycle=small)  # nothing to take over: a new band
    assert np.array_equal(fresh.solve(g, r)[0], ref.solve(g, r)[0])


@pytest.mark.parametrize("metric", ["h1", "h2"])
def test_split_band_solves_what_the_whole_band_solves(metric, monkeypatch):
    """A band cut in two halves and a separator (SPLIT_FROM) solves the same systems as the
    whole band, to rounding: fields and multipliers of one and of many right-hand sides, the
    hs preconditioner's band (edge parts) too. Measured 6e-16 to 1.5e-10 relative (h2 the
    largest, as against the dense solver)."""
    X, lay, con, jac = _system("fhw")
    rng = np.random.default_rng(4)
    g = rng.standard_normal((3, lay.n, 3))
    r = 1e-3 * rng.standard_normal((3, con.size))
    op = hs_metric.HsOperator(X, lay, "hs")
    for parts, product in ((metrics.banded_parts(metric, X, lay), True),
                           (op.preconditioner_edges(), False)):
        whole = banded.BandedSaddle(parts, jac, product=product)
        monkeypatch.setattr(banded, "SPLIT_FROM", 100)
        split = banded.BandedSaddle(parts, jac, product=product)
        monkeypatch.setattr(banded, "SPLIT_FROM", 10**9)
        assert list(split.part) == [0, 0, 0] and list(whole.part) == [-1]
        assert split.cuts[1] == 4 * (lay.n // 2) and split.rev[2] == split.cuts[2] + 4 * lay.n - 1
        for (u0, l0), (u1, l1) in [(whole._solve(g[0], r[0]), split._solve(g[0], r[0])),
                                   (whole.solve_many(g, r), split.solve_many(g, r))]:
            assert np.linalg.norm(u1 - u0) <= 1e-9 * np.linalg.norm(u0)
            assert np.linalg.norm(l1 - l0) <= 1e-9 * np.linalg.norm(l0)



def _dense_band(parts, nxt):
    """The banded part of ``parts`` (triplets, or :class:`banded.EdgeParts` of the closed
    components whose next vertices are ``nxt``) as a dense matrix over vertices, without the
    barycenter term."""
    n = nxt.shape[0]
    A = np.zeros((n, n))
    if isinstance(parts, banded.EdgeParts):
        v, w = np.arange(n), nxt
        np.add.at(A, (v, v), parts.p)
        np.add.at(A, (w, w), parts.p)
        np.add.at(A, (v, w), parts.q)
        np.add.at(A, (w, v), parts.q)
    else:
        np.add.at(A, (parts[0], parts[1]), parts[2])
    return A


def _constraint_rows(jac, m):
    """``C`` as a dense (m, 3N) matrix, row by row from ``Cᵀ``."""
    return np.array([jac.rmatvec(np.eye(m)[i]).ravel() for i in range(m)])


def _saddle_matrix(H, C):
    """``[[H, Cᵀ], [C, 0]]``."""
    k, m = H.shape[0], C.shape[0]
    K = np.zeros((k + m, k + m))
    K[:k, :k] = H
    K[:k, k:] = C.T
    K[k:, :k] = C
    return K


@pytest.mark.parametrize("name", ["trefoil", "fhw", "noneq"])
def test_barycenter_term_left_out_of_a_preconditioner(name):
    """``barycenter_term=False`` solves the saddle-point system of the band's metric without
    ``B`` (against a dense solve of it), with six columns: the same fields as with ``B``
    for any ``C u = r``, the same multipliers for ``r = 0``."""
    X, lay, con, jac = _system(name)
    n, m = lay.n, con.size
    C = _constraint_rows(jac, m)
    rng = np.random.default_rng(6)
    g = rng.standard_normal((n, 3))
    r = 1e-3 * rng.standard_normal(m)
    op = hs_metric.HsOperator(X, lay, "hs")
    for parts in (metrics.banded_parts("h1", X, lay), op.preconditioner_edges()):
        K = _saddle_matrix(np.kron(_dense_band(parts, lay.nxt), np.eye(3)), C)
        without = banded.BandedSaddle(parts, jac, product=False, barycenter_term=False)
        assert without.Z.shape[0] == 6
        with_b = banded.BandedSaddle(parts, jac, product=False)
        for rr in (r, np.zeros(m)):
            x = np.linalg.solve(K, np.concatenate([g.ravel(), rr]))
            u, lam = without._solve(g, rr)
            assert np.linalg.norm(u.ravel() - x[:3 * n]) <= 1e-8 * np.linalg.norm(x[:3 * n])
            assert np.linalg.norm(lam - x[3 * n:]) <= 1e-7 * np.linalg.norm(x[3 * n:])
        ub, lamb = with_b._solve(g, np.zeros(m))
        assert np.linalg.norm(u - ub) <= 1e-9 * np.linalg.norm(ub)
        assert np.linalg.norm(lam - lamb) <= 1e-7 * np.linalg.norm(lamb)
        # with C u = r ≠ 0 too the fields agree (B's range, multiples of β, lies in Cᵀ's),
        # and only the barycenter rows' multipliers move
        (u1, lam1), (u2, lam2) = without._solve(g, r), with_b._solve(g, r)
        assert np.linalg.norm(u1 - u2) <= 1e-8 * np.linalg.norm(u2)
        assert np.linalg.norm(lam1[n:] - lam2[n:]) > 1e-6 * np.linalg.norm(lam2[n:])
    with pytest.raises(ValueError, match="preconditioner"):
        banded.BandedSaddle(metrics.banded_parts("h1", X, lay), jac, barycenter_term=False)


@pytest.mark.parametrize("name", sorted(CURVES))
def test_projected_barycenter_rows_solve_the_translation_free_metric(name):
    """``projected=True`` solves the saddle-point system of ``H′``, the band's metric (its
    spring of ``PROJECTED_SPRING`` included) with the translations of every component
    minimized out, against a dense solve of it: fields and multipliers, for ``C u = r`` and
    ``r = 0``; the solve is symmetric and maps into ``ker C``."""
    X, lay, con, jac = _system(name)
    n, m = lay.n, con.size
    C = _constraint_rows(jac, m)
    rng = np.random.default_rng(8)
    g = rng.standard_normal((n, 3))
    r = 1e-3 * rng.standard_normal(m)
    op = hs_metric.HsOperator(X, lay, "hs")
    for parts in (metrics.banded_parts("h1", X, lay), op.preconditioner_edges()):
        A = _dense_band(parts, lay.nxt)
        anchors = lay.starts[:-1]
        A[anchors, anchors] *= 1 + banded.PROJECTED_SPRING
        H = np.kron(A, np.eye(3))
        T = np.zeros((3 * n, 3 * lay.k))  # the translations of every component
        for c in range(lay.k):
            for d in range(3):
                T[3 * np.arange(lay.starts[c], lay.starts[c + 1]) + d, 3 * c + d] = 1.0
        HT = H @ T
        K = _saddle_matrix(H - HT @ np.linalg.solve(T.T @ HT, HT.T), C)
        solver = banded.BandedSaddle(parts, jac, product=False, barycenter_term=False,
                                     projected=True)
        assert not hasattr(solver, "Z")  # no column solves
        for rr in (r, np.zeros(m)):
            x = np.linalg.solve(K, np.concatenate([g.ravel(), rr]))
            u, lam = solver._solve(g, rr)
            assert np.linalg.norm(u.ravel() - x[:3 * n]) <= 1e-8 * np.linalg.norm(x[:3 * n])
            assert np.linalg.norm(lam - x[3 * n:]) <= 1e-7 * np.linalg.norm(x[3 * n:])
            assert np.abs(C @ u.ravel() - rr).max() <= 1e-12 * max(1.0, np.abs(u).max())
        u0 = solver.pseudo_inverse(r)
        assert np.linalg.norm(u0.ravel() - np.linalg.solve(K, np.r_[np.zeros(3 * n), r])[:3 * n]
                              ) <= 1e-8 * np.linalg.norm(u0)
        g2 = rng.standard_normal((n, 3))
        z1, z2 = solver._solve(g, np.zeros(m))[0], solver._solve(g2, np.zeros(m))[0]
        assert abs(np.vdot(z1, g2) - np.vdot(z2, g)) <= 1e-10 * abs(np.vdot(z1, g2))
    with pytest.raises(ValueError, match="barycenter term"):
        banded.BandedSaddle(op.preconditioner_edges(), jac, product=False, projected=True)


SPLIT_FLOW = """
from moebius_addon import core
from moebius_addon.core.metrics import banded
old, banded.SPLIT_FROM = banded.SPLIT_FROM, 300
try:
    P = core.resample(core.knots.named("5_2"), 1500)
    r = core.relax(P, max_iter=3, engine="tree")
finally:
    banded.SPLIT_FROM = old
OUT = [r.x.tobytes().hex(), r.stats["krylov_iterations"], r.history["energy"]]
"""


def test_split_band_flow_same_bits_for_any_thread_count_and_the_whole_bands_energies():
    # the hs preconditioner's band and its levels split (1 500 vertices; levels of 375 and
    # more): the same iterates bit for bit in one thread as in all of them, and the energies
    # of the flow with whole bands within 1e-9
    here, there = out_here_and_in_one_thread(SPLIT_FLOW)
    assert there == here
    whole = core.relax(core.resample(core.knots.named("5_2"), 1500), max_iter=3, engine="tree")
    assert np.allclose(here[2], whole.history["energy"], rtol=1e-9, atol=0)
