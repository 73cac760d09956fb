"""Planar diagram codes and the Jones polynomial: construction from braids, projections and
text; simplification; mirror and reversal; the bracket against the plain state sum."""

import itertools

import numpy as np
import pytest

from moebius_addon.core.topology import invariants, jones, knots, pd
from moebius_addon.core.topology.pd import PlanarDiagram, from_braid, from_rows, parse_pd

knotinfo = pytest.importorskip("database_knotinfo")
KNOTS = {r["name"]: r for r in knotinfo.link_list()[1:] if r["name"] != "0_1"
         and int(r["crossing_number"]) <= 12}


def knotinfo_jones(name) -> dict[int, int]:
    v = [int(x) for x in KNOTS[name]["jones_polynomial_vector"].strip("[]").split(",")]
    return {2 * (v[0] + k): c for k, c in enumerate(v[2:]) if c}


def brute_bracket(d: PlanarDiagram) -> dict[int, int]:
    """Kauffman's state sum over all 2^c smoothings, loops counted by union-find: slow and
    obviously right."""
    out: dict[int, int] = {}
    for state in itertools.product((1, -1), repeat=d.crossings):
        parent: dict[int, int] = {}

        def find(a, parent=parent):
            parent.setdefault(a, a)
            while parent[a] != a:
                a = parent[a]
            return a

        for (i, j, k, l), s in zip(d.X.tolist(), state, strict=True):  # noqa: E741
            for a, b in (((i, j), (k, l)) if s == 1 else ((i, l), (j, k))):
                parent[find(a)] = find(b)
        loops = len({find(int(e)) for e in np.unique(d.X)}) + d.loops
        # A^(a - b) d^loops, d = -A^2 - A^-2
        poly = {sum(state): 1}
        for _ in range(loops):
            nxt = {}
            for e, c in poly.items():
                nxt[e + 2] = nxt.get(e + 2, 0) - c
                nxt[e - 2] = nxt.get(e - 2, 0) - c
            poly = nxt
        for e, c in poly.items():
            out[e] = out.get(e, 0) + c
    return {e: c for e, c in out.items() if c}


@pytest.mark.parametrize("word", [[1, 1, 1], [1, -2, 1, -2], [1, 1, 2, -1, 2, 2],
                                  [1, 1], [1, -2, 1, -2, 1, -2], [1, 2, -3, 2, -1, 3, 3]])
def test_bracket_equals_the_plain_state_sum(word):
    d = from_braid(word)
    assert jones.kauffman_bracket(d) == brute_bracket(d)


@pytest.mark.parametrize("name", ["3_1", "4_1", "5_2", "8_19", "10_161", "11n_34", "12a_1",
                                  "12n_888"])
def test_jones_of_knotinfos_pd_codes(name):
    # the PD code as KnotInfo writes it: signs inferred from the edges' orientation
    d = parse_pd(KNOTS[name]["pd_notation"])
    assert jones.jones(d) == knotinfo_jones(name)
    assert invariants.alexander_polynomial(d) == [
        int(x) for x in KNOTS[name]["alexander_polynomial_vector"].strip("[]").split(",")][2:]


def test_jones_of_linkinfos_pd_codes():
    links = {r["name"]: r for r in knotinfo.link_list(proper_links=True)[1:]}
    for name in ["L2a1{0}", "L2a1{1}", "L4a1{1}", "L5a1{0}", "L6a4{0,0}", "L7n1{0}",
                 "L11n459{1,1,1}"]:
        r = links[name]
        d = parse_pd(r["pd_notation_vector"])  # {{4, 1, 3, 2}, {2, 3, 1, 4}}
        v = [int(x) for x in r["jones_polynomial_vector"].replace("{", "").replace(
            "}", "").split(",")]
        assert jones.jones(d) == {v[0] + k: c for k, c in enumerate(v[2:]) if c}, name
        assert len(d.components()) == int(r["components"])


def test_text_forms_of_a_pd_code():
    want = jones.jones(from_braid([1, 1, 1]))
    for text in ["[[1,5,2,4],[3,1,4,6],[5,3,6,2]]", "PD[X[1,5,2,4], X[3,1,4,6], X[5,3,6,2]]",
                 "{{1, 5, 2, 4}, {3, 1, 4, 6}, {5, 3, 6, 2}}",
                 "[[1,5,2,4,1],[3,1,4,6,1],[5,3,6,2,1]]"]:  # Knoodle: handedness last
        assert jones.jones(parse_pd(text)) == want, text


@pytest.mark.parametrize("text, why", [
    ("[[1,5,2,4],[3,1,4,6],[5,3,6,7]]", "edge 2 appears 1 time"),
    ("[[1,5,2,4],[3,1,4]]", "4 edge labels per crossing"),
    ("[[1,5,2,4,-1],[3,1,4,6,1],[5,3,6,2,1]]", "crossing 1 .*contradicts"),
    ("hello", "no crossings found"),
    ("[[1,2,3,4],[1,2,3,4]]", "not describe a diagram in the plane|cannot be oriented"),
])
def test_bad_pd_codes_are_refused(text, why):
    with pytest.raises(ValueError, match=why):
        parse_pd(text)


def test_rows_round_trip_and_mirror_and_reverse():
    d = from_braid([1, -2, 1, 1, -2, 3, -2, 3])
    e = from_rows(d.rows())
    assert jones.jones(e) == jones.jones(d)
    m = d.mirror()
    assert jones.jones(m) == {-k: c for k, c in jones.jones(d).items()}
    hopf = from_braid([1, 1])
    assert pd.linking_matrix(hopf.reverse([1])).tolist() == [[0, -1], [-1, 0]]
    assert jones.jones(hopf.reverse([1])) == jones.jones(from_braid([-1, -1]))
    assert jones.jones(hopf.reverse([0, 1])) == jones.jones(hopf)


def test_simplification_keeps_the_link_and_removes_kinks_and_bigons():
    # 3_1 with a removable bigon (σ2 σ2⁻¹) and a kink (the last σ2, a Markov stabilization)
    d = from_braid([1, 2, -2, 1, 1, 2])
    s = pd.simplify(d)
    assert s.crossings == 3 and s.loops == 0
    assert jones.jones(s) == jones.jones(d) == jones.jones(from_braid([1, 1, 1]))
    # σ3 on strands 3-4 beside σ1³: the trefoil and a split circle with a kink
    split = pd.simplify(from_braid([1, 1, 1, 3]))
    assert split.crossings == 3 and split.loops == 1
    unknot = pd.simplify(from_braid([1, 2, -1, -2, 3]))
    assert unknot.crossings == 0 and jones.jones(unknot) == {0: 1}
    two = pd.simplify(from_braid([1, -1], 2))  # an unlink of two circles
    assert two.crossings == 0 and two.loops == 2
    assert jones.jones(two) == {-1: -1, 1: -1}


def test_projection_diagram_has_the_curves_linking_matrix():
    L = knots.named("L10n99{0,0,0}")
    d = invariants.planar_diagram(L)
    assert jones.jones(d) == jones.jones(from_braid(knots.info("L10n99{0,0,0}")["braid"], 5)
                                         .reverse([0]))
    np.testing.assert_array_equal(invariants.linking_numbers(L),
                                  knots.info("L10n99{0,0,0}")["linking"])


def test_jones_budget():
    with pytest.raises(jones.TooComplex, match="intermediate states"):
        jones.jones(from_braid([1, -2, 3, -4, 5, -6] * 4), max_states=5)
