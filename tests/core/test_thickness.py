"""Tubes that never meet (``thickness=``): checked with this file's own segment distances at
every iterate and at three points of the straight path between consecutive iterates — strands
at least twice the thickness apart (parts of one strand more than π × thickness apart along
it), the container's wall at least the thickness away; on both engines, both energies and the
feasible methods; thickness 0 the same bits as no option; starts that break it refused by
name with the distance; a refined run keeps the thickness in the caller's units."""

import re

import numpy as np
import pytest

from moebius_addon import core
from moebius_addon.core.runs.engine import AUTO_TREE_FROM

FEASIBLE = ("projected_gradient", "projected_gradient_implicit", "trust_region")
ENERGIES = ("moebius", "tangent_point")
PATH = (0.25, 0.5, 0.75)  # points on the straight path between consecutive iterates


def _point_segment(x, a, b):
    """Distance of points ``x`` to segments ``a b``, rows at a time (the clamped projection)."""
    d = b - a
    dd = np.einsum("ij,ij->i", d, d)
    t = np.clip(np.einsum("ij,ij->i", x - a, d) / np.where(dd > 0, dd, 1.0), 0.0, 1.0)
    return np.linalg.norm(a + t[:, None] * d - x, axis=1)


def segment_distances(p0, p1, q0, q1):
    """Distances of the segments ``p0 p1`` and ``q0 q1``, rows at a time. The squared
    distance of ``p0 + s u`` and ``q0 + t v`` is convex on the square 0 ≤ s, t ≤ 1, so its
    least value lies on the boundary (an endpoint of one segment against the other segment:
    four point–segment distances) or at the stationary point inside (the closest points of
    the two lines, where they fall inside both segments)."""
    best = np.minimum.reduce([_point_segment(p0, q0, q1), _point_segment(p1, q0, q1),
                              _point_segment(q0, p0, p1), _point_segment(q1, p0, p1)])
    u, v, w = p1 - p0, q1 - q0, p0 - q0
    a, b, c = (np.einsum("ij,ij->i", x, y) for x, y in ((u, u), (u, v), (v, v)))
    d, e = np.einsum("ij,ij->i", u, w), np.einsum("ij,ij->i", v, w)
    den = a * c - b * b
    ok = den > 1e-12 * a * c
    safe = np.where(ok, den, 1.0)
    s = (b * e - c * d) / safe
    t = (a * e - b * d) / safe
    inside = ok & (s > 0) & (s < 1) & (t > 0) & (t < 1)
    between = np.linalg.norm(w + s[:, None] * u - t[:, None] * v, axis=1)
    return np.where(inside, np.minimum(best, between), best)


def _edges(parts, closed):
    """Stacked edges ``(p0, p1, component, index along it, edges of the component)``."""
    p0, p1, comp, idx, size = [], [], [], [], []
    for c, (X, cl) in enumerate(zip(parts, closed, strict=True)):
        Y = np.roll(X, -1, axis=0) if cl else X[1:]
        m = len(Y)
        p0.append(X[:m])
        p1.append(Y)
        comp += [c] * m
        idx += list(range(m))
        size += [m] * m
    return (np.concatenate(p0), np.concatenate(p1), np.array(comp), np.array(idx),
            np.array(size))


def _tube_pairs(start, closed, radius):
    """The pairs of edges the rule keeps ``2 × radius`` apart: every pair of two components,
    and pairs of one whose edges strictly between them span at least π × radius along it
    (the component's mean edge length at the start), the shorter way round a closed one."""
    p0, p1, comp, idx, size = _edges(start, closed)
    mean = {c: float(np.linalg.norm(p1[comp == c] - p0[comp == c], axis=1).mean())
            for c in set(comp.tolist())}
    i, j = np.triu_indices(len(p0), 1)
    same = comp[i] == comp[j]
    gap = np.abs(idx[j] - idx[i])
    wrap = np.array([closed[c] for c in comp[i]])
    gap = np.where(same & wrap, np.minimum(gap, size[i] - gap), gap)
    ell = np.array([mean[c] for c in comp[i]])
    keep = ~same | ((gap - 1) * ell >= np.pi * radius)
    return i[keep], j[keep]


def closest_tubes(parts, closed, pairs):
    """Least distance over ``pairs`` of edges of the polygon(s) ``parts``."""
    p0, p1, *_ = _edges(parts, closed)
    i, j = pairs
    return float(segment_distances(p0[i], p1[i], p0[j], p1[j]).min())


def path_points(xs):
    """Every iterate and three points of each straight path between consecutive ones."""
    out = [xs[0]]
    for a, b in zip(xs, xs[1:], strict=False):
        out += [[(1 - s) * p + s * q for p, q in zip(a, b, strict=True)] for s in PATH]
        out.append(b)
    return out


def braid(edges, radius=0.15, turns=0.5):
    """Two cables from z = 0 to z = 1 with their ends pinned, twisted half a turn about each
    other: the flow pulls each straight, pressing them together in the middle."""
    t = np.linspace(0.0, 1.0, 4000)
    return [core.resample(np.c_[radius * np.cos(a), radius * np.sin(a), t], edges + 1,
                          closed=False)
            for a in (2 * np.pi * turns * t, np.pi + 2 * np.pi * turns * t)]


def _relax(start, **options):
    xs = [start]
    res = core.relax(start, callback=lambda s: xs.append(s.x), **options)
    return res, xs


def _check_tubes(start, xs, closed, radius):
    """Every iterate and path point keeps the tubes apart; returns the least distance."""
    pairs = _tube_pairs(start, closed, radius)
    worst = min(closest_tubes(x, closed, pairs) for x in path_points(xs))
    assert worst >= 2 * radius * (1 - 1e-9), f"tubes {worst} apart, below {2 * radius}"
    return worst


#: the runs below press the tubes together: they end within this of the contact (the rule
#: was what held them, not a flow that never came near)
BINDING = 1.01


# (1) strands: the cables keep the thickness, and come closer without it


@pytest.mark.parametrize("energy", ENERGIES)
@pytest.mark.parametrize("method", FEASIBLE)
def test_cables_keep_their_thickness_exact(method, energy):
    L, r = braid(40), 0.148
    res, xs = _relax(L, closed=False, pinned=[[0, 40], [0, 40]], max_iter=6, refine=False,
                     thickness=r, method=method, energy=energy, engine="exact")
    assert res.nit >= 2
    assert _check_tubes(L, xs, [False, False], r) <= BINDING * 2 * r
    assert res.history["energy"][-1] < res.history["energy"][0]
    # without the thickness this method's flow goes below it
    _, free = _relax(L, closed=False, pinned=[[0, 40], [0, 40]], max_iter=6, refine=False,
                     method=method, energy=energy, engine="exact")
    pairs = _tube_pairs(L, [False, False], r)
    assert min(closest_tubes(x, [False, False], pairs) for x in free) < 2 * r


@pytest.mark.parametrize("energy", ENERGIES)
def test_cables_keep_their_thickness_tree(energy):
    edges = AUTO_TREE_FROM // 2 - 1  # two cables of AUTO_TREE_FROM / 2 vertices
    L, r = braid(edges), 0.148
    pairs = _tube_pairs(L, [False, False], r)
    res, xs = _relax(L, closed=False, pinned=[[0, edges], [0, edges]], max_iter=3,
                     refine=False, thickness=r, energy=energy, engine="tree")
    assert res.stats["engine"] == "tree"
    assert len(xs) >= 3
    worst = min(closest_tubes(x, [False, False], pairs) for x in path_points(xs))
    assert 2 * r * (1 - 1e-9) <= worst <= BINDING * 2 * r
    # without the thickness the same run goes below it
    _, free = _relax(L, closed=False, pinned=[[0, edges], [0, edges]], max_iter=3,
                     refine=False, energy=energy, engine="tree")
    assert min(closest_tubes(x, [False, False], pairs) for x in free) < 2 * r


# (1) the container's wall


def box(h):
    """An axis-aligned box of half sides ``h``, outward triangles."""
    V = np.array([[x, y, z] for x in (-h[0], h[0]) for y in (-h[1], h[1])
                  for z in (-h[2], h[2])], float)
    F = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    return V, F


HALF = np.array([1.2, 1.2, 0.3])


def wall_distance(X):
    """Distance of a polygon inside the box to its wall: for a point inside a box, the least
    distance to the planes of its faces; along a segment that is least at an end."""
    return float((HALF - np.abs(X)).min())


def wavy_ring(n=120):
    """A ring whose edges, made round, would not fit the box: the flow presses it outwards."""
    t = np.linspace(0, 2 * np.pi, 3000, endpoint=False)
    rr = 1 + 0.1 * np.cos(10 * t)
    return core.resample(np.c_[rr * np.cos(t), rr * np.sin(t), np.zeros_like(t)], n)


@pytest.mark.parametrize("energy", ENERGIES)
@pytest.mark.parametrize("method", FEASIBLE)
def test_ring_keeps_its_thickness_from_the_container(method, energy):
    P, r = wavy_ring(), 0.05
    opts = dict(container=box(HALF), obstacle_weight=1e-4, max_iter=8, refine=False,
                method=method, energy=energy)
    res, xs = _relax(P, thickness=r, **opts)
    assert res.nit >= 2
    assert r * (1 - 1e-9) <= min(wall_distance(x) for x in path_points(xs)) <= BINDING * r
    _check_tubes([P], [[x] for x in xs], [True], r)


# (2) thickness 0 is the run without the option, bit for bit


@pytest.mark.parametrize("engine", ["exact", "tree"])
@pytest.mark.parametrize("thickness", [0.0, 1e-12])
def test_thickness_zero_is_no_thickness(engine, thickness):
    """Thickness 0, and one below the contact distance (1e-3 edge lengths) that takes every
    path of the rule, give the iterates of a run without the option, bit for bit."""
    edges = 40 if engine == "exact" else AUTO_TREE_FROM // 2 - 1
    L = braid(edges)
    opts = dict(closed=False, pinned=[[0, edges], [0, edges]], max_iter=3, refine=False,
                engine=engine)
    a, xa = _relax(L, **opts)
    b, xb = _relax(L, thickness=thickness, **opts)
    assert a.history["energy"] == b.history["energy"] and a.nit == b.nit
    assert all(np.array_equal(p, q) for x, y in zip(xa, xb, strict=True)
               for p, q in zip(x, y, strict=True))


# (3) starts that break the thickness


def test_start_closer_than_twice_the_thickness_is_refused():
    L = braid(40)
    d = closest_tubes(L, [False, False], _tube_pairs(L, [False, False], 0.16))
    msg = (f"component 0 and component 1 are {d:.4g} apart (edges 19 and 19), below twice "
           f"the thickness 0.16")
    with pytest.raises(ValueError, match=re.escape(msg)):
        core.relax(L, closed=False, pinned=[[0, 40], [0, 40]], thickness=0.16)


def test_strand_near_itself_is_refused():
    # a racetrack: two straight stretches 0.12 apart, joined by half circles
    a = np.linspace(-np.pi / 2, np.pi / 2, 200)
    bend = np.c_[0.06 * np.cos(a), 0.06 * np.sin(a), 0 * a]
    line = np.c_[np.linspace(-1, 0, 200), np.full(200, 0.06), np.zeros(200)]
    loop = np.r_[bend, line[::-1][1:], (bend * [-1, -1, 1] + [-1, 0, 0])[1:],
                 (line * [1, -1, 1])[1:-1]]
    P = core.resample(loop, 300)
    with pytest.raises(ValueError, match=r"the curve comes within [0-9.]+ of itself \(edges "
                                         r"\d+ and \d+, more than π × thickness apart along "
                                         r"it\), below twice the thickness 0.1:"):
        core.relax(P, thickness=0.1, refine=False)


def test_tube_through_the_wall_is_refused():
    P = wavy_ring()
    d = wall_distance(P)
    with pytest.raises(ValueError, match=r"the curve's tube meets the container's wall: edge "
                                         rf"\d+ is {d:.4g} from triangle \d+ of the container, "
                                         rf"below the thickness 0.12"):
        core.relax(P, container=box(HALF), thickness=0.12)


def test_too_thick_for_the_strand_and_penalty_methods_refused():
    L = braid(40)
    with pytest.raises(ValueError, match=r"thickness too large for component 0: its 40 edges "
                                         r"are too few"):
        core.relax(L, closed=False, pinned=[[0, 40], [0, 40]], thickness=1.0)
    P = wavy_ring()
    with pytest.raises(ValueError, match="method 'lbfgs' cannot keep a thickness"):
        core.relax(P, method="lbfgs", thickness=0.01)
    with pytest.raises(ValueError, match="thickness must be"):
        core.relax(P, thickness=-1.0)


# (4) refinement keeps the thickness in the caller's units


def test_refined_run_keeps_the_thickness():
    # cables closer than an edge: the start is split before it runs, then pressed together
    L, r = braid(10, radius=0.05, turns=1.0), 0.04735
    run = core.make_run("projected_gradient", L, closed=False, pinned=[[0, 10], [0, 10]],
                        max_iter=10, thickness=r)
    xs = [run.x]
    while not run.done:
        run.step()
        xs.append(run.x)
    res = run.result()
    assert res.refinements and res.refinements[0]["edges_after"] == 40
    start = xs[0]
    assert len(start[0]) == 21
    pairs = _tube_pairs(start, [False, False], r)
    assert closest_tubes(start, [False, False], pairs) > 2 * r * 1.001
    _check_tubes(start, xs, [False, False], r)


# (5) push apart: a start whose tubes meet runs with the tubes it allows, grown to the thickness


def test_a_start_whose_tubes_meet_is_pushed_apart_to_the_thickness():
    t = np.linspace(0.0, 1.0, 400)
    start = core.resample([np.c_[0.1 * np.sin(np.pi * t), 0 * t, t],
                           np.c_[0.25 - 0.1 * np.sin(np.pi * t), 0.01 * np.sin(2 * np.pi * t),
                                 t]], [41, 41], closed=False)  # 0.05 apart in the middle
    options = dict(closed=False, pinned=[[0, 40]] * 2, thickness=0.04)
    with pytest.raises(ValueError, match="below twice the thickness 0.04"):
        core.make_run("projected_gradient", start, **options)
    run = core.make_run("projected_gradient", start, max_iter=30, tol=0.0, push_apart=True,
                        **options)
    xs, radii = [start], [run.engine.radius * run._scale]
    while run.step():
        xs.append([p.copy() for p in run.x])
        radii.append(run.engine.radius * run._scale)
    if run.nit > len(xs) - 1:  # the last iterate comes with False
        xs.append([p.copy() for p in run.x])
        radii.append(run.engine.radius * run._scale)
    assert radii[0] < 0.026 and np.all(np.diff(radii) >= 0) and radii[-1] == pytest.approx(0.04)
    pairs = _tube_pairs(start, [False, False], 0.04)
    for k in range(1, len(xs)):  # each move kept the tubes of the radius it had
        for x in path_points(xs[k - 1:k + 1]):
            assert closest_tubes(x, [False, False], pairs) >= 2 * radii[k - 1] * (1 - 1e-9)
    assert closest_tubes(xs[-1], [False, False], pairs) >= 0.08 * (1 - 1e-9)
