"""Adaptive resolution (``refine=``) and restarts (``restarts=``): core/solvers/adaptive.py."""

import numpy as np
import pytest

from moebius_addon import core
from moebius_addon.core.runs import adaptive
from moebius_addon.core.topology import knots
from moebius_addon.core.tree import moebius as barnes_hut
from tests.mesh_checks import segments_closest


def _min_gap_distance(P, gap=2):
    """Closest distance between edges at least ``gap`` apart along a component (any two of
    different components), by numpy alone: the independent check of these tests. Pairs whose
    midpoints are farther apart than their half lengths and one mean edge are left out (their
    distance is larger than a mean edge: the result is capped there)."""
    parts = P if isinstance(P, list) else [P]
    A = np.concatenate(parts)
    B = np.concatenate([np.roll(p, -1, axis=0) for p in parts])
    comp = np.concatenate([np.full(len(p), c) for c, p in enumerate(parts)])
    idx = np.concatenate([np.arange(len(p)) for p in parts])
    size = np.concatenate([np.full(len(p), len(p)) for p in parts])
    mid, half = 0.5 * (A + B), 0.5 * np.linalg.norm(B - A, axis=1)
    cap = 2.0 * half.mean()
    i, j = np.triu_indices(len(A), 1)
    near = np.linalg.norm(mid[i] - mid[j], axis=1) - half[i] - half[j] < cap
    i, j = i[near], j[near]
    d = np.abs(idx[i] - idx[j])
    d = np.minimum(d, size[i] - d)
    keep = (comp[i] != comp[j]) | (d >= gap)
    i, j = i[keep], j[keep]
    return float(min(cap, segments_closest(A[i], B[i], A[j], B[j]).min(initial=np.inf)))


# -- subdivide ---------------------------------------------------------------------------------

def test_subdivide_keeps_the_curve_its_vertices_and_equal_edges():
    P = knots.named("3_1", 60)
    Q = core.subdivide(P, 2)
    assert Q.shape == (120, 3)
    np.testing.assert_array_equal(Q[::2], P)  # the old vertices, bit for bit
    np.testing.assert_allclose(Q[1::2], 0.5 * (P + np.roll(P, -1, axis=0)), rtol=0, atol=1e-15)
    ln = np.linalg.norm(np.roll(Q, -1, axis=0) - Q, axis=1)
    assert np.ptp(ln) / ln.mean() < 1e-12
    R = core.subdivide(P, 3)
    np.testing.assert_array_equal(R[::3], P)
    np.testing.assert_array_equal(core.subdivide(P, 1), P)


def test_subdivide_open_polylines_and_links():
    L = knots.named("L2a1{1}", 60)
    S = core.subdivide(L, 2)
    assert [len(c) for c in S] == [2 * len(c) for c in L]
    line = np.c_[np.arange(5.0), np.zeros(5), np.zeros(5)]
    opened = core.subdivide(line, 2, closed=False)
    np.testing.assert_array_equal(opened[:, 0], np.arange(9) / 2)
    mixed = core.subdivide([line, knots.circle(8)], 2, closed=[False, True])
    assert [len(c) for c in mixed] == [9, 16]
    with pytest.raises(ValueError, match="factor"):
        core.subdivide(line, 0)


def test_pins_after_a_split_keep_the_fixed_pieces():
    from moebius_addon.core.geometry.layout import as_layout

    _, layout = as_layout(knots.circle(10))
    # 3 alone; 6 and 7 side by side (the edge between them is fixed: its new midpoint too);
    # 9 and 0 side by side around the closing edge
    assert adaptive._pins_after(np.array([0, 3, 6, 7, 9]), layout, 2) == [
        0, 6, 12, 13, 14, 18, 19]
    _, open_layout = as_layout(np.c_[np.arange(6.0), np.zeros(6), np.zeros(6)], closed=False)
    assert adaptive._pins_after(np.array([0, 5]), open_layout, 2) == [0, 10]


# -- refinement --------------------------------------------------------------------------------

def test_a_too_coarse_start_is_refined_not_refused():
    P = knots.named("3_1", 24)  # 27 is the least that passes the start check
    with pytest.raises(ValueError, match="too coarse"):
        core.relax(P, max_iter=2, refine=False)
    r = core.relax(P, max_iter=2)
    assert len(r.x) == 48 and r.nit == 2
    assert r.refinements[0]["iteration"] == 0
    assert (r.refinements[0]["edges_before"], r.refinements[0]["edges_after"]) == (24, 48)
    assert "start too coarse" in r.refinements[0]["reason"]
    assert "refined 24 → 48 edges at iteration 0" in r.message
    assert r.history["edges"] == [48, 48, 48]
    assert r.stats["refinements"] == 1
    # a start too coarse for max_edges, whose strands cannot be pushed apart at 16 edges
    # either, is refused as before, naming the count that works
    with pytest.raises(ValueError, match="too coarse.*at least"):
        core.relax(knots.named("3_1", 16), max_iter=2, max_edges=20)


@pytest.fixture(scope="module")
def jammed_run():
    # 5_2 at 180 edges (the old default count): the explicit flow squeezes two strands from
    # 0.73 to 0.50 edge lengths in two iterates (the edges 0.12 apart) and stalls at 60
    seen = []

    def record(state):
        seen.append(state.x.copy())

    P = knots.named("5_2", 180)
    plain = core.relax(P, max_iter=100, tol=1e-4, refine=False)
    r = core.relax(P, max_iter=100, tol=1e-4, callback=record)
    return P, plain, r, seen


def test_a_jammed_run_is_refined_and_goes_on_lower(jammed_run):
    P, plain, r, _ = jammed_run
    assert plain.status == core.Status.STALLED and "pressed together" in plain.message
    assert len(r.refinements) == 1
    ref = r.refinements[0]
    assert (ref["edges_before"], ref["edges_after"]) == (180, 360)
    assert ref["reason"].startswith("jammed")
    # it goes on from its last healthy iterate, before the squeeze, and the iterates after it
    # are dropped
    assert 0 < ref["iteration"] < plain.nit and ref["iterations_dropped"] > 0
    assert r.status != core.Status.STALLED and r.nit == 100
    assert len(r.x) == 360 and r.history["edges"][ref["iteration"]:] == [360] * (
        101 - ref["iteration"])
    assert r.fun < ref["energy_after"] - 1.0
    # energy falls at every iterate at one resolution (the refined start is the same iterate)
    E = np.array(r.history["energy"])
    assert np.all(np.diff(E[: ref["iteration"]]) < 0)
    assert np.all(np.diff(E[ref["iteration"]:]) <= 0)
    assert core.identify(r.x).names == ("5_2",)


def test_a_refined_run_never_crosses(jammed_run):
    # independent of the core's contact search: all pairs of edges of every iterate the
    # callback saw, and of the midpoint of the straight path between two iterates of one resolution
    P, _, r, seen = jammed_run
    h = np.linalg.norm(np.roll(P, -1, axis=0) - P, axis=1).mean()
    prev = P
    for x in seen:
        scale = np.linalg.norm(np.roll(x, -1, axis=0) - x, axis=1).mean()
        assert _min_gap_distance(x) > 1e-4 * scale
        if len(prev) == len(x):
            assert _min_gap_distance(0.5 * (prev + x)) > 1e-4 * scale
        prev = x
    assert h > 0


def test_a_run_that_needs_no_refinement_is_unchanged(trefoil_table):
    a = core.relax(trefoil_table, max_iter=8, refine=False)
    b = core.relax(trefoil_table, max_iter=8)
    np.testing.assert_array_equal(a.x, b.x)
    assert a.history["energy"] == b.history["energy"] and b.refinements == []


@pytest.fixture(scope="module")
def trefoil_table():
    return knots.named("3_1", 60)


def test_refinement_keeps_pins_and_link_components():
    # a too-coarse link with pins on both components: the pinned vertices keep their bits
    L = knots.named("L2a1{1}", 20)
    assert core.contact_ratio(L) < 1
    pins = [[0, 5], [3]]
    r = core.relax(L, max_iter=3, pinned=pins)
    assert r.refinements and [len(c) for c in r.x] == [2 * len(c) for c in L]
    f = r.refinements[0]["edges_after"] // r.refinements[0]["edges_before"]
    for c, idx in enumerate(pins):
        for i in idx:
            np.testing.assert_array_equal(r.x[c][f * i], L[c][i])
    assert core.identify(r.x).names[0].startswith("L2a1")


def test_refinement_of_an_open_curve_keeps_its_ends():
    t = np.linspace(0, 4 * np.pi, 400)  # two turns of a helix, 0.9 edges apart at 14 vertices
    Q = core.resample(np.c_[np.cos(t), np.sin(t), 0.12 * t], 14, closed=False)
    with pytest.raises(ValueError, match="too coarse"):
        core.relax(Q, closed=False, max_iter=2, refine=False, engine="exact")
    r = core.relax(Q, closed=False, max_iter=2, pinned=[0, 13], engine="exact")
    assert len(r.x) == 2 * 14 - 1 and r.refinements[0]["edges_after"] == 26
    np.testing.assert_array_equal(r.x[0], Q[0])
    np.testing.assert_array_equal(r.x[-1], Q[-1])


def test_refinement_on_the_tree_engine():
    P = knots.named("3_1", 24)
    r = core.relax(P, max_iter=1, engine="tree")
    assert len(r.x) == 48 and r.stats["engine"] == "tree"


def test_refine_options_are_checked():
    P = knots.named("3_1", 60)
    with pytest.raises(ValueError, match="refine must be True or False"):
        core.relax(P, refine="yes")
    with pytest.raises(ValueError, match="max_edges must be"):
        core.relax(P, max_edges=-1)
    with pytest.raises(ValueError, match="restarts need a feasible method"):
        core.relax(P, method="lbfgs", restarts=1)
    with pytest.raises(ValueError, match="restarts must be"):
        core.relax(P, restarts=-2)


# -- separated starts --------------------------------------------------------------------------

def _barrier_by_numpy(X, reach, gap):
    """The separation barrier summed over every pair of edges, by numpy alone."""
    n = len(X)
    A, B = X, np.roll(X, -1, axis=0)
    h = np.linalg.norm(B - A, axis=1).mean()
    i, j = np.triu_indices(n, 1)
    d = np.minimum(j - i, n - (j - i))
    i, j = i[d >= gap], j[d >= gap]
    x = segments_closest(A[i], B[i], A[j], B[j]) / h
    x = x[x < reach]
    return float(np.sum((1.0 / x - 1.0 / reach) ** 2))


def test_the_separation_barrier_against_numpy_and_its_gradient():
    from moebius_addon.core.geometry import push_apart as separate

    rng = np.random.default_rng(3)
    X = core.resample(knots.named("3_1", 30) * [1.0, 1.0, 0.3], 30)  # flattened: strands close
    B, G, d = separate.barrier(X)
    assert B > 0 and 0 < d < 1
    assert B == pytest.approx(_barrier_by_numpy(X, separate.REACH, 4), rel=1e-12)
    # central differences in random directions, the edge length h held (as the steps hold
    # it); the barrier is smooth where no pair enters or leaves its reach
    h = np.linalg.norm(np.roll(X, -1, axis=0) - X, axis=1).mean()
    for _ in range(5):
        V = rng.standard_normal(X.shape)
        t = 1e-6
        fd = (separate.barrier(X + t * V, h=h)[0] - separate.barrier(X - t * V, h=h)[0]) / (
            2 * t)
        assert np.sum(G * V) == pytest.approx(fd, rel=1e-5)


@pytest.fixture(scope="module")
def separated_run():
    # a braid-tangled trefoil (bench/untangle.py's trefoil-braid-49): two edges 0.003 edge
    # lengths apart; split four times it still fails the start check (3 552 edges would pass)
    P = core.tangle.tangled("3_1", 100, 149, "braid", pairs=10, conjugations=5)
    seen = []
    r = core.relax(P, method="projected_gradient_implicit", tol=1e-4, max_iter=400,
                   callback=lambda s: seen.append((s.nit, s.x.copy(), s.energy)))
    return P, r, seen


def test_strands_that_nearly_touch_are_pushed_apart(separated_run):
    P, r, seen = separated_run
    assert core.contact_ratio(P) < 0.4 and core.contact_ratio(core.subdivide(P, 4)) < 1
    ref = r.refinements[0]
    steps = ref["separation_steps"]
    assert ref["iteration"] == 0 and ref["edges_before"] == ref["edges_after"] == len(P)
    assert 0 < steps < 400 and "strands pushed apart" in ref["reason"]
    assert "(strands pushed apart)" in r.message
    # the separation's steps are the path's first iterates: energies, no gradient norms
    assert len(r.history["energy"]) == r.nit + 1
    assert np.all(np.isnan(r.history["grad_norm"][:steps]))
    assert not np.isnan(r.history["grad_norm"][steps])
    assert [s[0] for s in seen] == list(range(1, r.nit + 1))
    assert [s[2] for s in seen] == r.history["energy"][1:]
    assert core.contact_ratio(seen[steps - 1][1]) >= 1.0
    # relaxed to the table's energy at its edge count (74.5295 at 136 edges), a trefoil
    assert r.status == core.Status.CONVERGED
    assert core.identify(r.x).names == ("3_1",)
    assert r.fun == pytest.approx(74.5295, rel=1e-3)


def test_a_separated_run_never_crosses(separated_run):
    # independent of the core's contact search: every iterate, and the midpoint of the straight
    # path between two iterates of one resolution
    P, _, seen = separated_run
    prev = P
    for _, x, _ in seen:
        scale = np.linalg.norm(np.roll(x, -1, axis=0) - x, axis=1).mean()
        assert _min_gap_distance(x) > 1e-4 * scale
        if len(prev) == len(x):
            assert _min_gap_distance(0.5 * (prev + x)) > 1e-4 * scale
        prev = x


def test_a_separation_stopped_half_way_ends_where_it_is(separated_run):
    P, r, seen = separated_run
    run = core.make_run("projected_gradient_implicit", P, tol=1e-4)
    for _ in range(3):
        assert run.step()
    run.stop()
    res = run.result()
    assert res.nit == 3 and len(res.history["energy"]) == 4
    np.testing.assert_array_equal(res.x, seen[2][1])
    assert res.fun == seen[2][2]
    # its steps count as iterations: max_iter ends it half way, or leaves the run the rest
    steps = r.refinements[0]["separation_steps"]
    short = core.relax(P, method="projected_gradient_implicit", tol=1e-4, max_iter=5)
    assert short.status == core.Status.MAX_ITER and short.nit == 5
    np.testing.assert_array_equal(short.x, seen[4][1])
    more = core.relax(P, method="projected_gradient_implicit", tol=1e-4, max_iter=steps + 3)
    assert more.nit == steps + 3 and more.status == core.Status.MAX_ITER
    np.testing.assert_array_equal(more.x, seen[steps + 2][1])


def test_a_link_and_an_open_curve_are_pushed_apart():
    # a Hopf link whose second circle passes 0.03 from the first (0.19 edge lengths at 40
    # edges each; split four times still 0.65), and an open curve crossing over itself 0.03
    # edge lengths above
    s = np.linspace(0, 2 * np.pi, 40, endpoint=False) + 0.04
    L = [np.c_[np.cos(s), np.sin(s), 0 * s], np.c_[1.97 + np.cos(s), 0 * s, np.sin(s)]]
    t = np.linspace(-1, 1, 400)
    P = core.resample(np.vstack([np.c_[t, 0 * t, 0 * t], [[1, 0.5, 0.003], [0.5, 1, 0.006]],
                                 np.c_[0 * t, -t, 0.006 + 0 * t]]), 30, closed=False)
    for start, closed, engine in ((L, True, "auto"), (P, False, "exact")):
        assert core.contact_ratio(core.subdivide(start, 4, closed), closed=closed) < 1
        seen: list = []
        r = core.relax(start, closed=closed, engine=engine, max_iter=20,
                       callback=lambda st, seen=seen: seen.append(st.x))
        ref = r.refinements[0]
        assert ref["separation_steps"] > 0 and ref["edges_after"] == ref["edges_before"]
        assert core.contact_ratio(seen[ref["separation_steps"] - 1], closed=closed) >= 1
        if closed:
            assert [len(c) for c in r.x] == [40, 40]
            assert core.identify(r.x).names == core.identify(L).names
            assert min(_min_gap_distance(x) for x in seen) > 1e-3
        else:
            assert len(r.x) == 30


def test_pins_and_obstacles_are_not_pushed_past():
    # the separation would move pinned vertices and does not see meshes: such starts are
    # split as before (here not enough within max_edges: refused)
    P = core.tangle.tangled("3_1", 100, 149, "braid", pairs=10, conjugations=5)
    with pytest.raises(ValueError, match="too coarse"):
        core.relax(P, max_iter=2, pinned=[0])
    with pytest.raises(ValueError, match="too coarse"):
        core.relax(P, max_iter=2, refine=False)


# -- restarts ----------------------------------------------------------------------------------

def test_restarts_are_seeded_and_keep_the_lowest():
    P = knots.named("3_1", 60)
    opts = {"method": "projected_gradient_implicit", "tol": 1e-3, "max_iter": 60}
    plain = core.relax(P, **opts)
    a = core.relax(P, restarts=2, seed=7, **opts)
    b = core.relax(P, restarts=2, seed=7, **opts)
    c = core.relax(P, restarts=2, seed=8, **opts)
    np.testing.assert_array_equal(a.x, b.x)
    assert a.history["energy"] == b.history["energy"] and a.nit == b.nit
    assert len(a.stats["restarts"]) == 2
    assert a.fun <= plain.fun
    # each restart starts from a nudge: a different seed, different nudges
    assert [r["energy"] for r in a.stats["restarts"]] != [r["energy"] for r in c.stats["restarts"]]
    # the kept path: energy falls at every iterate but at the nudges of kept restarts
    E = np.array(a.history["energy"])
    rises = set(np.flatnonzero(np.diff(E) > 0) + 1)
    kept = {r["iteration"] for r in a.stats["restarts"] if r["kept"]}
    assert rises <= kept
    assert len(E) == a.nit + 1


def test_a_stall_with_the_strands_apart_starts_the_method_afresh(monkeypatch, trefoil_table):
    # a large ftol stalls the implicit method on the table's trefoil after 4 iterates with the
    # projected gradient still 0.157 (no two strands near: nothing to refine); started afresh
    # from that polygon at the same edge count it goes on lower
    opts = {"tol": 1e-4, "ftol": 1e-3, "max_iter": 300}
    plain = core.relax(trefoil_table, refine=False, **opts)
    assert plain.status == core.Status.STALLED
    r = core.relax(trefoil_table, **opts)
    (fresh,) = r.stats["fresh_starts"]
    assert fresh["iteration"] == plain.nit and fresh["energy"] == plain.fun
    assert r.refinements == [] and len(r.x) == 60 and set(r.history["edges"]) == {60}
    assert r.fun < plain.fun and r.nit > plain.nit and len(r.history["energy"]) == r.nit + 1
    assert np.all(np.diff(r.history["energy"]) < 0)
    # the same path up to the stall, bit for bit; the stalled polygon is the new run's start
    # (its energy as that run evaluates it, in its own scaled copy)
    np.testing.assert_array_equal(r.history["energy"][: plain.nit], plain.history["energy"][:-1])
    assert r.history["energy"][plain.nit] == pytest.approx(plain.fun, rel=1e-13)
    assert "started afresh 1 time" in r.message and r.status == core.Status.CONVERGED
    # none allowed: the stall stands, as before
    monkeypatch.setattr(adaptive, "FRESH_STARTS", 0)
    again = core.relax(trefoil_table, **opts)
    assert again.status == core.Status.STALLED and again.fun == plain.fun
    assert again.stats["fresh_starts"] == [] and "no two strands are closer" in again.message


def test_a_stall_on_the_tree_tightens_theta_for_the_fresh_start(monkeypatch, trefoil_table):
    # the same stall on the tree engine: each fresh start halves the tree's θ, not below
    # FRESH_THETA_FLOOR times the first (the tree's error, not the flow, is what stalls there)
    # (a tolerance it cannot reach: the large ftol stalls it again after every fresh start)
    opts = {"tol": 1e-9, "ftol": 1e-3, "max_iter": 300, "engine": "tree"}
    theta0 = barnes_hut.THETA
    monkeypatch.setattr(adaptive, "FRESH_THETA_FLOOR", 0.3)
    run = core.make_run("projected_gradient", trefoil_table, **opts)
    assert run.run.engine.name == "tree" and run.run.engine.theta == theta0
    seen = []
    while run.step():
        seen.append(run.run.engine.theta)
    fresh = run.result().stats["fresh_starts"]
    assert [f["theta"] for f in fresh] == [0.5 * theta0, 0.3 * theta0, 0.3 * theta0]
    # each fresh start's own energy at its start is the path's entry there (the next stall is
    # judged against it, an evaluation at the same θ)
    E = run.result().history["energy"]
    assert [f["start_energy"] for f in fresh] == [E[f["iteration"]] for f in fresh]
    assert set(seen) <= {theta0, 0.5 * theta0, 0.3 * theta0} and 0.3 * theta0 in seen
    assert f"θ tightened to {0.3 * theta0:.3g}" in run.result().message
    # the exact engine has no θ to tighten: its fresh starts record none
    r = core.relax(trefoil_table, **{**opts, "tol": 1e-4, "engine": "exact"})
    assert r.stats["fresh_starts"] and all(f["theta"] is None for f in r.stats["fresh_starts"])
