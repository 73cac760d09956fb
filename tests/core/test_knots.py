"""The knot catalogue: every curve is equilateral, centred, in the unit ball, fine enough for the
flow at its default size, and has the knot type it claims (checked independently with topoly's
HOMFLY-PT polynomial)."""

import gzip
import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from moebius_addon.core import Relaxation, check_polygon, contact_ratio
from moebius_addon.core.topology import knots
from tests.conftest import random_rotation

topoly = pytest.importorskip("topoly")

ROOT = Path(__file__).resolve().parents[2]
TABLE = ROOT / "moebius_addon" / "core" / "data" / "knot_table.json.gz"
ROTATION = random_rotation(np.random.default_rng(2024))  # topoly can hang on flat input


def homfly(P, chiral=False) -> str:
    """topoly's name for the knot type of a closed polygon, e.g. '3_1', '0_1', '10_132|5_1'
    (knots it cannot tell apart), with chiral=True '+3_1' or '-3_1'."""
    return topoly.homfly(
        (P @ ROTATION.T).tolist(),
        closure=topoly.Closure.CLOSED,
        max_cross=60,
        translate=topoly.Translate.PIU,
        minimal=False,
        chiral=chiral,
    )


def knot_names(P) -> set[str]:
    return set(homfly(P).split("|"))


def unsigned(chiral_name: str) -> set[str]:
    return {k.lstrip("+-") for k in chiral_name.split("|")}


def linking_number(A, B) -> float:
    """Gauss linking integral, midpoint rule on edges."""
    ea, eb = np.roll(A, -1, axis=0) - A, np.roll(B, -1, axis=0) - B
    d = (A + ea / 2)[:, None] - (B + eb / 2)[None]
    cross = np.cross(ea[:, None], eb[None])
    return float(((d * cross).sum(-1) / np.linalg.norm(d, axis=2) ** 3).sum() / (4 * np.pi))


def assert_catalogue_polygon(P, n, min_ratio=2.0):
    comps = P if isinstance(P, list) else [P]
    assert sum(len(c) for c in comps) == n
    allv = np.concatenate(comps)
    assert allv.dtype == np.float64 and allv.shape[1] == 3
    np.testing.assert_allclose(allv.mean(axis=0), 0.0, atol=1e-12)
    assert np.linalg.norm(allv, axis=1).max() == pytest.approx(1.0, abs=1e-12)
    for c in comps:
        edges = np.linalg.norm(np.roll(c, -1, axis=0) - c, axis=1)
        assert edges.max() / edges.min() - 1 < 1e-9
    check_polygon(P)  # embedded and fine enough for the flow
    assert contact_ratio(P) >= min_ratio


# --------------------------------------------------------------------------------------------
# The table


def test_table_lists_the_prime_knots_and_links():
    names = knots.names()
    knot_names_, link_names = knots.names("knot"), knots.names("link")
    # KnotInfo: 2 977 prime knots up to 12 crossings and the unknot; LinkInfo: 4 188 prime links
    # up to 11 crossings, one entry per orientation it lists
    assert len(knot_names_) == 2978 and len(link_names) == 4188
    assert names == knot_names_ + link_names
    assert knot_names_[:3] == ["0_1", "3_1", "4_1"] and knot_names_[-1] == "12n_888"
    assert "10_161" in names and "11a_1" in names and "11n_34" in names
    assert link_names[:2] == ["L2a1{0}", "L2a1{1}"] and link_names[-1] == "L11n459{1,1,1}"
    assert "L6a4{0,0}" in names
    for name in ("3_1", "8_19", "10_161", "12n_888"):
        entry = knots.info(name)
        assert entry["crossings"] == int(name.split("_")[0].rstrip("an"))
        assert entry["strands"] >= entry["braid_index"]
        assert entry["description"] and entry["kind"] == "knot"
    assert knots.info("Trefoil")["name"] == "3_1"
    assert not knots.info("8_19")["alternating"]
    hopf = knots.info("L2a1{1}")
    assert hopf["kind"] == "link" and hopf["components"] == 2
    assert hopf["linking"] == [[0, 1], [1, 0]] and hopf["jones"] == (0.5, [-1, 0, -1])


def test_table_agrees_with_knotinfo():
    # every stored value against the source (the build checked the braid words against them)
    knotinfo = pytest.importorskip("database_knotinfo")
    rows = {r["name"]: r for r in knotinfo.link_list()}
    for name in knots.names("knot")[1:]:
        r, e = rows[name], knots.info(name)
        assert e["alexander"] == json.loads(r["alexander_polynomial_vector"])[2:], name
        v = json.loads(r["jones_polynomial_vector"])
        assert e["jones"] == (v[0], v[2:]), name
        assert e["determinant"] == int(r["determinant"]), name
        assert e["signature"] == int(r["signature"]), name
    links = {r["name"]: r for r in knotinfo.link_list(proper_links=True)}
    for name in knots.names("link"):
        r, e = links[name], knots.info(name)
        assert e["components"] == int(r["components"]) and e["crossings"] == int(
            r["crossing_number"]), name
        assert e["determinant"] == int(r["determinant"]), name
        assert e["signature"] == int(r["signature"]), name


def test_shipped_table_is_what_the_build_tool_makes():
    pytest.importorskip("database_knotinfo")
    spec = importlib.util.spec_from_file_location("bkt", ROOT / "tools" / "build_knot_table.py")
    tool = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tool)
    with gzip.open(TABLE, "rt", encoding="utf-8") as f:
        shipped = json.load(f)
    built = tool.build()
    assert built["knots"] == shipped["knots"] and built["links"] == shipped["links"]
    assert built["aliases"] == shipped["aliases"]


# A seeded sample of the table (tools/verify_knot_table.py checks every entry: run it by hand)
_RNG = np.random.default_rng(16)
SAMPLE = sorted(set(
    ["3_1", "4_1", "10_161", "11n_34", "12n_888", "L2a1{0}", "L6a4{0,0}", "L10n99{0,0,0}",
     "L11n459{1,1,1}"]
    + [knots.names("knot")[i] for i in _RNG.choice(2978, 12, replace=False)]
    + [knots.names("link")[i] for i in _RNG.choice(4188, 8, replace=False)]))


def topoly_jones(P, seed: int = 2024) -> dict[int, int]:
    """topoly's Jones polynomial of a polygon or link, ``{exponent of t^(1/2): coefficient}``
    (in the direction of a random rotation of ``seed``)."""
    spec = importlib.util.spec_from_file_location("vkt", ROOT / "tools" / "verify_knot_table.py")
    tool = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tool)
    return tool.topoly_jones(P, seed)


def table_jones(name) -> dict[int, int]:
    low, coeffs = knots.info(name)["jones"]
    return {round(2 * (low + k)): c for k, c in enumerate(coeffs) if c}


@pytest.mark.parametrize("name", SAMPLE)
def test_named_entry_has_its_type(name):
    P = knots.named(name)
    n = sum(map(len, P)) if isinstance(P, list) else len(P)
    assert_catalogue_polygon(P, n)  # start check passed at the default edge count
    assert isinstance(P, list) == (knots.info(name)["kind"] == "link")
    # topoly, an implementation independent of ours, against KnotInfo's/LinkInfo's value
    assert topoly_jones(P) == table_jones(name)
    if isinstance(P, list):
        L = np.array([[round(linking_number(A, B)) if a != b else 0 for b, B in enumerate(P)]
                      for a, A in enumerate(P)])
        assert L.tolist() == knots.info(name)["linking"]


@pytest.mark.parametrize("name", ["3_1", "5_2", "L4a1{1}", "L5a1{0}"])
def test_mirror_images(name):
    P, M = knots.named(name), knots.named("m" + name)
    jones = table_jones(name)
    assert topoly_jones(M) == {-e: c for e, c in jones.items()} != jones
    assert knots.info("m" + name)["mirror_of"] == name
    for alias in (name + "*", f"mirror of {name}", f"{name} mirror"):
        assert knots.info(alias)["name"] == "m" + name
    if isinstance(P, list):
        assert np.array(knots.info("m" + name)["linking"]).tolist() == (
            -np.array(knots.info(name)["linking"])).tolist()


def test_a_link_whose_braid_closes_to_another_orientation():
    # LinkInfo's braid of L10n99{0,0,0} closes to the orientation {1,1,1} (the same Jones
    # polynomial); named reverses the first component to give the linking matrix LinkInfo lists
    assert knots.info("L10n99{0,0,0}")["linking"] == [[0, -1, 1, 0], [-1, 0, 1, 0],
                                                      [1, 1, 0, -2], [0, 0, -2, 0]]
    P = knots.named("L10n99{0,0,0}")
    L = [[round(linking_number(A, B)) if a != b else 0 for b, B in enumerate(P)]
         for a, A in enumerate(P)]
    assert L == knots.info("L10n99{0,0,0}")["linking"]


def test_aliases_and_search():
    for alias, name in [("trefoil", "3_1"), ("left-handed trefoil", "m3_1"),
                        ("Figure-Eight", "4_1"), ("figure_eight", "4_1"), ("unknot", "0_1"),
                        ("Hopf link", "L2a1{1}"), ("Whitehead link", "L5a1{0}"),
                        ("borromean rings", "L6a4{0,0}"), ("Solomon's knot", "L4a1{1}"),
                        ("Solomons knot", "L4a1{1}"), ("Conway knot", "11n_34"),
                        ("Perko pair", "10_161"), ("l6a4", "L6a4{0,0}"),
                        ("L2A1{0}", "L2a1{0}"), ("12N_888", "12n_888")]:
        assert knots.info(alias)["name"] == name, alias
    assert knots.search("borromean")[0] == "L6a4{0,0}"
    assert knots.search("10_16")[:7] == ["10_16", "10_160", "10_161", "10_162", "10_163",
                                         "10_164", "10_165"]
    assert knots.search("trefoil")[0] == "3_1"
    assert knots.search("m3_1") == ["m3_1"] + knots.search("m3_1")[1:]
    assert set(knots.search("L6a4")) >= {"L6a4{0,0}", "L6a4{1,0}", "L6a4{0,1}", "L6a4{1,1}"}
    assert len(knots.search("", limit=None)) == 7166
    assert knots.search("no such knot") == []


def test_default_count_is_fine_enough_for_the_flow():
    # at the old default (180 edges) the flow of 5_2 pressed two strands to 0.52 edge lengths
    # by iteration 50 and stalled at 61 ("jammed — use more edges")
    run = Relaxation(knots.named("5_2"), max_iter=70)
    closest = contact_ratio(run.x)
    while not run.done:
        run.step()
        closest = min(closest, contact_ratio(run.x))
    assert run.nit == 70 and "stalled" not in run.message, run.message
    assert closest > 0.9


def test_names_aliases_and_unknown_names():
    np.testing.assert_array_equal(knots.named("trefoil", 120), knots.named("3_1", 120))
    np.testing.assert_array_equal(knots.named(" Figure-Eight ", 150), knots.named("4_1", 150))
    np.testing.assert_array_equal(knots.named("figure_eight", 150), knots.named("4_1", 150))
    np.testing.assert_array_equal(knots.named("unknot", 32), knots.circle(32))
    with pytest.raises(ValueError, match=r"unknown knot or link '13n_1'"):
        knots.named("13n_1")
    with pytest.raises(ValueError, match=r"unknown knot or link 'trefoyl'; did you mean trefoil\?"):
        knots.named("trefoyl")


# --------------------------------------------------------------------------------------------
# Closed braids: the crossing sign convention (σ_i positive) and links


@pytest.mark.parametrize("word, lk", [([1, 1], 1), ([-1, -1], -1), ([1, 1, 1, 1], 2)])
def test_braid_closure_link_and_sign_convention(word, lk):
    A, B = knots.braid_closure(word, 300)
    assert len(A) + len(B) == 300
    assert linking_number(A, B) == pytest.approx(lk, abs=1e-2)
    check_polygon([A, B])


def test_braid_closure_chirality_matches_torus_knots():
    right = homfly(knots.named("3_1"), chiral=True)
    assert right == homfly(knots.torus_knot(2, 3), chiral=True)
    assert right == homfly(knots.braid_closure([1, 2, 1, 2], 200), chiral=True)  # T(3, 2)
    assert right != homfly(knots.braid_closure([-1, -1, -1], 200), chiral=True)


def test_braid_closure_degenerate_words_and_errors():
    assert knot_names(knots.braid_closure([1, 2], 100)) == {"0_1"}
    circle = knots.braid_closure([], 50)
    assert_catalogue_polygon(circle, 50)
    unlink = knots.braid_closure([], 100, strands=3)
    assert len(unlink) == 3 and sum(map(len, unlink)) == 100
    with pytest.raises(ValueError, match="nonzero"):
        knots.braid_closure([1, 0, 1])
    with pytest.raises(ValueError, match="needs at least 3 strands"):
        knots.braid_closure([1, 2], strands=2)


# --------------------------------------------------------------------------------------------
# Torus knots and the figure eight


@pytest.mark.parametrize(
    "p, q, name", [(2, 3, "3_1"), (3, 2, "3_1"), (2, 5, "5_1"), (3, 4, "8_19")]
)
def test_torus_knot(p, q, name):
    P = knots.torus_knot(p, q)
    assert_catalogue_polygon(P, 40 * (p + q))
    chiral = homfly(P, chiral=True)
    assert name in unsigned(chiral)
    assert chiral == homfly(knots.named(name), chiral=True)  # both positive knots


def test_torus_link_and_mirror():
    A, B = knots.torus_knot(2, 4, 400)
    assert linking_number(A, B) == pytest.approx(2.0, abs=1e-2)
    A, B = knots.torus_knot(2, -4, 400)
    assert linking_number(A, B) == pytest.approx(-2.0, abs=1e-2)
    assert homfly(knots.torus_knot(-2, 3, 200), chiral=True) != homfly(
        knots.torus_knot(2, 3, 200), chiral=True
    )
    with pytest.raises(ValueError, match="0 < r < R"):
        knots.torus_knot(2, 3, R=1.0, r=1.0)


def test_figure_eight_and_circle():
    P = knots.figure_eight()
    assert_catalogue_polygon(P, 200)
    assert knot_names(P) == {"4_1"}
    C = knots.circle(64)
    assert_catalogue_polygon(C, 64)
    np.testing.assert_allclose(np.linalg.norm(C, axis=1), 1.0)


# --------------------------------------------------------------------------------------------
# Unknots that look knotted


def test_freedman_unknot():
    P = knots.freedman_unknot()
    assert_catalogue_polygon(P, 600, min_ratio=1.1)
    assert knot_names(P) == {"0_1"}


@pytest.mark.parametrize("turns", [2, 6, 12])
def test_helix_unknot(turns):
    n = 300 if turns <= 6 else 600
    P = knots.helix_unknot(n, turns=turns)
    assert_catalogue_polygon(P, n)
    assert knot_names(P) == {"0_1"}


@pytest.mark.parametrize("seed", range(6))
def test_random_unknot(seed):
    P = knots.random_unknot(seed=seed)
    assert_catalogue_polygon(P, 400)
    assert knot_names(P) == {"0_1"}


def test_random_unknot_is_deterministic_and_tangled():
    np.testing.assert_array_equal(
        knots.random_unknot(300, seed=7), knots.random_unknot(300, seed=7)
    )
    assert not np.allclose(knots.random_unknot(300, seed=7), knots.random_unknot(300, seed=8))
    assert knot_names(knots.random_unknot(seed=1, laps=6)) == {"0_1"}


# --------------------------------------------------------------------------------------------
# The documented smallest vertex counts pass the coarseness rule


@pytest.mark.parametrize(
    "make, n",
    [
        (knots.figure_eight, 36),
        (lambda n: knots.torus_knot(2, 3, n), 18),
        (lambda n: knots.torus_knot(3, 4, n), 35),
        (lambda n: knots.named("3_1", n), 27),
        (lambda n: knots.named("7_2", n), 136),
        (lambda n: knots.named("8_1", n), 197),
        (knots.freedman_unknot, 470),
        (knots.helix_unknot, 62),
    ],
)
def test_documented_smallest_n(make, n):
    check_polygon(make(n))
    with pytest.raises(ValueError, match="too coarse"):
        check_polygon(make(n - 3))


def test_planar_crossings_kernel_matches_numpy(rng):
    xy = np.cumsum(rng.normal(size=(60, 2)), axis=0)
    xy -= np.linspace(0, 1, 60)[:, None] * (xy[-1] - xy[0])  # close the walk
    d = np.roll(xy, -1, axis=0) - xy
    expected = set()
    for i in range(60):
        for j in range(i + 2, 60 - (i == 0)):
            A = np.column_stack([d[i], -d[j]])
            if abs(np.linalg.det(A)) > 0:
                a, b = np.linalg.solve(A, xy[j] - xy[i])
                if 0 <= a < 1 and 0 <= b < 1:
                    expected.add((i, j))
    assert len(expected) > 10
    assert set(map(tuple, knots._planar_crossings(xy).tolist())) == expected


def test_bad_vertex_counts():
    with pytest.raises(ValueError, match="at least 4 vertices per component"):
        knots.torus_knot(2, 4, 7)
    with pytest.raises(TypeError, match="n must be an int"):
        knots.circle(10.0)


@pytest.mark.parametrize("n", [5, 6, 7])
def test_curves_too_coarse_for_the_start_check_are_refused(n):
    # T(2, 3) at 5, 6 and 7 vertices passed check_polygon (no vertex pair is 4 edges apart) and
    # were unknots (topoly: 0_1); at 8-17 the check refuses it, from 18 it passes as a trefoil
    with pytest.raises(ValueError, match=r"too few vertices for this curve.*use n >= (\d+)") as e:
        knots.torus_knot(2, 3, n)
    k = int(e.value.args[0].rsplit(">= ", 1)[1])
    check_polygon(knots.torus_knot(2, 3, k))
    for make in (lambda: knots.named("3_1", 8), lambda: knots.torus_knot(2, 4, 16),
                 lambda: knots.random_unknot(8), lambda: knots.freedman_unknot(8)):
        with pytest.raises(ValueError, match="too few vertices for this curve"):
            make()
    assert knots.circle(n).shape == (n, 3)  # a convex polygon: nothing to lose
