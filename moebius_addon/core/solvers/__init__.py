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

from ..engine import engine_class
from ..metrics import METRICS
from ..pinned_solve import tree_borders
from .base import Run, check_dense_size
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


def make_run(method: str, P, metric: str = "hs", max_iter: int = 200, tol: float = 1e-6, *,
             engine: str = "auto", theta: float | None = None, **options) -> Run:
    """A run object of ``method`` (see :data:`METHODS`) with :class:`Relaxation`'s interface.

    Parameters
    ----------
    method : str
        One of :data:`METHODS`.
    P, metric, max_iter, tol, **options
        As in :class:`Relaxation` and the method's own class.
    engine : str
        "exact", "tree" or "auto" (the tree from ``engine.AUTO_TREE_FROM`` vertices on;
        ``core.engine``): the tree evaluates energy and gradient by Barnes–Hut and holds
        no dense matrix (hs: Krylov solves, the banded metrics: direct O(N) solves);
        contacts stay exact.
    theta : float, optional
        Admissibility of the tree in (0, 2) (default ``barnes_hut.THETA``); checked
        for every engine.

    Raises
    ------
    ValueError
        For an unknown method (the message lists the valid ones), metric or engine; for
        ``pinned=`` with a penalty method or bad pins (:func:`..pins.check_pins`).
    """
    if method not in METHOD_CLASSES:
        raise ValueError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    return METHOD_CLASSES[method](P, metric, max_iter, tol, engine=engine, theta=theta,
                                  **options)


def check_size(n: int, metric: str = "hs", method: str = "projected_gradient",
               engine: str = "auto", *, edge_lengths: bool = True,
               barycenter: bool = True, pinned: int = 0) -> None:
    """Refuse, before any work, a polygon of ``n`` vertices (in all) that a run of ``method``
    in ``metric`` on ``engine`` would refuse for its size: the same ``ValueError`` (naming the
    way out) the run's constructor raises. Sizes are bounded where the metric is held as a
    dense matrix: the exact engine, the penalty methods on every engine, and a feasible
    method without one of its constraints (``edge_lengths``, ``barycenter``: the tree's
    solvers need both) or with more than ``pinned_solve.TREE_MAX_PINS`` pinned vertices
    (``pinned``: how many, after ``pin_tangents``; ``True`` counts as one).

    Raises
    ------
    ValueError
        For a size the run would refuse, or an unknown method, metric or engine; for
        ``pinned`` with a method that cannot keep pins (the penalty methods).
    """
    if method not in METHOD_CLASSES:
        raise ValueError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    if metric not in METRICS:
        raise ValueError(f"unknown metric {metric!r}; choose one of {', '.join(METRICS)}")
    if pinned and method not in FEASIBLE:
        raise ValueError(pinned_refusal(method))
    if METHOD_CLASSES[method]._DENSE_METRIC:
        check_dense_size(n, "method")
    elif engine_class(engine, n).holds_dense(metric):
        check_dense_size(n)
    elif pinned and not tree_borders(int(pinned)):
        check_dense_size(n, "pins")
    elif not (edge_lengths and barycenter):
        check_dense_size(n, "constraints")
