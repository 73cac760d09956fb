"""Pinned vertices: pinned vertices keep their bits on every iterate of every
feasible method and engine, the energy still decreases on the constraints, the pinned solve is
the saddle-point system with explicit pin rows, runs without pins are bit-for-bit what they
were before pins, and every bad ``pinned=`` is refused before anything runs."""

import json

import numpy as np
import pytest

from moebius_addon.core import check_size, max_collision_free_step, relax, resample
from moebius_addon.core.geometry.constraints import (
    TangentProjector,
    jacobian,
    make_constraints,
    residual,
    weighted_barycenters,
)
from moebius_addon.core.geometry.layout import as_layout
from moebius_addon.core.metrics.banded import BandedSaddle
from moebius_addon.core.metrics.gram import banded_parts, gram_x
from moebius_addon.core.metrics.hs_solve import HsSaddle
from moebius_addon.core.metrics.pinned_solve import (
    TREE_MAX_PINS,
    BorderedPins,
    unpinned_jacobian,
)
from moebius_addon.core.metrics.saddle import Factorization
from moebius_addon.core.runs import base as solvers_base
from moebius_addon.core.runs.methods import FEASIBLE, INFEASIBLE, METHOD_CLASSES, make_run
from moebius_addon.core.topology import knots
from moebius_addon.core.tree.hs_metric import HsOperator
from tests.core import _unchanged_runs as unchanged

PINS = [0, 1, 17, 40]  # 0–1: an edge between two pins (its length row drops out)


@pytest.fixture(scope="module")
def trefoil60():
    return resample(knots.torus_knot(2, 3, 200), 60)


@pytest.fixture(scope="module")
def reference_curves():
    return unchanged.curves()


@pytest.fixture(scope="module")
def reference():
    return json.loads(unchanged.REFERENCE.read_text())


def lengths(X, layout):
    return np.linalg.norm(X[layout.nxt] - X, axis=1)


# -- without pins: the same bits as before pins existed ---------------------------------------

# Each history against the reference, relative to its largest value. The reference was
# written on main before pins and matched bit for bit on that machine; another CPU rounds
# differently (vector widths of numba's sums, OpenBLAS kernels), and stopping rules on
# tolerances (Krylov, back-projection, contact times) turn last bits into differences at their
# tolerance: on an AMD Zen 4 (2026-11-25) up to 1.8e-7 in energies, 6.4e-7 in gradient norms
# and 5.1e-6 in steps, every iteration count equal. A change to the method moves them by far
# more; in one process the runs are compared bit for bit (test_empty_pins_are_no_pins).
# Constraint residuals: rounding-level for the feasible methods (1e-12 absolute), up to 2e-11 of
# their size for the penalty methods, whose residuals are large.
_SCALED_TOL = {"energy": 1e-5, "step": 1e-4, "grad_norm": 1e-4, "constraint_residual": 1e-9}


def same_run(got: dict, ref: dict) -> None:
    """The histories of ``got`` and ``ref``: the iteration count exactly, the rest to
    :data:`_SCALED_TOL` of each history's largest value (constraint residuals at least to
    1e-12 absolute)."""
    assert got["nit"] == ref["nit"]
    for key in ("energy", "step", "grad_norm", "constraint_residual"):
        a = np.array([float.fromhex(v) for v in got[key]])
        b = np.array([float.fromhex(v) for v in ref[key]])
        atol = _SCALED_TOL[key] * np.abs(b).max()
        if key == "constraint_residual":
            atol = max(atol, 1e-12)
        np.testing.assert_allclose(a, b, rtol=0, atol=atol, err_msg=key)


@pytest.mark.parametrize("case", unchanged.CASES, ids=unchanged.case_id)
def test_without_pins_every_iterate_is_unchanged(case, reference_curves, reference):
    same_run(unchanged.run_case(case, reference_curves[case[0]]),
             reference[unchanged.case_id(case)])


@pytest.mark.parametrize("case", [unchanged.CASES[0], unchanged.CASES[-3]],
                         ids=unchanged.case_id)
def test_empty_pins_are_no_pins(case, reference_curves):
    # in one process: bit for bit, the final polygon's hash included
    P = reference_curves[case[0]]
    empty = [[] for _ in P] if isinstance(P, list) else []
    assert unchanged.run_case(case, P, pinned=empty) == unchanged.run_case(case, P)


# -- pins hold, the flow still relaxes --------------------------------------------------------

RUNS = [(m, "exact", "hs") for m in FEASIBLE] + [(m, "tree", "hs") for m in FEASIBLE] + [
    ("projected_gradient", "exact", "l2"), ("projected_gradient", "tree", "h1"),
    ("trust_region", "exact", "h2"),
]


@pytest.mark.parametrize(("method", "engine", "metric"), RUNS)
def test_pinned_vertices_do_not_move(trefoil60, method, engine, metric):
    P = trefoil60
    run = make_run(method, P, metric, 6, 0.0, engine=engine, pinned=PINS)
    X0 = run.X.copy()
    xs = [P]
    while run.step():
        xs.append(run.x)
        assert np.array_equal(run.X[PINS], X0[PINS])  # the run's own copy: every iterate
        assert np.array_equal(run.x[PINS], P[PINS])  # the caller's coordinates
    if len(xs) == run.nit:
        xs.append(run.x)
    assert run.nit == 6, run.message
    if engine == "tree":  # its own O(N) solvers, bordered by the pins: nothing dense
        assert run.engine.solver.n_factor == 0
    h = run.history
    assert np.all(np.diff(h["energy"]) <= 0)
    assert h["energy"][-1] < h["energy"][0] - 1.0
    # the other vertices do move
    free = np.setdiff1d(np.arange(len(P)), PINS)
    assert np.abs(run.x[free] - P[free]).max() > 1e-2
    # edge lengths kept as without pins
    assert max(h["constraint_residual"]) <= 1e-10
    ln = np.linalg.norm(np.roll(run.x, -1, 0) - run.x, axis=1)
    np.testing.assert_allclose(ln, np.linalg.norm(np.roll(P, -1, 0) - P, axis=1).mean(),
                               rtol=1e-9)
    # the straight path between consecutive iterates never comes near itself
    for a, b in zip(xs, xs[1:], strict=False):
        assert max_collision_free_step(a, a - b, 1.0) == 1.0


def test_pins_through_relax_and_the_krylov_path():
    """600 vertices: single-precision factorization refined by GMRES (and the reused one)."""
    P = knots.freedman_unknot(600)
    pins = list(range(0, 600, 50))
    runs = [relax(P, max_iter=4, tol=0.0, engine="exact", pinned=pins, **kw)
            for kw in ({}, {"reuse_factorization": True})]
    for r in runs:
        assert r.nit == 4, r.message
        assert np.array_equal(r.x[pins], P[pins])
        assert r.fun < r.history["energy"][0] - 100
        assert max(r.history["constraint_residual"]) <= 1e-10
    np.testing.assert_allclose(runs[0].fun, runs[1].fun, rtol=1e-10)


def test_link_with_pins_on_one_component():
    P = unchanged.curves()["hopf"]
    pins = [[0, 5, 12], []]
    run = make_run("projected_gradient", P, "hs", 5, 0.0, engine="exact", pinned=pins)
    con = run.con
    assert con.n_bary_rows == 3  # the pinned component has none, the free one keeps its own
    assert con.size == 48 + 3
    b0 = weighted_barycenters(run.X, run.layout)[1]
    while run.step():
        assert np.array_equal(run.x[0][pins[0]], P[0][pins[0]])
    assert run.nit == 5, run.message
    # the free component's barycenter is held, and it moved
    np.testing.assert_allclose(weighted_barycenters(run.X, run.layout)[1], b0, atol=1e-11)
    assert np.abs(run.x[1] - P[1]).max() > 1e-3
    h = run.history
    assert h["energy"][-1] < h["energy"][0] - 0.5
    assert max(h["constraint_residual"]) <= 1e-10


@pytest.mark.parametrize("engine", ["exact", "tree"])
def test_a_whole_component_pinned_is_a_fixed_obstacle(engine):
    P = unchanged.curves()["hopf"]
    r = relax(P, max_iter=4, tol=0.0, engine=engine, pinned=[list(range(24)), []])
    assert r.nit == 4, r.message
    assert np.array_equal(r.x[0], P[0])
    assert np.abs(r.x[1] - P[1]).max() > 1e-2
    assert r.fun < r.history["energy"][0] - 0.1
    assert max(r.history["constraint_residual"]) <= 1e-10


def test_fixed_tangents_at_pins(trefoil60):
    P = trefoil60
    r = relax(P, max_iter=5, tol=0.0, engine="exact", pinned=[0, 30], pin_tangents=True)
    held = [59, 0, 1, 29, 30, 31]
    assert np.array_equal(r.x[held], P[held])  # both edges at each pin keep their direction
    assert r.nit == 5 and r.fun < r.history["energy"][0] - 1.0


# -- the pinned solve against the saddle-point system with explicit pin rows ----------------

def _dense_rows(jac, size, n):
    """C as a dense (size, 3N) matrix, column by column through ``matvec``."""
    C = np.empty((size, 3 * n))
    for col in range(3 * n):
        e = np.zeros(3 * n)
        e[col] = 1.0
        C[:, col] = jac.matvec(e.reshape(n, 3))
    return C


def test_solve_is_the_system_with_pin_rows(trefoil60):
    X, lay = as_layout(trefoil60)
    n = lay.n
    ln = lengths(X, lay)
    pins = np.array(PINS)
    con = make_constraints(X, lay, ln, pinned=pins)
    assert con.n_bary_rows == 0 and con.n_edge_rows == n - 1  # edge 0–1 has no row
    jac = jacobian(X, con)
    A = gram_x("hs", X, lay)
    fac = Factorization(A, jac)
    # the obvious system: every edge row of the free vertices, and u_p = 0 at every pin
    C = _dense_rows(jac, con.size, n)
    pin_rows = np.zeros((3 * len(pins), 3 * n))
    for a, p in enumerate(pins):
        for d in range(3):
            pin_rows[3 * a + d, 3 * p + d] = 1.0
    Ct = np.vstack([C, pin_rows])
    m = Ct.shape[0]
    K = np.block([[np.kron(A, np.eye(3)), Ct.T], [Ct, np.zeros((m, m))]])
    g = np.random.default_rng(1).standard_normal((n, 3))
    ref = np.linalg.solve(K, np.concatenate([g.ravel(), np.zeros(m)]))[: 3 * n]
    u, _ = fac.solve(g, np.zeros(con.size))
    np.testing.assert_allclose(u.ravel(), ref, atol=1e-9 * np.abs(ref).max())
    assert np.all(u[pins] == 0.0)
    phi = np.random.default_rng(2).standard_normal(con.size) * 1e-3
    ref = np.linalg.solve(K, np.concatenate([np.zeros(3 * n), phi, np.zeros(3 * len(pins))]))
    d = fac.pseudo_inverse(phi)
    np.testing.assert_allclose(d.ravel(), ref[: 3 * n], atol=1e-9 * np.abs(ref).max())
    assert np.all(d[pins] == 0.0)
    # the residual has the same rows
    assert residual(X, con).shape == (con.size,)


def test_o_n_solvers_refuse_pins(trefoil60):
    X, lay = as_layout(trefoil60)
    jac = jacobian(X, make_constraints(X, lay, lengths(X, lay), pinned=np.array([3])))
    with pytest.raises(ValueError, match="no pinned vertices"):
        TangentProjector(jac)
    with pytest.raises(ValueError, match="no pinned vertices"):
        BandedSaddle(banded_parts("h1", X, lay), jac)


# -- refusals, before anything runs ---------------------------------------------------------

@pytest.fixture
def nothing_runs(monkeypatch):
    """Fail the test if a run gets as far as building its engine."""
    def fail(*args, **kwargs):
        raise AssertionError("the run started before refusing its pins")
    monkeypatch.setattr(solvers_base, "make_engine", fail)


def _rectangle():
    """Equilateral 4 × 1 rectangle, 10 unit edges: a straight side of 4 edges."""
    side = [(x, 0.0, 0.0) for x in range(4)] + [(4.0, 0.0, 0.0)]
    top = [(x, 1.0, 0.0) for x in range(4, 0, -1)] + [(0.0, 1.0, 0.0)]
    return np.array(side + top, float)


BAD = [
    ([60], "pinned index 60 is out of range: the polygon has 60 vertices, indices 0 to 59"),
    ([-1], "pinned index -1 is out of range"),
    ([3, 7, 3], "pinned index 3 is given more than once"),
    ([1.5], r"pinned must hold whole vertex indices \(int\), got 1.5"),
    ([2.0], r"pinned must hold whole vertex indices \(int\), got 2.0"),
    ([True], r"pinned must hold whole vertex indices \(int\), got True"),
    (np.array([1.0, 2.0]), r"whole vertex indices \(int\), got np.float64\(1.0\)|got 1.0"),
    ("012", "pinned must be a sequence of vertex indices, got '012'"),
    (5, "pinned must be a sequence of vertex indices, got 5"),
    ([[1, 2]], "pinned must be a flat sequence of vertex indices"),
    (list(range(60)), "every vertex is pinned: nothing can move; leave some vertices free"),
]


@pytest.mark.parametrize("method", FEASIBLE)
@pytest.mark.parametrize(("pinned", "message"), BAD)
def test_bad_pins_are_refused(trefoil60, nothing_runs, method, pinned, message):
    with pytest.raises(ValueError, match=message):
        make_run(method, trefoil60, "hs", 5, engine="exact", pinned=pinned)


def test_pinning_every_vertex_by_tangents_is_refused(trefoil60, nothing_runs):
    with pytest.raises(ValueError, match=r"every vertex is pinned \(with their neighbours\)"):
        relax(trefoil60, pinned=list(range(0, 60, 3)), pin_tangents=True)


def test_straight_free_stretch_is_refused(nothing_runs):
    R = _rectangle()
    with pytest.raises(ValueError, match="the 3 free vertices between pinned vertices 0 and 4 "
                                         "lie on a straight segment: too few free vertices"):
        relax(R, pinned=[0, 4], engine="exact")
    with pytest.raises(ValueError, match="drop pin_tangents"):
        relax(R, pinned=[0, 6], pin_tangents=True, engine="exact")


def test_straight_stretch_is_fine_without_edge_lengths():
    r = relax(_rectangle(), pinned=[0, 4], engine="exact", edge_lengths=False, max_iter=2,
              check=False)
    assert np.array_equal(r.x[[0, 4]], _rectangle()[[0, 4]])


LINK_BAD = [
    ([0, 1], "pinned must hold one list of vertex indices per component of the link"),
    ([[0]], "pinned must hold one list of vertex indices per component of the link"),
    ([[0], [24]], "pinned index 24 of component 1 is out of range: the component has 24 "
                  "vertices, indices 0 to 23"),
    ([[0, 0], []], "pinned index 0 of component 0 is given more than once"),
]


@pytest.mark.parametrize(("pinned", "message"), LINK_BAD)
def test_bad_link_pins_are_refused(nothing_runs, pinned, message):
    with pytest.raises(ValueError, match=message):
        relax(unchanged.curves()["hopf"], pinned=pinned)


@pytest.mark.parametrize("method", INFEASIBLE)
def test_penalty_methods_refuse_pins(trefoil60, nothing_runs, method):
    msg = (f"method '{method}' cannot keep pinned vertices fixed .* use a feasible method, "
           f"projected_gradient, projected_gradient_implicit or trust_region")
    with pytest.raises(ValueError, match=msg):
        make_run(method, trefoil60, "hs", 5, engine="exact", pinned=[3])
    with pytest.raises(ValueError, match=msg):
        check_size(60, "hs", method, "exact", pinned=True)
    assert METHOD_CLASSES[method].NAME == method


@pytest.mark.parametrize("method", INFEASIBLE)
def test_penalty_methods_accept_no_pins(trefoil60, method):
    for pinned in (None, []):
        r = relax(trefoil60, max_iter=1, method=method, engine="exact", pinned=pinned)
        assert r.nit == 1


def test_tree_with_many_pins_is_bounded_as_dense():
    check_size(16000, "hs", "projected_gradient", "tree")  # no dense matrix without pins
    check_size(16000, "hs", "projected_gradient", "tree", pinned=TREE_MAX_PINS)
    with pytest.raises(ValueError, match=f"or pin at most {TREE_MAX_PINS} vertices: with "
                                         f"more the tree engine solves with a dense matrix"):
        check_size(16000, "hs", "projected_gradient", "tree", pinned=TREE_MAX_PINS + 1)


def test_tree_with_many_pins_solves_densely(trefoil60):
    free = list(range(3, 60, 6))[:60 - TREE_MAX_PINS - 1]  # single free vertices between pins
    pins = [v for v in range(60) if v not in free]
    assert len(pins) == TREE_MAX_PINS + 1
    run = make_run("projected_gradient", trefoil60, "hs", 3, 0.0, engine="tree", pinned=pins)
    while run.step():
        pass
    assert run.nit == 3, run.message
    assert np.array_equal(run.x[pins], trefoil60[pins])
    assert run.engine.solver.n_factor > 0  # the dense solver ran
    assert run.history["energy"][-1] < run.history["energy"][0]


# -- the tree engine's bordered solvers against the dense elimination -----------------------

@pytest.mark.parametrize("metric", ["l2", "h1", "h2"])
def test_bordered_banded_solve_is_the_dense_elimination(trefoil60, metric):
    X, lay = as_layout(trefoil60)
    pins = np.array(PINS)
    jac = jacobian(X, make_constraints(X, lay, lengths(X, lay), pinned=pins))
    dense = Factorization(gram_x(metric, X, lay), jac)
    bordered = BorderedPins(BandedSaddle(banded_parts(metric, X, lay), unpinned_jacobian(jac)),
                            jac)
    rng = np.random.default_rng(3)
    g = rng.standard_normal((lay.n, 3))
    r = 1e-3 * rng.standard_normal(jac.con.size)
    for (u1, l1), (u2, l2) in [(dense.solve(g, r), bordered.solve(g, r)),
                               ((dense.pseudo_inverse(r), 0), (bordered.pseudo_inverse(r), 0))]:
        np.testing.assert_allclose(u2, u1, atol=1e-10 * np.abs(u1).max())
        np.testing.assert_allclose(l2, l1, atol=1e-10 * np.abs(l1).max())
        assert np.all(u2[pins] == 0.0)


def test_banded_solve_many_is_solve_for_each(trefoil60):
    X, lay = as_layout(trefoil60)
    jac = jacobian(X, make_constraints(X, lay, lengths(X, lay)))
    band = BandedSaddle(banded_parts("h2", X, lay), jac)
    rng = np.random.default_rng(5)
    G = rng.standard_normal((3, lay.n, 3))
    R = rng.standard_normal((3, jac.con.size))
    U, L = band.solve_many(G, R)
    for q in range(3):
        u, lam = band._solve(G[q], R[q])
        np.testing.assert_allclose(U[q], u, rtol=1e-12, atol=1e-12 * np.abs(u).max())
        np.testing.assert_allclose(L[q], lam, rtol=1e-12, atol=1e-12 * np.abs(lam).max())


def test_hs_krylov_solve_with_pins_is_the_dense_elimination(trefoil60):
    X, lay = as_layout(trefoil60)
    pins = np.array(PINS)
    jac = jacobian(X, make_constraints(X, lay, lengths(X, lay), pinned=pins))
    op = HsOperator(X, lay, "hs")
    A = np.stack([op.product(np.outer(np.eye(lay.n)[i], [1.0, 0, 0]))[:, 0]
                  for i in range(lay.n)], axis=1)  # the tree's metric Ã as a matrix
    dense = Factorization(0.5 * (A + A.T), jac)
    hs = HsSaddle(op, jac, rtol=1e-12, X=X)
    g = np.random.default_rng(4).standard_normal((lay.n, 3))
    u1, _ = dense.solve(g, np.zeros(jac.con.size))
    u2, _ = hs.solve(g, np.zeros(jac.con.size))
    np.testing.assert_allclose(u2, u1, atol=1e-8 * np.abs(u1).max())
    assert np.all(u2[pins] == 0.0)
