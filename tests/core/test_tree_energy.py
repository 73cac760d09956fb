"""The tree engine's energy and gradient (core/barnes_hut.py): against a slow numpy version of
the same approximated sum, against the exact sum, against its own finite differences, and
bitwise across thread counts."""

import numpy as np
import pytest

from moebius_addon import core
from moebius_addon.core.energies.moebius_dense import energy_gradient_x
from moebius_addon.core.geometry.layout import as_layout
from moebius_addon.core.runs.engine import FRAME_REUSE, GRADIENT_REUSE, TreeEngine
from moebius_addon.core.tree import moebius as bh
from tests.conftest import ngon, out_here_and_in_one_thread, trefoil


def _taylor(f, d, u, points=64):
    """Σ over the pairs of the Taylor polynomial of ``t ↦ f(d + t u)`` to second order at t = 1,
    its coefficients by Cauchy's formula on a circle inside the radius of convergence
    ``|d| / |u|`` (f is rational in d; independent of the expansion's closed forms)."""
    radius = 0.5 * np.sqrt(d @ d) / np.sqrt((u * u).sum(axis=-1)).max()
    z = radius * np.exp(2j * np.pi * np.arange(points) / points)
    vals = f(d + z[:, None, None, None] * u)  # (points, edges of A, edges of B)
    total = 0.0
    for n in range(3):
        total += (np.tensordot(z**-n, vals, axes=1).sum() / points).real
    return total


def slow_frame_energy(X, layout, frame):
    """The approximated sum of a frame, literally: every near pair with docs/design.md's kernel,
    every far pair of clusters ``(A, B)`` with the kernel of each pair of edges ``(I, J)``
    expanded to second order in ``u = δ_I − δ_J`` around the centres' difference ``d``."""
    tree = frame.tree
    perm = tree.perm
    nxt = layout.nxt
    e = X[nxt] - X
    m = 0.5 * (X + X[nxt])
    ln = np.linalg.norm(e, axis=1)
    comp = layout.comp
    starts = layout.starts

    def disjoint(i, j):
        if comp[i] != comp[j]:
            return True
        size = starts[comp[i] + 1] - starts[comp[i]]
        gap = (j - i) % size
        return gap not in (0, 1, size - 1)

    def f(i, j):
        d = m[i] - m[j]
        r2 = d @ d
        if comp[i] != comp[j]:
            return ln[i] * ln[j] / r2
        return (ln[i] * ln[j] + e[i] @ e[j]) / r2 - 2 * (d @ e[i]) * (d @ e[j]) / r2**2

    def cluster(a):
        idx = perm[tree.lo[a]:tree.hi[a]]
        c = (ln[idx, None] * m[idx]).sum(axis=0) / ln[idx].sum()
        return idx, m[idx] - c, c, set(comp[idx])

    total = 4.0 * layout.k
    for a, b in frame.near:  # unordered pairs of leaves
        for i in perm[tree.lo[a]:tree.hi[a]]:
            for j in perm[tree.lo[b]:tree.hi[b]]:
                if disjoint(i, j):
                    total += f(i, j) if a == b else f(i, j) + f(j, i)
    for a in range(tree.size):
        for p in range(frame.foff[a], frame.foff[a + 1]):
            b = frame.fpart[p]
            ia, da, ca, ka = cluster(a)
            ib, db, cb, kb = cluster(b)
            assert len(ka) == 1 and len(kb) == 1
            ll = ln[ia, None] * ln[ib]
            ee = e[ia] @ e[ib].T

            def kernel(x, ll=ll, ee=ee, ea=e[ia], eb=e[ib], same=ka == kb):
                r2 = (x * x).sum(axis=-1)  # complex x: no conjugate (analytic in t)
                if not same:
                    return ll / r2
                xa = np.einsum("pijk,ik->pij", x, ea)
                xb = np.einsum("pijk,jk->pij", x, eb)
                return (ll + ee) / r2 - 2 * xa * xb / r2**2

            total += _taylor(kernel, ca - cb, da[:, None] - db[None, :])
    return total


def _perturbed_trefoil(n, rng, noise=0.05):
    P = core.resample(trefoil(400), n)
    return P + noise * np.linalg.norm(P[1] - P[0]) * rng.standard_normal(P.shape)


def _link():
    return [ngon(40), ngon(44)[:, [0, 2, 1]] + [1.0, 0.0, 0.0], ngon(36) * 0.5 + [0, 0, 3.0]]


@pytest.mark.parametrize("which, leaf_size", [("knot", 4), ("link", 4), ("knot", 12)])
def test_frame_matches_slow_reference(which, leaf_size, rng):
    # leaves of 4 edges fill half the near field's 8 lanes, of 12 one block of 8 and one of 4
    P = _perturbed_trefoil(90 * leaf_size // 4, rng) if which == "knot" else _link()
    X, layout = as_layout(P)
    frame = bh.Frame(X, layout, theta=0.6, leaf_size=leaf_size, keep_near=True)
    assert frame.far_pairs > 10  # the test covers the far field
    assert frame.energy(X) == pytest.approx(slow_frame_energy(X, layout, frame), rel=1e-9)


@pytest.mark.parametrize("which", ["knot", "link"])
def test_gradient_is_derivative_of_the_approximated_sum(which, rng):
    P = _perturbed_trefoil(300, rng) if which == "knot" else _link()
    X, layout = as_layout(P)
    frame = bh.Frame(X, layout, theta=0.5, leaf_size=8)
    E, G = frame.energy_gradient(X)
    assert E == pytest.approx(frame.energy(X), rel=1e-13)
    h = 1e-6 * np.linalg.norm(X[1] - X[0])
    for _ in range(3):
        V = rng.standard_normal(X.shape)
        fd = (frame.energy(X + h * V) - frame.energy(X - h * V)) / (2 * h)
        assert np.sum(G * V) == pytest.approx(fd, rel=1e-6)
    # and per coordinate on a few vertices
    for v in rng.choice(len(X), 4, replace=False):
        for k in range(3):
            Y = X.copy()
            Y[v, k] += h
            ep = frame.energy(Y)
            Y[v, k] -= 2 * h
            assert G[v, k] == pytest.approx((ep - frame.energy(Y)) / (2 * h), rel=1e-5,
                                            abs=1e-6 * np.abs(G).max())


@pytest.mark.parametrize("name", ["fhw", "7_2", "noneq", "link"])
def test_tree_close_to_exact(name, rng):
    if name == "fhw":
        P = core.knots.freedman_unknot(3000)
    elif name == "7_2":
        P = core.resample(core.knots.named("7_2"), 3000)
    elif name == "noneq":
        P = _perturbed_trefoil(3000, rng, noise=0.2)
    else:
        P = core.resample([ngon(400), ngon(400)[:, [0, 2, 1]] + [1.0, 0.0, 0.0],
                           ngon(400) + [0.0, 0.0, 2.5]], 3000)
    E0 = core.moebius_energy(P, engine="exact")
    G0 = core.moebius_gradient(P, engine="exact")
    G0 = np.concatenate(G0) if name == "link" else G0
    E1 = core.moebius_energy(P, engine="tree")
    G1 = core.moebius_gradient(P, engine="tree")
    G1 = np.concatenate(G1) if name == "link" else G1
    # the default theta's accuracy as measured at this size: energy 9.8e-7 (FHW) to 8.1e-6
    # (link), gradient 3.7e-6 (noneq) to 4.2e-4 (FHW)
    assert abs(E1 - E0) / E0 < 2e-5
    assert np.linalg.norm(G1 - G0) / np.linalg.norm(G0) < 8e-4


def test_small_theta_converges_to_exact(rng):
    P = _perturbed_trefoil(1200, rng)
    E0 = core.moebius_energy(P)
    errors = [abs(core.moebius_energy(P, engine="tree", theta=t) - E0) / E0
              for t in (1.0, 0.5, 0.25)]
    assert errors[0] > errors[1] > errors[2]


@pytest.mark.parametrize("scale", [2.0**-900, 1e-30, 1e30, 2.0**900])
def test_tree_scale_free(scale, rng):
    P = _perturbed_trefoil(600, rng)
    E = core.moebius_energy(P, engine="tree")
    G = core.moebius_gradient(P, engine="tree")
    assert core.moebius_energy(P * scale, engine="tree") == pytest.approx(E, rel=1e-12)
    Gs = core.moebius_gradient(P * scale, engine="tree")
    assert np.allclose(Gs * scale, G, rtol=1e-10, atol=1e-10 * np.abs(G).max())


@pytest.mark.parametrize("theta", [0.05, 1.0, 1.99])
def test_neighbours_always_near(theta, rng):
    # admissible boxes never touch: edges sharing a vertex stay in the exact near field
    P = _perturbed_trefoil(500, rng)
    X, layout = as_layout(P)
    frame = bh.Frame(X, layout, theta=theta, leaf_size=4)
    tree = frame.tree
    n = len(X)
    for a in range(tree.size):
        A = set(tree.perm[tree.lo[a]:tree.hi[a]])
        for p in range(frame.foff[a], frame.foff[a + 1]):
            b = frame.fpart[p]
            for j in tree.perm[tree.lo[b]:tree.hi[b]]:
                assert not A & {(j - 1) % n, j, (j + 1) % n}
    assert np.isfinite(core.moebius_energy(ngon(2000), engine="tree", theta=theta))


@pytest.mark.parametrize("theta", [float("nan"), -0.1, 0.0, 2.0, 5.0, "a", None])
def test_bad_theta_refused(theta):
    P = ngon(50)
    if theta is None:
        assert core.moebius_energy(P, engine="tree", theta=None) > 0  # None: the default
        return
    with pytest.raises(ValueError, match="theta"):
        core.moebius_energy(P, engine="tree", theta=theta)
    with pytest.raises(ValueError, match="theta"):
        core.moebius_gradient(P, engine="tree", theta=theta)


def test_bad_engine_refused():
    with pytest.raises(ValueError, match="engine"):
        core.moebius_energy(ngon(50), engine="fast")


def test_auto_switches_at_crossover():
    from moebius_addon.core.runs import engine

    # the energy alone, and runs (earlier): both thresholds in engine.py
    assert not engine.uses_tree("auto", engine.ENERGY_TREE_FROM - 1)
    assert engine.uses_tree("auto", engine.ENERGY_TREE_FROM)
    assert not engine.uses_tree("auto", engine.AUTO_TREE_FROM - 1, run=True)
    assert engine.uses_tree("auto", engine.AUTO_TREE_FROM, run=True)
    assert (engine.ENERGY_TREE_FROM, engine.AUTO_TREE_FROM) == (3000, 1000)
    assert engine.uses_tree("tree", 10) and not engine.uses_tree("exact", 10**6)
    with pytest.raises(ValueError, match="choose one of auto, exact, tree"):
        engine.uses_tree("fast", 10)


def test_same_function_as_exact_where_everything_is_near():
    # a tiny polygon is one leaf: the tree sums every pair exactly
    P = trefoil(12)
    X, layout = as_layout(P)
    E0, G0 = energy_gradient_x(X, layout)
    E1, G1 = bh.Frame(X, layout).energy_gradient(X)
    assert E1 == pytest.approx(E0, rel=1e-13)
    assert np.allclose(G1, G0, rtol=1e-12, atol=1e-12 * np.abs(G0).max())


CODE = """
import json, numpy as np
from moebius_addon.core.tree import moebius as bh
from moebius_addon.core.geometry.layout import as_layout
rng = np.random.default_rng(5)
# a (2, 5) torus knot made with numpy alone: only the tree's kernels run
t = np.linspace(0, 2 * np.pi, 4000, endpoint=False)
r = 2 + np.cos(5 * t)
P = np.c_[r * np.cos(2 * t), r * np.sin(2 * t), np.sin(5 * t)]
P += 1e-3 * rng.standard_normal((4000, 3))
X, layout = as_layout(P)
E, G = bh.Frame(X, layout).energy_gradient(X)
OUT = [E.hex(), G.tobytes().hex()]
"""


def test_bitwise_identical_across_thread_counts():
    # this process evaluates with all its threads, with the kernels it compiled (in CI, from an
    # empty cache) or loaded; a second process with one thread loads them from the cache this
    # one wrote: the same bits for a first run and later runs, for any thread count (with
    # fast-math the far field differed). Compiling into a fresh cache in a subprocess instead
    # cost 60-70 s.
    here, there = out_here_and_in_one_thread(CODE)
    assert there == here


def test_trial_energy_keeps_the_iterates_split_nearby(rng):
    # a line search's trial within FRAME_REUSE edge lengths takes the split of the iterate whose
    # gradient was evaluated last, within GRADIENT_REUSE with its gradient in the same pass
    # (what energy_gradient then returns for it, without a new frame); farther, a split built
    # where it is
    X, layout = as_layout(_perturbed_trefoil(600, rng))
    engine = TreeEngine(layout, "h1")
    engine.energy_gradient(X)
    h = np.linalg.norm(X[layout.nxt] - X, axis=1).mean()
    V = rng.standard_normal(X.shape)
    V *= h / np.linalg.norm(V, axis=1).max()  # every vertex at most h
    frame = engine.energy_choice.frame(X, layout, engine.theta)
    assert GRADIENT_REUSE < FRAME_REUSE
    between = X + 0.5 * (GRADIENT_REUSE + FRAME_REUSE) * V
    assert engine.trial_energy(between) == frame.energy(between)
    near = X + 0.5 * GRADIENT_REUSE * V
    # a trial whose back-projection is unfinished: the energy alone, nothing kept
    assert engine.trial_energy(near, gradient=False) == frame.energy(near)
    assert engine._trial is None
    E, G = frame.energy_gradient(near)
    assert engine.trial_energy(near) == E
    E1, G1 = engine.energy_gradient(near)
    assert E1 == E and np.array_equal(G1, G)
    G1[0] += 1.0  # the caller's copy: the kept gradient is not changed through it
    assert np.array_equal(engine.energy_gradient(near)[1], G)
    nearer = X + 0.25 * GRADIENT_REUSE * V  # not a trial: the kept split, a pass of its own
    assert np.array_equal(engine.energy_gradient(nearer)[1], frame.energy_gradient(nearer)[1])
    far = X + 3.0 * FRAME_REUSE * V
    assert engine.trial_energy(far) == engine.energy_choice.frame(far, layout,
                                                                  engine.theta).energy(far)
    engine = TreeEngine(layout, "h1")  # (reach counts edge lengths of the frame's polygon)
    engine.energy_gradient(X)
    beyond = X + 3.0 * GRADIENT_REUSE * V
    E, G = engine.energy_gradient(beyond)
    Ef, Gf = engine.energy_choice.frame(beyond, layout, engine.theta).energy_gradient(beyond)
    assert E == Ef and np.array_equal(G, Gf)


def test_split_that_runs_out_of_room_gives_the_same_lists():
    # a chunk whose buffer fills has every chunk split again with twice the room (rare since
    # the room is 12 m/θ): from a room of 1 pair the same far and near lists as with room to
    # spare
    from moebius_addon.core.tree import bvh

    P = trefoil(2400) + 0.002 * np.random.default_rng(5).standard_normal((2400, 3))
    X, layout = as_layout(P)
    frame = bh.Frame(X, layout, theta=0.5, keep_near=True)
    tree = frame.tree
    bmin, bmax = bvh.segment_boxes(tree, X, layout)
    nc = frame._clusters(frame._edges(X))[-1]
    masks = bh.open_masks(layout, tree)
    lists = [bh._split(tree.left, tree.right, bmin, bmax, nc, 0.25, masks, 16, 64 * 16, cap)
             for cap in (1, 10**5)]
    assert lists[0][1].shape[0] == frame.near_pairs > 1000
    for small, roomy in zip(*lists, strict=True):
        assert small.shape[0] > 1000 and np.array_equal(small, roomy)
