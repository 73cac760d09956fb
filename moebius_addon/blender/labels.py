"""Names, labels and defaults of the Blender layer: what the panel's menus and the command line's
choices list, each derived from the core's own list where there is one.

No bpy: the properties, the panel, the operators and the command line all read these.
"""

from __future__ import annotations

from fractions import Fraction

from .. import core
from ..core import energies as core_energies
from ..core.metrics import records as metric_records
from ..core.runs.engine import AUTO_TREE_FROM, ENGINE_NAMES

#: Metrics offered for the flow, as ``(core name, label, description)``: the core's metric
#: records (``core.metrics.records.METRIC_RECORDS``) in their order.
METRICS = tuple((m.name, m.label, m.help) for m in metric_records.METRIC_RECORDS.values())
#: The metric of a run when none is chosen.
DEFAULT_METRIC = metric_records.DEFAULT_METRIC

#: The energy records of the core (``core.energies.ENERGIES``): the menu, sliders and command-line
#: options below are derived from them.
ENERGY_RECORDS = tuple(core_energies.ENERGIES.values())
#: Energies the flow can minimize, as ``(core name, label, description)``: the repulsive
#: records (``core.energies.choice.RUN_ENERGY_NAMES``).
ENERGIES = tuple((r.name, r.label, r.help) for r in ENERGY_RECORDS if r.repulsive)
#: The energy of a run when none is chosen.
DEFAULT_ENERGY = core_energies.DEFAULT_ENERGY
#: The energies' parameters (α, β) and the added energies' weights (Stiffness), as
#: ``(record, core.energies.Parameter)``: one setting each (``Parameter.setting``).
ENERGY_PARAMETERS = tuple((r, p) for r in ENERGY_RECORDS for p in r.options)


def metric_order_text(energy: str, alpha: float | None = None, beta: float | None = None,
                      **params) -> str:
    """The order ``s`` of the ``hs`` metrics for ``energy`` with the panel's values of the
    energies' parameters (``alpha``, ``beta``, ...: only the energy's own are used) as the
    panel shows it under the metric: "s = 3/2" (Möbius, and tangent-point at (2, 4)),
    "s = 7/4" (tangent-point at the default (2, 4.5)); ValueError (naming the parameter) for
    values the energy refuses."""
    own = {p.name for p in core_energies.ENERGIES[energy].parameters}
    given = {k: v for k, v in dict(params, alpha=alpha, beta=beta).items() if k in own}
    s = core.check_energy(energy, **given).metric_order
    # a small fraction where it is one (the panel's α, β are single-precision floats)
    f = Fraction(s).limit_denominator(12)
    return f"s = {f.numerator}/{f.denominator}" if abs(float(f) - s) < 1e-6 else f"s = {s:.4g}"


#: The paper's explicit projected gradient (``core.Relaxation``): best on unknots.
EXPLICIT_METHOD = "projected_gradient"
#: The implicit projected gradient: best on knots.
KNOT_METHOD = "projected_gradient_implicit"
#: Default: :data:`KNOT_METHOD` for a curve its knot determinant proves knotted, else
#: :data:`EXPLICIT_METHOD` (``choose_method``; measured in docs/lab/flows-and-methods.md, "The
#: automatic method": the implicit one ended lower on 32 of the 36 table knots in the same
#: seconds, the explicit one is faster on the FHW unknot).
AUTO_METHOD = "auto"
DEFAULT_METHOD = AUTO_METHOD

#: Default weight α of the edge-stretch penalty of the penalty methods (the core's default).
DEFAULT_PENALTY = core.DEFAULT_PENALTY_WEIGHT
#: defaults of Max Iterations and Tolerance (the panel, the scripting API, the command line)
DEFAULT_MAX_ITERATIONS = 200
DEFAULT_TOLERANCE = 1e-6
#: A run ends when no vertex moved more than this many mean edge lengths in each of
#: ``core.runs.base.SETTLE_ITERATIONS`` (5) iterations in a row: the shape stopped changing
#: visibly, so its keys end where its motion ends (0.1 %: a 7_2 of 150 edges ends at
#: iteration 61 of its 67, its energy the same to 10 digits).
DEFAULT_SETTLE = 1e-3

_METHOD_TEXT = {
    AUTO_METHOD: (
        "Automatic",
        "Implicit Gradient for a knotted curve (knot determinant above 1) or a link, Projected "
        "Gradient for unknots: the faster of the two on each, as measured (default)"),
    "projected_gradient": (
        "Projected Gradient",
        "The paper's explicit projected Sobolev gradient with Armijo steps: keeps edge lengths "
        "and barycenter exactly; the fastest on unknots"),
    "projected_gradient_implicit": (
        "Implicit Gradient",
        "Backward Euler on the projected flow, solved by Newton–Krylov: keeps edge lengths and "
        "barycenter exactly; fewer but costlier iterations"),
    "trust_region": (
        "Trust Region",
        "Subspace trust-region method with Hessian products: keeps edge lengths and barycenter "
        "exactly"),
    "ncg": (
        "Nonlinear CG (penalty)",
        "Polak–Ribière conjugate gradients; edge lengths held only by a penalty (they may "
        "stretch), barycenter free"),
    "lbfgs": (
        "L-BFGS (penalty)",
        "Limited-memory BFGS; edge lengths held only by a penalty (they may stretch), "
        "barycenter free"),
    "nesterov": (
        "Nesterov (penalty)",
        "Nesterov's accelerated gradient; edge lengths held only by a penalty (they may "
        "stretch), barycenter free"),
}

#: Optimizers offered for the flow, as ``(name, label, description)``: :data:`AUTO_METHOD`,
#: then exactly ``core.METHODS`` in its order (a method without a text here gets its name as
#: label).
METHODS = tuple(
    (m, *_METHOD_TEXT.get(m, (m.replace("_", " ").title(), f"core.runs.methods '{m}'")))
    for m in (AUTO_METHOD, *core.METHODS)
)

#: Methods that replace the edge-length constraints by a penalty of weight α.
PENALTY_METHODS = core.runs.methods.INFEASIBLE


#: Default engine: the tree from ``core.runs.engine.AUTO_TREE_FROM`` edges on, exact below (the
#: core's).
DEFAULT_ENGINE = "auto"
#: The panel's θ when none is typed: 0, the energy's own default (each energy's record has
#: its own; one value for all gave the tangent-point tree the Möbius tree's).
DEFAULT_THETA = 0.0
#: Each energy's own θ, as the θ setting's tooltip lists them.
THETA_TEXT = ", ".join(f"{r.label} {r.default_theta:g}" for r in ENERGY_RECORDS
                       if r.default_theta is not None)

_ENGINE_TEXT = {
    "auto": (
        "Automatic",
        f"Exact below {AUTO_TREE_FROM} edges, the tree from there on (default)"),
    "exact": (
        "Exact",
        "Every pair of edges summed exactly: time per iteration grows as N²"),
    "tree": (
        "Tree",
        "Barnes–Hut: energy and gradient in about N log N (at the default θ within 1e-5 and "
        "7e-4 of the exact sums), the metric without a dense matrix: for large curves"
        + "".join(f" (except {label}, dense)" for key, label, _ in METRICS
                  if core.ENGINES["tree"].holds_dense(key))),
}

#: Engines that evaluate the energy, as ``(name, label, description)``: exactly
#: ``core.runs.engine.ENGINE_NAMES`` in its order.
ENGINES = tuple(
    (e, *_ENGINE_TEXT.get(e, (e.title(), f"core.runs.engine '{e}'")))
    for e in ENGINE_NAMES
)


def method_label(method: str) -> str:
    """The label the panel shows for ``method`` (its name when it has none)."""
    return next((label for key, label, _ in METHODS if key == method), method)


def engine_label(engine: str) -> str:
    """The label the panel shows for ``engine`` (its name when it has none)."""
    return next((label for key, label, _ in ENGINES if key == engine), engine)


#: Catalogue entries besides the named knots of ``core.knots.names()``.
SPECIAL_KNOTS = (
    ("fhw", "Freedman–He–Wang unknot", "The tangled unknot of Freedman, He and Wang"),
    ("helix", "Helix unknot", "A coiled unknot"),
    ("random", "Random unknot", "A seeded random unknot"),
    ("torus", "Torus knot (p, q)", "The (p, q) torus knot"),
    ("circle", "Circle", "A regular polygon (the energy minimiser)"),
    ("figure_eight", "Figure-eight knot", "The 4_1 knot"),
)

