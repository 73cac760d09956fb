"""Entry points of the relaxation: :func:`relax` runs any method of :mod:`.solvers` to the end
(one call, scipy style), :func:`sobolev_gradient` gives the gradient field of one metric.

The projected Sobolev-gradient flow itself (docs/design.md, "One iteration") is
:class:`.solvers.projected.Relaxation`; the other optimizers live beside it in :mod:`.solvers`.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..energies.choice import DEFAULT_ENERGY, check_run_energy
from ..geometry.constraints import jacobian, make_constraints
from ..geometry.layout import as_checked_layout
from ..metrics.gram import ORDERED_METRICS, gram_x
from ..metrics.saddle import Factorization
from .base import IterationState, RelaxResult, check_dense_size
from .methods import make_run


def relax(
    P,
    metric: str = "hs",
    max_iter: int = 200,
    tol: float = 1e-6,
    callback: Callable[[IterationState], bool | None] | None = None,
    method: str = "projected_gradient",
    *,
    engine: str = "auto",
    theta: float | None = None,
    **options,
) -> RelaxResult:
    """Relax a knot or link by the projected Sobolev-gradient flow of the Möbius energy.

    Parameters
    ----------
    P : (N, 3) array or list of arrays
        Equilateral closed polygon (see :func:`resample`) or link.
    metric : {"hs", "hs_pure", "h2", "h1", "l2"}
        Gradient metric; ``hs`` (geometric W^{3/2,2}) is the paper's and the fastest.
    max_iter, tol : int, float
        Iteration limit and tolerance on the projected gradient norm ``sqrt(<g, u>)``; also
        accepted as ``max_iterations=`` and ``tolerance=`` (the Blender layer's spelling,
        ``core.runs.aliases``).
    callback : callable, optional
        ``callback(state)`` after every accepted iterate; returning True stops the run cleanly.
    method : str
        ``projected_gradient`` (the paper's explicit method, docs/design.md) or another optimizer
        of :mod:`moebius_addon.core.runs.methods` (``METHODS`` lists them).
    engine : str
        "exact", "tree" or "auto" (the tree from ``engine.AUTO_TREE_FROM`` vertices on;
        ``core.runs.engine``): the tree evaluates energy and gradient by Barnes–Hut and holds
        no dense matrix (hs: Krylov solves, the banded metrics: direct O(N) solves);
        contacts stay exact.
    theta : float, optional
        Admissibility of the tree in (0, 2) (default ``barnes_hut.THETA``); checked
        for every engine.
    **options
        See :class:`Relaxation` (``energy_target``, ``ftol``, ``max_seconds``, ``initial_step``,
        ``armijo``, ``growth``, ``backproject_iter``, ``backproject_tol``, ``edge_lengths``,
        ``barycenter``, ``target_lengths``, ``check``, ``reuse_factorization``,
        ``precision``, ``pinned``, ``pin_tangents``, ``length_target``, ``length_growth``,
        ``thickness``) and the method's own class. ``thickness``: a tube radius kept at every
        iterate and between them (docs/api.md, "Thickness"). ``length_target``: grow the
        total length to this during the run, ``length_growth`` (default 0.01) per
        iteration, then hold it (docs/api.md, "Length growth").
        ``pinned``: vertex indices (a list per component for a link) that keep their
        positions exactly; feasible methods only (docs/api.md, "Pinned vertices").

    Returns
    -------
    RelaxResult
        ``x`` (same shape as ``P``), ``fun``, ``nit``, ``success``, ``message``, ``status``
        (a ``Status`` code) and ``history`` (per-iteration lists from the start: energy, step,
        grad_norm, constraint_residual, seconds; the feasible methods also length). Deterministic
        for a given input.
    """
    run = make_run(method, P, metric, max_iter, tol, engine=engine, theta=theta, **options)
    try:
        while not run.done:
            before = run.nit
            run.step()
            # every accepted iterate reaches the callback, the last one of the run included
            if run.nit > before and callback is not None and callback(run.state()):
                run.stop("stopped by callback")
    except KeyboardInterrupt as err:  # the iterates so far stay the caller's
        run.stop(f"interrupted by KeyboardInterrupt after {run.nit} iterations")
        err.result = run.result()
        err.add_note(f"core.relax: interrupted after {run.nit} iterations; the result so far "
                     "is the exception's .result")
        raise
    return run.result()


def sobolev_gradient(P, metric: str = "hs", projected: bool = True, *,
                     energy: str = DEFAULT_ENERGY, **energy_options):
    """The ``metric``-gradient of the energy ``energy`` at ``P`` (exact sums).

    Parameters
    ----------
    P : (N, 3) array or list of arrays
    metric : {"hs", "hs_pure", "h2", "h1", "l2"}
        ``hs`` and ``hs_pure`` of the order that fits the energy, as a run takes them
        (:attr:`.EnergyChoice.metric_order`: 3/2 for the Möbius energy).
    projected : bool
        Project onto the tangent space of the constraints (edge lengths and barycenter fixed),
        as the flow does; otherwise ``G⁻¹ ∇E``.
    energy, **energy_options
        The energy and its options (``alpha``, ``beta``, ``stiffness``), as :func:`relax`
        takes them (default the Möbius energy); ``stiffness`` acts on ``P`` as it is.

    Returns
    -------
    same shape as P
        Direction of steepest ascent in that metric (the flow moves along its negative); the
        paper's Fig. 2 compares these fields.
    """
    choice = check_run_energy(energy, **energy_options)
    X, layout, k = as_checked_layout(P)  # the vertices scaled by 2^-k
    check_dense_size(layout.n)
    order = choice.metric_order
    _, g = choice.exact_gradient(X, layout, k)
    A = gram_x(metric, X, layout, order=order)
    if not projected:
        u = np.linalg.solve(A, g)
    else:
        ln = np.linalg.norm(X[layout.nxt] - X, axis=1)
        con = make_constraints(X, layout, ln)
        fac = Factorization(A, jacobian(X, con))
        u, _ = fac.solve(g, np.zeros(con.size))
    # u(λX) = λ^p u(X): the gradient scales as λ^(scaling − 1), every Gram matrix as λ^-2 but
    # hs and hs_pure of order s, as λ^(1 − 2s) (both 3/2 for the Möbius energy: p = 1)
    gram = 1.0 - 2.0 * order if metric in ORDERED_METRICS else -2.0
    p = choice.scaling - 1.0 - gram
    return layout.split(u * 2.0 ** (k * p) if k else u)
