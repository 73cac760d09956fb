"""One record per metric: its name, UI label and help, its order and which solvers serve it.
The lists the rooms use (:data:`.gram.ORDERED_METRICS`, :data:`.banded.BANDED_METRICS`,
``tree.hs_metric.METRICS``) and the Blender layer's menu are read from :data:`METRIC_RECORDS`.

Pure data: no module of the metrics is imported here (they import this one).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Metric:
    """A metric of the flow (docs/design.md, step 1).

    ``order``: the metric's Sobolev order, or None for the fractional ones, whose order is the
    energy's (``EnergyChoice.metric_order``: 3/2 for the Möbius energy). ``tree_solver``: how
    the tree engine solves its saddle-point systems without a dense matrix, ``"banded"`` (a
    direct O(N) band solve, ``metrics.banded``) or ``"krylov"`` (conjugate gradients on the
    tree's hs operator, ``metrics.hs_solve``), None: as a dense matrix on every engine."""

    name: str
    label: str
    help: str
    order: float | None
    tree_solver: str | None


#: The metrics by name, in the order the panel lists them (the default first).
METRIC_RECORDS: dict[str, Metric] = {m.name: m for m in (
    Metric("hs", "W^{s,2} (geometric)",
           "Geometric fractional Sobolev metric of the paper, of the order that fits the energy "
           "(s = 3/2 for Möbius, (β − 1)/α for tangent-point): fastest, scale-aware",
           None, "krylov"),
    Metric("hs_pure", "W^{s,2} (pure)",
           "Fractional Sobolev metric of order s without the lower-order terms", None,
           "krylov"),
    Metric("h2", "H²", "Second-order Sobolev metric (too strong: slow for fine polygons)", 2.0,
           "banded"),
    Metric("h1", "H¹", "First-order Sobolev metric (too weak: step sizes shrink with N)", 1.0,
           "banded"),
    Metric("l2", "L²", "Plain L² gradient descent (needs tiny steps; for comparison only)", 0.0,
           "banded"),
)}
#: The metric of a run when none is named.
DEFAULT_METRIC = "hs"
#: The metrics whose order is the energy's (weakest first).
ORDERED = tuple(n for n, m in reversed(METRIC_RECORDS.items()) if m.order is None)


def served_by(tree_solver: str) -> tuple[str, ...]:
    """The metrics the tree engine solves by ``tree_solver`` ("banded" or "krylov"), in the
    order of :data:`METRIC_RECORDS`' reversed (weakest first, as the solvers list them)."""
    return tuple(n for n, m in reversed(METRIC_RECORDS.items()) if m.tree_solver == tree_solver)
