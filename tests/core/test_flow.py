"""The projected Sobolev-gradient flow: reference behaviour, invariants after every iteration,
stopping, determinism."""

import re

import numpy as np
import pytest

from moebius_addon import core
from moebius_addon.core import METRICS, Relaxation, Status, moebius_energy, relax, resample
from moebius_addon.core.runs import base, projected
from moebius_addon.core.runs.engine import ENGINES, DenseEngine, make_engine
from moebius_addon.core.topology import knots
from tests.conftest import ngon, trefoil


@pytest.fixture(scope="module")
def trefoil300():
    return resample(trefoil(600), 300)


def linking_number(A, B):
    """Gauss linking integral by the midpoint rule (exact up to discretisation error)."""
    ea, eb = np.roll(A, -1, 0) - A, np.roll(B, -1, 0) - B
    ma, mb = A + ea / 2, B + eb / 2
    d = ma[:, None] - mb[None]
    cr = np.cross(ea[:, None], eb[None])
    return float(np.sum(np.einsum("ijk,ijk->ij", d, cr) / np.linalg.norm(d, axis=2) ** 3)
                 / (4 * np.pi))


def test_trefoil_settles_at_the_reference_energy(trefoil300):
    # docs/design.md: with hs at 300 edges the energy settles near 74.436 within a few dozen
    # iterations (the continuous minimum is about 74.41)
    r = relax(trefoil300, metric="hs", max_iter=40)
    assert r.success, r.message
    assert 74.42 < r.fun < 74.45
    assert r.nit <= 40
    assert r.history["energy"][0] == pytest.approx(moebius_energy(trefoil300))


def test_every_iterate_is_feasible_and_energy_decreases(trefoil300):
    r = relax(trefoil300, max_iter=15, backproject_tol=1e-10)
    h = r.history
    assert len(h["energy"]) == r.nit + 1 == len(h["seconds"]) == len(h["step"])
    assert max(h["constraint_residual"][1:]) <= 1e-10
    assert np.all(np.diff(h["energy"]) <= 0)
    ln = np.linalg.norm(np.roll(r.x, -1, 0) - r.x, axis=1)
    ln0 = np.linalg.norm(np.roll(trefoil300, -1, 0) - trefoil300, axis=1)
    np.testing.assert_allclose(ln, ln0.mean(), rtol=1e-9)
    # the weighted barycenter stays put
    w = (ln + np.roll(ln, 1)) / 2
    np.testing.assert_allclose(w @ r.x / w.sum(), w @ trefoil300 / w.sum(), atol=1e-9)


@pytest.mark.parametrize("metric", METRICS)
def test_every_metric_decreases_the_energy(metric):
    P = resample(trefoil(300), 120)
    r = relax(P, metric=metric, max_iter=5)
    assert r.nit == 5
    assert r.fun < r.history["energy"][0] - 0.1
    assert max(r.history["constraint_residual"]) <= 1e-10


def test_sobolev_metric_beats_l2(trefoil300):
    hs = relax(trefoil300, metric="hs", max_iter=20)
    l2 = relax(trefoil300, metric="l2", max_iter=20)
    assert hs.fun < l2.fun - 0.3


def test_callback_stops_cleanly(trefoil300):
    seen = []

    def cb(state):
        seen.append((state.nit, state.energy, state.x.shape))
        return state.nit == 3

    r = relax(trefoil300, max_iter=50, callback=cb)
    assert r.nit == 3 and r.success and "callback" in r.message
    assert r.status == Status.STOPPED == 5
    assert [s[0] for s in seen] == [1, 2, 3]
    assert seen[-1][1] == r.fun and seen[-1][2] == (300, 3)


def test_callback_sees_the_last_iterate(trefoil300):
    # the run ends on the energy target at an accepted iterate: the callback sees that one too
    seen = []
    r = relax(trefoil300, max_iter=50, energy_target=75.0, callback=lambda s: seen.append(s))
    assert r.success and "target" in r.message
    assert [s.nit for s in seen] == list(range(1, r.nit + 1))
    assert seen[-1].energy == r.fun <= 75.0


def test_single_precision_falls_back_to_double_when_it_is_not_definite():
    # h2 at 600 vertices has κ(A) beyond single precision: float32 Cholesky fails, the run
    # must switch to double precision instead of raising
    P = resample(trefoil(1200), 600)
    with np.errstate(all="raise"):  # and no overflow warnings from wild trial steps
        r = relax(P, metric="h2", max_iter=2, precision="single")
    assert r.nit == 2 and r.fun < r.history["energy"][0]


def test_stepper_and_stop(trefoil300):
    run = Relaxation(trefoil300, max_iter=100)
    energies = [run.energy]
    while run.step():
        energies.append(run.energy)
        if run.nit == 4:
            run.stop("cancelled")
    res = run.result()
    assert res.nit == 4 and res.message == "cancelled" and res.success
    assert res.status == Status.STOPPED
    assert energies == res.history["energy"]
    assert not run.step()


def test_deterministic(trefoil300):
    a = relax(trefoil300, max_iter=6)
    b = relax(trefoil300.copy(), max_iter=6)
    np.testing.assert_array_equal(a.x, b.x)
    assert a.history["energy"] == b.history["energy"]


def test_early_armijo_test_changes_no_iterate(monkeypatch, fhw_raw):
    # trials that miss Armijo by far are rejected at |Φ| ≤ 1e-5, before the last Newton steps
    # of their back-projection: the same iterates with fewer steps
    P = resample(fhw_raw, 600)

    def run():
        r = Relaxation(P, max_iter=40)
        calls = []
        solve = r.engine.pseudo_inverse
        r.engine.pseudo_inverse = lambda phi: calls.append(1) or solve(phi)
        while r.step():
            pass
        return r, len(calls)

    early, n_early = run()
    monkeypatch.setattr(projected, "_EARLY", 0.0)  # back-project every trial to the end first
    full, n_full = run()
    assert early.nit == full.nit == 40 and early.rejected == full.rejected > 20
    assert early.history["energy"] == full.history["energy"]
    np.testing.assert_array_equal(early.X, full.X)
    assert n_early < 0.85 * n_full


def test_scale_and_position_do_not_matter(trefoil300):
    a = relax(trefoil300, max_iter=6)
    b = relax(250.0 * trefoil300 + [1e3, -5.0, 2.0], max_iter=6)
    assert a.nit == b.nit
    np.testing.assert_allclose(a.history["energy"], b.history["energy"], rtol=1e-9)
    np.testing.assert_allclose((b.x - [1e3, -5.0, 2.0]) / 250.0, a.x, atol=1e-7)


def test_reused_factorization_follows_the_exact_flow():
    P = resample(trefoil(900), 450)
    exact = relax(P, max_iter=6, reuse_factorization=False)
    reused = relax(P, max_iter=6, reuse_factorization=True)
    assert reused.stats["factorizations"] < exact.stats["factorizations"]
    # same projected gradients (GMRES to 1e-10); the back-projection with a stale factorization
    # is a different chord iteration and lands on a neighbouring feasible point (~1e-6 apart)
    np.testing.assert_allclose(reused.history["energy"], exact.history["energy"], rtol=1e-5)


def test_energy_target_and_iteration_limit(trefoil300):
    r = relax(trefoil300, max_iter=50, energy_target=75.0)
    assert r.success and "target" in r.message and r.fun <= 75.0
    assert r.status == Status.TARGET == 1
    assert r.history["energy"][-2] > 75.0
    r = relax(trefoil300, max_iter=2)
    assert not r.success and "maximum number of iterations" in r.message and r.nit == 2
    assert r.status == Status.MAX_ITER == 2


def test_status_codes_of_the_other_endings(trefoil300):
    assert relax(trefoil300, max_iter=500).status == Status.CONVERGED == 0
    assert relax(trefoil300, max_iter=500, max_seconds=0.0).status == Status.TIME == 3
    run = Relaxation(trefoil300, max_iter=50)
    run.step()
    res = run.result()  # taken early
    assert res.status == Status.NOT_FINISHED == 6 and "not finished" in res.message
    assert (Status.STALLED, Status.STOPPED) == (4, 5)


def test_engine_by_name(trefoil300):
    r = relax(trefoil300, max_iter=3)  # "auto": exact below engine.AUTO_TREE_FROM edges
    assert r.stats["engine"] == "exact" and ENGINES["exact"] is DenseEngine
    # theta is accepted for every engine and ignored by the exact one: the same bits
    t = relax(trefoil300, max_iter=3, engine="exact", theta=0.5)
    np.testing.assert_array_equal(t.x, r.x)
    tree = relax(trefoil300, max_iter=3, engine="tree", theta=0.5)
    assert tree.stats["engine"] == "tree" and tree.fun < tree.history["energy"][0]
    assert not np.array_equal(tree.x, r.x)  # the tree's energy is another function
    with pytest.raises(ValueError, match="unknown engine 'fast'; choose one of auto, exact, tree"):
        relax(trefoil300, max_iter=3, engine="fast")
    for theta in (float("nan"), -1.0, 2.0):
        with pytest.raises(ValueError, match="theta"):
            relax(trefoil300, max_iter=3, engine="tree", theta=theta)
    with pytest.raises(ValueError, match="unknown engine"):
        make_engine("fast", None, "hs")


def test_hopf_link_stays_linked_and_rounds_up():
    A = resample(ngon(64) + 0.15 * np.c_[np.zeros(64), np.zeros(64), np.sin(np.arange(64))], 48)
    B = ngon(48)[:, [0, 2, 1]] * 1.2 + [1.0, 0.0, 0.0]
    r = relax([A, B], max_iter=30)
    assert isinstance(r.x, list) and [len(c) for c in r.x] == [48, 48]
    assert r.fun < r.history["energy"][0]
    assert abs(linking_number(*r.x)) == pytest.approx(1.0, abs=0.05)
    assert max(r.history["constraint_residual"][1:]) <= 1e-10


def test_bad_inputs_raise_with_advice(trefoil300):
    with pytest.raises(ValueError, match="not equilateral.*resample"):
        relax(trefoil(100), max_iter=1)
    r = relax(trefoil(100), max_iter=2, target_lengths="keep")
    assert r.nit == 2
    with pytest.raises(ValueError, match="unknown metric"):
        relax(trefoil300, metric="w32")
    bad = trefoil300.copy()
    bad[10] = np.inf
    with pytest.raises(ValueError, match="NaN or infinite"):
        relax(bad)


_BAD_OPTIONS = [
    ("tol", np.nan, "tol must be a finite number >= 0"),  # ignored
    ("energy_target", np.nan, "energy_target must be a finite number"),  # ignored
    ("max_iter", -1, "max_iter must be a finite number >= 0"),  # ran no iteration
    ("max_iter", 2.5, "max_iter must be a whole number"),  # ran 2
    ("max_seconds", -1.0, "max_seconds must be a finite number >= 0"),  # "budget used up"
    ("initial_step", np.inf, "initial_step must be a finite number > 0"),
    ("tol", "small", "tol must be a number"),
]
# options of the feasible methods (the penalty methods ignore them)
_BAD_FEASIBLE_OPTIONS = [
    ("growth", np.nan, "growth must be a finite number >= 1"),  # ran, then "stalled"
    ("backproject_tol", 0.0, "backproject_tol must be a finite number > 0"),  # "stalled"
]


@pytest.mark.parametrize(("method", "option", "value", "says"),
                         [("projected_gradient", *bad) for bad in _BAD_OPTIONS
                          + _BAD_FEASIBLE_OPTIONS] + [("lbfgs", *bad) for bad in _BAD_OPTIONS])
def test_bad_options_are_refused_by_name(trefoil300, method, option, value, says):
    options = {"max_iter": 3, option: value}
    with pytest.raises(ValueError, match=re.escape(says)):
        relax(trefoil300, method=method, **options)


def test_bad_penalty_is_refused_by_name(trefoil300):
    with pytest.raises(ValueError, match="penalty must be a finite number >= 0"):
        relax(trefoil300, method="lbfgs", penalty=np.nan)


def test_sizes_beyond_memory_are_refused_before_any_work(monkeypatch, trefoil300):
    # this machine has room for a 300-gon; pretend it has 1 MB (32 bytes × 300² = 2.9 MB)
    monkeypatch.setattr(base, "_physical_memory", lambda: 1e6)
    with pytest.raises(ValueError, match=r"300 vertices need about 0.0 GB.*at most 153 vertices"):
        relax(trefoil300, max_iter=1)
    with pytest.raises(ValueError, match="at most 153 vertices"):
        relax(trefoil300, method="lbfgs", max_iter=1)
    assert relax(resample(trefoil300, 150), max_iter=1).nit == 1
    monkeypatch.setattr(base, "_physical_memory", lambda: None)  # system does not say: no check
    assert relax(trefoil300, max_iter=1).nit == 1


def test_single_precision_factorization_gives_the_double_precision_flow():
    P = resample(trefoil(900), 420)
    double = relax(P, max_iter=5, precision="double")
    single = relax(P, max_iter=5, precision="single")
    # the projected gradients agree to the GMRES tolerance; the back-projection (a chord
    # iteration with the float32 factors) lands on a neighbouring feasible point, ~1e-8 apart
    np.testing.assert_allclose(single.history["energy"], double.history["energy"], rtol=1e-8)
    np.testing.assert_allclose(single.x, double.x, atol=1e-6 * np.abs(P).max())
    assert max(single.history["constraint_residual"][1:]) <= 1e-10
    assert all(k >= 2 for k in single.stats["krylov_iterations"])  # refined, not raw float32


def test_absurd_sizes_relax_like_size_one(trefoil300):
    a = relax(trefoil300, max_iter=4)
    for k in (-960, 960):  # a power of 4: the same iterates to the last bit
        b = relax(np.ldexp(trefoil300, k), max_iter=4)
        assert b.history["energy"] == a.history["energy"]
        np.testing.assert_array_equal(np.ldexp(b.x, -k), a.x)
    for s in (1e-300, 1e300):  # lengths squared leave the float64 range here
        b = relax(s * trefoil300, max_iter=4)
        assert b.nit == a.nit and np.isfinite(b.x).all()
        np.testing.assert_allclose(b.history["energy"], a.history["energy"], rtol=1e-9)
        np.testing.assert_allclose(b.x / s, a.x, atol=1e-7)


def test_sizes_whose_dense_factorization_crashes_are_refused():
    # numpy's OpenBLAS segfaulted in np.linalg.cholesky at 16 000 and 17 000 rows (2 threads):
    # refuse before any work, naming the size that runs, in every door that factors
    from moebius_addon.core import sobolev_gradient

    P = ngon(base.DENSE_MAX_VERTICES + 1)
    for call in (lambda: relax(P, engine="exact", max_iter=1), lambda: sobolev_gradient(P),
                 lambda: relax(P, engine="tree", max_iter=1, edge_lengths=False)):
        with pytest.raises(ValueError, match=f"at most {base.DENSE_MAX_VERTICES} vertices"):
            call()
    with pytest.raises(ValueError, match="keep both constraints"):
        relax(P, engine="tree", max_iter=1, barycenter=False)


def test_check_size_says_before_any_work_what_a_run_would_refuse():
    # the Blender layer asks this before it converts or keys anything: same rule as the run
    from moebius_addon.core import check_size

    n = base.DENSE_MAX_VERTICES + 1
    for metric, method, engine in (("hs", "projected_gradient", "exact"),
                                   ("h2", "projected_gradient", "exact"),
                                   ("h2", "lbfgs", "tree")):
        with pytest.raises(ValueError, match=f"at most {base.DENSE_MAX_VERTICES} vertices"):
            check_size(n, metric, method, engine)
        with pytest.raises(ValueError, match=f"at most {base.DENSE_MAX_VERTICES} vertices"):
            relax(ngon(n), metric=metric, method=method, engine=engine, max_iter=1)
    for metric in ("h2", "h1", "hs", "hs_pure"):  # the tree engine holds nothing dense
        check_size(n, metric, "projected_gradient", "tree")
        check_size(n, metric, "projected_gradient_implicit", "auto")
    with pytest.raises(ValueError, match="keep both constraints"):
        check_size(n, "hs", "projected_gradient", "tree", barycenter=False)
    for bad, word in ((("hs", "projected_gradient", "nope"), "engine"),
                      (("nope", "projected_gradient", "auto"), "metric"),
                      (("hs", "nope", "auto"), "method")):
        with pytest.raises(ValueError, match=f"unknown {word}"):
            check_size(100, *bad)


def test_far_apart_link_components_relax_or_are_refused():
    # a component 1e5 times its size away stalled at once ("strands are probably jammed"):
    # the back-projection's tolerance is now no finer than the coordinates' rounding; farther
    # out the steps themselves are lost in it, and the run is refused before any work
    A, B = knots.named("3_1", 60), knots.circle(40)
    r = relax([A, B + [1e5, 0, 0]], max_iter=12, refine=False)
    assert r.status == Status.MAX_ITER and r.nit == 12
    with pytest.raises(ValueError, match="components are too far apart"):
        relax([A, B + [1e7, 0, 0]], max_iter=2)


def test_a_tree_run_reports_the_exact_energy_of_its_result(monkeypatch):
    # near the circle the tree's far field is low (by 1e-4 here: it reported 3.99991 for the
    # round 1 648-gon, where no closed curve goes below 4)
    t = np.linspace(0.0, 2.0 * np.pi, 1200, endpoint=False)
    P = core.resample(np.c_[np.cos(t), np.sin(t), 0.02 * np.sin(3 * t)], 1200)
    r = core.relax(P, max_iter=3, engine="tree")
    assert r.fun == pytest.approx(core.energy(r.x, engine="exact"), rel=1e-12, abs=0)
    assert r.fun > 4.0
    assert r.stats["run_energy"] == r.history["energy"][-1] != r.fun  # what the run saw
    # above the limit the tree's value is the result's
    monkeypatch.setattr(core.runs.engine, "EXACT_RESULT_MAX", 1000)
    r = core.relax(P, max_iter=3, engine="tree")
    assert r.fun == r.history["energy"][-1] and "run_energy" not in r.stats


def test_a_run_ends_when_its_shape_stops_changing():
    # settle: no vertex moved more than that many mean edges in 5 iterations in a row; the
    # moves checked here from the iterates the callback sees
    P = core.knots.named("3_1", 60)
    xs = [P]
    r = core.relax(P, max_iter=300, tol=0.0, settle=1e-3, method="projected_gradient",
                   callback=lambda s: xs.append(s.x.copy()))
    assert r.status == core.Status.CONVERGED and r.message.startswith("settled: no vertex moved")
    edge = np.linalg.norm(np.roll(P, -1, 0) - P, axis=1).mean()
    moves = [np.linalg.norm(b - a, axis=1).max() / edge
             for a, b in zip(xs[:-1], xs[1:], strict=True)]
    assert r.nit < 300 and all(m <= 1e-3 for m in moves[-5:]) and moves[-6] > 1e-3
    # the same run without it goes on, through the same iterates
    r0 = core.relax(P, max_iter=r.nit, tol=0.0, method="projected_gradient")
    np.testing.assert_array_equal(r0.x, r.x)
    with pytest.raises(ValueError, match="settle"):
        core.relax(P, max_iter=1, settle=-1.0)


def test_an_interrupted_relax_raises_with_the_result_so_far():
    P = core.knots.named("3_1", 60)
    seen = []

    def callback(state):
        seen.append(state.x.copy())
        if state.nit == 3:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt) as caught:
        core.relax(P, max_iter=50, callback=callback)
    result = caught.value.result
    assert result.nit == 3 and result.status == core.Status.STOPPED
    np.testing.assert_array_equal(result.x, seen[-1])
    assert len(result.history["energy"]) == 4
    assert "the result so far is the exception's .result" in caught.value.__notes__[0]


def test_ctrl_c_in_a_kernel_outside_a_step_is_a_keyboard_interrupt(monkeypatch):
    # Ctrl+C as a numba kernel returns reaches Python as a SystemError carrying the interrupt;
    # the start checks of a run (outside its step) run kernels too
    from moebius_addon.core.runs import base as solver_base

    def interrupted(*args, **kwargs):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as err:
            raise SystemError("CPUDispatcher(...) returned a result with an exception set"
                              ) from err

    monkeypatch.setattr(solver_base, "check_layout", interrupted)
    with pytest.raises(KeyboardInterrupt):
        core.relax(core.knots.named("3_1", 60), max_iter=2, refine=False)
    with pytest.raises(KeyboardInterrupt):
        core.make_run("projected_gradient", core.knots.named("3_1", 60), refine=False)
