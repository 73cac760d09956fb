"""The edge hierarchy (core/bvh.py): its shape, its splits and its boxes."""

import time

import numpy as np
import pytest

from moebius_addon import core
from moebius_addon.core.geometry.layout import as_layout
from moebius_addon.core.tree import bvh


def _tree(P, leaf_size=bvh.LEAF_SIZE):
    X, layout = as_layout(P)
    return X, layout, bvh.build(X, layout, leaf_size)


@pytest.mark.parametrize("n, leaf_size", [(1, 8), (8, 8), (9, 8), (1000, 8), (1001, 4), (777, 12)])
def test_full_leaves_in_preorder(n, leaf_size, rng):
    P = rng.standard_normal((max(n, 3), 3))[:n] if n >= 3 else rng.standard_normal((3, 3))
    X, layout, tree = _tree(P, leaf_size)
    n = len(X)
    assert sorted(tree.perm) == list(range(n))
    leaves = np.flatnonzero(tree.left < 0)
    sizes = tree.hi[leaves] - tree.lo[leaves]
    k = -(-n // leaf_size)
    assert tree.size == 2 * k - 1 and len(leaves) == k
    # every leaf but the last in tree order is full
    last = leaves[np.argmax(tree.lo[leaves])]
    assert np.all(sizes[leaves != last] == leaf_size) and 1 <= tree.hi[last] - tree.lo[last]
    for node in np.flatnonzero(tree.left >= 0):
        a, b = tree.left[node], tree.right[node]
        assert a == node + 1 and b > a  # preorder: a parent before its children
        assert tree.lo[a] == tree.lo[node] and tree.hi[a] == tree.lo[b]
        assert tree.hi[b] == tree.hi[node]
        assert (tree.hi[a] - tree.lo[a]) % leaf_size == 0
        assert b - a == 2 * ((tree.hi[a] - tree.lo[a]) // leaf_size) - 1


def _ties():
    # midpoints in groups of equal x (and equal y in pairs): ties everywhere
    Y = np.zeros((40, 3))
    Y[:, 0] = np.repeat(np.arange(10.0), 4)
    Y[:, 1] = np.tile([0.0, 1.0, 1.0, 0.0], 10)
    return Y


@pytest.mark.parametrize("which", ["7_2", "ties"])
def test_split_at_a_quantile_of_the_longest_side(which):
    P = core.resample(core.knots.named("7_2"), 3000) if which == "7_2" else _ties()
    X, layout, tree = _tree(P, 8 if which == "7_2" else 4)
    mid = 0.5 * (X + X[layout.nxt])
    for node in np.flatnonzero(tree.left >= 0):
        a, b = tree.left[node], tree.right[node]
        m = mid[tree.perm[tree.lo[node]:tree.hi[node]]]
        axis = int(np.argmax(m.max(axis=0) - m.min(axis=0)))
        # the left child holds the smallest (coordinate, edge index): ties go by index
        left = [(mid[i, axis], i) for i in tree.perm[tree.lo[a]:tree.hi[a]]]
        right = [(mid[i, axis], i) for i in tree.perm[tree.lo[b]:tree.hi[b]]]
        assert max(left) < min(right)
    _, _, again = _tree(P.copy(), 8 if which == "7_2" else 4)
    for x, y in zip(tree, again, strict=True):
        np.testing.assert_array_equal(x, y)


def test_boxes_hold_their_edges(rng):
    P = core.knots.freedman_unknot(1184) + 1e-3 * rng.standard_normal((1184, 3))
    X, layout, tree = _tree(P)
    bmin, bmax = bvh.segment_boxes(tree, X, layout)
    for node in range(tree.size):
        idx = tree.perm[tree.lo[node]:tree.hi[node]]
        pts = np.vstack([X[idx], X[layout.nxt[idx]]])
        np.testing.assert_array_equal(bmin[node], pts.min(axis=0))
        np.testing.assert_array_equal(bmax[node], pts.max(axis=0))


def test_select_and_sort_order_by_key_then_index(rng):
    key = rng.integers(0, 5, 200).astype(float)  # many ties
    perm = rng.permutation(200)
    for k in (0, 1, 57, 199):
        kk, pp = key.copy(), perm.copy()
        bvh._select(kk, pp, 0, 200, k)
        assert sorted(zip(kk, pp, strict=True)) == sorted(zip(key, perm, strict=True))
        if k > 0:
            assert max(zip(kk[:k], pp[:k], strict=True)) < min(zip(kk[k:], pp[k:], strict=True))
    kk, pp = key.copy(), perm.copy()
    bvh._sort_range(kk, pp, 20, 180)
    assert list(zip(kk[20:180], pp[20:180], strict=True)) == sorted(
        zip(key[20:180], perm[20:180], strict=True))
    np.testing.assert_array_equal(kk[:20], key[:20])


def test_build_is_not_quadratic_on_a_circle():
    # the coordinates of a circle along an axis rise and fall: median-of-three pivots took
    # 1.8 s at 100 000 edges and 134 s at 10^6 (quadratic); pseudo-random pivots 12 and 160 ms
    t = np.linspace(0, 2 * np.pi, 300000, endpoint=False)
    X, layout = as_layout(np.c_[np.cos(t), np.sin(t), 0 * t])
    bvh.build(X[:100], as_layout(X[:100])[1])  # compiled
    t0 = time.perf_counter()
    bvh.build(X, layout)
    assert time.perf_counter() - t0 < 5.0
