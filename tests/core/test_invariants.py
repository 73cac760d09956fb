"""Invariants from a projection (determinant, Alexander polynomial, linking numbers), against
KnotInfo's values for the whole table and known links."""

import json

import numpy as np
import pytest

from moebius_addon import core
from moebius_addon.core.topology import invariants
from moebius_addon.core.topology.invariants import (
    alexander_polynomial,
    determinant,
    is_knotted,
    knot_determinant,
    linking_numbers,
)

SAMPLE = ["0_1", "3_1", "4_1", "5_2", "7_2", "8_19", "8_21"] + [
    core.knots.names("knot")[i]
    for i in np.random.default_rng(11).choice(2978, 8, replace=False)]


@pytest.mark.parametrize("name", SAMPLE)
def test_determinant_of_table_knots_is_knotinfos(name):
    # knots.info carries KnotInfo's determinant (tools/build_knot_table.py), computed there
    # from the Alexander polynomial, not from a diagram of ours
    assert knot_determinant(core.knots.named(name)) == core.knots.info(name)["determinant"]


def test_determinant_does_not_depend_on_projection_size_or_resolution():
    P = core.knots.named("7_2")
    R, _ = np.linalg.qr(np.random.default_rng(1).normal(size=(3, 3)))
    for Q in (P @ R.T, 1e-30 * P, 1e30 * P + 5.0, -P, P[::-1], core.resample(P, 5000)):
        assert knot_determinant(Q) == 11


@pytest.mark.parametrize("make", [lambda: core.knots.freedman_unknot(600),
                                  lambda: core.knots.helix_unknot(300),
                                  lambda: core.knots.random_unknot(400, seed=3),
                                  lambda: core.knots.circle(16)])
def test_unknots_have_determinant_one(make):
    P = make()
    assert knot_determinant(P) == 1
    assert not is_knotted(P)


def test_knots_are_knotted():
    assert is_knotted(core.knots.named("3_1"))
    assert is_knotted(core.knots.torus_knot(3, 4, 200))  # 8_19, the first non-alternating knot


def test_alexander_polynomial_of_table_knots_is_knotinfos():
    knotinfo = pytest.importorskip("database_knotinfo")  # the build-time source of the table
    rows = {r["name"]: r for r in knotinfo.link_list()}
    for name in SAMPLE:
        # KnotInfo's vector: lowest degree, highest degree, then the coefficients
        want = [1] if name == "0_1" else json.loads(rows[name]["alexander_polynomial_vector"])[2:]
        assert alexander_polynomial(core.knots.named(name)) == want, name


def test_alexander_polynomial_of_a_fine_polygon():
    P = core.resample(core.knots.named("8_19"), 20000)  # T(3, 4): 1 - t + t^3 - t^5 + t^6
    assert alexander_polynomial(P) == [1, -1, 0, 1, 0, -1, 1]
    assert alexander_polynomial(core.knots.freedman_unknot(600)) == [1]


@pytest.mark.parametrize("word, lk, det, alexander", [
    ([1, 1], 1, 2, [1, -1]),  # the positive Hopf link
    ([-1, -1], -1, 2, [1, -1]),  # its mirror
    ([1, 1, 1, 1], 2, 4, [1, -1, 1, -1]),  # T(2, 4), Solomon's link
])
def test_two_component_links(word, lk, det, alexander):
    L = core.knots.braid_closure(word)
    assert linking_numbers(L).tolist() == [[0, lk], [lk, 0]]
    assert determinant(L) == det
    assert alexander_polynomial(L) == alexander


def test_borromean_rings_and_a_split_link():
    B = core.knots.braid_closure([1, -2, 1, -2, 1, -2])
    assert linking_numbers(B).tolist() == [[0] * 3] * 3  # linked, yet pairwise unlinked
    assert determinant(B) == 16  # LinkInfo's L6a4
    far = [core.knots.circle(16), core.knots.circle(16) + [5.0, 0.0, 0.0]]
    assert determinant(far) == 0 and alexander_polynomial(far) == [0]
    assert linking_numbers(far).tolist() == [[0, 0], [0, 0]]


def _slow_crossing_count(X):
    """Every pair of non-adjacent edges of the projection, by the plain formula."""
    n, count = len(X), 0
    for i in range(n):
        for j in range(i + 2, n if i else n - 1):
            a, d = X[i, :2], X[(i + 1) % n, :2] - X[i, :2]
            b, e = X[j, :2], X[(j + 1) % n, :2] - X[j, :2]
            den = d[0] * e[1] - d[1] * e[0]
            q = b - a
            s = (q[0] * e[1] - q[1] * e[0]) / den
            t = (q[0] * d[1] - q[1] * d[0]) / den
            count += 0 <= s <= 1 and 0 <= t <= 1
    return count


def test_sweep_finds_every_crossing():
    X = core.knots.random_unknot(150, seed=7)
    nxt = np.roll(np.arange(len(X)), -1)
    assert len(invariants._sweep(np.ascontiguousarray(X), nxt)) == _slow_crossing_count(X) > 10


@pytest.mark.parametrize("bad, why", [(np.zeros((2, 3)), "n >= 3"),
                                      (np.full((5, 3), np.nan), "NaN"),
                                      ([core.knots.circle(8)] * 2, "one closed polygon")])
def test_bad_input_is_refused(bad, why):
    with pytest.raises(ValueError, match=why):
        knot_determinant(bad)


def test_touching_curves_are_refused():
    C = core.knots.circle(16)  # vertices at (1, 0, 0) and (-1, 0, 0)
    with pytest.raises(ValueError, match="touches"):
        determinant([C, C + [2.0, 0.0, 0.0]])  # the two circles share a vertex
    with pytest.raises(ValueError, match="at least 3 vertices"):
        linking_numbers([C, C[:2]])


def test_every_projection_sees_the_same_chirality():
    # the projection directions were orthogonal matrices of determinant -1 half the time: a
    # reflection, so those projections saw the mirror image (linking number -2 for T(2, 4),
    # the Jones polynomial of m7_4 for 7_4); Alexander and the determinant cannot tell
    L = core.knots.braid_closure([1, 1, 1, 1], 300)
    K = core.knots.named("7_4")
    layout_l, found_l = invariants._projections(L)
    layout_k, found_k = invariants._projections(K)
    assert len(found_l) > 6 and len(found_k) > 6
    for rows in found_l:
        d = invariants._as_diagram(rows, layout_l.starts)
        a, b = d.component(d.over), d.component(d.under)
        assert d.sign[a != b].sum() // 2 == 2
    want = core.topology.jones.jones(core.pd.from_braid(core.knots.info("7_4")["braid"]))
    for rows in found_k:
        d, _ = core.pd.from_passages(rows[:, 0], rows[:, 1], rows[:, 2].astype(np.int64),
                                     layout_k.starts)
        assert core.topology.jones.jones(d) == want

