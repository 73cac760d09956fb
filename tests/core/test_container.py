"""Containers: a closed mesh the curve stays inside."""

import numpy as np
import pytest

from moebius_addon import core
from moebius_addon.core.geometry import container as ct
from tests.mesh_checks import crossings, ray_parity_inside


def uv_sphere(r=1.0, nu=24, nv=12, centre=(0.0, 0.0, 0.0)):
    """A closed UV sphere, triangles facing outwards, one vertex at each pole."""
    th = np.linspace(0, np.pi, nv + 1)[1:-1]
    ph = np.linspace(0, 2 * np.pi, nu, endpoint=False)
    T, PH = np.meshgrid(th, ph, indexing="ij")
    V = np.stack([np.sin(T) * np.cos(PH), np.sin(T) * np.sin(PH), np.cos(T)], -1).reshape(-1, 3)
    V = np.vstack([[0, 0, 1], V, [0, 0, -1]]) * r + np.asarray(centre)

    def ring(i, j):
        return 1 + i * nu + j % nu

    F = [[0, ring(0, j), ring(0, j + 1)] for j in range(nu)]
    for i in range(nv - 2):
        for j in range(nu):
            a, b, c, d = ring(i, j), ring(i + 1, j), ring(i + 1, j + 1), ring(i, j + 1)
            F += [[a, b, c], [a, c, d]]
    south = len(V) - 1
    F += [[south, ring(nv - 2, j + 1), ring(nv - 2, j)] for j in range(nu)]
    return V, np.array(F)


def wavy_loop(n=80):
    """An unknot squeezed into a ball of radius 0.66: its relaxed round circle (radius 1.02,
    the free flow's) does not fit in the sphere of radius 0.8 below."""
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return core.resample(np.stack([0.6 * np.cos(t), 0.6 * np.sin(t), 0.25 * np.sin(5 * t)],
                                  -1), n)


# -- independent checks (numpy; another algorithm than the module's winding number) ----------


def left_on_the_way(iterates, V, F, rng):
    """Whether a vertex of any iterate is outside, or a straight move between iterates passes
    through the wall: every vertex's path segment, and the curve at 7 points of each step."""
    for X in iterates:
        if not ray_parity_inside(X, V, F, rng).all():
            return True
    for A, B in zip(iterates[:-1], iterates[1:], strict=True):
        paths = np.stack([A, B], 1)  # each vertex's straight move, as a 2-vertex open polygon
        if any(crossings(p, V, F, closed=False) for p in paths):
            return True
        for s in np.linspace(0, 1, 9)[1:-1]:
            if crossings(A + s * (B - A), V, F):
                return True
    return False


def wall_distance(X, V, F):
    """Least distance of the vertices ``X`` to the sphere's vertices' hull, from inside: the
    distance to the planes of the triangles (a lower bound for a convex mesh)."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1)[:, None]
    return float(np.min(np.einsum("kj,nkj->nk", n, a[None] - X[:, None])))


# -- the guarantee ----------------------------------------------------------------------------


def test_the_winding_number_agrees_with_ray_parity(rng):
    V, F = uv_sphere(1.0, 16, 8)
    V = V * [1.0, 0.6, 1.4] + 0.3 * np.sin(3 * V[:, [1, 2, 0]])  # not convex, not round
    V, F = ct.check_container((V, F))
    P = rng.uniform(-1.8, 1.8, size=(400, 3))
    ours = ct.inside(V, F, P)
    assert 0 < ours.sum() < len(P)
    assert np.array_equal(ours, ray_parity_inside(P, V, F, rng))


@pytest.mark.parametrize("weight", [1.0, 0.0])
def test_the_flow_never_leaves_the_container(weight, rng):
    # the free flow rounds the loop to radius 1.02, out of a sphere of radius 0.8; with weight 0
    # only the step bound keeps it in
    V, F = uv_sphere(0.8)
    P = wavy_loop()
    free = [P]
    core.relax(P, max_iter=40, engine="exact", callback=lambda s: free.append(s.x.copy()))
    assert left_on_the_way(free, V, F, rng)
    iterates = [P]
    r = core.relax(P, max_iter=40, container=(V, F), obstacle_weight=weight, engine="exact",
                   callback=lambda s: iterates.append(s.x.copy()))
    # with weight 0 the loop jams against the wall (the run stalls there, in 14 iterations)
    E = np.asarray(r.history["energy"])  # non-increasing up to the rounding of a sum of E
    assert r.nit >= (20 if weight else 10) and np.all(np.diff(E) <= 1e-14 * E[:-1])
    assert not left_on_the_way(iterates, V, F, rng)
    if weight == 0.0:  # pressed against the wall, which it reaches within a few eps
        assert wall_distance(r.x, V, F) < 0.02


def test_the_tree_engine_and_every_method_take_a_container(rng):
    V, F = uv_sphere(0.8)
    P = wavy_loop()
    for method, engine in [("projected_gradient", "tree"), *(
            (m, "exact") for m in core.METHODS if m != "projected_gradient")]:
        iterates = [P]
        r = core.relax(P, method=method, max_iter=4, container=(V, F), engine=engine,
                       callback=lambda s, it=iterates: it.append(s.x.copy()))
        assert r.nit >= 1, method
        assert not left_on_the_way(iterates, V, F, rng), method


def test_an_inward_facing_mesh_bounds_the_same_region():
    V, F = uv_sphere(0.8)
    P = wavy_loop()
    a = core.relax(P, max_iter=5, container=(V, F), engine="exact")
    b = core.relax(P, max_iter=5, container=(V, F[:, ::-1]), engine="exact")
    assert np.array_equal(a.x, b.x)


def test_obstacles_inside_a_container():
    V, F = uv_sphere(0.8)
    Vs, Fs = uv_sphere(0.1, 8, 4)  # a small ball in the middle, inside the loop's hole
    P = wavy_loop()
    r = core.relax(P, max_iter=10, container=(V, F), obstacles=[(Vs, Fs)], engine="exact")
    assert r.nit >= 5 and not crossings(r.x, Vs, Fs) and not crossings(r.x, V, F)


# -- refusals ---------------------------------------------------------------------------------


def _refused(P, container, message, **options):
    before = (P.copy(), *(np.array(a, copy=True) for a in container))
    with pytest.raises(ValueError, match=message):
        core.relax(P, max_iter=1, container=container, **options)
    for a, b in zip(before, (P, *container), strict=True):
        assert np.array_equal(a, b)  # the arguments are left as they were


@pytest.mark.parametrize("s", [1e-300, 1e-150, 1e160, 1e300])
def test_a_container_at_any_size_holds_as_at_size_one(s):
    # the enclosed volume under- or overflowed: "the container encloses no volume" (at 1e-150
    # and 1e160 its triangles were refused as having no area first)
    V, F = uv_sphere(0.8)
    P = wavy_loop()
    one = core.relax(P, max_iter=2, container=(V, F), engine="exact")
    r = core.relax(s * P, max_iter=2, container=(s * V, F), engine="exact")
    assert r.nit == 2
    np.testing.assert_allclose(r.history["energy"], one.history["energy"], rtol=1e-12)
    np.testing.assert_allclose(r.x / s, one.x, atol=1e-12)


def test_an_open_mesh_is_refused():
    V, F = uv_sphere(0.8)
    _refused(wavy_loop(), (V, F[1:]), r"the container is not closed: its edge between "
             r"vertices \d+ and \d+ belongs to one triangle only \(3 such edges\)")


def test_an_inconsistently_oriented_mesh_is_refused():
    V, F = uv_sphere(0.8)
    F = F.copy()
    F[5] = F[5, ::-1]
    _refused(wavy_loop(), (V, F), "the container is not consistently oriented: .* Recalculate "
             "Outside")


def test_a_non_manifold_mesh_is_refused():
    V, F = uv_sphere(0.8)
    V2 = np.vstack([V, [[0.0, 0.0, 0.0]]])
    F2 = np.vstack([F, [[F[0, 0], F[0, 1], len(V)]]])  # a fin on a sphere's edge
    _refused(wavy_loop(), (V2, F2), "the container is not a manifold: its edge between "
             "vertices .* belongs to 3 triangles")


def test_a_start_outside_is_refused():
    V, F = uv_sphere(0.8)
    _refused(wavy_loop() + [5.0, 0.0, 0.0], (V, F), "the curve is outside the container: .*"
             "move the curve into the container")


def test_a_start_partly_outside_is_refused_saying_how_much():
    V, F = uv_sphere(0.8)
    P = wavy_loop() + [0.5, 0.0, 0.0]
    out = int((~ray_parity_inside(P, V, F, np.random.default_rng(1))).sum())
    assert 0 < out < len(P)
    _refused(P, (V, F), rf"the curve is partly outside the container: {out} of its {len(P)} "
             r"vertices are outside \(the first: vertex \d+\)")


def test_a_start_inside_but_through_the_wall_is_refused():
    # every vertex inside a dented sphere, one edge cutting through the dent
    V, F = uv_sphere(1.0, 24, 12)
    # (off the plane x = 0, where the dent's triangles have edges: a crossing, not a touch)
    P = np.array([[0.013, -0.3, 0.5], [0.013, 0.3, 0.5], [0.013, 0.3, -0.5],
                  [0.013, -0.3, -0.5]])
    dent = np.argmin(np.linalg.norm(V - [0.0, 0.0, 1.0], axis=1))
    V = V.copy()
    V[dent] = [0.0, 0.0, 0.2]  # the north pole pushed in, below the first edge
    assert ray_parity_inside(P, V, F, np.random.default_rng(2)).all()
    _refused(P, (V, F), "the curve crosses the container's wall: edge 0 passes through "
             "triangle .* of the container", target_lengths="keep")


def test_a_container_that_is_not_a_mesh_is_refused():
    P = wavy_loop()
    with pytest.raises(ValueError, match="the container is not a"):
        core.relax(P, max_iter=1, container=np.zeros((4, 3)))
    with pytest.raises(ValueError, match="the container is empty"):
        core.relax(P, max_iter=1, container=(np.eye(3), np.zeros((0, 3), int)))
