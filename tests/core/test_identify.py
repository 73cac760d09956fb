"""core.identify: table entries, mirror images, links, relaxed curves, ambiguities, refusals."""

import importlib
import time
from pathlib import Path

import numpy as np
import pytest

from moebius_addon import core
from moebius_addon.core import Match, identify
from moebius_addon.core.topology import knots
from tests.conftest import random_rotation

_RNG = np.random.default_rng(2026)
SAMPLE = ([knots.names("knot")[i] for i in _RNG.choice(2978, 16, replace=False)]
          + [knots.names("link")[i] for i in _RNG.choice(4188, 10, replace=False)])


@pytest.mark.parametrize("name", SAMPLE)
def test_a_seeded_sample_of_the_table_is_identified(name):
    R = random_rotation(np.random.default_rng(len(name)))
    P = knots.named(name)
    P = [c @ R.T for c in P] if isinstance(P, list) else P @ R.T
    r = identify(P)
    assert name in r.names
    assert r.status == (Match.UNIQUE if len(r.names) == 1 else Match.SEVERAL)
    e = knots.info(name)
    assert r.alexander == e["alexander"] and r.jones == e["jones"]
    assert r.fingerprint.signature == e["signature"]
    if e["kind"] == "knot" and e["symmetry"] not in ("fully amphicheiral",
                                                     "negative amphicheiral",
                                                     "positive amphicheiral"):
        M = identify(knots.named("m" + name))
        assert M.fingerprint.signature == -e["signature"]
        assert "m" + name in M.names and (name in M.names) == (r.jones == M.jones
                                                               and e["signature"] == 0)


@pytest.mark.parametrize("name, want", [
    ("3_1", ("3_1",)), ("m3_1", ("m3_1",)), ("4_1", ("4_1",)), ("0_1", ("0_1",)),
    ("10_161", ("10_161",)), ("12n_888", ("12n_888",)), ("L2a1{1}", ("L2a1{1}",)),
    ("L2a1{0}", ("L2a1{0}",)), ("mL4a1{1}", ("mL4a1{1}",)),
])
def test_classics(name, want):
    r = identify(knots.named(name))
    assert r.names == want and r.name == want[0]


def test_mutants_and_orientations_share_their_invariants():
    r = identify(knots.named("11n_34"))  # the Conway knot and the Kinoshita–Terasaka knot
    assert r.status == Match.SEVERAL and set(r.names) == {"11n_34", "11n_42"}
    assert r.name is None and "Conway knot" in r.message and "share" in r.message
    b = identify(knots.named("Borromean rings"))
    assert set(b.names) == {"L6a4{0,0}", "L6a4{1,0}", "L6a4{0,1}", "L6a4{1,1}"}
    assert b.link == "L6a4" and "Borromean rings" in b.message


def test_entries_with_more_crossings_than_the_diagram_are_ruled_out():
    # 8_8 and the mirror of 10_129 share Alexander and Jones polynomials and signature; a
    # diagram of fewer than 10 crossings (the braid closure simplifies to 9) rules out a knot of 10
    r = identify(knots.named("8_8"))
    assert r.names == ("8_8",) and "m10_129" in r.excluded and r.crossings < 10


RELAXED = Path(__file__).resolve().parents[2] / "docs" / "data" / "energy_table_curves.npz"


def test_further_directions_find_a_simpler_diagram(monkeypatch):
    # the relaxed 10_95 of the energy table: every diagram of the first dozen directions keeps
    # 12 crossings, as many as 12n_595 (the same invariants) needs; another dozen has 10
    from moebius_addon.core.topology.invariants import planar_diagram

    module = importlib.import_module("moebius_addon.core.topology.identify")

    with np.load(RELAXED) as packed:
        P, Q = packed["10_95"].astype(np.float64), packed["10_156"].astype(np.float64)
    assert planar_diagram(P).crossings == 12
    r = identify(P)
    assert r.names == ("10_95",) and r.crossings == 10 and "12n_595" in r.excluded
    monkeypatch.setattr(module, "MORE_DIAGRAMS", 0)
    assert identify(P).names == ("10_95", "12n_595")
    monkeypatch.undo()
    # 8_16 and 10_156 share every invariant: no diagram of 10_156 has 8 crossings, so after
    # every further dozen both names stay
    r = identify(Q)
    assert r.names == ("8_16", "10_156") and r.crossings >= 10


def test_unknots_and_not_in_the_table():
    for P in (knots.freedman_unknot(600), knots.helix_unknot(300), knots.random_unknot(400)):
        assert identify(P).names == ("0_1",)
    granny = identify(knots.braid_closure([1, 1, 1, 2, 2, 2]))  # 3_1 # 3_1
    assert granny.status == Match.NONE and granny.names == ()
    assert "composite" in granny.message
    split = identify([knots.circle(40), knots.circle(40) + [3.0, 0.0, 0.0]])
    assert split.status == Match.NONE and split.alexander == [0]


def test_without_the_jones_polynomial():
    r = identify(knots.named("3_1"), max_states=1)
    assert r.jones is None and "not computed" in r.message
    assert r.names == ("3_1",)  # the signature tells it from its mirror image
    r = identify(knots.named("6_1"), max_states=1)
    # signature 0: the Alexander polynomial and the signature cannot tell 6_1 from its mirror
    # image (nor from 9_46, which has more crossings than the diagram)
    assert set(r.names) == {"6_1", "m6_1"} and "9_46" in r.excluded


def test_the_signature_tells_chiral_knots_the_jones_polynomial_cannot():
    # 9_42 and 10_125 share Alexander and Jones polynomials with their mirror images; their
    # signatures (KnotInfo: 2 for both) do not
    for name in ("9_42", "10_125"):
        e = knots.info(name)
        assert e["jones"] == knots.info("m" + name)["jones"] and e["signature"] == 2
        assert identify(knots.named(name)).names == (name,)
        assert identify(knots.named("m" + name)).names == ("m" + name,)
    # 10_48's signature is 0: it stays named together with its mirror image
    assert set(identify(knots.named("10_48")).names) == {"10_48", "m10_48"}


@pytest.mark.parametrize("name, method", [("7_4", "projected_gradient_implicit"),
                                          ("8_17", "projected_gradient_implicit"),
                                          ("L5a1{0}", "projected_gradient")])
def test_relaxed_curves_keep_their_name(name, method):
    # before the projections were made rotations, relaxed 7_4 read as m7_4 (a reflected
    # projection)
    P = knots.named(name)
    before = identify(P)
    r = core.relax(P, method=method, max_iter=20)
    after = identify(r.x)
    assert after.fingerprint == before.fingerprint and name in after.names


def test_fine_polygons_of_twelve_crossings_answer_quickly():
    P = core.resample(knots.named("12a_1"), 5000)
    t0 = time.perf_counter()
    r = identify(P)
    assert r.names == ("12a_1",)
    assert time.perf_counter() - t0 < 10.0  # 0.03 s measured (docs/api.md)


@pytest.mark.parametrize("s", [1e-300, 1e-200, 1e200, 1e300])
def test_a_curve_at_any_size_is_identified_as_at_size_one(s):
    # edges of 1e-201 squared underflow: the trefoil at 1e-200 that check_polygon accepts was
    # refused as "repeats a point"
    for P in (knots.named("3_1"), knots.named("4_1"), knots.named("L4a1{1}")):
        scaled = [s * c for c in P] if isinstance(P, list) else s * P
        assert identify(scaled).names == identify(P).names != ()


@pytest.mark.parametrize("bad, why", [
    ([knots.circle(16), knots.circle(16) + [2.0, 0.0, 0.0]], "intersects itself"),
    (np.full((8, 3), np.nan), "NaN"),
    (np.zeros((3, 3)), "3 vertices; a closed polygon needs at least 4"),
])
def test_refusals(bad, why):
    with pytest.raises(ValueError, match=why):
        identify(bad)
