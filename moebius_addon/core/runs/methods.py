"""The optimizers of the paper's comparison (section "Optimization methods employed",
Figs. 3 and 4), each usable with every metric, and the table that names them.

* :mod:`.base`: what every run shares (options, the scaled start, stopping rules and status
  codes, ``RelaxResult``);
* :mod:`.projected`: ``projected_gradient``, the paper's explicit method (:class:`Relaxation`);
* :mod:`.second_order`: ``projected_gradient_implicit``, ``trust_region`` (feasible, with
  Hessian products of the Lagrangian);
* :mod:`.penalty`: ``ncg``, ``lbfgs``, ``nesterov`` (edge lengths held by a penalty).

Feasible methods keep the constraints of docs/design.md (edge lengths, barycenter) at every
iterate, and can pin vertices (``pinned=``: those keep their positions exactly); infeasible
ones replace the edge-length constraints by a penalty and refuse pins. Every run has the
same interface: ``step()``, ``state()``, ``stop()``, ``result()``, ``x``, ``energy``, ``nit``,
``history`` (the Möbius energy ``E``, never the penalized one, so methods compare directly),
and reaches the numerics only through its engine (:mod:`..engine`).
"""

from __future__ import annotations

from ..metrics.gram import METRICS
from ._interrupts import as_interrupt
from .adaptive import RESTART_SCALE, AdaptiveRun
from .aliases import take_spelling
from .base import Run, check_dense_size, check_number
from .checks import check_flag
from .engine import engine_class, tree_solves_pins
from .penalty import LBFGS, Nesterov, NonlinearCG, pinned_refusal
from .projected import Relaxation
from .second_order import ImplicitProjectedGradient, TrustRegion

#: Run class of every method, in the order of the paper's comparison.
METHOD_CLASSES: dict[str, type[Run]] = {
    "projected_gradient": Relaxation,
    "projected_gradient_implicit": ImplicitProjectedGradient,
    "trust_region": TrustRegion,
    "ncg": NonlinearCG,
    "lbfgs": LBFGS,
    "nesterov": Nesterov,
}
METHODS = tuple(METHOD_CLASSES)
#: Methods that keep the constraints exactly (the explicit method and its subclasses).
FEASIBLE = tuple(m for m, cls in METHOD_CLASSES.items() if issubclass(cls, Relaxation))
#: Methods that hold the edge lengths by a penalty.
INFEASIBLE = tuple(m for m in METHODS if m not in FEASIBLE)
#: Methods that can grow the curve's length (``length_target=``).
GROWING = tuple(m for m, cls in METHOD_CLASSES.items() if cls._LENGTH_GROWTH)


@as_interrupt
def make_run(method: str, P, metric: str = "hs", max_iter: int = 200, tol: float = 1e-6, *,
             engine: str = "auto", theta: float | None = None, refine: bool = True,
             max_edges: int | None = None, restarts: int = 0, seed: int = 0,
             restart_scale: float = RESTART_SCALE, **options) -> Run | AdaptiveRun:
    """A run object of ``method`` (see :data:`METHODS`) with :class:`Relaxation`'s interface.

    Parameters
    ----------
    method : str
        One of :data:`METHODS`.
    P, metric, max_iter, tol, **options
        As in :class:`Relaxation` and the method's own class; ``max_iterations`` and
        ``tolerance`` (the Blender layer's spelling) are taken for ``max_iter`` and ``tol``.
    engine : str
        "exact", "tree" or "auto" (the tree from ``engine.AUTO_TREE_FROM`` vertices on;
        ``core.runs.engine``): the tree evaluates energy and gradient by Barnes–Hut and holds
        no dense matrix (hs: Krylov solves, the banded metrics: direct O(N) solves);
        contacts stay exact.
    theta : float, optional
        Admissibility of the tree in (0, 2) (default ``barnes_hut.THETA``); checked
        for every engine.
    refine : bool
        Adaptive resolution (:mod:`.adaptive`): a start too coarse for its shape is split
        into twice (four times, …) the edges instead of refused, and a run whose strands jam
        (``Status.STALLED``) goes on from its polygon split in two, up to ``max_edges``
        edges in all (default: 4 times the start's, at least 2 000). False: the plain run of
        the method (the start refused, the jam reported).
    restarts, seed, restart_scale
        After a run that converged, ``restarts`` times relax a nudged copy of the best
        polygon (a random smooth field, seeded by ``seed``, moving vertices by at most
        ``restart_scale`` mean edge lengths) and keep it if it ends lower; feasible methods
        only.

    Returns
    -------
    The method's run class itself when ``refine`` is False and ``restarts`` 0, else an
    :class:`.adaptive.AdaptiveRun` around it (the same interface; ``result().refinements``).

    Raises
    ------
    ValueError
        For an unknown method (the message lists the valid ones), metric or engine; for
        ``pinned=`` with a penalty method or bad pins (:func:`..pins.check_pins`).
    """
    if method not in METHOD_CLASSES:
        raise ValueError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    max_iter = take_spelling(options, "max_iter", max_iter, 200)
    tol = take_spelling(options, "tol", tol, 1e-6)
    cls = METHOD_CLASSES[method]
    if not isinstance(refine, (bool, int)) or refine not in (0, 1):
        raise ValueError(f"refine must be True or False, got {refine!r}")
    restarts = check_number("restarts", restarts, 0, integer=True)
    _check_start_size(P, method, metric, engine, options)
    if not refine and not restarts:
        return cls(P, metric, max_iter, tol, engine=engine, theta=theta, **options)
    if restarts and method not in FEASIBLE:
        raise ValueError(f"restarts need a feasible method ({', '.join(FEASIBLE)}): a nudge "
                         f"keeps the constraints, which {method!r} holds by a penalty")

    def make(Q, iterations, seconds, **changes):
        return cls(Q, metric, iterations, tol, engine=engine,
                   **{"theta": theta, **options, "max_seconds": seconds, **changes})

    return AdaptiveRun(make, P, max_iter, refine=bool(refine), max_edges=max_edges,
                       restarts=restarts, seed=seed, restart_scale=restart_scale,
                       max_seconds=options.get("max_seconds"),
                       closed=options.get("closed", True), pinned=options.get("pinned"),
                       pin_tangents=options.get("pin_tangents", False),
                       check=options.get("check", True), obstacles=options.get("obstacles"),
                       container=options.get("container"))


def _check_start_size(P, method: str, metric: str, engine: str, options: dict) -> None:
    """:func:`check_size` of the start ``P`` before anything else looks at its vertices: the
    start checks and the refinement of a coarse start take seconds to minutes on millions of
    vertices (5 000 000 were refused for their size after 14 s, on a loaded machine after more
    than 60). What the size cannot tell (pins, the vertices themselves) the run checks."""
    try:
        n = sum(len(p) for p in P) if isinstance(P, (list, tuple)) else len(P)
    except TypeError:  # no vertex count: the run's own checks say what is wrong
        return
    check_size(n, metric, method, engine,
               edge_lengths=check_flag("edge_lengths", options.get("edge_lengths", True)),
               barycenter=check_flag("barycenter", options.get("barycenter", True)))


def check_size(n: int, metric: str = "hs", method: str = "projected_gradient",
               engine: str = "auto", *, edge_lengths: bool = True,
               barycenter: bool = True, pinned: int = 0, open_curves: bool = False) -> None:
    """Refuse, before any work, a polygon of ``n`` vertices (in all) that a run of ``method``
    in ``metric`` on ``engine`` would refuse for its size: the same ``ValueError`` (naming the
    way out) the run's constructor raises. Sizes are bounded where the metric is held as a
    dense matrix: the exact engine, the penalty methods on every engine, and a feasible
    method without one of its constraints (``edge_lengths``, ``barycenter``: the tree's
    solvers need both) or with more than ``pinned_solve.TREE_MAX_PINS`` pinned vertices
    (``pinned``: how many, after ``pin_tangents``; ``True`` counts as one) on closed curves
    (``open_curves``: the curve has an open component, whose band solver on the tree
    eliminates any number of pins).

    Raises
    ------
    ValueError
        For a size the run would refuse (the dense sizes, and on the tree engine what would
        not fit in memory: ``engine.TreeEngine.BYTES_PER_VERTEX``), or an unknown method,
        metric or engine; for
        ``pinned`` with a method that cannot keep pins (the penalty methods).
    """
    if method not in METHOD_CLASSES:
        raise ValueError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    if metric not in METRICS:
        raise ValueError(f"unknown metric {metric!r}; choose one of {', '.join(METRICS)}")
    if pinned and method not in FEASIBLE:
        raise ValueError(pinned_refusal(method))
    engine_class(engine, n).check_size(n)  # the tree engine's memory (nothing dense)
    if METHOD_CLASSES[method]._DENSE_METRIC:
        check_dense_size(n, "method")
    elif engine_class(engine, n).holds_dense(metric):
        check_dense_size(n)
    elif pinned and not tree_solves_pins(int(pinned), open_curves):
        check_dense_size(n, "pins")
    elif not (edge_lengths and barycenter):
        check_dense_size(n, "constraints")
