"""The tree engine's near field (core/_near_field.py), which sums each unordered pair of edges
once: its rows per edge against a numpy sum over the frame's ordered near pairs of edges,
differentiated by complex steps, with one round of its buffer and with many; the same bits for
any thread count when there are many rounds."""

import numpy as np
import pytest

from moebius_addon import core
from moebius_addon.core import barnes_hut as bh
from moebius_addon.core._layout import as_layout
from moebius_addon.core._near_field import _near
from tests.conftest import out_here_and_in_one_thread, trefoil


def _scene(rng):
    """A closed knot, a ring around it and two open cables through it: pairs of one closed
    component, of one open one and of different components."""
    knot = core.resample(trefoil(300), 150) + 0.01 * rng.standard_normal((150, 3))
    s = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    ring = np.c_[3.0 * np.cos(s), 3.0 * np.sin(s), 0.3 * np.sin(2 * s)]
    t = np.linspace(0.0, 1.0, 81)[:, None]
    cables = [np.c_[-3 + 6 * t, 0.2 * k + 0.1 * np.sin(5 * t + k), 0.5 * np.cos(3 * t)]
              for k in range(2)]
    return [knot, ring, *cables], [True, True, False, False]


def _numpy_rows(X, layout, frame):
    """Per edge in tree order: ``Σ_J f(I, J)`` over the ordered near pairs and ``2 Σ_J ∂f/∂e_I``,
    ``2 Σ_J ∂f/∂m_I``, the derivatives by complex steps (f is analytic in e_I, m_I)."""
    tree = frame.tree
    perm = tree.perm
    e = (X[layout.nxt] - X)[perm]
    m = (0.5 * (X + X[layout.nxt]))[perm]
    edge = perm
    comp = layout.comp[perm]
    closed = layout.closed[comp]
    Q1, Q2 = [], []  # tree positions of the ordered pairs (I, J)
    for a, b in frame.near:  # unordered pairs of leaves, both directions
        qa = np.arange(tree.lo[a], tree.hi[a])
        qb = np.arange(tree.lo[b], tree.hi[b])
        i, j = np.meshgrid(qa, qb, indexing="ij")
        Q1.append(i.ravel())
        Q2.append(j.ravel())
        if a != b:
            Q1.append(j.ravel())
            Q2.append(i.ravel())
    Q1, Q2 = np.concatenate(Q1), np.concatenate(Q2)
    ei, ej = edge[Q1], edge[Q2]
    ok = (ei != ej) & (layout.nxt[ei] != ej) & (layout.prv[ei] != ej)
    Q1, Q2 = Q1[ok], Q2[ok]
    same = (comp[Q1] == comp[Q2]) & closed[Q1]

    def f(eI, mI):
        eJ, mJ = e[Q2], m[Q2]
        d = mI - mJ
        r2 = (d * d).sum(1)
        ll = np.sqrt((eI * eI).sum(1)) * np.sqrt((eJ * eJ).sum(1))
        full = (ll + (eI * eJ).sum(1)) / r2 - 2 * (d * eI).sum(1) * (d * eJ).sum(1) / r2**2
        return np.where(same, full, ll / r2)

    n = perm.shape[0]
    rows = np.zeros((7, n))
    np.add.at(rows[0], Q1, f(e[Q1], m[Q1]))
    h = 1e-30
    for k in range(3):
        du = np.zeros((Q1.shape[0], 3), complex)
        du[:, k] = 1j * h
        np.add.at(rows[1 + k], Q1, 2 * f(e[Q1] + du, m[Q1]).imag / h)
        np.add.at(rows[4 + k], Q1, 2 * f(e[Q1], m[Q1] + du).imag / h)
    return rows


@pytest.mark.parametrize("leaf_size, round_slots", [(8, 1 << 15), (8, 7), (4, 1), (12, 3)])
def test_rows_match_numpy(leaf_size, round_slots, rng):
    # leaves of 12: groups of 8 and 4 on both sides of a pair; 1 and 3 slots per round: a
    # round per leaf (or a few), the buffer's slots refilled and each leaf's partner slots
    # spread over many rounds
    X, layout = as_layout(*_scene(rng))
    frame = bh.Frame(X, layout, theta=0.5, leaf_size=leaf_size)
    tree = frame.tree
    lists = bh._owner_lists(frame.near, tree.size, frame.leaves, round_slots)
    assert (len(lists[-1]) - 1 > 10) == (round_slots < 100)  # rounds as meant
    E, M, ln = frame._edges(X)[:3]
    nbr = frame._near_lists[-1]
    args = (E, M, ln, frame._near_cp, tree.lo, tree.hi, frame.leaves, *lists, nbr)
    rows = _near(*args, True)
    ref = _numpy_rows(X, layout, frame)
    for k in range(7):
        np.testing.assert_allclose(rows[k], ref[k], rtol=1e-9, atol=1e-11 * np.abs(ref[k]).max())
    assert np.array_equal(_near(*args, False)[0], rows[0])  # the energy alone: the same bits


def test_each_leaf_pair_has_one_owner_and_its_partner_the_slot(rng):
    X, layout = as_layout(*_scene(rng))
    frame = bh.Frame(X, layout, theta=0.5)
    m = frame.tree.size
    uoff, upart, toff, tslot, rounds = bh._owner_lists(frame.near, m, frame.leaves, 5)
    owner = np.repeat(np.arange(m), np.diff(uoff))
    pairs = {tuple(p) for p in np.c_[owner, upart]}
    assert pairs == {tuple(p) for p in frame.near} and len(pairs) == len(frame.near)
    for b in range(m):  # the slots a leaf is the partner of, ascending, self pairs left out
        mine = tslot[toff[b]:toff[b + 1]]
        assert np.all(np.diff(mine) > 0)
        assert np.array_equal(np.sort(mine), np.flatnonzero((upart == b) & (owner != b)))
    assert rounds[0] == 0 and rounds[-1] == len(frame.leaves) and np.all(np.diff(rounds) > 0)
    slots = uoff[frame.leaves[rounds[1:] - 1] + 1] - uoff[frame.leaves[rounds[:-1]]]
    assert np.all((slots <= 5) | (np.diff(rounds) == 1))


CODE = """
import numpy as np
from moebius_addon import core
from moebius_addon.core import barnes_hut as bh
from moebius_addon.core._layout import as_layout
rng = np.random.default_rng(3)
t = np.linspace(0, 2 * np.pi, 3000, endpoint=False)
P = np.c_[(2 + np.cos(3 * t)) * np.cos(2 * t), (2 + np.cos(3 * t)) * np.sin(2 * t), np.sin(3 * t)]
P += 1e-3 * rng.standard_normal(P.shape)
s = np.linspace(0, 1, 401)[:, None]
parts = [P] + [np.c_[-3 + 6 * s, 0.3 * k + 0 * s, 0.2 * np.sin(7 * s + k)] for k in range(3)]
X, layout = as_layout(parts, [True, False, False, False])
slots, bh._ROUND_SLOTS = bh._ROUND_SLOTS, 300  # many rounds
try:
    frame = bh.Frame(X, layout)
finally:
    bh._ROUND_SLOTS = slots
E, G = frame.energy_gradient(X)
OUT = [E.hex(), G.tobytes().hex(), len(frame._near_lists[4]) - 1]
"""


def test_bitwise_identical_across_thread_counts_over_many_rounds():
    here, there = out_here_and_in_one_thread(CODE)
    assert here[2] > 20  # rounds
    assert there == here
