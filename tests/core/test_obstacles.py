"""Obstacles: meshes the curve is repelled from and never crosses."""

import re

import numpy as np
import pytest

from moebius_addon import core
from moebius_addon.core.geometry import obstacles as ob
from moebius_addon.core.geometry.layout import as_layout
from tests.conftest import out_here_and_in_one_thread
from tests.mesh_checks import crossings, segments_closest


def torus(R=1.0, r=0.3, nu=24, nv=10):
    u = np.linspace(0, 2 * np.pi, nu, endpoint=False)
    v = np.linspace(0, 2 * np.pi, nv, endpoint=False)
    U, W = np.meshgrid(u, v, indexing="ij")
    V = np.stack([(R + r * np.cos(W)) * np.cos(U), (R + r * np.cos(W)) * np.sin(U),
                  r * np.sin(W)], -1).reshape(-1, 3)
    F = []
    for i in range(nu):
        for j in range(nv):
            a, b = i * nv + j, (i + 1) % nu * nv + j
            c, d = (i + 1) % nu * nv + (j + 1) % nv, i * nv + (j + 1) % nv
            F += [[a, b, c], [a, c, d]]
    return V, np.array(F)


def ring_around_tube(n=120):
    """A wobbly loop around the torus' tube (linked with its core circle)."""
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    P = np.stack([1.0 + 0.6 * np.cos(t) + 0.1 * np.cos(3 * t), 0.15 * np.sin(5 * t),
                  0.6 * np.sin(t)], -1)
    return core.resample(P, n)


# -- independent references (numpy, other algorithms than the module's) -----------------------


def ref_point_triangle(p, a, b, c):
    """Distance by the plane projection when it falls inside, else the nearest of the sides."""
    n = np.cross(b - a, c - a)
    n = n / np.linalg.norm(n)
    q = p - np.dot(p - a, n) * n
    M = np.array([b - a, c - a]).T
    vw, *_ = np.linalg.lstsq(M, q - a, rcond=None)
    if vw[0] >= 0 and vw[1] >= 0 and vw.sum() <= 1:
        return np.linalg.norm(p - q)

    def seg(p, x, y):
        t = np.clip(np.dot(p - x, y - x) / np.dot(y - x, y - x), 0, 1)
        return np.linalg.norm(p - (x + t * (y - x)))

    return min(seg(p, a, b), seg(p, b, c), seg(p, c, a))


def ref_crosses(p0, p1, a, b, c):
    """Segment–triangle intersection by Cramer's rule on p0 + t (p1 − p0) = a + v e1 + w e2."""
    M = np.array([p0 - p1, b - a, c - a]).T
    if abs(np.linalg.det(M)) < 1e-300:
        return False
    t, v, w = np.linalg.solve(M, p0 - a)
    return 0 <= t <= 1 and v >= 0 and w >= 0 and v + w <= 1


def ref_energy(X, tris):
    E = 0.0
    n = len(X)
    for i in range(n):
        x0, x1 = X[i], X[(i + 1) % n]
        m, ln = 0.5 * (x0 + x1), np.linalg.norm(x1 - x0)
        for T in tris:
            area = 0.5 * np.linalg.norm(np.cross(T[1] - T[0], T[2] - T[0]))
            E += ln * area / ref_point_triangle(m, *T) ** 3
    return E


# -- geometry ---------------------------------------------------------------------------------


def test_nearest_point_of_a_triangle_against_a_reference(rng):
    for _ in range(300):
        T = rng.normal(size=(1, 3, 3))
        p = rng.normal(size=3) * 2
        q = ob._closest_on_triangle(p[0], p[1], p[2], T, 0)
        assert np.linalg.norm(p - np.array(q)) == pytest.approx(ref_point_triangle(p, *T[0]),
                                                                rel=1e-9, abs=1e-12)


def test_segment_triangle_distance_against_sampling(rng):
    for _ in range(50):
        T = rng.normal(size=(1, 3, 3))
        p0, p1 = rng.normal(size=3) * 1.5, rng.normal(size=3) * 1.5
        d = np.sqrt(ob._segment_triangle_distance2(*p0, *p1, T, 0))
        if ref_crosses(p0, p1, *T[0]):
            assert d == 0.0
            continue
        s = np.linspace(0, 1, 1001)
        sampled = min(ref_point_triangle(p0 + t * (p1 - p0), *T[0]) for t in s)
        assert d <= sampled + 1e-12  # never above any point's distance
        assert d == pytest.approx(sampled, abs=2e-3 * np.linalg.norm(p1 - p0))


# -- energy and gradient ----------------------------------------------------------------------


def test_energy_against_a_slow_reference():
    V, F = torus(nu=8, nv=6)
    P = ring_around_tube(40)
    fld = ob.ObstacleField(ob.check_obstacles([(V, F)]), weight=2.0)
    X, lay = as_layout(P)
    assert fld.energy(X, lay.nxt) == pytest.approx(2.0 * ref_energy(X, V[F]), rel=1e-12)
    E, _ = fld.energy_gradient(X, lay.nxt, lay.prv)
    assert E == pytest.approx(fld.energy(X, lay.nxt), rel=1e-14)


def test_gradient_by_finite_differences(rng):
    V, F = torus(nu=10, nv=6)
    P = ring_around_tube(50)
    fld = ob.ObstacleField(ob.check_obstacles([(V, F)]))
    X, lay = as_layout(P)
    _, G = fld.energy_gradient(X, lay.nxt, lay.prv)
    for _ in range(3):
        D = rng.normal(size=X.shape)
        h = 1e-6
        fd = (fld.energy(X + h * D, lay.nxt) - fld.energy(X - h * D, lay.nxt)) / (2 * h)
        assert np.sum(G * D) == pytest.approx(fd, rel=1e-6)


# -- the flow ---------------------------------------------------------------------------------


def plate_across_the_flow(fhw_raw):
    """FHW at 600 edges, its free flow's first 20 iterates, and a small square plate (two
    triangles) across the path of the vertex that moves most from iterate 15 to 16."""
    P = core.resample(fhw_raw, 600)
    free = [P]
    core.relax(P, max_iter=20, engine="exact", callback=lambda s: free.append(s.x.copy()))
    step = np.linalg.norm(free[16] - free[15], axis=1)
    v = int(np.argmax(step))
    c = 0.5 * (free[15][v] + free[16][v])
    n = (free[16][v] - free[15][v]) / step[v]
    e1 = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    h = 3.0 * np.linalg.norm(P[1] - P[0])
    V = np.array([c + h * (a * e1 + b * e2) for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
    return P, free, V, np.array([[0, 1, 2], [0, 2, 3]])


def crossed_on_the_way(iterates, V, F):
    """Whether a straight step from one iterate to the next (what the step bound checks)
    passes through the mesh, at 7 points of each step besides the iterates themselves."""
    for A, B in zip(iterates[:-1], iterates[1:], strict=True):
        for s in np.linspace(0, 1, 9):
            if crossings(A + s * (B - A), V, F):
                return True
    return False


@pytest.mark.parametrize("weight", [1.0, 0.0])
def test_the_flow_never_crosses_the_obstacle(weight, fhw_raw):
    # with weight 0 only the step bound keeps the curve out of the plate, which the free
    # flow passes through
    P, free, V, F = plate_across_the_flow(fhw_raw)
    assert not crossings(P, V, F) and crossed_on_the_way(free, V, F)
    iterates = [P]
    r = core.relax(P, max_iter=30, obstacles=[(V, F)], obstacle_weight=weight,
                   engine="exact", callback=lambda s: iterates.append(s.x.copy()))
    E = np.asarray(r.history["energy"])  # non-increasing up to the rounding of a sum of E
    assert r.nit >= 20 and np.all(np.diff(E) <= 1e-14 * E[:-1])
    assert not crossed_on_the_way(iterates, V, F)


def test_a_ring_around_a_tube_stays_around_it():
    V, F = torus()
    P = ring_around_tube()
    core_circle = np.stack([np.cos(t := np.linspace(0, 2 * np.pi, 200, endpoint=False)),
                            np.sin(t), 0 * t], -1)
    r = core.relax(P, max_iter=30, obstacles=(V, F), engine="exact")
    assert r.fun < r.history["energy"][0] and not crossings(r.x, V, F)
    # still linked with the tube's core circle: Gauss' integral, summed over edge midpoints
    def gauss(A, B):
        dA, dB = np.roll(A, -1, 0) - A, np.roll(B, -1, 0) - B
        mA, mB = A + dA / 2, B + dB / 2
        R = mA[:, None] - mB[None]
        cr = np.cross(dA[:, None], dB[None])
        return np.sum(np.einsum("ijk,ijk->ij", R, cr) / np.linalg.norm(R, axis=2) ** 3) / (
            4 * np.pi)
    assert abs(gauss(P, core_circle)) == pytest.approx(1.0, abs=0.05)
    assert abs(gauss(r.x, core_circle)) == pytest.approx(1.0, abs=0.05)


def test_the_tree_engine_takes_obstacles_too():
    V, F = torus()
    P = ring_around_tube(300)
    r = core.relax(P, max_iter=8, obstacles=[(V, F)], engine="tree")
    assert r.nit == 8 and r.fun < r.history["energy"][0] and not crossings(r.x, V, F)


def test_every_method_takes_obstacles():
    V, F = torus()
    P = ring_around_tube(80)
    for method in core.METHODS:
        r = core.relax(P, method=method, max_iter=4, obstacles=[(V, F)], engine="exact")
        assert r.fun < r.history["energy"][0], method
        assert not crossings(r.x, V, F), method


# -- refusals ---------------------------------------------------------------------------------


def test_a_start_through_an_obstacle_is_refused_saying_where():
    V, F = torus()
    t = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    P = np.stack([1.0 + 0.5 * np.cos(t), 0.5 * np.sin(t), 0 * t], -1)  # cuts the tube twice
    with pytest.raises(ValueError, match=r"crosses an obstacle: edge \d+ passes through "
                                         r"triangle \d+ of obstacle 0"):
        core.relax(P, obstacles=[(V, F)], max_iter=1)
    # given by name (as the Blender layer gives them: object names), named so
    plate = (np.array([[5.0, 5, 5], [6, 5, 5], [5, 6, 5]]), np.array([[0, 1, 2]]))
    with pytest.raises(ValueError, match=r"passes through triangle \d+ of obstacle 'Torus'; "
                                         r"move the curve or obstacle 'Torus' so"):
        core.relax(P, obstacles={"Plate": plate, "Torus": (V, F)}, max_iter=1)
    with pytest.raises(ValueError, match=r"the curve is partly outside the container 'Box': "):
        core.relax(P, container={"Box": (V, F)}, max_iter=1)
    with pytest.raises(ValueError, match="container given as a mapping must name one mesh"):
        core.relax(P, container={"A": (V, F), "B": (V, F)}, max_iter=1)


@pytest.mark.parametrize("mesh, message", [
    ((np.zeros((0, 3)), np.zeros((0, 3), int)), "at least 3 vertices"),
    ((np.eye(3), np.zeros((0, 3), int)), "is empty: it has no triangles"),
    ((np.eye(3), np.array([[0, 1]])), r"\(K, 3\) array of triangles"),
    ((np.eye(3), np.array([[0, 1, 3]])), r"triangle 0 \[0, 1, 3\] indexes a vertex outside"),
    ((np.eye(3), np.array([[0, 1, 1]])), "repeats a vertex"),
    ((np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0.0]]), np.array([[0, 1, 2]])), "has no area"),
    ((np.array([[0, 0, np.nan], [1, 0, 0], [0, 1, 0.0]]), np.array([[0, 1, 2]])),
     "vertex 0 has a non-finite coordinate"),
    ((np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1.0]]),
      np.array([[0, 1, 2], [0, 1, 3], [0, 1, 4]])),
     "not a manifold: its edge between vertices 0 and 1 belongs to 3 triangles"),
    ((np.eye(3), np.array([[0, 1, 2.5]])), "integer vertex indices"),
])
def test_bad_meshes_are_refused_by_name(mesh, message):
    P = ring_around_tube(60)
    with pytest.raises(ValueError, match=message):
        core.relax(P + 10.0, obstacles=[mesh], max_iter=1)


def test_a_complex_mesh_is_refused():
    V, F = torus()  # was cast to its real part with a ComplexWarning
    with pytest.raises(ValueError, match="obstacle 0: V must hold real numbers, got an array of "
                                         "complex128"):
        core.relax(ring_around_tube(60), obstacles=[(V + 0j, F)], max_iter=1)


@pytest.mark.parametrize("s", [1e-300, 1e-150, 1e160, 1e300])
def test_a_scene_at_any_size_relaxes_as_at_size_one(s):
    # the triangles' areas under- or overflowed: from 1e-150 and 1e160 the torus was refused
    # as "triangle 0 [0, 10, 11] has no area"
    V, F = torus()
    P = ring_around_tube(60)
    one = core.relax(P, max_iter=2, obstacles=[(V, F)], engine="exact")
    r = core.relax(s * P, max_iter=2, obstacles=[(s * V, F)], engine="exact")
    assert r.nit == 2
    np.testing.assert_allclose(r.history["energy"], one.history["energy"], rtol=1e-12)
    np.testing.assert_allclose(r.x / s, one.x, atol=1e-12)


def test_other_bad_obstacle_arguments():
    P = ring_around_tube(60)
    V, F = torus()
    with pytest.raises(ValueError, match="obstacle 0 is not a"):
        core.relax(P, obstacles=[V], max_iter=1)
    with pytest.raises(ValueError, match="obstacles is empty"):
        core.relax(P, obstacles=[], max_iter=1)
    with pytest.raises(ValueError, match="obstacle_weight"):
        core.relax(P, obstacles=[(V, F)], obstacle_weight=-1.0, max_iter=1)
    # a circle a millionth of its radius above a large triangle's plane
    t = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    C = np.stack([np.cos(t), np.sin(t), 0 * t + 1e-6], -1)
    plane = (np.array([[-10, -10, 0], [10, -10, 0], [0, 10, 0.0]]), np.array([[0, 1, 2]]))
    with pytest.raises(ValueError, match=r"touches an obstacle: edge \d+ is 1e-06 from "
                                         r"triangle 0 of obstacle 0"):
        core.relax(C, obstacles=[plane], max_iter=1)


def _trefoil_above_plate(gap):
    """A trefoil (100 edges) ``gap`` edge lengths above a large plate."""
    P = core.knots.named("3_1", 100)
    z0 = P[:, 2].min() - gap * np.linalg.norm(P[1] - P[0])
    return P, {"Plate": (np.array([[-5, -5, z0], [5, -5, z0], [0, 5, z0]]),
                         np.array([[0, 1, 2]]))}


def test_a_start_too_near_to_move_is_refused_and_a_stall_says_what_holds_it():
    # 1.2 contact distances above a plate a trefoil passed the start check and stalled at once
    # (energy 1e9, "strands are probably jammed — use more edges"); now refused, and 1.6
    # contact distances up it relaxes
    P, plate = _trefoil_above_plate(1.2e-3)
    with pytest.raises(ValueError, match=r"touches an obstacle: edge \d+ is [\d.e-]+ from "
                                         r"triangle 0 of obstacle 'Plate', nearer than the "
                                         r"[\d.e-]+ the flow needs to move"):
        core.relax(P, obstacles=plate, max_iter=5, method="projected_gradient")
    P, plate = _trefoil_above_plate(2.5e-3)
    r = core.relax(P, obstacles=plate, max_iter=30, method="projected_gradient")
    assert r.nit == 30 and r.fun < 1e-3 * r.history["energy"][0]
    # what a stall would say of these states: the plate holds the first, nothing the second;
    # strands closer than an edge length between pins are held by the pins (a braid between
    # pinned ends), without pins a finer polygon may let them pass
    def cause(P, **options):
        return core.make_run("projected_gradient", P, refine=False, **options)._stall_cause()

    assert cause(P, obstacles=plate).startswith(
        "the curve is pressed against obstacle 'Plate' (0.0025 edge lengths from it)")
    assert cause(P).startswith("no strand touches another or an obstacle")
    t = np.linspace(0.0, 1.0, 400)
    near = core.resample([np.c_[0.1 * np.sin(np.pi * t), 0 * t, t],
                          np.c_[0.1 * np.sin(np.pi * t) + 0.02, 0 * t, t]], [41, 41],
                         closed=False)  # 0.8 edge lengths apart at most
    held = cause(near, closed=False, pinned=[[0, 40]] * 2, check=False)
    assert re.fullmatch(r"strands are pressed together \(0\.[5-8]\d* edge lengths apart\) "
                        r"between the pinned points that hold them: as untangled as the pins "
                        r"allow", held), held
    assert re.match(r"strands are pressed together \(0\.[5-8]\d* edge lengths apart\) \(a "
                    r"finer polygon may let them slide past", cause(near, closed=False,
                                                                     check=False))


def test_the_step_bound_through_the_hierarchy_is_the_all_pairs_one(rng):
    # a torus and a ring around its tube moved along random fields: the same first contact
    V, F = torus(nu=40, nv=16)
    fld = ob.ObstacleField(ob.check_obstacles([(V, F)]))
    X, lay = as_layout(ring_around_tube(150))
    hits = 0
    for scale in (0.05, 0.3, 1.0, 3.0):
        for _ in range(4):
            U = scale * rng.normal(size=X.shape)
            tree = fld.contact_time(X, U, lay.nxt, 1.0, 1e-3)
            pairs = fld.contact_time(X, U, lay.nxt, 1.0, 1e-3, search="pairs")
            assert tree == pairs
            hits += tree < 1.0
    assert hits >= 4  # most of these fields do reach the torus within τ = 1


def test_the_nearest_pair_through_the_hierarchy_is_the_all_pairs_one(rng):
    # the start check's nearest edge-triangle pair: the same edge, triangle and distance,
    # for rings moved about near, through and far from a torus
    V, F = torus(nu=40, nv=16)
    fld = ob.ObstacleField(ob.check_obstacles([(V, F)]))
    X, lay = as_layout(ring_around_tube(150))
    met = 0
    for scale in (0.0, 0.05, 0.3, 1.0, 3.0):
        for _ in range(3):
            Y = X + scale * rng.normal(size=3) + 0.02 * scale * rng.normal(size=X.shape)
            tree = fld.nearest(Y, lay.nxt)
            assert tree == fld.nearest(Y, lay.nxt, search="pairs")
            met += tree[2] == 0.0
    assert 0 < met < 15  # some of the moved rings cross the torus, most do not


def test_triangle_tree_holds_every_triangle_once(rng):
    T = rng.normal(size=(1000, 3, 3))
    order, lo, hi, left, right, bmin, bmax = ob.triangle_tree(T)
    assert np.array_equal(np.sort(order), np.arange(1000))
    leaves = left < 0
    assert np.all(hi[leaves] - lo[leaves] <= 8) and (hi[leaves] - lo[leaves]).sum() == 1000
    pts = T[order]
    for i in range(len(lo)):
        box = pts[lo[i]:hi[i]].reshape(-1, 3)
        assert np.all(box >= bmin[i]) and np.all(box <= bmax[i])


# -- the energy through the hierarchy ----------------------------------------------


def _fine_torus_and_ring():
    V, F = torus(nu=120, nv=40)  # 9 600 triangles
    return V, F, ring_around_tube(300)


@pytest.mark.parametrize("tol", [0.1, 0.01])
def test_the_hierarchy_energy_is_within_its_bound_of_all_pairs(tol):
    V, F, P = _fine_torus_and_ring()
    X, layout = as_layout(P, True)
    exact = ob.ObstacleField([(V, F)])
    tree = ob.ObstacleField([(V, F)], tol=tol)
    e0, _, _ = exact._terms(X, layout.nxt, False)
    e, _, _ = tree._terms(X, layout.nxt, False)
    assert not np.array_equal(e, e0)  # the far field was used
    # each edge's sum within 4 tol / (1 − tol) of its own (module text: both acceptances)
    bound = 4 * tol / (1 - tol)
    assert np.all(np.abs(e - e0) <= bound * e0)
    E0, G0 = exact.energy_gradient(X, layout.nxt, layout.prv)
    E, G = tree.energy_gradient(X, layout.nxt, layout.prv)
    assert abs(E - E0) <= bound * E0
    assert E == pytest.approx(tree.energy(X, layout.nxt), rel=1e-14)
    # the gradient has no proven bound; measured (docs/lab/cables-and-obstacles.md) well within tol
    assert np.linalg.norm(G - G0) <= tol * np.linalg.norm(G0)


def _box_sums(field, P):
    """Per point and node: (exact sum, L, U, G) where the node has bounds, by brute force."""
    lo, hi = field.tree[0], field.tree[1]
    A, c, *rest = field._moments
    rows = []
    for p in P:
        for node in range(len(lo)):
            r = p - c[node]
            L, U, _, G = ob._box_bounds(r[0], r[1], r[2], node, A, *rest)
            if U < 0:
                continue
            s = 0.0
            for k in range(lo[node], hi[node]):
                q = np.array(ob._closest_on_triangle(p[0], p[1], p[2], field.T, k))
                s += field.area[k] / np.linalg.norm(p - q) ** 3
            rows.append((s, L, U, G))
    return np.array(rows)


@pytest.mark.parametrize("mesh", ["torus", "skinny torus", "random triangles"])
def test_a_boxs_bounds_hold_its_nearest_point_sum(mesh, rng):
    """The proven bounds of :func:`obstacles._box_bounds` against the box's sum by brute
    force, at random points around the mesh (near boxes have no bounds), and the estimate
    between them."""
    if mesh == "random triangles":  # no smooth surface: wide cones of normals, slivers
        V = (rng.uniform(-1.0, 1.0, (200, 1, 3)) + 0.05 * rng.normal(size=(200, 3, 3)))
        V[::10, 2] = V[::10, 0] + 1e-9 * (V[::10, 1] - V[::10, 0])  # slivers
        V, F = V.reshape(-1, 3), np.arange(600).reshape(-1, 3)
    else:
        V, F = torus(nu=48, nv=16) if mesh == "torus" else torus(nu=80, nv=8, r=0.1)
    field = ob.ObstacleField([(V, F)], tol=0.1)
    rows = _box_sums(field, rng.uniform(-1.8, 1.8, (60, 3)))
    s, L, U, G = rows.T
    assert len(rows) > 1000 and np.all(L <= s * (1 + 1e-12)) and np.all(s <= U * (1 + 1e-12))
    assert np.all((L <= G) & (G <= U))
    tight = (U - L) <= 0.1 * (U + L)
    assert tight.sum() > 50  # the bounds are not vacuous far away
    assert np.median(np.abs(G - s)[tight] / s[tight]) < np.median(((U - L) / s)[tight])


def test_the_hierarchy_energy_at_tol_0_is_all_pairs():
    V, F, P = _fine_torus_and_ring()
    X, layout = as_layout(P, True)
    a = ob.ObstacleField([(V, F)]).energy_gradient(X, layout.nxt, layout.prv)
    b = ob.ObstacleField([(V, F)], tol=0.0).energy_gradient(X, layout.nxt, layout.prv)
    assert a[0] == b[0] and np.array_equal(a[1], b[1])


def test_a_run_takes_obstacle_tol():
    V, F, P = _fine_torus_and_ring()
    P = core.resample(P, 120)
    r = core.relax(P, max_iter=5, obstacles=[(V, F)], obstacle_tol=0.1, engine="exact")
    assert r.nit == 5 and not crossings(r.x, V, F)
    with pytest.raises(ValueError, match="obstacle_tol"):
        core.relax(P, max_iter=1, obstacles=[(V, F)], obstacle_tol=1.5)


def test_obstacle_tol_is_chosen_by_size_unless_given():
    V, F, P = _fine_torus_and_ring()  # 300 edges x 9 600 triangles: 2.9M pairs
    X, layout = as_layout(P, True)
    assert ob.auto_obstacle_tol(None, layout, [(V, F)]) == ob.AUTO_OBSTACLE_TOL > 0
    assert ob.auto_obstacle_tol(0.0, layout, [(V, F)]) == 0.0
    assert ob.auto_obstacle_tol(0.02, layout, [(V, F)]) == 0.02
    small = torus()  # 480 triangles: 0.14M pairs
    assert ob.auto_obstacle_tol(None, layout, [small]) == 0.0
    # the pairs of all meshes count: 8 x 480 x 300 = 1.15M
    assert ob.auto_obstacle_tol(None, layout, [small] * 8) == ob.AUTO_OBSTACLE_TOL
    for given, tol in ((None, ob.AUTO_OBSTACLE_TOL), (0, 0.0)):
        run = core.make_run("projected_gradient", P, max_iter=1, obstacles=[(V, F)],
                            obstacle_tol=given)
        assert run.engine.obstacles.tol == tol


HIERARCHY_CODE = """
import numpy as np
from tests.core.test_obstacles import _fine_torus_and_ring
from moebius_addon.core.geometry import obstacles as ob
from moebius_addon.core.geometry.layout import as_layout
V, F, P = _fine_torus_and_ring()
X, layout = as_layout(P, True)
E, G = ob.ObstacleField([(V, F)], tol=0.05).energy_gradient(X, layout.nxt, layout.prv)
OUT = [float(E).hex(), G.tobytes().hex()]
"""


def test_the_hierarchy_energy_is_bitwise_the_same_for_any_thread_count():
    here, there = out_here_and_in_one_thread(HIERARCHY_CODE)
    assert there == here


def test_the_cone_axis_is_the_principal_eigenvector():
    # written out in the kernel (numba's eigh needs scipy): against numpy's, sums of rank-one
    # normal-line matrices of every scale, and the matrices a degenerate node gives
    from moebius_addon.core.geometry.obstacles import _principal_axis

    rng = np.random.default_rng(3)
    out = np.empty(3)
    for _ in range(2000):
        n = rng.normal(size=(rng.integers(1, 6), 3))
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        w = rng.uniform(0.0, 1.0, len(n)) * 10.0 ** rng.uniform(-150, 150)
        N = np.einsum("k,ki,kj->ij", w, n, n)
        _principal_axis(N, out)
        lam = np.linalg.eigvalsh(N)
        assert np.linalg.norm(out) == pytest.approx(1.0, abs=1e-14)
        assert out @ N @ out == pytest.approx(lam[2], rel=1e-13)
    for N in (np.zeros((3, 3)), np.eye(3), np.diag([0.0, 2.0, 1.0])):
        _principal_axis(N, out)
        assert out @ N @ out == pytest.approx(np.linalg.eigvalsh(N)[2], abs=1e-15)


def _plate(z0, z1):
    """A closed box from (-2, -2, z0) to (2, 2, z1), faces outward."""
    from moebius_addon.core.compilation.warmup import _box

    return _box([-2.0, -2.0, z0], [2.0, 2.0, z1])


def test_cable_ends_may_lie_on_the_plates_they_hang_from_with_their_tangents_pinned():
    # two cables from the top face of one plate (z = 0) to the bottom face of another (z = 1),
    # bent towards each other: with their ends and end tangents pinned, the plates are
    # obstacles like any other; no free point reaches a plate, the fixed ones stay to the bit
    t = np.linspace(0.0, 1.0, 400)
    cables = core.resample([np.c_[0.15 * np.sin(np.pi * t), 0 * t, t],
                            np.c_[0.4 - 0.1 * np.sin(np.pi * t), 0.02 * np.sin(2 * np.pi * t),
                                  t]], [41, 41], closed=False)
    plates = {"Floor": _plate(-0.1, 0.0), "Ceiling": _plate(1.0, 1.1)}
    pins = [[0, 40]] * 2
    with pytest.raises(ValueError, match=r"the pinned vertex 0 of component 0 touches an "
                                         r"obstacle \(triangle \d+ of obstacle 'Floor'\) and the "
                                         r"edge beside it can move: pin its tangent too"):
        core.relax(cables, closed=False, pinned=pins, obstacles=plates, max_iter=1)
    xs = [cables]
    r = core.relax(cables, closed=False, pinned=pins, pin_tangents=True, obstacles=plates,
                   max_iter=15, tol=0.0, callback=lambda s: xs.append([p.copy() for p in s.x]))
    assert r.nit == 15 and r.fun < r.history["energy"][0]
    for k in range(2):
        fixed = [0, 1, 39, 40]
        for x in xs:
            np.testing.assert_array_equal(x[k][fixed], cables[k][fixed])
            assert np.all((x[k][2:-2, 2] > 0.0) & (x[k][2:-2, 2] < 1.0))
    # the cables moved, apart from each other (the independent check: segment distances)
    i, j = (g.ravel() for g in np.meshgrid(np.arange(40), np.arange(40), indexing="ij"))
    gap = min(segments_closest(a[i], a[i + 1], b[j], b[j + 1]).min() for a, b in xs)
    assert gap > 0.0 and np.abs(xs[-1][0] - cables[0]).max() > 1e-3
