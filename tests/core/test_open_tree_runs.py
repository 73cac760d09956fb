"""Runs with open components on the tree engine: the banded saddle-point solver with
dummy edges and pins eliminated against a dense numpy solve, "auto" and the refusals, short runs
on pinned cables against the exact engine, with the pins kept to the bit and no two edges
meeting (tests/mesh_checks.py), and the contact queries' hierarchy on open curves."""

import numpy as np
import pytest

from moebius_addon import core
from moebius_addon.core.energies.choice import check_energy
from moebius_addon.core.geometry import collision
from moebius_addon.core.geometry.constraints import jacobian, make_constraints
from moebius_addon.core.geometry.layout import as_layout
from moebius_addon.core.metrics.banded import OpenBandedSaddle
from moebius_addon.core.metrics.gram import banded_parts, gram_x
from moebius_addon.core.metrics.pinned_solve import TREE_MAX_PINS
from moebius_addon.core.runs.engine import DenseEngine, TreeEngine, make_engine
from moebius_addon.core.runs.methods import make_run
from moebius_addon.core.tree.hs_metric import HsOperator
from tests.conftest import ngon
from tests.mesh_checks import segments_closest


def cables(n, edges, spacing=0.08, jitter=0.02, seed=0):
    """Equilateral cables from z = 0 to z = 1 on a square grid, bent by random sines."""
    rng = np.random.default_rng(seed)
    k = int(np.ceil(np.sqrt(n)))
    t = np.linspace(0.0, 1.0, 4 * edges + 1)
    parts = []
    for c in range(n):
        w = rng.uniform(-1, 1, (2, 2)) * jitter
        parts.append(np.c_[spacing * (c % k) + w[0, 0] * np.sin(np.pi * t)
                           + w[0, 1] * np.sin(2 * np.pi * t),
                           spacing * (c // k) + w[1, 0] * np.sin(np.pi * t)
                           + w[1, 1] * np.sin(3 * np.pi * t), t])
    return core.resample(parts, [edges + 1] * n, closed=False)


def ends(parts):
    return [[0, len(p) - 1] for p in parts]


@pytest.mark.parametrize("metric", ["h1", "h2"])
def test_the_band_in_blocks_gives_the_bits_of_one_band(metric, rng, monkeypatch):
    """The band of several components factored and solved block by block, in parallel
    (banded._BLOCKS), against one band: the same bits; a single component is one block."""
    from moebius_addon.core.metrics import banded

    parts = cables(6, 30) + [ngon(24) * 0.1 + [0.1, 0.1, 0.5]]
    X, layout = as_layout(parts, [False] * 6 + [True])
    ln = np.linalg.norm(X[layout.nxt] - X, axis=1)
    ln[~layout.real] = 1.0
    con = make_constraints(X, layout, ln, True, True, np.array([0, 30, 31, 61]))
    jac = jacobian(X, con)
    g = rng.standard_normal(X.shape)
    r = rng.standard_normal(con.size)
    out = {}
    for blocks in (1, banded._BLOCKS):
        monkeypatch.setattr(banded, "_BLOCKS", blocks)
        solver = OpenBandedSaddle(banded_parts(metric, X, layout), jac)
        U, L, uw, lw, _, _, piv = solver.factors  # (the blocks' offsets: one per block)
        out[blocks] = (len(solver.cuts) - 1, U, L, uw, lw, piv, *solver.solve(g, r))
    assert out[1][0] == 1 and out[banded._BLOCKS][0] == 7  # a block per component
    for a, b in zip(out[1][1:], out[banded._BLOCKS][1:], strict=True):
        assert np.array_equal(a, b)
    single = as_layout(parts[0], False)[1]
    ab = np.ones((4 * single.n, 7))
    assert np.array_equal(banded.block_cuts(ab, 3, 3, single.starts[:-1].astype(np.int64), 1),
                          [0, 4 * single.n])


@pytest.mark.parametrize("metric", ["h1", "h2", "l2"])
def test_open_banded_solver_matches_dense_solve(metric, rng):
    # three pinned cables, one free cable and a free ring: every kind of component
    parts = cables(4, 30) + [ngon(24) * 0.1 + [0.1, 0.1, 0.5]]
    closed = [False] * 4 + [True]
    X, layout = as_layout(parts, closed)
    ln = np.linalg.norm(X[layout.nxt] - X, axis=1)
    ln[~layout.real] = 1.0  # the dummy edges have no row (as in a run)
    pinned = np.array([0, 30, 31, 61, 62, 92])
    con = make_constraints(X, layout, ln, True, True, pinned)
    jac = jacobian(X, con)
    solver = OpenBandedSaddle(banded_parts(metric, X, layout), jac)
    g = rng.standard_normal(X.shape)
    r = rng.standard_normal(con.size)
    u, lam = solver.solve(g, r)
    # dense: G = A ⊗ I₃, C column by column, the pinned coordinates' unknowns removed
    n = layout.n
    A = gram_x(metric, X, layout)
    G = np.kron(A, np.eye(3))
    C = np.stack([jac.matvec(e.reshape(n, 3)) for e in np.eye(3 * n)], axis=1)
    free = np.ones((n, 3), bool)
    free[pinned] = False
    free = free.ravel()
    m = con.size
    K = np.block([[G[np.ix_(free, free)], C[:, free].T], [C[:, free], np.zeros((m, m))]])
    sol = np.linalg.solve(K, np.concatenate([g.ravel()[free], r]))
    u0 = np.zeros(3 * n)
    u0[free] = sol[:free.sum()]
    assert np.all(u[pinned] == 0.0)
    np.testing.assert_allclose(u.ravel(), u0, rtol=0, atol=1e-8 * np.abs(u0).max())
    np.testing.assert_allclose(lam, sol[free.sum():], rtol=0, atol=1e-8 * np.abs(lam).max())
    # the metric's product is the dense one
    V = rng.standard_normal(X.shape)
    np.testing.assert_allclose(solver.metric_product(V), A @ V, rtol=1e-12,
                               atol=1e-12 * np.abs(A @ V).max())


def test_hs_operator_of_open_layouts_is_the_dense_metric_where_all_is_near(rng):
    # every pair near (tiny theta): Ã is the dense open metric (core/open_metrics.py, tested
    # against numpy in test_open_curves.py), its L² term and barycenter term included
    parts = cables(3, 40) + [ngon(30) * 0.1 + [0.5, 0.1, 0.5]]
    X, layout = as_layout(parts, [False] * 3 + [True])
    U = rng.standard_normal(X.shape)
    for metric in ("hs", "hs_pure"):
        A = gram_x(metric, X, layout)
        op = HsOperator(X, layout, metric, theta=1e-6)
        assert op.far_pairs == 0
        np.testing.assert_allclose(op.product(U), A @ U, rtol=0,
                                   atol=1e-13 * np.abs(A @ U).max())
        np.testing.assert_allclose(op.diagonal(), np.diag(A), rtol=1e-13)
        assert HsOperator(X, layout, metric).far_pairs > 0  # the default has a far field


def test_auto_takes_the_tree_for_open_curves():
    X, layout = as_layout(cables(9, 120), False)  # 1 089 vertices
    assert isinstance(make_engine("auto", layout, "h1"), TreeEngine)
    assert isinstance(make_engine("auto", layout, "hs"), TreeEngine)
    X, layout = as_layout(cables(2, 60), False)
    assert isinstance(make_engine("auto", layout, "hs"), DenseEngine)
    X, layout = as_layout(cables(9, 120), False)  # the tangent-point energy too
    tp = check_energy("tangent_point")
    assert isinstance(make_engine("auto", layout, "hs", energy=tp), TreeEngine)


def _min_gap(x):
    """Smallest distance between two edges that share no vertex (numpy, all pairs)."""
    segs = [(p[:-1], p[1:], c) for c, p in enumerate(x)]
    P = np.concatenate([s[0] for s in segs])
    Q = np.concatenate([s[1] for s in segs])
    comp = np.concatenate([np.full(len(s[0]), s[2]) for s in segs])
    idx = np.concatenate([np.arange(len(s[0])) for s in segs])
    i, j = np.triu_indices(len(P), 1)
    ok = (comp[i] != comp[j]) | (np.abs(idx[i] - idx[j]) >= 2)
    i, j = i[ok], j[ok]
    return segments_closest(P[i], Q[i], P[j], Q[j]).min()


def test_tree_run_on_pinned_cables():
    parts = cables(9, 110, spacing=0.05)  # 1 000 edges
    pins = ends(parts)
    runs = {}
    for engine in ("tree", "exact"):
        xs = []
        res = core.relax(parts, closed=False, pinned=pins, engine=engine, metric="h1",
                         max_iter=4, callback=lambda s, xs=xs: xs.append(s.x))
        runs[engine] = (res, xs)
    res, xs = runs["tree"]
    E = res.history["energy"]
    assert all(b < a for a, b in zip(E, E[1:], strict=False))  # every step lowers it
    for x in xs:
        for c, p in enumerate(parts):
            assert np.array_equal(x[c][[0, -1]], p[[0, -1]])  # the pins, to the bit
    gap0 = _min_gap(parts)
    assert min(_min_gap(x) for x in xs) > 0.2 * gap0  # nothing meets
    # the first iterates follow the exact engine's within the tree's accuracy
    res0, xs0 = runs["exact"]
    np.testing.assert_allclose(E, res0.history["energy"][:len(E)], rtol=1e-4)
    edge = 1.0 / 110
    for x, x0 in zip(xs[:2], xs0[:2], strict=True):
        assert max(np.abs(a - b).max() for a, b in zip(x, x0, strict=True)) < 1e-3 * edge


@pytest.mark.parametrize("metric", ["h1", "hs"])
def test_tangent_point_tree_run_on_pinned_cables(metric):
    # the tangent-point energy on open cables on the tree (it was refused there): every step
    # lowers it, the pins keep their bits, nothing meets; in h1 (the same band metric on both
    # engines) the energy follows the exact engine's run within the tree's accuracy (measured
    # after 6 iterations: 2.8e-5 apart). In hs the tree's metric is an approximation too and
    # the runs' step sizes part (as for the Möbius energy: 2134 against 2041 after 6): 12 984
    # against 11 987, from 19 029
    parts = cables(9, 110, spacing=0.05)
    pins = ends(parts)
    runs = {}
    for engine in ("tree", "exact"):
        runs[engine] = core.relax(parts, closed=False, pinned=pins, engine=engine,
                                  metric=metric, energy="tangent_point", max_iter=6)
    res = runs["tree"]
    assert res.stats["engine"] == "tree"
    E = res.history["energy"]
    assert len(E) == 7 and all(b < a for a, b in zip(E, E[1:], strict=False))
    for c, p in enumerate(parts):
        assert np.array_equal(res.x[c][[0, -1]], p[[0, -1]])
    assert _min_gap(res.x) > 0.2 * _min_gap(parts)
    if metric == "h1":
        assert res.fun == pytest.approx(runs["exact"].fun, rel=2e-4)
    else:
        assert res.fun < 0.75 * E[0] and runs["exact"].fun < 0.75 * E[0]


def test_tree_run_on_pinned_cables_in_hs():
    # the default metric: Ã through the hierarchy of arcs (an approximation of the dense
    # metric, so the iterates differ from the exact engine's more than in h1)
    parts = cables(9, 110, spacing=0.05)
    pins = ends(parts)
    res = core.relax(parts, closed=False, pinned=pins, engine="tree", max_iter=4)
    E = res.history["energy"]
    assert all(b < a for a, b in zip(E, E[1:], strict=False))
    res0 = core.relax(parts, closed=False, pinned=pins, engine="exact", max_iter=1)
    # the first step's energy: measured 2.3e-3 apart (Ã's far field at hs_tree.THETA)
    assert E[1] == pytest.approx(res0.history["energy"][1], rel=5e-3)
    for c, p in enumerate(parts):
        assert np.array_equal(res.x[c][[0, -1]], p[[0, -1]])
    assert _min_gap(res.x) > 0.2 * _min_gap(parts)


@pytest.mark.parametrize("metric", ["hs", "h1"])
def test_many_pins_stay_off_the_dense_solver(metric):
    # 64 pins, more than pinned_solve.TREE_MAX_PINS: closed curves would be solved densely
    # there; open ones eliminate the pins in the band (hs: its preconditioner)
    parts = cables(32, 12, spacing=0.4)
    run = make_run("projected_gradient", parts, metric, 2, 0.0, engine="tree", closed=False,
                   pinned=ends(parts), refine=False)
    assert run.pinned.size > TREE_MAX_PINS
    while run.step():
        pass
    assert run.engine.solver.n_factor == 0  # no dense factorization
    assert run.engine._saddle is not None
    assert run.history["energy"][-1] < run.history["energy"][0]


def test_the_size_check_takes_many_pins_on_open_curves():
    # the run takes them (above); the pre-check refused them above the dense size as for
    # closed curves, where they do need the dense solver
    from moebius_addon.core import check_size
    from moebius_addon.core.runs.base import DENSE_MAX_VERTICES

    n, pins = DENSE_MAX_VERTICES + 1000, 2 * TREE_MAX_PINS
    for metric in ("hs", "h1"):
        with pytest.raises(ValueError, match="pin"):
            check_size(n, metric, "projected_gradient", "tree", pinned=pins)
        check_size(n, metric, "projected_gradient", "tree", pinned=pins, open_curves=True)
    with pytest.raises(ValueError):  # the dense methods still say no
        check_size(n, "hs", "lbfgs", "tree", open_curves=True)


@pytest.mark.parametrize("method", ["projected_gradient_implicit", "trust_region"])
def test_other_feasible_methods_on_the_tree(method):
    parts = cables(4, 60) + [ngon(40) * 0.1 + [0.4, 0.04, 0.5]]
    closed = [False] * 4 + [True]
    res = core.relax(parts, closed=closed, pinned=ends(parts[:4]) + [[]], engine="tree",
                     metric="h2", method=method, max_iter=3)
    assert res.fun < res.history["energy"][0]
    for c in range(4):
        assert np.array_equal(res.x[c][[0, -1]], parts[c][[0, -1]])


def test_contact_queries_through_the_hierarchy_on_open_curves(rng):
    # a hairpin whose two ends come close (along the polyline they are far: no way round)
    t = np.linspace(0, np.pi, 600)
    hairpin = np.c_[np.cos(t) * (1 + 0.02 * t), np.sin(t), 0.01 * t]
    hairpin = np.r_[hairpin, hairpin[::-1][1:] * [1, -1, 1] + [0, 0, 0.004]][:-1]
    parts = [hairpin, ngon(300) * 0.3 + [0.2, 0, 0.1]] + cables(3, 200)
    closed = [False, True, False, False, False]
    X, layout = as_layout(parts, closed)
    assert layout.n >= collision.CONTACT_TREE_FROM
    for gap in (2, 4):
        both = collision.closest_pairs(X, layout, gap, search="pairs")
        assert collision.closest_pairs(X, layout, gap, search="tree") == both
        assert collision.closest_vertices(X, layout, gap, search="tree") == both[0]
    for _ in range(3):
        U = rng.standard_normal(X.shape)
        assert collision.contact_time_x(X, U, layout, 1.0, 1e-4, search="tree") == \
            collision.contact_time_x(X, U, layout, 1.0, 1e-4, search="pairs")
