"""Runs that minimize the tangent-point energy (``relax(energy="tangent_point", alpha=, beta=)``):
the energy the run reports is the energy of its iterates, it goes down, the knot stays
itself, on both engines and for every kind of curve; the Möbius runs are untouched by the
option (their bits: tests/core/test_pins.py's unchanged runs)."""

import numpy as np
import pytest

from moebius_addon import core
from moebius_addon.core.runs.methods import FEASIBLE, INFEASIBLE


@pytest.fixture(scope="module")
def trefoil120():
    return core.resample(core.knots.named("3_1"), 120)


def _unit(P):
    """``P`` scaled to total length 1 (a run's own scale)."""
    return P / np.linalg.norm(np.roll(P, -1, axis=0) - P, axis=1).sum()


@pytest.mark.parametrize("engine", ["exact", "tree"])
def test_tangent_point_run_lowers_its_energy_and_keeps_the_knot(trefoil120, engine):
    r = core.relax(trefoil120, max_iter=40, tol=0.0, energy="tangent_point", engine=engine,
                   method="projected_gradient_implicit", refine=False, alpha=2, beta=4)
    assert r.energy == "tangent_point(2, 4)" and r.stats["engine"] == engine
    E = np.array(r.history["energy"])
    assert np.all(np.diff(E) <= 0) and E[-1] < 0.9 * E[0]
    # (2, 4) is scale-invariant: the run's energies are the caller's curve's
    assert E[0] == pytest.approx(core.energy(trefoil120, energy="tangent_point", alpha=2,
                                             beta=4, engine=engine), rel=1e-12)
    # the result's energy is the exact sum on both engines (engine.EXACT_RESULT_MAX)
    assert r.fun == pytest.approx(core.energy(r.x, energy="tangent_point", alpha=2, beta=4,
                                              engine="exact"), rel=1e-9)
    # the Möbius energy is not what this run minimized, and it is not what it reports
    assert abs(r.fun - core.moebius_energy(r.x)) > 1.0
    assert core.identify(r.x).names == ("3_1",)
    ln = np.linalg.norm(np.roll(r.x, -1, axis=0) - r.x, axis=1)
    assert np.ptp(ln) / ln.mean() < 1e-8  # edge lengths kept


def test_exponents_reach_the_run_and_its_energies_are_at_total_length_one(trefoil120):
    P = 3.0 * trefoil120  # (3, 6) scales as λ^-1: the run reports it at total length 1
    r = core.relax(P, max_iter=5, tol=0.0, energy="tangent_point", alpha=3, beta=6,
                   engine="exact", refine=False)
    assert r.energy == "tangent_point(3, 6)"
    E0 = core.energy(_unit(P), energy="tangent_point", alpha=3, beta=6, engine="exact")
    assert r.history["energy"][0] == pytest.approx(E0, rel=1e-12)
    assert E0 != pytest.approx(core.energy(P, energy="tangent_point", alpha=3, beta=6,
                                           engine="exact"), rel=1e-3)
    assert r.history["energy"][-1] < r.history["energy"][0]


@pytest.mark.parametrize("method", [*FEASIBLE, *INFEASIBLE])
def test_every_method_minimizes_the_chosen_energy(trefoil120, method):
    r = core.relax(trefoil120, max_iter=3, tol=0.0, method=method, energy="tangent_point",
                   engine="exact", refine=False)
    assert r.energy == "tangent_point(2, 4.5)"  # the default exponents
    assert r.history["energy"][0] == pytest.approx(
        core.energy(_unit(trefoil120), energy="tangent_point", engine="exact"), rel=1e-12)
    assert r.history["energy"][-1] < r.history["energy"][0]


def test_link_and_open_curve_runs():
    link = [np.asarray(c) for c in core.knots.named("L2a1{1}")]
    link = [core.resample(c, 60) for c in link]
    r = core.relax(link, max_iter=10, tol=0.0, energy="tangent_point", refine=False,
                   method="projected_gradient_implicit")
    assert r.history["energy"][-1] < r.history["energy"][0]
    total = sum(np.linalg.norm(np.roll(c, -1, axis=0) - c, axis=1).sum() for c in link)
    assert r.history["energy"][0] == pytest.approx(
        core.energy([c / total for c in link], energy="tangent_point"), rel=1e-12)
    t = np.linspace(0, 3 * np.pi, 80)
    arc = np.c_[np.cos(t), np.sin(t), 0.2 * t]  # an open helix, equal parameter steps
    arc = core.resample(arc, 80, closed=False)
    r = core.relax(arc, max_iter=10, tol=0.0, energy="tangent_point", closed=False)
    length = np.linalg.norm(np.diff(arc, axis=0), axis=1).sum()
    assert r.history["energy"][0] == pytest.approx(
        core.energy(arc / length, energy="tangent_point", closed=False), rel=1e-12)
    assert r.history["energy"][-1] < r.history["energy"][0]


def test_a_jammed_tangent_point_start_is_refined_like_a_moebius_one():
    """The adaptive run (refine, the separation prelude) carries the energy choice into every
    run it makes: the braid-tangled trefoil untangles with the tangent-point energy too."""
    P = core.tangle.tangled("3_1", 100, 149, "braid", pairs=10, conjugations=5)
    r = core.relax(P, max_iter=300, tol=1e-3, energy="tangent_point",
                   method="projected_gradient_implicit")
    assert r.energy == "tangent_point(2, 4.5)"
    assert core.identify(r.x).names == ("3_1",)
    assert r.history["energy"][-1] < 0.5 * np.nanmax(r.history["energy"])


@pytest.mark.parametrize("kw, word", [
    (dict(energy="tangent"), "unknown energy 'tangent'"),
    (dict(energy="tangent_point", alpha=-1), "alpha"),
    (dict(energy="tangent_point", beta=np.nan), "beta"),
    (dict(energy="tangent_point", alpha=2, beta=6), "beta"),  # β ≥ 2α + 1
    (dict(alpha=2), "option of the tangent-point energy"),  # Möbius has none
    (dict(method="lbfgs", alpha=1e4), "penalty="),  # the penalty weight's old name
])
def test_bad_energy_options_refused_by_name(trefoil120, kw, word):
    with pytest.raises(ValueError, match=word):
        core.relax(trefoil120, max_iter=1, **kw)


def test_penalty_weight_is_penalty(trefoil120):
    a = core.relax(trefoil120, max_iter=2, method="lbfgs", penalty=10.0, refine=False)
    b = core.relax(trefoil120, max_iter=2, method="lbfgs", penalty=1e6, refine=False)
    assert a.history["penalized_energy"] != b.history["penalized_energy"]
