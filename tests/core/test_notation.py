"""Braid words and PD codes as typed, and the curves made from them (core.knots.from_*)."""

import numpy as np
import pytest

from moebius_addon.core import check_polygon, contact_ratio, identify
from moebius_addon.core.topology import knots, notation, pd

knotinfo = pytest.importorskip("database_knotinfo")


@pytest.mark.parametrize("text, word, strands", [
    ("1 -2 1 -2", [1, -2, 1, -2], None),
    ("[1,-2,1,-2]", [1, -2, 1, -2], None),
    ("{3, {1, -2, 1, -2}}", [1, -2, 1, -2], 3),
    ("BR[4, {1, -2, 1, -2}]", [1, -2, 1, -2], 4),
    ("s1 s2^-1 s1 s2^-1", [1, -2, 1, -2], None),
    ("σ1 σ2⁻¹ σ1 σ2⁻¹", [1, -2, 1, -2], None),
    ("1, 1, 1", [1, 1, 1], None),
])
def test_braid_words(text, word, strands):
    assert notation.parse_braid(text) == (word, strands)
    assert notation.parse_notation(text) == ("braid", (word, strands))


@pytest.mark.parametrize("text, why", [
    ("", "empty"), ("1 0 1", "nonzero"), ("1 x 2", "could not read 'x'"),
    ("{2, {1, 2}}", "needs 3 strands, not 2"),
    ("1 2 -", "sign '-' .* stands before no generator"),
    ("1 --2", "sign '-' .* stands before no generator"),
    # a number after the brackets was skipped, or read into the word
    ("{3, {1, -2, 1, -2}} 5", "could not read the brackets"),
    ("[1, -2, 1, -2] 3", "could not read the brackets"),
])
def test_bad_braid_words(text, why):
    with pytest.raises(ValueError, match=why):
        notation.parse_braid(text)


@pytest.mark.parametrize("text", ["1 - 2 1 - 2", "{3, {1, - 2, 1, - 2}}", "[1, - 2, 1, - 2]"])
def test_a_sign_typed_apart_from_its_generator_is_kept(text):
    # "- 2" is σ2⁻¹: read as 2 it made the figure-eight knot's word a trefoil's
    assert notation.parse_braid(text)[0] == [1, -2, 1, -2]


@pytest.mark.parametrize("text, stray", [
    ("[[1,5,2,4],[3,1,4,6],[5,3,6,2]] 4_1", "4_1"),
    ("PD[X[1,5,2,4], X[3,1,4,6], X[5,3,6,2]] and more", "and"),
    ("[[1,5,2,4],[3,1,4,6],[5,3,6,2x]]", "5,3,6,2x"),
])
def test_text_around_a_pd_code_is_refused(text, stray):
    with pytest.raises(ValueError, match=f"could not read .*{stray}"):
        notation.parse_notation(text)


def test_pd_or_braid():
    for text in ["[[1,5,2,4],[3,1,4,6],[5,3,6,2]]", "PD[X[1,5,2,4], X[3,1,4,6], X[5,3,6,2]]",
                 "{{4, 1, 3, 2}, {2, 3, 1, 4}}", "X[1,5,2,4] X[3,1,4,6] X[5,3,6,2]"]:
        assert notation.is_pd(text), text
    for text in ["[1, 1, 1, 1]", "{2, {1, 1, 1, 1}}", "1 -2 1 -2", "BR[2, {1, 1, 1}]"]:
        assert not notation.is_pd(text), text


@pytest.mark.parametrize("text, name", [
    ("1 -2 1 -2", "4_1"), ("-1 -1 -1", "m3_1"), ("{3, {1, -2, 1, -2, 1, -2}}", "L6a4{0,0}"),
    ("[[1,5,2,4],[3,1,4,6],[5,3,6,2]]", "3_1"),
    ("[[1,5,2,4,1],[3,1,4,6,1],[5,3,6,2,1]]", "3_1"),  # Knoodle's rows, handedness last
    ("PD[X[4,2,5,1], X[8,6,1,5], X[6,3,7,4], X[2,7,3,8]]", "4_1"),
    ("{{4, 1, 3, 2}, {2, 3, 1, 4}}", "L2a1{0}"),
])
def test_from_notation_names_the_link(text, name):
    P = knots.from_notation(text)
    check_polygon(P)  # ready to relax at the default edge count
    assert name in identify(P).names


_RNG = np.random.default_rng(7)
KNOTS = [r for r in knotinfo.link_list()[1:] if r["name"] != "0_1"
         and int(r["crossing_number"]) <= 12]
LINKS = [r for r in knotinfo.link_list(proper_links=True)[1:]
         if int(r["crossing_number"]) <= 11]
SAMPLE = ([(KNOTS[i]["name"], KNOTS[i]["pd_notation"]) for i in _RNG.choice(len(KNOTS), 8)]
          + [(LINKS[i]["name"], LINKS[i]["pd_notation_vector"])
             for i in _RNG.choice(len(LINKS), 5)])


@pytest.mark.parametrize("name, code", SAMPLE)
def test_knotinfos_and_linkinfos_pd_codes_become_their_curves(name, code):
    # tools/verify_knot_table.py --pd draws every entry this way
    P = knots.from_pd(code)
    check_polygon(P)
    assert contact_ratio(P) > 2.5
    assert name in identify(P).names


def test_orientation_and_chirality_are_kept():
    code = knotinfo.link_list()[2]["pd_notation"]  # 3_1 (positive)
    assert knotinfo.link_list()[2]["name"] == "3_1"
    assert identify(knots.from_pd(code)).names == ("3_1",)
    assert identify(knots.from_pd(pd.parse_pd(code).mirror())).names == ("m3_1",)
    hopf = pd.from_braid([1, 1])
    A, B = knots.from_pd(hopf.reverse([1]))
    assert identify([A, B]).names == ("L2a1{0}",)


def test_kinks_nugatory_crossings_and_loose_circles():
    # 3_1 with a kink: drawn without it, still the trefoil
    kinked = pd.from_braid([1, 1, 1, 2], 3)
    assert identify(knots.from_pd(kinked)).names == ("3_1",)
    assert identify(knots.from_pd("[[1,1,2,2]]")).names == ("0_1",)  # a one-crossing unknot
    granny = knots.from_pd(pd.from_braid([1, 1, 1, 2, 2, 2]))  # composite: 3_1 # 3_1
    check_polygon(granny)
    assert identify(granny).names == ()
    split = knots.from_pd(pd.from_braid([1, 1, 1, 3, 3, 3]))  # two trefoils side by side
    assert len(split) == 2
    check_polygon(split)


@pytest.mark.parametrize("text, why", [
    ("[[1,5,2,4],[3,1,4,6],[5,3,6,7]]", "edge 2 appears 1 time"),
    ("[[1,5,2,4,-1],[3,1,4,6,1],[5,3,6,2,1]]", "contradicts"),
    ("1 0 1", "nonzero"),
])
def test_bad_notation_is_refused(text, why):
    with pytest.raises(ValueError, match=why):
        knots.from_notation(text)
