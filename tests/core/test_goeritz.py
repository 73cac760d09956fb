"""core.topology.goeritz: the signature by the Goeritz matrix and Gordon–Litherland's correction.

Against values that do not come from this code: the signatures of torus knots and links
T(2, n) (−(n − 1) for n positive crossings), KnotInfo's and LinkInfo's values for the whole
table (the build tool compares them, tests/core/test_knots.py runs it), numpy's eigenvalues for
the exact inertia."""

import numpy as np
import pytest

from moebius_addon import core
from moebius_addon.core.topology import goeritz, knots, pd
from tests.conftest import random_rotation


@pytest.mark.parametrize("n", [2, 3, 4, 5, 6, 7, 9])
def test_torus_knots_and_links_of_two_strands(n):
    # the closure of sigma_1^n, n positive crossings: signature -(n - 1), its mirror n - 1
    d = pd.from_braid([1] * n)
    assert goeritz.signature(d) == -(n - 1)
    assert goeritz.signature(d.mirror()) == n - 1


def test_either_colour_and_the_determinant():
    rng = np.random.default_rng(5)
    names = ["3_1", "4_1", "8_19", "9_42", "10_161", "L6a4{0,0}", "L10n99{0,0,0}"]
    names += [knots.names("knot")[i] for i in rng.choice(np.arange(1, 2978), 10, replace=False)]
    for name in names:
        e = core.table.entry(name)
        d = pd.from_braid(list(e.braid), e.strands)
        if e.reverse:
            d = d.reverse(list(e.reverse))
        values = []
        for white in (0, 1):
            G, mu = goeritz.goeritz(d, white)
            pos, neg, zero = goeritz.inertia(G)
            values.append(pos - neg - mu)
            assert round(abs(np.linalg.det(G))) == e.determinant, name
            assert zero == (e.determinant == 0), name
        assert values[0] == values[1] == e.signature, name


def test_orientation_of_a_link_matters():
    # reversing one component of the Hopf link changes the sign of its linking number and of
    # its signature (LinkInfo: L2a1{0} has 1, L2a1{1} has -1)
    assert core.signature(knots.named("L2a1{0}")) == 1
    assert core.signature(knots.named("L2a1{1}")) == -1
    hopf = pd.from_braid([1, 1], 2)
    assert goeritz.signature(hopf.reverse([1])) == -goeritz.signature(hopf)


def test_polygons_rotations_and_split_links():
    R = random_rotation(np.random.default_rng(7))
    assert core.signature(knots.named("m3_1") @ R.T) == 2
    assert core.signature(knots.named("5_1")) == -4
    assert core.signature(knots.freedman_unknot(600)) == 0
    # a split link: two trefoils apart add, an unknotted circle beside adds nothing
    T = knots.named("3_1")
    assert core.signature([T, T + [4.0, 0.0, 0.0]]) == -4
    assert core.signature([T, knots.circle(50) * 0.3 + [4.0, 0.0, 0.0]]) == -2
    assert goeritz.signature(pd.PlanarDiagram(np.zeros((0, 4), np.int64),
                                              np.zeros(0, np.int64), loops=1)) == 0


def test_inertia_is_exact():
    rng = np.random.default_rng(3)
    for _ in range(200):
        n = int(rng.integers(1, 9))
        B = rng.integers(-3, 4, size=(n, int(rng.integers(1, n + 1))))
        A = B @ np.diag(rng.choice([-1, 1], B.shape[1])) @ B.T  # often singular
        if rng.random() < 0.3:
            np.fill_diagonal(A, 0)  # zero pivots: the off-diagonal step
        ev = np.linalg.eigvalsh(A.astype(float))
        tol = 1e-9 * max(1.0, np.abs(ev).max())
        want = (int((ev > tol).sum()), int((ev < -tol).sum()), int((abs(ev) <= tol).sum()))
        assert goeritz.inertia(A) == want
    assert goeritz.inertia(np.zeros((0, 0), np.int64)) == (0, 0, 0)
    assert goeritz.inertia(np.array([[0, 1], [1, 0]])) == (1, 1, 0)
