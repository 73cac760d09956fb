"""Equilateral resampling and the start checks (clear messages for every bad input)."""

import re

import numpy as np
import pytest

from moebius_addon.core import (
    check_polygon,
    contact_ratio,
    resample,
    subdivide,
    suggest_edge_count,
)
from moebius_addon.core.geometry.polygon import equalize
from moebius_addon.core.metrics._tridiagonal import cyclic_tridiagonal_solve
from tests.conftest import ngon, trefoil


def _distance_to_polyline(points, poly, closed=True):
    a = poly if closed else poly[:-1]
    b = np.roll(poly, -1, axis=0) if closed else poly[1:]
    d = b - a
    t = np.clip(np.einsum("ikj,kj->ik", points[:, None, :] - a[None], d) / (d * d).sum(1), 0, 1)
    closest = a[None] + t[..., None] * d[None]
    return np.linalg.norm(points[:, None, :] - closest, axis=2).min(axis=1)


@pytest.mark.parametrize("n", [7, 100, 1000])
def test_resample_is_equilateral_and_on_the_curve(n):
    raw = trefoil(333)
    P = resample(raw, n)
    assert P.shape == (n, 3)
    ln = np.linalg.norm(np.roll(P, -1, axis=0) - P, axis=1)
    assert ln.max() / ln.min() - 1 < 1e-10
    assert _distance_to_polyline(P, raw).max() < 1e-12 * np.abs(raw).max()
    np.testing.assert_array_equal(P[0], raw[0])


def test_resample_open_polyline_keeps_both_ends():
    raw = trefoil(100)[:60]
    P = resample(raw, 25, closed=False)
    ln = np.linalg.norm(np.diff(P, axis=0), axis=1)
    assert ln.max() / ln.min() - 1 < 1e-10
    np.testing.assert_allclose(P[[0, -1]], raw[[0, -1]], atol=1e-12)


def _open_star():
    ang = np.arange(20) * np.pi / 10
    r = np.where(np.arange(20) % 2 == 0, 1.0, 0.4)
    return np.c_[r * np.cos(ang), r * np.sin(ang), 0 * ang]  # 20 points, not closed


@pytest.mark.parametrize("n", [12, 31, 97, 312])
def test_resample_open_polyline_with_sharp_turns_is_equilateral(n):
    # no equal-chord march reaches the far end at these counts (the last chord was up to 11
    # times the others); the closest march is made equilateral between the two ends
    raw = _open_star()
    P = resample(raw, n, closed=False)
    ln = np.linalg.norm(np.diff(P, axis=0), axis=1)
    assert P.shape == (n, 3) and ln.max() / ln.min() - 1 < 1e-10
    np.testing.assert_array_equal(P[0], raw[0])
    np.testing.assert_allclose(P[-1], raw[-1], atol=1e-14)
    assert _distance_to_polyline(P, raw, closed=False).max() < 2 * ln.mean()


def test_resample_link_and_duplicates():
    raw = np.repeat(ngon(20), 2, axis=0)  # every point twice
    P = resample([raw, 2 * ngon(30)], 90)
    assert [len(c) for c in P] == [30, 60]  # proportional to length


def test_resample_rejects_nonsense():
    with pytest.raises(ValueError, match="NaN"):
        resample(np.array([[0, 0, 0], [1, np.nan, 0], [1, 1, 0]]), 10)
    with pytest.raises(ValueError, match="at least 4"):
        resample(ngon(10), 3)
    with pytest.raises(ValueError, match="coincide"):
        resample(np.zeros((5, 3)), 10)


def test_check_accepts_good_curves():
    check_polygon(resample(trefoil(300), 200))
    check_polygon([ngon(20), ngon(20)[:, [0, 2, 1]] + [1.0, 0.0, 0.0]])


def test_check_messages():
    with pytest.raises(ValueError, match="3 vertices; a closed polygon needs at least 4"):
        check_polygon(ngon(3))
    P = ngon(10)
    P[4, 1] = np.nan
    with pytest.raises(ValueError, match="NaN or infinite.*vertex 4"):
        check_polygon(P)
    P = ngon(10)
    P[5] = P[4]
    with pytest.raises(ValueError, match="repeats a point: vertex 4"):
        check_polygon(P)
    with pytest.raises(ValueError, match="repeats a point: vertex 2 of component 1"):
        Q = ngon(10)
        Q[3] = Q[2]
        check_polygon([ngon(10), Q + [5, 0, 0]])


def test_self_intersection_is_located():
    bowtie = np.array([[0, 0, 0], [1, 1, 0], [1, 0, 0], [0, 1, 0]], dtype=float)
    P = resample(bowtie, 40)
    with pytest.raises(ValueError, match=r"intersects itself.*near \(0\.5, 0\.5, 0\)"):
        check_polygon(P)


def test_too_coarse_start_names_an_edge_count_that_works(fhw_raw):
    # docs/design.md: the FHW unknot at 300 edges is a true near-contact (ratio ~0.7)
    P = resample(fhw_raw, 300)
    assert contact_ratio(P) < 0.75
    with pytest.raises(ValueError, match=r"too coarse.*at least (\d+) edges") as info:
        check_polygon(P)
    k = int(info.value.args[0].rsplit("at least ", 1)[1].split()[0])
    assert 450 < k < 700
    check_polygon(resample(fhw_raw, k))
    assert suggest_edge_count(P) == k
    assert contact_ratio(resample(fhw_raw, 600)) > 1.1


def test_resample_through_its_start_twice_keeps_both_lobes():
    # a lemniscate started at its crossing passes through the start point halfway: the
    # closing condition also holds after one lobe, which is not the resampling asked for
    t = np.linspace(0, 2 * np.pi, 400, endpoint=False) + np.pi / 2
    raw = np.c_[np.cos(t), np.sin(t) * np.cos(t), 0 * t] / (1 + np.sin(t) ** 2)[:, None]
    for n in (50, 101, 200):
        P = resample(raw, n)
        ln = np.linalg.norm(np.roll(P, -1, axis=0) - P, axis=1)
        assert ln.max() / ln.min() - 1 < 1e-10
        assert P[:, 0].min() < -0.99 and P[:, 0].max() > 0.99  # both lobes
        assert ln.sum() > 0.998 * np.linalg.norm(np.roll(raw, -1, axis=0) - raw, axis=1).sum()


@pytest.mark.parametrize("n", [40, 57])
def test_resample_of_sharp_corners_is_equilateral(n):
    # a crossing and 135° corners: these counts came back with one long edge (it was 69%
    # longer at 40, 103% at 57); starting the march elsewhere on the curve finds equal edges
    bowtie = np.array([[0, 0, 0], [1, 1, 0], [1, 0, 0], [0, 1, 0]], dtype=float)
    P = resample(bowtie, n)
    ln = np.linalg.norm(np.roll(P, -1, axis=0) - P, axis=1)
    assert ln.max() / ln.min() - 1 < 1e-10
    assert _distance_to_polyline(P, bowtie).max() < 1e-12


def _spread(P):
    ln = np.linalg.norm(np.roll(P, -1, axis=0) - P, axis=1)
    return ln.max() / ln.min() - 1, ln.mean()


@pytest.mark.parametrize("n", [12, 31, 97, 361])
def test_resample_is_equilateral_where_no_polygon_on_the_polyline_is(n):
    # a ten-pointed star (turns of 130°): at these counts no march along it closes with equal
    # chords from any start tried (before: one edge 1.5 to 3.6 times the others)
    ang = np.arange(10) * 2 * np.pi / 10
    r = np.where(np.arange(10) % 2 == 0, 1.0, 0.4)
    star = np.c_[r * np.cos(ang), r * np.sin(ang), 0 * ang]
    P = resample(star, n)
    spread, h = _spread(P)
    assert P.shape == (n, 3) and spread < 1e-10
    off = _distance_to_polyline(P, star)
    assert 1e-6 * h < off.max() < h  # off the polyline, but by less than an edge


def test_equalize_makes_equal_edges_with_small_moves(rng):
    P = resample(trefoil(400), 200)
    np.testing.assert_allclose(equalize(P), P, atol=1e-14)  # equilateral already: unmoved
    noisy = P + 1e-4 * rng.standard_normal(P.shape)
    Q = equalize(noisy)
    spread, h = _spread(Q)
    assert spread < 1e-12
    assert np.abs(Q - noisy).max() < 3e-4  # of the order of the noise, not of an edge (0.04)
    # one edge 3 times too long: made equal in stages
    raw = trefoil(400)
    bad = np.vstack([raw[:1], raw[5:]])
    spread, _ = _spread(equalize(bad))
    assert spread < 1e-12


def test_equalize_open_chain_keeps_its_ends(rng):
    P = resample(trefoil(400)[:150], 60, closed=False)
    np.testing.assert_allclose(equalize(P, closed=False), P, atol=1e-14)  # unmoved
    noisy = P + 1e-4 * rng.standard_normal(P.shape)
    Q = equalize(noisy, closed=False)
    ln = np.linalg.norm(np.diff(Q, axis=0), axis=1)
    assert ln.max() / ln.min() - 1 < 1e-12
    np.testing.assert_array_equal(Q[[0, -1]], noisy[[0, -1]])
    assert np.abs(Q - noisy).max() < 3e-4


@pytest.mark.parametrize("n", [3, 4, 17])
@pytest.mark.parametrize("cyclic", [True, False])
def test_cyclic_tridiagonal_solve(n, cyclic, rng):
    a = 2.0 + rng.random(n)
    b = rng.uniform(-0.9, 0.9, n)
    if not cyclic:
        b[-1] = 0.0  # plain tridiagonal (equalize's open chains)
    M = np.diag(a)
    for i in range(n):
        M[i, (i + 1) % n] += b[i]
        M[(i + 1) % n, i] += b[i]
    r = rng.standard_normal(n)
    np.testing.assert_allclose(M @ cyclic_tridiagonal_solve(a, b, r), r, atol=1e-12)


@pytest.mark.parametrize("s", [1e-300, 1e300])
def test_checks_and_resampling_at_absurd_sizes(fhw_raw, s):
    # squared edge lengths under- or overflow at these sizes: a 1e-300 trefoil was refused as
    # "repeats a point", a 1e300 one as touching itself "after vertex 0 and after vertex 0"
    P = resample(trefoil(400), 120)
    check_polygon(s * P)
    assert contact_ratio(s * P) == pytest.approx(contact_ratio(P), rel=1e-12)
    np.testing.assert_allclose(resample(s * P, 90) / s, resample(P, 90), atol=1e-12)
    k = 900 if s > 1 else -900
    np.testing.assert_array_equal(np.ldexp(resample(np.ldexp(P, k), 90), -k), resample(P, 90))
    link = resample([s * P, s * (P + 3.0)], 150)
    np.testing.assert_allclose(link[1] / s, resample([P, P + 3.0], 150)[1], atol=1e-12)
    bowtie = np.array([[0, 0, 0], [1, 1, 0], [1, 0, 0], [0, 1, 0]], dtype=float)
    where = re.escape(f"near ({0.5 * s:.6g}, {0.5 * s:.6g}, 0)")
    with pytest.raises(ValueError, match=f"intersects itself.*{where}"):
        check_polygon(s * resample(bowtie, 40))
    coarse = resample(fhw_raw, 300)
    with pytest.raises(ValueError, match=r"too coarse.*at least (\d+) edges") as info:
        check_polygon(s * coarse)
    with pytest.raises(ValueError, match=r"too coarse") as plain:
        check_polygon(coarse)
    assert info.value.args[0] == plain.value.args[0]


def test_equalize_many_edges_down_to_rounding():
    # edges computed as differences of coordinates carry ε|x|/l of rounding: 1.8e-12 here,
    # above the old fixed tolerance of 1e-13, so equalize and resample(trefoil, 40 000) failed
    n = 50_000
    t = 2 * np.pi * np.arange(n) / n
    P = np.stack([np.cos(t), np.sin(t), 1e-4 * np.sin(7 * t)], axis=1)
    P *= (1 + 1e-5 * np.cos(3 * t))[:, None]
    Q = equalize(P)
    ln = np.linalg.norm(np.roll(Q, -1, axis=0) - Q, axis=1)
    assert ln.max() / ln.min() - 1 < 1e-10
    assert np.abs(Q - P).max() < 1e-3


def test_link_counts_add_up_to_the_total_with_tiny_components():
    # a tiny component raised to the minimum of 4 vertices made the counts add up to more than
    # n (19 + 4 + 4 for n = 20): the docstring promises n
    t = np.linspace(0, 2 * np.pi, 50, endpoint=False)
    ring = np.c_[np.cos(t), np.sin(t), 0 * t]
    link = [ring, 0.01 * ring + [3, 0, 0], 0.02 * ring[:, [0, 2, 1]] + [-3, 0, 0]]
    for n in (12, 20, 57):
        counts = [len(c) for c in resample(link, n)]
        assert sum(counts) == n
        assert min(counts) >= 4
    with pytest.raises(ValueError, match="at least 12"):
        resample(link, 11)


@pytest.mark.parametrize("call, option", [
    (lambda: resample(trefoil(60), 30, closed="False"), "closed"),
    (lambda: resample([trefoil(60), trefoil(60) + 9.0], 60, closed="False"), "closed"),
    (lambda: subdivide(trefoil(20), 2, closed="False"), "closed"),
    (lambda: subdivide([trefoil(20)], 2, closed=["False"]), "closed"),
    (lambda: suggest_edge_count(trefoil(60), closed="False"), "closed"),
    (lambda: equalize(trefoil(20), closed="False"), "closed"),
    (lambda: check_polygon(trefoil(60), coarseness="False"), "coarseness"),
])
def test_a_flag_given_as_text_is_refused(call, option):
    # bool("False") is True: the curve was taken as closed
    with pytest.raises(ValueError, match=rf"{option} must be True or False, got 'False' \(str\)"):
        call()


def test_resampling_an_open_polyline_takes_its_own_least_count():
    raw = trefoil(333)[:100]
    Q = resample(raw, 3, closed=False)  # was refused as "... for a closed polygon"
    np.testing.assert_array_equal(Q[[0, -1]], raw[[0, -1]])
    ln = np.linalg.norm(np.diff(Q, axis=0), axis=1)
    assert len(Q) == 3 and ln.max() / ln.min() - 1 < 1e-10
    with pytest.raises(ValueError, match=r"at least 3 vertices for an open polyline "
                                         r"\(closed=False\), got 2"):
        resample(raw, 2, closed=False)


def test_unclear_link_inputs_get_messages_that_say_why():
    P = trefoil(60)
    # numpy's "zip() argument 2 is shorter than argument 1"
    with pytest.raises(ValueError, match="n has 1 count for 2 components: give one count per "
                                         "component, or one total"):
        resample([P, P + 9.0], [30])
    # numpy's "all the input array dimensions except for the concatenation axis must match"
    for call in (lambda: resample(P.tolist(), 30), lambda: check_polygon(P.tolist()),
                 lambda: subdivide(P.tolist())):
        with pytest.raises(ValueError, match=r"is a list of 60 points, but a list is read as a "
                                             r"link.*np\.asarray\(P\)"):
            call()


@pytest.mark.parametrize("factor, words", [("2", r"factor must be a number, got '2' \(str\)"),
                                           (2.7, "factor must be a whole number, got 2.7")])
def test_subdivide_takes_a_whole_number_of_edges(factor, words):
    # int(factor) took "2" as 2 and 2.7 as 2
    with pytest.raises(ValueError, match=words):
        subdivide(trefoil(20), factor)
