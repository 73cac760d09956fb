"""The hs metric on the tree (core/hs_tree.py): the hierarchy of arcs, the operator against a
slow numpy version of the same approximated matrix and against the dense Gram matrix, the
preconditioned Krylov solves against dense solves, and the flow on the tree path."""

import os

import numpy as np
import pytest

from moebius_addon import core
from moebius_addon.core.geometry.constraints import jacobian, make_constraints, residual
from moebius_addon.core.geometry.layout import as_layout
from moebius_addon.core.metrics import hs_solve
from moebius_addon.core.metrics.gram import gram_x
from moebius_addon.core.tree import hs_metric as hs_tree
from tests.conftest import ngon, out_here_and_in_one_thread, trefoil


def _unit(P):
    """Stacked vertices scaled to total length 1 (the runs' scale) and the layout."""
    X, lay = as_layout(P)
    return X / np.linalg.norm(X[lay.nxt] - X, axis=1).sum(), lay


def _link(n):
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    ring = np.c_[np.cos(t), np.sin(t), 0 * t]
    return [ring, ring[:, [0, 2, 1]] + [1.2, 0, 0], ring + [2.4, 0, 0]]


CURVES = {
    "trefoil": lambda: core.resample(trefoil(300), 240),
    "fhw": lambda: core.knots.freedman_unknot(600),
    "link": lambda: core.resample(_link(200), [90, 80, 70]),
    "noneq": lambda: trefoil(200),  # equal parameter steps: edges of different lengths
}


def slow_matrix(X, lay, op):
    """``Ã`` literally, from the operator's lists of near and far pairs: exact weights for every
    pair of edges of a near pair of leaves, one weight from the clusters' centres for every pair
    of edges of a far pair of clusters; then docs/design.md's formula."""
    n = lay.n
    tree = op.tree
    nxt = lay.nxt
    ln = np.linalg.norm(X[nxt] - X, axis=1)
    mid = 0.5 * (X + X[nxt])
    arc = np.empty(n)
    clen = np.empty(lay.k)
    for c in range(lay.k):
        s = slice(lay.starts[c], lay.starts[c + 1])
        arc[s] = np.cumsum(ln[s]) - 0.5 * ln[s]
        clen[c] = ln[s].sum()
    comp = lay.comp
    pos = np.arange(n) - lay.starts[comp]
    size = lay.starts[comp + 1] - lay.starts[comp]

    def exact(q, r):
        if comp[q] == comp[r]:
            gap = (pos[r] - pos[q]) % size[q]
            if gap in (0, 1, size[q] - 1):
                return 0.0, 0.0
            d2 = np.sum((mid[q] - mid[r]) ** 2)
            fwd = abs(arc[r] - arc[q])
            rho = min(fwd, clen[comp[q]] - fwd)
            w = ln[q] * ln[r] / d2
            return w, op.low * w * (1 / d2 - 1 / rho**2)
        d2 = np.sum((mid[q] - mid[r]) ** 2)
        w = ln[q] * ln[r] / d2
        return w, op.low * w / d2

    def node(a):
        idx = np.arange(tree.lo[a], tree.hi[a])
        L = ln[idx].sum()
        c = (ln[idx, None] * mid[idx]).sum(0) / L
        s = 0.5 * ((arc[idx[0]] - 0.5 * ln[idx[0]]) + (arc[idx[-1]] + 0.5 * ln[idx[-1]]))
        return idx, c, s

    W = np.zeros((n, n))
    V = np.zeros((n, n))
    seen = np.zeros((n, n), int)
    for a in range(tree.size):
        for p in range(op.noff[a], op.noff[a + 1]):
            b = op.npart[p]
            for q in range(tree.lo[a], tree.hi[a]):
                for r in range(tree.lo[b], tree.hi[b]):
                    W[q, r], V[q, r] = exact(q, r)
                    seen[q, r] += 1
        for p in range(op.foff[a], op.foff[a + 1]):
            b = op.fpart[p]
            ia, ca, sa = node(a)
            ib, cb, sb = node(b)
            inv = 1.0 / np.sum((ca - cb) ** 2)
            if comp[ia[0]] == comp[ib[0]]:
                fwd = abs(sa - sb)
                rho = min(fwd, clen[comp[ia[0]]] - fwd)
                v = op.low * inv * max(0.0, inv - 1 / rho**2)
            else:
                v = op.low * inv * inv
            W[np.ix_(ia, ib)] = np.outer(ln[ia], ln[ib]) * inv
            V[np.ix_(ia, ib)] = np.outer(ln[ia], ln[ib]) * v
            seen[np.ix_(ia, ib)] += 1
    assert (seen == 1).all()  # the split covers every ordered pair of edges exactly once
    i = np.arange(n)
    D = np.zeros((n, n))
    M = np.zeros((n, n))
    D[i, i], D[i, nxt] = -1 / ln, 1 / ln
    M[i, i], M[i, nxt] = 0.5, 0.5
    A = 2 * D.T @ (np.diag(W.sum(1)) - W) @ D + 2 * M.T @ (np.diag(V.sum(1)) - V) @ M
    total = ln.sum()
    b = 0.5 * (ln[lay.prv] + ln) * np.sqrt(n) / total**2
    for c in range(lay.k):
        s = slice(lay.starts[c], lay.starts[c + 1])
        A[s, s] += np.outer(b[s], b[s])
    if op.metric == "hs_pure":
        mass = np.zeros((n, n))
        np.add.at(mass, (i, i), ln / 3)
        np.add.at(mass, (nxt, nxt), ln / 3)
        np.add.at(mass, (i, nxt), ln / 6)
        np.add.at(mass, (nxt, i), ln / 6)
        A += hs_tree._PURE_L2 * mass / total**3
    return A


def test_arcs_of_the_hierarchy():
    P = [ngon(37), ngon(5), ngon(120)]
    X, lay = as_layout(P)
    tree = hs_tree.arc_tree(lay, 8)
    assert np.array_equal(tree.perm, np.arange(lay.n))
    for a in range(tree.size):
        lo, hi = tree.lo[a], tree.hi[a]
        comps = set(lay.comp[lo:hi])
        if tree.left[a] < 0:
            assert hi - lo <= 8 and len(comps) == 1  # a leaf: a short arc of one component
        else:
            left, right = tree.left[a], tree.right[a]
            assert left > a and right > a  # parents first
            assert (tree.lo[left], tree.hi[left], tree.hi[right]) == (lo, tree.lo[right], hi)
            if len(comps) > 1:  # several components are split at one of their boundaries
                assert tree.hi[left] in lay.starts


def _one_walk(left, right, bmin, bmax, nc, s0, s1, clen, closed, theta2):
    """The split as one depth-first walk from (root, root) in plain Python
    (:func:`bvh.dual_traversal`'s order: the last pair pushed is taken first)."""
    from moebius_addon.core.tree import bvh

    diam2 = bvh.node_diam2(bmin, bmax)
    ctx = (bmin, bmax, diam2, nc, s0, s1, clen, closed, theta2)
    far, near, stack = [], [], [(0, 0)]
    while stack:
        a, b = stack.pop()
        if hs_tree._split_test(a, b, ctx, None) == bvh.ACCEPT:
            far.append((a, b))
        elif left[a] < 0 and left[b] < 0:
            near.append((a, b))
        else:
            tmp, top = bvh.push_split(np.empty((4, 2), np.int64), 0, a, b, left, right, diam2)
            stack += [tuple(p) for p in tmp[:top]]
    return np.array(far).reshape(-1, 2), np.array(near).reshape(-1, 2)


@pytest.mark.parametrize("layout", ["fhw", "link", "cables"])
def test_parallel_split_gives_the_one_walks_lists(layout):
    # the walks from a frontier of pairs, dealt to chunks that run out of room and go on
    # (rows for 64 pairs at the start), gathered: the lists of one walk, pair for pair
    from moebius_addon.core.tree import bvh

    if layout == "cables":
        t = np.linspace(0, 1, 31)
        P = [np.c_[0.03 * (c % 7) + 0.01 * np.sin(7 * t + c), 0.03 * (c // 7) + 0 * t, t]
             for c in range(40)]
        X, lay = as_layout(P, closed=False)
    else:
        X, lay = _unit(core.knots.freedman_unknot(3000) if layout == "fhw"
                       else core.resample(_link(900), [1200, 900, 700]))
    tree = hs_tree.arc_tree(lay)
    ln, mid, arc, clen = hs_tree._edge_data(X, lay.nxt, lay.starts)
    nc, _, _, s0, s1 = hs_tree._node_data(ln, mid, arc, lay.starts, tree.lo, tree.hi,
                                          tree.left, tree.right)
    bmin, bmax = bvh.segment_boxes(tree, X, lay)
    closed = np.ones(lay.k, np.bool_) if lay.closed is None else lay.closed
    args = (tree.left, tree.right, bmin, bmax, nc, s0, s1, clen, closed, 0.25)
    far, near = _one_walk(*args)
    assert far.shape[0] > 1000 and near.shape[0] > 1000
    for chunks, tasks in ((1, 1), (1, 64), (32, 1024), (7, 50)):
        f, n = hs_tree._split(*args, chunks, tasks)
        assert np.array_equal(f, far) and np.array_equal(n, near), (chunks, tasks)


@pytest.mark.parametrize("name", list(CURVES))
@pytest.mark.parametrize("metric", ["hs", "hs_pure"])
def test_operator_is_the_approximated_matrix(name, metric, rng):
    X, lay = _unit(CURVES[name]())
    op = hs_tree.HsOperator(X, lay, metric, theta=0.5)
    A = slow_matrix(X, lay, op)
    U = rng.standard_normal((lay.n, 3))
    assert np.allclose(op.product(U), A @ U, rtol=0, atol=1e-11 * np.abs(A @ U).max())
    assert np.allclose(op.diagonal(), np.diag(A), rtol=1e-12)
    # symmetric, positive definite: the structure of the exact matrix is kept
    assert np.allclose(A, A.T, rtol=0, atol=1e-12 * np.abs(A).max())
    assert np.linalg.eigvalsh(A)[0] > 0


@pytest.mark.parametrize("name", list(CURVES))
def test_operator_against_the_dense_gram_matrix(name, rng):
    X, lay = _unit(CURVES[name]())
    A = gram_x("hs", X, lay)
    U = rng.standard_normal((lay.n, 3))
    exact = A @ U
    # every pair near: the exact matrix to rounding
    op = hs_tree.HsOperator(X, lay, "hs", theta=1e-9)
    assert op.far_pairs == 0
    assert np.allclose(op.product(U), exact, rtol=0, atol=1e-11 * np.abs(exact).max())
    # the default far field: relative errors of products below 2e-2 (measured at most 1.0e-2
    # on random fields, docs/lab/tree-engine.md), falling with theta
    errors = []
    for theta in (hs_tree.THETA, 0.25):
        op = hs_tree.HsOperator(X, lay, "hs", theta=theta)
        errors.append(np.linalg.norm(op.product(U) - exact) / np.linalg.norm(exact))
    assert errors[0] < 2e-2 and errors[1] < errors[0]


def _dense_saddle(A, jac, g, r):
    n = A.shape[0]
    m = jac.con.size
    C = np.column_stack([jac.matvec(e.reshape(n, 3)) for e in np.eye(3 * n)])
    K = np.zeros((3 * n + m, 3 * n + m))
    K[:3 * n, :3 * n] = np.kron(A, np.eye(3))
    K[3 * n:, :3 * n] = C
    K[:3 * n, 3 * n:] = C.T
    x = np.linalg.solve(K, np.concatenate([g.ravel(), r]))
    return x[:3 * n].reshape(n, 3), x[3 * n:]


@pytest.mark.parametrize("name", ["trefoil", "link"])
def test_krylov_solves_against_a_dense_solve(name, rng):
    X, lay = _unit(CURVES[name]())
    ln = np.linalg.norm(X[lay.nxt] - X, axis=1)
    con = make_constraints(X, lay, ln)
    jac = jacobian(X, con)
    op = hs_tree.HsOperator(X, lay, "hs")
    A = slow_matrix(X, lay, op)
    g = rng.standard_normal((lay.n, 3))
    r = 1e-3 * rng.standard_normal(con.size)
    solver = hs_solve.HsSaddle(op, jac)
    _check_solves(solver, A, jac, g, r, con)
    # the same with the preconditioner's coarse level (a quarter of the vertices)
    coarse = hs_solve.HsSaddle(op, jac, X=X, coarse=lay.n // 4)
    assert coarse.coarse is not None
    _check_solves(coarse, A, jac, g, r, con)
    # back-projection steps: onto C d = φ, in the preconditioner's metric or in Ã's
    phi = residual(X + 1e-3 * rng.standard_normal(X.shape) * ln.mean(), con)
    for exact in (False, True):
        solver.exact_backprojection = exact
        d = solver.pseudo_inverse(phi)
        assert np.abs(jac.matvec(d) - phi).max() < 1e-10 * np.abs(phi).max()
    assert solver.iterations and max(solver.iterations) < 100


def _check_solves(solver, A, jac, g, r, con):
    for rtol, tol in ((1e-8, 1e-6), (1e-2, 3e-2)):
        for rhs in ((g, np.zeros(con.size)), (g, r), (0 * g, r)):
            u0, lam0 = _dense_saddle(A, jac, *rhs)
            u, lam = solver.solve(*rhs, rtol=rtol)
            assert np.abs(jac.matvec(u) - rhs[1]).max() < 1e-9 * max(1.0, np.abs(r).max())
            assert np.linalg.norm(u - u0) <= tol * np.linalg.norm(u0)
            if rtol == 1e-8:
                assert np.allclose(lam, lam0, rtol=0, atol=1e-6 * np.abs(lam0).max())


def test_coarse_level_interpolates_along_the_curve(rng):
    X, lay = _unit(CURVES["link"]())
    ln = np.linalg.norm(X[lay.nxt] - X, axis=1)
    jac = jacobian(X, make_constraints(X, lay, ln))
    op = hs_tree.HsOperator(X, lay, "hs")
    level = hs_solve.HsSaddle(op, jac, X=X, coarse=60).coarse
    Uc = rng.standard_normal((level.n, 3))
    R = rng.standard_normal((lay.n, 3))
    # restriction is the transpose of the interpolation
    assert np.isclose(np.sum(level.prolong(Uc) * R), np.sum(Uc * level.restrict(R)))
    # constants and the coarse polygon itself are interpolated exactly at coarse vertices
    assert np.allclose(level.prolong(np.ones((level.n, 3))), 1.0)
    # the correction lies on the constraints' tangent space
    w = level(R)
    assert np.abs(jac.matvec(w)).max() < 1e-10 * np.abs(w).max() / ln.mean()


def test_tree_flow_ends_at_the_circle_like_the_exact_flow():
    P = core.knots.freedman_unknot(600)
    exact = core.relax(P, max_iter=400, energy_target=4.01, engine="exact")
    tree = core.relax(P, max_iter=400, energy_target=4.01, engine="tree")
    assert tree.success and tree.fun <= 4.01 and tree.stats["engine"] == "tree"
    assert abs(tree.nit - exact.nit) <= 0.2 * exact.nit  # measured 194 against 177
    assert np.all(np.diff(tree.history["energy"]) <= 0)  # the tree's own energy never rises
    assert max(tree.history["constraint_residual"]) <= 1e-10
    its = tree.stats["krylov_iterations"]
    assert len(its) == tree.nit + 1 and 0 < np.mean(its) < 30  # measured 9.5 per solve


@pytest.mark.parametrize("method", core.METHODS)
def test_every_method_runs_on_the_tree_or_says_what_does(method):
    P = core.resample(trefoil(300), 200)
    if method in ("ncg", "lbfgs", "nesterov"):  # a dense metric: refused past the dense size
        with pytest.raises(ValueError, match="feasible method"):
            core.check_size(20000, "hs", method, "tree")
    r = core.relax(P, method=method, max_iter=3, engine="tree")
    assert r.nit == 3 and r.fun < r.history["energy"][0]


CODE = """
import json, numpy as np
from moebius_addon import core
P = core.resample(core.knots.named("5_2"), 1500)
r = core.relax(P, max_iter=3, engine="tree")
OUT = [r.x.tobytes().hex(), r.stats["krylov_iterations"]]
"""


def test_tree_flow_bitwise_identical_across_thread_counts():
    # this process relaxes with all its threads (the kernels compiled here or loaded from the
    # cache); a second process with one thread loads them from the cache: the same iterates,
    # bit for bit. Two fresh processes (one per thread count) took 112 s, compiling twice.
    here, there = out_here_and_in_one_thread(CODE)
    assert there == here


def test_bad_krylov_tolerance_refused_by_name():
    P = core.resample(trefoil(300), 100)
    for bad in (0.0, 1.0, -1e-3, float("nan"), "x"):
        with pytest.raises(ValueError, match="krylov_rtol"):
            core.relax(P, max_iter=1, krylov_rtol=bad)


@pytest.mark.parametrize("preconditioner", hs_solve.PRECONDITIONERS)
def test_flow_with_the_coarse_level(monkeypatch, preconditioner):
    # the coarse levels start at 20 000 vertices; the same paths on a smaller curve
    monkeypatch.setattr(hs_solve, "PRECONDITIONER", preconditioner)
    monkeypatch.setattr(hs_solve, "COARSE_FROM", 1000)
    monkeypatch.setattr(hs_solve, "MULTILEVEL_FROM", 1000)
    P = core.resample(core.knots.named("5_2"), 2000)
    r = core.relax(P, max_iter=6, engine="tree")
    assert r.nit == 6 and np.all(np.diff(r.history["energy"]) < 0)
    assert max(r.history["constraint_residual"]) <= 1e-10
    assert max(r.stats["krylov_iterations"]) < 40


def test_hs_pure_flow_on_the_tree():
    P = core.resample(trefoil(300), 300)
    r = core.relax(P, metric="hs_pure", max_iter=4, engine="tree")
    assert r.nit == 4 and r.fun < r.history["energy"][0] and r.metric == "hs_pure"
    assert max(r.history["constraint_residual"]) <= 1e-10


def test_an_indefinite_coarse_level_is_dropped_not_followed(monkeypatch, rng):
    # a coarse level whose correction points against the residual (what a single-precision
    # coarse factorization did on a nearly relaxed 7_2): the solve goes on without it; a
    # preconditioner that gives NaN is an error, never a zero direction (which read as
    # "converged")
    X, lay = _unit(CURVES["trefoil"]())
    ln = np.linalg.norm(X[lay.nxt] - X, axis=1)
    con = make_constraints(X, lay, ln)
    jac = jacobian(X, con)
    op = hs_tree.HsOperator(X, lay, "hs")
    g = rng.standard_normal((lay.n, 3))
    good, _ = hs_solve.HsSaddle(op, jac).solve(g, np.zeros(con.size))
    solver = hs_solve.HsSaddle(op, jac, X=X, coarse=60)
    monkeypatch.setattr(hs_solve.CoarseLevel, "__call__", lambda self, R: -1e6 * R)
    u, _ = solver.solve(g, np.zeros(con.size))
    assert solver.coarse is None
    assert np.linalg.norm(u - good) < 1e-2 * np.linalg.norm(good)
    broken = hs_solve.HsSaddle(op, jac)
    monkeypatch.setattr(broken.K, "_solve", lambda R, r: (np.full_like(R, np.nan), 0 * r))
    with pytest.raises(np.linalg.LinAlgError, match="not positive definite"):
        broken.solve(g, np.zeros(con.size))


@pytest.mark.parametrize("metric", ["hs", "h2"])
def test_the_previous_iterates_solver_is_let_go_before_the_next_is_built(monkeypatch, metric):
    # built while the old solver was whole, two iterates' operators, coarse levels and band
    # fields were alive at once (+240 MB at the peak, 7_2 at 100 000 edges); only the band's
    # memory may pass on, and the old operator must be gone when the new one is built
    import weakref

    from moebius_addon.core.runs import engine as engines

    monkeypatch.setattr(hs_solve, "COARSE_FROM", 100)
    monkeypatch.setattr(hs_solve, "MULTILEVEL_FROM", 100)
    monkeypatch.setattr(hs_solve, "COARSEST", 100)
    P = core.resample(core.knots.named("5_2"), 400)
    X, lay = as_layout(P)
    jac = jacobian(X, make_constraints(X, lay, np.linalg.norm(X[lay.nxt] - X, axis=1)))
    eng = engines.make_engine("tree", lay, metric)
    eng.update(X, jac)
    old = eng._saddle
    band = old.K.ab if metric == "hs" else old.ab
    held = weakref.ref(old.op if metric == "hs" else old.Z)
    alive_at_build = []
    if metric == "hs":
        assert isinstance(old.coarse, hs_solve.Multilevel) and old.coarse.levels == 1
        levels = weakref.ref(old.coarse)

        class Spy(hs_tree.HsOperator):
            def __init__(self, *args, **kwargs):
                alive_at_build.append(held() is not None or levels() is not None)
                super().__init__(*args, **kwargs)

        monkeypatch.setattr(hs_tree, "HsOperator", Spy)
    else:
        real = engines.banded_parts

        def spy(*args):
            alive_at_build.append(held() is not None)
            return real(*args)

        monkeypatch.setattr(engines, "banded_parts", spy)
    eng.update(X, jac)
    assert alive_at_build == [False]
    new = eng._saddle
    assert (new.K.ab if metric == "hs" else new.ab) is band  # the band's memory passed on
    u, _ = eng.solve(-eng.energy_gradient(X)[1], np.zeros(jac.con.size))
    assert np.all(np.isfinite(u)) and np.abs(jac.matvec(u)).max() < 1e-8


def test_memory_does_not_grow_across_iterations(monkeypatch):
    # what one iteration holds is let go before the next: a tree run's memory after each of 16
    # iterations, past the first three (caches, the compiled kernels' buffers) — the Python and
    # numpy allocations (tracemalloc) and the process's resident set (numba's own allocations);
    # measured flat at 2 000 vertices: 7.57-7.67 MB traced and 226.3 MB resident at every
    # iteration (5_2, the coarse level on); here 1 200 vertices, where one vertex array kept per
    # iteration would add 0.23 MB over the second half, with the hierarchy of coarse levels on
    import tracemalloc

    monkeypatch.setattr(hs_solve, "MULTILEVEL_FROM", 600)
    P = core.resample(core.knots.named("5_2"), 1200)
    run = core.make_run("projected_gradient_implicit", P, "hs", 40, 1e-6, engine="tree",
                        refine=False)
    for _ in range(3):
        run.step()
    assert isinstance(run.engine._saddle.coarse, hs_solve.Multilevel)

    def resident_mb():
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1e6

    tracemalloc.start()
    try:
        seen = []
        for _ in range(16):
            run.step()
            seen.append((tracemalloc.get_traced_memory()[0] / 1e6, resident_mb()))
    finally:
        tracemalloc.stop()
    assert run.nit == 19 and not run.done
    traced, resident = np.array(seen).T
    assert traced[8:].max() - traced[:8].max() < 0.15
    assert resident[8:].max() - resident[:8].max() < 8.0


def _lean(monkeypatch, single: bool):
    """Lean iterations (engine.LEAN_FROM) from 0 vertices, single-precision weights or not, and
    a spy counting the solvers that let go of their operator."""
    from moebius_addon.core.runs import engine as engines

    monkeypatch.setattr(engines, "LEAN_FROM", 0)
    monkeypatch.setattr(engines, "LEAN_SHARE", 0.0)  # short of memory at any size
    monkeypatch.setattr(engines, "SINGLE_WEIGHTS_FROM", 0 if single else 10**12)
    monkeypatch.setattr(hs_solve, "MULTILEVEL_FROM", 600)
    shed = []
    real = hs_solve.HsSaddle.shed

    def spy(self):
        shed.append(real(self))
        return shed[-1]

    monkeypatch.setattr(hs_solve.HsSaddle, "shed", spy)
    return shed


def test_lean_iterations_are_the_same_iterates(monkeypatch):
    # letting go of the operator and the coarse levels after the direction's solve and of the
    # frame while the next solver is built must not change a bit: the frame a trial asks for
    # is built again at the same polygon, and nothing else is asked of the solver
    P = core.resample(core.knots.named("5_2"), 1200)
    monkeypatch.setattr(hs_solve, "MULTILEVEL_FROM", 600)
    whole = core.relax(P, max_iter=8, engine="tree")
    from moebius_addon.core.runs import engine as engines

    shed = _lean(monkeypatch, single=False)
    trims = []
    monkeypatch.setattr(engines, "give_back", lambda: trims.append(1))
    lean = core.relax(P, max_iter=8, engine="tree")
    assert shed and all(shed)  # every iterate's solver let go of its operator
    assert lean.stats["lean"] is True and "lean" not in whole.stats
    assert lean.nit == whole.nit == 8
    assert lean.x.tobytes() == whole.x.tobytes()
    assert lean.history["energy"] == whole.history["energy"]
    assert lean.stats["krylov_iterations"] == whole.stats["krylov_iterations"]
    # short of memory it also gave the heap's pages back; with memory to spare (the default
    # from LEAN_FROM on) it does not, and the iterates are the same
    assert len(trims) >= 8
    monkeypatch.setattr(engines, "LEAN_SHARE", 1e12)
    n_shed, n_trims = len(shed), len(trims)
    roomy = core.relax(P, max_iter=8, engine="tree")
    assert len(shed) > n_shed and len(trims) == n_trims
    assert roomy.stats["lean"] is True and roomy.x.tobytes() == whole.x.tobytes()


def test_a_shed_solver_is_built_again_for_a_later_solve(monkeypatch):
    # a solve after shed (a restart's nudge, another method's product) rebuilds the solver at
    # the same iterate: the same answer as before it was shed
    from moebius_addon.core.runs import engine as engines

    _lean(monkeypatch, single=False)
    P = core.resample(core.knots.named("5_2"), 800)
    X, lay = as_layout(P)
    jac = jacobian(X, make_constraints(X, lay, np.linalg.norm(X[lay.nxt] - X, axis=1)))
    eng = engines.make_engine("tree", lay, "hs")
    E, g = eng.energy_gradient(X)
    eng.update(X, jac)
    u0, lam0 = eng.solve(g, np.zeros(jac.con.size))
    Ag = eng.metric_product(g)
    eng.shed()
    assert eng._saddle.op is None and eng._saddle.coarse is None
    d = eng.pseudo_inverse(residual(X + 1e-3 * g, jac.con))  # the band alone still answers
    assert np.all(np.isfinite(d))
    u1, lam1 = eng.solve(g, np.zeros(jac.con.size))
    assert np.array_equal(u0, u1) and np.array_equal(lam0, lam1)
    eng.shed()
    assert np.array_equal(eng.metric_product(g), Ag)
    # exact back-projection solves with the operator: nothing is let go there
    eng = engines.make_engine("tree", lay, "hs", exact_backprojection=True)
    eng.update(X, jac)
    eng.shed()
    assert eng._saddle.op is not None


def test_single_precision_weights(rng):
    # half the operator's memory; products within rounding of the double ones, the same row
    # sums and banded preconditioner parts, and still symmetric
    P = core.knots.freedman_unknot(1500)
    X, lay = as_layout(P)
    a = hs_tree.HsOperator(X, lay)
    b = hs_tree.HsOperator(X, lay, single=True)
    assert b.w.dtype == np.float32 and a.w.dtype == np.float64
    assert b.w.nbytes + b.v.nbytes == (a.w.nbytes + a.v.nbytes) // 2
    U, V = rng.standard_normal((2, lay.n, 3))
    ya, yb = a.product(U), b.product(U)
    assert 0 < np.abs(yb - ya).max() <= 1e-6 * np.abs(ya).max()  # measured 8e-9 (FHW 5 000)
    for pa, pb in zip(a.preconditioner_parts(), b.preconditioner_parts(), strict=True):
        assert np.array_equal(pa, pb)
    uv, vu = np.sum(U * b.product(V)), np.sum(V * b.product(U))
    assert abs(uv - vu) <= 1e-12 * np.sqrt(np.sum(U * yb) * np.sum(V * b.product(V)))


def test_lean_run_with_single_weights_follows_the_double_run(monkeypatch):
    P = core.resample(core.knots.named("5_2"), 1200)
    monkeypatch.setattr(hs_solve, "MULTILEVEL_FROM", 600)
    whole = core.relax(P, max_iter=6, engine="tree")
    _lean(monkeypatch, single=True)
    lean = core.relax(P, max_iter=6, engine="tree")
    assert lean.nit == 6 and lean.x.tobytes() != whole.x.tobytes()
    # a Krylov solve stopped at its tolerance passes the metric's rounding-level change on,
    # amplified: measured 8.6e-7 relative in the energy, 1.7e-6 in the vertices
    e, f = np.array(lean.history["energy"]), np.array(whole.history["energy"])
    assert np.allclose(e, f, rtol=1e-5, atol=0)
    assert np.abs(lean.x - whole.x).max() <= 1e-5 * np.abs(whole.x).max()
    assert max(lean.history["constraint_residual"]) <= 1e-10


def test_a_run_is_lean_from_its_size_and_trims_where_memory_is_short(monkeypatch):
    from moebius_addon.core.runs import engine as engines

    assert engines.lean_run(engines.LEAN_FROM) and not engines.lean_run(engines.LEAN_FROM - 1)
    gb = 1e9
    monkeypatch.setattr(engines, "available_memory", lambda: 20 * gb)
    assert not engines.trim_run(engines.LEAN_FROM - 1)
    assert not engines.trim_run(10**6)  # 4.6 GB of 20 available
    assert engines.trim_run(3 * 10**6)  # 13.8 GB
    monkeypatch.setattr(engines, "available_memory", lambda: 8 * gb)
    assert engines.trim_run(10**6) and not engines.trim_run(5 * 10**5)
    monkeypatch.setattr(engines, "available_memory", lambda: None)  # the system does not say
    assert engines.trim_run(engines.LEAN_FROM) and not engines.trim_run(1000)
    from moebius_addon.core.runs.memory import available_memory

    assert available_memory() > 0


@pytest.mark.parametrize("name", ["fhw", "link", "noneq"])
def test_preconditioner_band_from_edges_is_the_band_from_triplets(name, rng):
    # the hs preconditioner's band filled vertex by vertex from one 2 × 2 block per edge
    # (banded.EdgeParts, in parallel) is the band of its triplets added in another order: the
    # same scaling, the same solves to rounding; without product=False it is refused
    from moebius_addon.core.metrics.banded import BandedSaddle, EdgeParts

    X, lay = _unit(CURVES[name]())
    jac = jacobian(X, make_constraints(X, lay, np.linalg.norm(X[lay.nxt] - X, axis=1)))
    op = hs_tree.HsOperator(X, lay)
    edges = op.preconditioner_edges()
    assert isinstance(edges, EdgeParts)
    a = BandedSaddle(op.preconditioner_parts(), jac, product=False)
    b = BandedSaddle(edges, jac, product=False)
    assert np.allclose(b.D, a.D, rtol=1e-14, atol=0)
    g = rng.standard_normal((lay.n, 3))
    r = rng.standard_normal(jac.con.size)
    for ua, ub in zip(a._solve(g, r), b._solve(g, r), strict=True):
        assert np.abs(ub - ua).max() <= 1e-11 * np.abs(ua).max()  # measured 2e-14-5e-14
    with pytest.raises(ValueError, match="product=False"):
        BandedSaddle(edges, jac)


def test_banded_back_projection_takes_a_fifth_more_steps():
    # the tree's hs back-projects in the preconditioner's banded metric, which contracts more
    # slowly than hs's own: its budget is backproject_iter plus a fifth (5 → 6 steps here), so
    # a trial needing 6 modified Newton steps passes and one needing 7 does not
    run = core.Relaxation(CURVES["trefoil"](), engine="tree", backproject_iter=5)
    assert run.engine.newton_steps(5) == 6 and run.engine.newton_steps(10) == 12

    def steps(Q):  # the modified Newton steps to the tolerance, each at least halving |Φ|
        prev = np.inf
        for i in range(40):
            size = float(np.abs(residual(Q, run.con)).max())
            if size <= run.backproject_tol:
                return i
            if not size < 0.5 * prev:
                return None
            prev = size
            Q = Q - run.engine.pseudo_inverse(residual(Q, run.con))
        return None

    trials = {}
    for tau in np.geomspace(0.5, 5.0, 60):
        trials.setdefault(steps(run.X - tau * run.u), tau)
    assert 6 in trials and 7 in trials
    assert run._backproject(run.X - trials[6] * run.u)[1]
    assert not run._backproject(run.X - trials[7] * run.u)[1]
    # the metric's own steps keep the run's budget: the exact engine, exact_backprojection,
    # and the banded metrics solved directly
    for engine, options in (("exact", {}), ("tree", {"exact_backprojection": True}),
                            ("tree", {"metric": "h2"})):
        other = core.Relaxation(CURVES["trefoil"](), engine=engine, **options)
        assert other.engine.newton_steps(10) == 10
