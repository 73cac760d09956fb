"""Open curves (``closed=False``): O'Hara's regularized energy of an open polygon, its
exact gradient, the metrics, and runs with pinned or free ends, a mixed link and an obstacle.
The closed runs' reference histories are in test_pins.py."""

import numpy as np
import pytest

from moebius_addon import core
from moebius_addon.core.geometry.collision import max_collision_free_step
from moebius_addon.core.geometry.layout import Layout, as_layout
from moebius_addon.core.metrics import gram as metrics
from moebius_addon.core.metrics.open import open_hs


def _slow_open_energy(P):
    """Σ over ordered pairs of edges |I − J| ≥ 2 of l_I l_J (1/|m_I − m_J|² − 1/D²), D the arc
    length between the midpoints: a plain double loop."""
    P = np.asarray(P, float)
    total = 0.0
    n = len(P) - 1
    for i in range(n):
        for j in range(n):
            if abs(i - j) < 2:
                continue
            li = np.linalg.norm(P[i + 1] - P[i])
            lj = np.linalg.norm(P[j + 1] - P[j])
            mi = (P[i] + P[i + 1]) / 2
            mj = (P[j] + P[j + 1]) / 2
            a, b = min(i, j), max(i, j)
            D = np.linalg.norm(P[a + 1] - P[a]) / 2 + np.linalg.norm(P[b + 1] - P[b]) / 2
            for k in range(a + 1, b):
                D += np.linalg.norm(P[k + 1] - P[k])
            total += li * lj * (1 / np.sum((mi - mj) ** 2) - 1 / D**2)
    return total


def _slow_cross(P, Q, closed_q):
    """O'Hara kernel between an open polyline P and a polygon Q (ordered pairs both ways)."""
    eP = [(P[i], P[i + 1]) for i in range(len(P) - 1)]
    nq = len(Q) if closed_q else len(Q) - 1
    eQ = [(Q[i], Q[(i + 1) % len(Q)]) for i in range(nq)]
    s = 0.0
    for a0, a1 in eP:
        for b0, b1 in eQ:
            d = (a0 + a1) / 2 - (b0 + b1) / 2
            s += np.linalg.norm(a1 - a0) * np.linalg.norm(b1 - b0) / np.dot(d, d)
    return 2 * s


def _wiggly(n=14, seed=1, noise=0.05):
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 3, n)
    return np.c_[np.cos(2 * t), np.sin(3 * t), t] + noise * rng.standard_normal((n, 3))


def _tangled(n=60):
    """An open coil: three turns of a helix along a segment (knotted-looking, not straight)."""
    t = np.linspace(0, 1, 400)
    pts = np.c_[t * 4, 0.6 * np.sin(6 * np.pi * t), 0.6 * np.cos(6 * np.pi * t) - 0.6]
    return core.resample(pts, n, closed=False)


def _fd(f, P, h=1e-6):
    g = np.zeros_like(P)
    for i in range(len(P)):
        for d in range(3):
            Q = P.copy()
            Q[i, d] += h
            R = P.copy()
            R[i, d] -= h
            g[i, d] = (f(Q) - f(R)) / (2 * h)
    return g


def test_energy_matches_slow_reference():
    for seed in range(3):
        P = _wiggly(seed=seed, noise=0.1)  # not equilateral
        E = core.moebius_energy(P, closed=False)
        assert E == pytest.approx(_slow_open_energy(P), rel=1e-12)
        assert E > 0


def test_gradient_by_finite_differences():
    for seed in (0, 4):
        P = _wiggly(seed=seed, noise=0.15)
        g = core.moebius_gradient(P, closed=False)
        gf = _fd(_slow_open_energy, P)
        assert np.abs(g - gf).max() <= 1e-6 * np.abs(gf).max()


def test_straight_polyline_energy_and_gradient_zero():
    x = np.cumsum(np.r_[0, np.linspace(1, 2, 11)])  # unequal edges on one line
    P = np.c_[x, 2 * x, -x] + [1, 2, 3]
    assert core.moebius_energy(P, closed=False) == pytest.approx(0, abs=1e-12)
    assert np.abs(core.moebius_gradient(P, closed=False)).max() < 1e-10
    # a bend raises it
    Q = P.copy()
    Q[6] += [0.5, 0, 0.5]
    assert core.moebius_energy(Q, closed=False) > 1e-3


def test_mixed_link_energy_and_gradient():
    P = _wiggly(n=10, noise=0.1)
    t = np.linspace(0, 2 * np.pi, 9, endpoint=False)
    C = np.c_[np.cos(t), np.sin(t), np.zeros(9)] * 0.8 + [0.3, 0.2, 1.5]
    C[2] += [0, 0, 0.1]
    link = [P, C]
    E = core.moebius_energy(link, closed=[False, True])
    ref = _slow_open_energy(P) + core.moebius_energy(C) + _slow_cross(P, C, True)
    assert E == pytest.approx(ref, rel=1e-12)
    g = core.moebius_gradient(link, closed=[False, True])

    def f(X):
        return core.moebius_energy([X[:10], X[10:]], closed=[False, True])

    gf = _fd(f, np.vstack(link))
    assert np.abs(np.vstack(g) - gf).max() <= 1e-6 * np.abs(gf).max()


def test_open_hs_agrees_with_closed_kernel_on_closed_components():
    # the open metric's assembly, run with every component flagged closed, is the closed matrix
    P = core.knots.torus_knot(2, 3, 40)
    X, lay = as_layout([P, P + 3.0])
    flagged = Layout(lay.starts, lay.nxt, lay.prv, lay.comp, lay.is_link, np.ones(2, bool))
    ln = np.linalg.norm(X[lay.nxt] - X, axis=1)
    for low in (1.0, 0.0):
        for order in (1.5, 1.75):  # the paper's, and the tangent-point default's
            A = metrics._hs_family(X, lay, ln, ln.sum(), None, low, order)
            B = open_hs(X, flagged, ln, low, metrics.kernel_exponent(order))
            assert np.abs(B - A).max() <= 1e-12 * np.abs(A).max()


@pytest.mark.parametrize("metric", metrics.METRICS)
def test_gram_spd_for_open_curves(metric):
    straight = np.c_[np.linspace(0, 1, 12), np.zeros(12), np.zeros(12)]
    for P in (_wiggly(n=30), straight):
        A = core.gram_matrix(metric, P, closed=False)
        assert np.isfinite(A).all()
        assert np.abs(A - A.T).max() <= 1e-12 * np.abs(A).max()
        assert np.linalg.eigvalsh(A).min() > 0


def _check_path(history_x, closed):
    """No straight step between consecutive iterates touches itself (contact time = 1)."""
    for a, b in zip(history_x, history_x[1:], strict=False):
        if isinstance(a, list):
            U = [x - y for x, y in zip(a, b, strict=True)]
        else:
            U = a - b
        tau = max_collision_free_step(a, U, 1.0) if closed is True else _open_step(a, U, closed)
        assert tau == 1.0


def _open_step(P, U, closed):
    from moebius_addon.core.geometry.collision import contact_time_x
    from moebius_addon.core.geometry.layout import as_layout

    X, lay = as_layout(P, closed)
    Ux, _ = as_layout(U, closed)
    ln = np.linalg.norm(X[lay.nxt] - X, axis=1)[lay.real]
    return contact_time_x(X, Ux, lay, 1.0, 1e-6 * ln.mean(), search="pairs")


@pytest.mark.parametrize("method", ["projected_gradient", "projected_gradient_implicit",
                                    "trust_region"])
def test_flow_with_pinned_ends(method):
    P = _tangled(60)
    E0 = core.moebius_energy(P, closed=False)
    xs = [P]
    res = core.relax(P, closed=False, pinned=[0, 59], method=method, max_iter=40,
                     callback=lambda s: xs.append(s.x))
    x = res.x
    assert np.array_equal(x[[0, -1]], P[[0, -1]])
    assert all(np.array_equal(y[[0, -1]], P[[0, -1]]) for y in xs)
    ln = np.linalg.norm(np.diff(x, axis=0), axis=1)
    l0 = np.linalg.norm(np.diff(P, axis=0), axis=1).mean()
    assert np.abs(ln / l0 - 1).max() < 1e-8
    E = res.history["energy"]
    assert all(b <= a + 1e-12 for a, b in zip(E, E[1:], strict=False))
    assert res.fun < 0.1 * E0  # relaxed towards a smooth arc
    assert res.fun == pytest.approx(core.moebius_energy(x, closed=False), rel=1e-9)
    _check_path(xs, False)


@pytest.mark.parametrize("metric", ["hs", "h1", "h2", "l2", "hs_pure"])
def test_metrics_relax_open_curve(metric):
    P = _tangled(40)
    res = core.relax(P, metric=metric, closed=False, pinned=[0, 39], max_iter=15)
    assert res.fun < res.history["energy"][0]
    assert np.array_equal(res.x[[0, -1]], P[[0, -1]])


def test_free_ends_straighten():
    P = core.resample(_wiggly(n=40, noise=0.0), 40, closed=False)
    xs = [P]
    res = core.relax(P, closed=False, max_iter=60, callback=lambda s: xs.append(s.x))
    E = res.history["energy"]
    assert res.fun < 0.2 * E[0]
    ln = np.linalg.norm(np.diff(res.x, axis=0), axis=1)
    assert np.abs(ln / ln.mean() - 1).max() < 1e-8
    # barycenter (length-weighted) kept: nothing pins the curve
    def bary(X):
        ln = np.linalg.norm(np.diff(X, axis=0), axis=1)
        return (ln[:, None] * (X[1:] + X[:-1]) / 2).sum(axis=0)
    assert np.allclose(bary(res.x), bary(P), atol=1e-8)
    _check_path(xs, False)


def test_pin_tangents_on_open_ends():
    P = _tangled(40)
    res = core.relax(P, closed=False, pinned=[0, 39], pin_tangents=True, max_iter=10)
    assert np.array_equal(res.x[[0, 1, 38, 39]], P[[0, 1, 38, 39]])
    assert not np.array_equal(res.x[2], P[2])


def test_mixed_link_relaxes():
    P = _tangled(40)
    t = np.linspace(0, 2 * np.pi, 30, endpoint=False)
    C = np.c_[np.zeros(30), 1.5 * np.cos(t), 1.5 * np.sin(t)] * 0.6 + [2.0, 0, -0.6]
    C = core.resample(C, 30)
    link = [P, C]
    core.check_polygon(link, closed=[False, True])
    xs = [link]
    res = core.relax(link, closed=[False, True], pinned=[[0, 39], []], max_iter=15,
                     callback=lambda s: xs.append(s.x))
    assert isinstance(res.x, list) and len(res.x) == 2
    assert np.array_equal(res.x[0][[0, -1]], P[[0, -1]])
    E = res.history["energy"]
    assert E[-1] < E[0]
    assert all(b <= a + 1e-12 for a, b in zip(E, E[1:], strict=False))
    _check_path(xs, [False, True])


def test_open_curve_with_obstacle():
    P = _tangled(40)
    # a plate below the coil that the free flow would not need; it must stay clear of it
    V = np.array([[-1, -2, -1.6], [5, -2, -1.6], [5, 2, -1.6], [-1, 2, -1.6]], float)
    F = np.array([[0, 1, 2], [0, 2, 3]])
    xs = [P]
    res = core.relax(P, closed=False, pinned=[0, 39], obstacles=[(V, F)], max_iter=15,
                     callback=lambda s: xs.append(s.x))
    assert res.fun < res.history["energy"][0]
    assert all(np.min(x[:, 2]) > -1.6 for x in xs)
    g = core.moebius_gradient(P, closed=False)
    assert np.isfinite(g).all()


def test_refusals():
    P = _tangled(40)
    with pytest.raises(ValueError, match="needs at least 3"):
        core.relax(P[:2], closed=False)
    with pytest.raises(ValueError, match="needs at least 3"):
        core.moebius_energy(P[:2], closed=False)
    for method in ("ncg", "lbfgs", "nesterov"):
        with pytest.raises(ValueError, match=f"method '{method}' cannot relax open curves"):
            core.relax(P, closed=False, method=method)
    with pytest.raises(ValueError, match="closed must be a bool"):
        core.relax(P, closed="no")
    with pytest.raises(ValueError, match="closed must be a bool or one bool per component"):
        core.relax([P, P + 5], closed=[False])
    with pytest.raises(ValueError, match="closed must be a bool"):
        core.moebius_energy(P, closed=[False])


def test_auto_engine_takes_exact_for_open_curves():
    P = _tangled(40)
    run = core.make_run("projected_gradient", P, closed=False, engine="auto", max_iter=1)
    assert run.engine.name == "exact"


def test_check_polygon_open():
    P = _tangled(40)
    core.check_polygon(P, closed=False)  # the ends far apart along the curve: no contact
    # the ends brought together are close in space but far along the polyline: refused
    t = np.linspace(0, 2 * np.pi * 0.97, 30)
    Q = np.c_[np.cos(t), np.sin(t), np.zeros(30)]
    with pytest.raises(ValueError, match="too coarse"):
        core.check_polygon(Q, closed=False)
    core.check_polygon(Q, coarseness=False, closed=False)


def test_too_coarse_open_curve_is_refused_as_too_coarse():
    # coils that double back: no resampling to suggest succeeds (equalize fails on the way);
    # the refusal must still say what is wrong, not that equalizing failed
    x = np.linspace(-2.5, 2.5, 4000)
    coil = np.clip((x + 2.1) / 1.3, 0, 1) * (x < -0.8)
    w = 0.3 * np.sin(np.pi * coil)
    phase = 4 * np.pi * coil
    P = np.stack([x - 0.25 * np.sin(phase) * (coil > 0), w * np.cos(phase) - w,
                  w * np.sin(phase)], -1)
    Q = core.resample(P, 240, closed=False)
    with pytest.raises(ValueError, match="too coarse for its shape"):
        core.check_polygon(Q, closed=False)
