"""The screens in front of the vertex checks (core.geometry.prechecks): never a pass where the numpy
checks refuse, and the refusals word for word those of the checks without their screens."""

import numpy as np
import pytest

from moebius_addon import core
from moebius_addon.core.geometry import layout as _layout
from moebius_addon.core.geometry.prechecks import (
    _PART_ROWS,
    equal_rows_possible,
    extent,
    short_edge_possible,
)
from moebius_addon.core.topology import knots

# below one part, several parts (of _PART_ROWS rows) of the screen's table
SIZES = [4, 9, 100, 3 * _PART_ROWS + 17]


def _walk(rng, n):
    steps = rng.normal(size=(n, 3))
    return np.cumsum(steps - steps.mean(axis=0), axis=0)


def _planar(rng, n):
    """A walk in the plane x = 0, half its zeros -0.0."""
    P = _walk(rng, n)
    P[:, 0] = np.where(rng.random(n) < 0.5, 0.0, -0.0)
    return P


def _unscreened(P, closed=True) -> str | None:
    """The message of as_checked_layout as the checks give it without their screens (and
    the scaling by numpy's unit_exponent), or None for a curve they accept."""
    X, layout = _layout.as_layout(P, closed)
    k = _layout.unit_exponent(X)
    X = np.ldexp(X, -k) if k else X
    try:
        _layout.check_counts(layout)
        _layout.check_finite(X, layout)
        _layout._distinct_by_numpy(X, layout, "the curve")
        _layout._not_touching_by_sorting(X, layout, "the curve")
    except ValueError as err:
        return str(err)
    return None


def _checked(P, closed=True) -> str | None:
    try:
        _layout.as_checked_layout(P, closed)
    except ValueError as err:
        return str(err)
    return None


def _far_apart(rng, n, gap=3):
    """Two vertices of a closed n-gon at least ``gap`` apart along it, in increasing order."""
    while True:
        i, j = sorted(int(v) for v in rng.choice(n, 2, replace=False))
        if gap <= j - i <= n - gap:
            return i, j


@pytest.mark.parametrize("n", SIZES[1:])
@pytest.mark.parametrize("shape", ["walk", "planar"])
def test_a_repeated_vertex_is_refused_as_without_the_screens(n, shape, rng):
    for _ in range(5):
        P = (_walk if shape == "walk" else _planar)(rng, n)
        i, j = _far_apart(rng, n)
        P[j] = P[i]
        c = int(rng.integers(3))  # the two copies differ in the sign of a zero
        P[i, c], P[j, c] = 0.0, -0.0
        want = (f"the curve touches itself: vertex {i} and vertex {j} are the same point; "
                f"move the strands apart")
        assert _unscreened(P) == want
        assert _checked(P) == want


@pytest.mark.parametrize("n", SIZES[2:])
def test_a_shared_midpoint_is_refused_as_without_the_screens(n, rng):
    for shape in (_walk, _planar):
        for _ in range(5):
            P = shape(rng, n)
            i, j = _far_apart(rng, n - 1, gap=3)
            # quarters: the midpoints are exact, and -0.0 + -0.0 meets -d + d = 0.0
            m = np.round(P[i] * 4) / 4
            d, e = rng.integers(1, 9, 3) / 8, rng.integers(9, 17, 3) / 8
            P[i], P[i + 1], P[j], P[j + 1] = m - d, m + d, m - e, m + e
            c = int(rng.integers(3))
            P[i, c], P[i + 1, c], P[j, c], P[j + 1, c] = -d[c], d[c], -0.0, -0.0
            want = (f"the curve touches itself: the edges after vertex {i} and after vertex "
                    f"{j} have the same midpoint; move the strands apart")
            assert _unscreened(P) == want
            assert _checked(P) == want


@pytest.mark.parametrize("n", SIZES)
def test_clean_curves_pass_the_screens(n, rng):
    for P in (_walk(rng, n), _planar(rng, n), core.resample(knots.freedman_unknot(), max(n, 8))):
        X, layout, k = _layout.as_checked_layout(P)
        assert _unscreened(P) is None and k == 0 and np.array_equal(X, P)
        assert not equal_rows_possible(X, layout.nxt, False, False)
        assert not equal_rows_possible(X, layout.nxt, True, False)
        assert not short_edge_possible(X, layout.nxt, False)


def test_neighbouring_edges_may_share_a_midpoint():
    # 2^53 + 1 and 2^53 + 0.5 both round to 2^53: the edges before and after vertex 1 have
    # one midpoint, (2^52, 0, 0), without vertices 0 and 2 being one point. The screen sees
    # equal midpoints, the sort lets neighbours pass
    P = np.array([[1.0, 0, 0], [2.0**53, 0, 0], [0.5, 0, 0], [0, 1e5, 0]])
    X, layout, _ = _layout.as_unit_layout(P)
    assert equal_rows_possible(X, layout.nxt, True, False)
    assert _checked(P) is None and _unscreened(P) is None


def test_grids_links_and_open_curves_as_without_the_screens(rng):
    # many coincidences at once: every message (which vertices, which edges) as without
    for _ in range(200):
        n = int(rng.choice([4, 6, 12, 40]))
        P = rng.integers(-2, 3, size=(n, 3)) * rng.choice([0.5, -0.5])
        closed = bool(rng.integers(2))
        if rng.random() < 0.5:
            assert _checked(P, closed) == _unscreened(P, closed)
        else:
            Q = _walk(rng, 30)
            link = [P, Q]
            assert _checked(link, [closed, True]) == _unscreened(link, [closed, True])


@pytest.mark.filterwarnings("ignore:overflow encountered")  # numpy's squares of 1e300
@pytest.mark.parametrize("scale", [1e-300, 1e-100, 1.0, 1e100, 1e300])
def test_short_edges_near_the_bound_as_without_the_screen(scale, rng):
    # an edge of 1e-13 to 1e-11 times the curve's size, about check_distinct's bound of 1e-12:
    # the screen hands those to numpy; unscaled (as invariants call it) and scaled
    for _ in range(40):
        n = int(rng.choice([10, 200]))
        X, layout = _layout.as_layout(_walk(rng, n) * scale + scale * 1e3 * rng.random())
        size = np.abs(X - X.mean(axis=0)).max()
        i = int(rng.integers(n - 1))
        X[i + 1] = X[i] + rng.normal(size=3) * size * 10.0 ** rng.uniform(-13, -11)
        want = _message(_layout._distinct_by_numpy, X, layout, "the curve")
        assert _message(_layout.check_distinct, X, layout) == want
        assert want is None or short_edge_possible(X, layout.nxt, False)
        assert _checked(X) == _unscreened(X)


def _message(f, *args) -> str | None:
    try:
        f(*args)
    except ValueError as err:
        return str(err)
    return None


def test_equal_rows_screen_against_unique(rng):
    # slow and plain: np.unique of the rows (+ 0.0: -0.0 and 0.0 are one value)
    for _ in range(300):
        n = int(rng.choice([2, 5, 30, 300, 2 * _PART_ROWS]))
        X = rng.integers(-1, 2, size=(n, 3)) * rng.choice([0.0, 0.25, 1e-300, 1e300], size=3)
        X = np.where(rng.random((n, 3)) < 0.3, -X, X)  # zeros of both signs
        if rng.random() < 0.5:
            X += rng.normal(size=(n, 3)) * (rng.random((n, 1)) < 0.9)
        nxt = np.roll(np.arange(n), -1)
        if rng.random() < 0.3:
            nxt[-1] = n - 1  # an open polyline: its dummy edge is skipped
        skip = bool(nxt[-1] == n - 1)
        real = np.flatnonzero(nxt != np.arange(n)) if skip else np.arange(n)
        M = 0.5 * (X[real] + X[nxt[real]])
        for rows, midpoints in ((X, False), (M, True)):
            repeats = len(np.unique(rows + 0.0, axis=0)) < len(rows)
            assert equal_rows_possible(X, nxt, midpoints, skip) == repeats


def test_extent_against_numpy(rng):
    for _ in range(200):
        n = int(rng.integers(1, 50))
        X = rng.normal(size=(n, 3)) * 10.0 ** rng.integers(-300, 300)
        X[rng.random((n, 3)) < 0.2] = -0.0
        if rng.random() < 0.2:
            X[rng.integers(n), rng.integers(3)] = rng.choice([np.nan, np.inf, -np.inf])
        finite, span = extent(X)
        assert finite == bool(np.isfinite(X).all())
        if finite:
            assert span == float((X.max(axis=0) / 2 - X.min(axis=0) / 2).max())
        assert _layout.as_unit_layout(X)[2] == _layout.unit_exponent(X)
