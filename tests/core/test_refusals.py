"""The public functions of the core refuse bad input before any work.

One table: each case is a call a user could make, what it used to do (in the comment), and
the exception and words it must raise now. Every refusal happens before a kernel runs, so
the whole table takes a second or two and compiles nothing of its own.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from moebius_addon import core
from moebius_addon.core.runs import _interrupts
from moebius_addon.core.runs import memory as _memory
from moebius_addon.core.topology import knots, pd

T = knots.named("3_1")  # 100 vertices
N = T.copy()
N[5, 1] = np.nan
U = np.ones_like(T)
EMPTY = np.zeros((0, 3))
COLLAPSED = T + 1e16  # float64 at 1e16 has steps of 2: the trefoil collapses onto few points
COLLINEAR = np.c_[np.arange(50.0), np.zeros(50), np.zeros(50)]  # closes back along itself


def _walk(n: int, seed: int = 0) -> np.ndarray:
    """A closed random walk of ``n`` steps."""
    steps = np.random.default_rng(seed).normal(size=(n, 3))
    return np.cumsum(steps - steps.mean(axis=0), axis=0)


def _lemniscate(n: int) -> np.ndarray:
    """A figure eight in the plane of ``n`` vertices: it crosses itself at the origin."""
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    return np.c_[np.sin(t), np.sin(2.0 * t), np.zeros(n)]


# (label, call, exception, words of the message)
CASES = [
    # NaN and inf: NaN results, or "no contact" (10.0) from the step bound
    ("energy of NaN", lambda: core.moebius_energy(N), ValueError, "NaN or infinite"),
    ("gradient of NaN", lambda: core.moebius_gradient(N), ValueError, "NaN or infinite"),
    ("Gram matrix of NaN", lambda: core.gram_matrix("hs", N), ValueError, "NaN or infinite"),
    ("Sobolev gradient of NaN", lambda: core.sobolev_gradient(N), ValueError,
     "NaN or infinite"),
    ("contact ratio of NaN", lambda: core.contact_ratio(N), ValueError, "NaN or infinite"),
    ("step bound, NaN vertex", lambda: core.max_collision_free_step(N, U, 10.0), ValueError,
     "NaN or infinite"),
    ("step bound, NaN direction", lambda: core.max_collision_free_step(T, N - T + 1, 10.0),
     ValueError, "the direction U has NaN"),
    ("step bound, tau_max NaN", lambda: core.max_collision_free_step(T, U, np.nan), ValueError,
     "tau_max must be a finite number >= 0"),
    ("step bound, tau_max -1", lambda: core.max_collision_free_step(T, U, -1.0), ValueError,
     "tau_max must be a finite number >= 0"),
    ("step bound, eps 0", lambda: core.max_collision_free_step(T, U, 1.0, eps=0.0), ValueError,
     "eps must be a finite number > 0"),
    ("step bound, U of another shape", lambda: core.max_collision_free_step(T, U[:50], 1.0),
     ValueError, "U must have the shape of P"),
    # empty input: IndexError from every function
    *[(f"{what} nothing", lambda f=f: f(EMPTY), ValueError, "has no vertices") for what, f in (
        ("energy of", core.moebius_energy), ("gradient of", core.moebius_gradient),
        ("Gram matrix of", lambda P: core.gram_matrix("hs", P)),
        ("Sobolev gradient of", core.sobolev_gradient), ("contact ratio of", core.contact_ratio),
        ("step bound of", lambda P: core.max_collision_free_step(P, P, 1.0)),
        ("start check of", core.check_polygon), ("edge count for", core.suggest_edge_count),
        ("relax", core.relax), ("Alexander of", core.alexander_polynomial),
        ("Jones of", core.jones_polynomial), ("signature of", core.signature),
        ("linking numbers of", core.linking_numbers), ("identify", core.identify))],
    ("resample nothing", lambda: core.resample(EMPTY, 10), ValueError, "at least 2 points"),
    ("a link with an empty component", lambda: core.moebius_energy([T, EMPTY]), ValueError,
     "component 1 has no vertices"),
    # degenerate curves: ZeroDivisionError in the tree kernels, NaN in the exact ones, and
    # the invariants of a collapsed trefoil answered as for the unknot
    ("one point, tree", lambda: core.moebius_energy(np.zeros((1, 3)), engine="tree"),
     ValueError, "1 vertex; a closed polygon needs at least 4"),
    ("20 identical points, tree", lambda: core.moebius_energy(np.ones((20, 3)), engine="tree"),
     ValueError, "repeats a point"),
    ("20 identical points", lambda: core.moebius_energy(np.ones((20, 3))), ValueError,
     "repeats a point"),
    ("collapsed trefoil, tree", lambda: core.moebius_energy(COLLAPSED, engine="tree"),
     ValueError, "repeats a point"),
    *[(name, lambda f=f: f(COLLAPSED), ValueError, "repeats a point") for name, f in (
        ("collapsed trefoil's gradient", core.moebius_gradient),
        ("collapsed trefoil's Alexander", core.alexander_polynomial),
        ("collapsed trefoil's signature", core.signature),
        ("collapsed trefoil's determinant", core.knot_determinant),
        ("is the collapsed trefoil knotted", core.is_knotted))],
    # 50 collinear points closing back along themselves: a matrix, then numba's SystemError
    ("Gram matrix of a doubled segment", lambda: core.gram_matrix("hs", COLLINEAR), ValueError,
     "touches itself: the edges after vertex 24 and after vertex 49 have the same midpoint"),
    ("energy of a doubled segment", lambda: core.moebius_energy(COLLINEAR), ValueError,
     "touches itself"),
    # counts too coarse for the knot: 4_1 at 9 vertices was a trefoil, 5_2 at 12 a trefoil
    ("4_1 at 9 vertices", lambda: knots.named("4_1", n=9), ValueError,
     r"n = 9 is too coarse for this curve.*use n >= \d+"),
    ("5_2 at 12 vertices", lambda: knots.named("5_2", n=12), ValueError,
     r"n = 12 is too coarse.*use n >= \d+"),
    # sizes that would not fit: accepted, hung or MemoryError (the machine: 24 GB, patched)
    ("tree run of 5 000 000", lambda: core.check_size(5_000_000, "hs", engine="tree"),
     ValueError, r"a tree-engine run of 5000000 vertices needs about 40 GB .* 24\.0 GB"),
    ("trefoil of 10**9 vertices", lambda: knots.named("3_1", n=10**9), ValueError,
     "a curve of n = 1000000000 vertices needs about 400 GB"),
    ("resample to 10**12", lambda: core.resample(T, 10**12), ValueError,
     "resampling to 1000000000000 vertices needs about"),
    ("braid on 2**40 strands", lambda: knots.from_braid([2**40]), ValueError,
     "the closure of a braid on 1099511627777 strands"),
    ("braid on 10**20 strands", lambda: knots.from_braid([10**20]), ValueError,
     "needs about"),
    ("Gram matrix of 10**5 vertices",
     lambda: core.gram_matrix("h1", knots.circle(100_000)), ValueError,
     "the 100000 x 100000 Gram matrix needs about 160 GB"),
    # too tangled to read: no answer in 300 s
    ("Alexander of a 3 000-step walk", lambda: core.alexander_polynomial(_walk(3000)),
     ValueError, "more than 2000 crossings .* relax the curve first"),
    ("identify a 3 000-step walk", lambda: core.identify(_walk(3000)), ValueError,
     "more than 2000 crossings"),
    ("Jones of 202 crossings", lambda: core.jones_polynomial(pd.from_braid([1, 2] * 101)),
     ValueError, "more than 200 crossings after simplification"),
    # options: ran and reported a jam, or were taken as something else
    ("trust region, eta NaN",
     lambda: core.relax(T, method="trust_region", max_iter=1, eta=np.nan), ValueError,
     "eta must be a finite number >= 0"),
    ("trust region, eta 1", lambda: core.relax(T, method="trust_region", max_iter=1, eta=1.0),
     ValueError, r"eta must lie in \[0, 1\)"),
    ("implicit, newton_iter -1",
     lambda: core.relax(T, method="projected_gradient_implicit", max_iter=1, newton_iter=-1),
     ValueError, "newton_iter must be a finite number >= 1"),
    ("implicit, cg_rtol 0",
     lambda: core.relax(T, method="projected_gradient_implicit", max_iter=1, cg_rtol=0.0),
     ValueError, "cg_rtol must be a finite number > 0"),
    ("lbfgs, history 0", lambda: core.relax(T, method="lbfgs", max_iter=1, history=0),
     ValueError, "history must be a finite number >= 1"),
    ("backproject_tol 1e-300", lambda: core.relax(T, max_iter=1, backproject_tol=1e-300),
     ValueError, "backproject_tol must be at least 1e-14"),
    ("max_iter '3'", lambda: core.relax(T, max_iter="3"), ValueError,
     r"max_iter must be a number, got '3' \(str\)"),
    ("max_iter True", lambda: core.relax(T, max_iter=True), ValueError,
     r"max_iter must be a number, got True \(bool\)"),
    ("armijo '0.5'", lambda: core.relax(T, max_iter=1, armijo="0.5"), ValueError,
     "armijo must be a number"),
    ("pinned 10**20", lambda: core.relax(T, max_iter=1, pinned=[5, 10**20]), ValueError,
     "pinned index 100000000000000000000 is out of range"),
    ("braid of 1.5", lambda: knots.from_braid([1.5]), TypeError,
     r"generators are nonzero integers .* got 1\.5"),
    ("braid of True", lambda: knots.braid_closure([True]), TypeError,
     "generators are nonzero integers"),
    ("torus knot T(2.5, 3)", lambda: knots.torus_knot(2.5, 3), TypeError,
     "p must be a whole number"),
    ("complex coordinates", lambda: core.moebius_energy(T.astype(complex)), TypeError,
     "must hold real numbers .* complex128"),
    ("object array", lambda: core.moebius_energy(T.astype(object)), TypeError,
     "must hold real numbers .* object"),
    ("boolean array", lambda: core.contact_ratio(np.ones((10, 3), bool)), TypeError,
     "must hold real numbers"),
    ("min_gap 2.5", lambda: core.contact_ratio(T, min_gap=2.5), ValueError,
     "min_gap must be a whole number"),
    # text and flags as text: the exponents were converted, bool("False") is True
    ("alpha '2'", lambda: core.check_energy("tangent_point", "2"), ValueError,
     r"alpha must be a number, got '2' \(str\)"),
    ("beta b'4.5'", lambda: core.check_energy("tangent_point", 2, b"4.5"), ValueError,
     r"beta must be a number, got b'4.5' \(bytes\)"),
    ("edge_lengths 'False'", lambda: core.relax(T, max_iter=1, edge_lengths="False"),
     ValueError, r"edge_lengths must be True or False, got 'False' \(str\)"),
    ("check 'False'", lambda: core.relax(T, max_iter=1, check="False", refine=False),
     ValueError, r"check must be True or False, got 'False' \(str\)"),
    ("reuse_factorization 'no'",
     lambda: core.relax(T, max_iter=1, refine=False, reuse_factorization="no"), ValueError,
     r"reuse_factorization must be True or False, got 'no'"),
    # the size first: these were refused by the start check's search for crossings (5 000 000
    # vertices took 14 s to be refused for their size, more than 60 on a loaded machine)
    ("5 000 000 vertices that cross", lambda: core.relax(_lemniscate(5_000_000), max_iter=1),
     ValueError, "a tree-engine run of 5000000 vertices needs about 40 GB"),
    ("15 001 vertices that cross, exact",
     lambda: core.relax(_lemniscate(15_001), max_iter=1, engine="exact"), ValueError,
     "15001 vertices are more than the dense metric's factorization handles"),
    # values that overflowed inside the run (its energy NaN, stopped as a stall) or left no
    # room to grow
    ("tangent-point beta 150", lambda: core.relax(T, max_iter=1, energy="tangent_point",
                                                  alpha=100, beta=150), ValueError,
     r"beta must be at most 40, got 150: \|x − y\|\^−beta between points an edge apart "
     "overflows float64"),
    ("obstacle_weight 1e300", lambda: core.relax(T, max_iter=1, obstacles=[(
        np.array([[9.0, 9, 9], [10, 9, 9], [9, 10, 9]]), np.array([[0, 1, 2]]))],
        obstacle_weight=1e300), ValueError,
     r"obstacle_weight must be at most 1e\+06, got 1e\+300: the weighted sum overflows"),
    ("length_growth 300", lambda: core.relax(T, max_iter=1, length_target=100.0,
                                             length_growth=300.0), ValueError,
     r"length_growth must be at most 1 \(every edge 2 times as long per iteration\), got "
     r"300\.0: a larger step leaves no room to grow"),
]


@pytest.fixture(autouse=True)
def _machine_of_24_gb(monkeypatch):
    monkeypatch.setattr(_memory, "physical_memory", lambda: 24e9)


@pytest.mark.parametrize(("call", "error", "words"), [c[1:] for c in CASES],
                         ids=[c[0] for c in CASES])
def test_bad_input_is_refused_by_name(call, error, words):
    with pytest.raises(error, match=words):
        call()


def test_the_same_calls_with_good_input_work():
    # the doors refuse what they should and nothing else: the neighbours of the table's cases
    assert core.moebius_energy(T) > 4
    assert core.max_collision_free_step(T, np.zeros_like(T), 0.0) == 0.0
    assert core.contact_ratio(T.astype(np.float32)) > 1
    assert core.relax(T, max_iter=1, backproject_tol=1e-14).nit == 1
    assert len(knots.from_braid([np.int64(1)] * 3)) == 100
    core.check_size(10**6, "hs", engine="tree")  # 10⁶ ran in 5.5 GB (about 8 GB asked)
    # the count a too coarse refusal names draws the knot, and is the knot
    with pytest.raises(ValueError, match=r"use n >= (\d+)") as info:
        knots.named("5_2", n=12)
    k = int(re.search(r"use n >= (\d+)", str(info.value)).group(1))
    assert core.identify(knots.named("5_2", n=k)).name == "5_2"


def test_a_tiny_theta_sums_every_pair_exactly():
    # theta <= 3e-8 raised numba's MemoryError: the split's first buffer was 8 m / theta pairs
    P = knots.named("3_1", n=120)
    exact = core.moebius_energy(P, engine="exact")
    assert core.moebius_energy(P, engine="tree", theta=1e-12) == pytest.approx(exact, rel=1e-13)


def test_an_interrupted_step_can_be_taken_again(monkeypatch):
    # Ctrl+C inside the engine's update left the factorization set aside for recycling: the
    # next step failed with "'NoneType' object has no attribute 'pseudo_inverse'"
    reference = core.Relaxation(T, max_iter=4)
    while reference.step():
        pass
    run = core.Relaxation(T, max_iter=4)
    engine = run.engine
    update = engine.update
    calls = []

    def interrupted_once(X, jac):
        calls.append(1)
        if len(calls) == 1:
            engine.solver.fac = None  # what an interrupt in refactor() leaves
            raise KeyboardInterrupt
        update(X, jac)

    monkeypatch.setattr(engine, "update", interrupted_once)
    with pytest.raises(KeyboardInterrupt):
        run.step()
    assert run.nit == 0 and run.history["energy"] == reference.history["energy"][:1]
    while run.step():
        pass
    assert run.nit == reference.nit
    np.testing.assert_array_equal(run.x, reference.x)


@pytest.mark.parametrize("method", ["projected_gradient", "projected_gradient_implicit",
                                    "lbfgs"])
def test_an_interrupt_inside_a_kernel_surfaces_as_itself(monkeypatch, method):
    # CPython reports a KeyboardInterrupt that arrives as a numba kernel returns as
    # "SystemError: ... returned a result with an exception set" (2 of 13 Ctrl+C in a relax)
    run = core.make_run(method, T, max_iter=3)

    def kernel(*args, **kwargs):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as err:
            raise SystemError("CPUDispatcher(<function _hs_rows>) returned a result with an "
                              "exception set") from err

    monkeypatch.setattr(run.engine, "energy_gradient", kernel)
    with pytest.raises(KeyboardInterrupt):
        run.step()
    monkeypatch.undo()
    assert run.step() or run.done  # and it goes on


def test_a_system_error_without_an_interrupt_stays_one():
    err = SystemError("a kernel failed")
    assert _interrupts._keyboard_interrupt(err) is None
