"""Which energy a run minimizes (the ``energy=``, ``alpha=``, ``beta=`` options of ``relax``).

An :class:`EnergyChoice` is the energy's name and parameters, checked once, with the three
evaluations an engine needs: the exact sum (:meth:`~EnergyChoice.exact`), the exact sum with
its gradient (:meth:`~EnergyChoice.exact_gradient`) and the tree's frame at a polygon
(:meth:`~EnergyChoice.frame`). The engines (:mod:`.engine`) hold one and never name an energy
themselves; the kernels behind it live in :mod:`.energies`.

* ``"moebius"``: the discrete Möbius energy (docs/design.md), scale-invariant, the paper's;
* ``"tangent_point"``: the tangent-point energy with exponents (α, β) (docs/design.md,
  "Tangent-point energy"), default (2, 4.5): ``E(λP) = λ^(2+α−β) E(P)``, scale-invariant only
  for β = α + 2. A run works at total length 1 (``solvers.base.Run``), so the energies of
  its history are those of the curve scaled to total length 1 (the same as the user's
  curve's for the default exponents).
"""

from __future__ import annotations

import numpy as np

from ..geometry.layout import Layout
from ..tree import moebius as barnes_hut
from ..tree import tangent_point as tangent_point_tree
from . import ENERGIES, tangent_point
from .moebius_dense import energy_gradient_x, energy_x
from .tangent_point_dense import tp_energy_gradient_x, tp_energy_x

#: The names of the ``energy=`` option, the default first.
ENERGY_NAMES = tuple(ENERGIES)
#: The tangent-point exponents when none are given (Repulsive Curves' choice; order 3/2,
#: scale-invariant).
DEFAULT_EXPONENTS = (tangent_point.DEFAULT_ALPHA, tangent_point.DEFAULT_BETA)


class EnergyChoice:
    """The energy ``name`` with its exponents (tangent-point only), checked; see the module
    docstring."""

    def __init__(self, name: str = "moebius", alpha=None, beta=None):
        if name not in ENERGY_NAMES:
            raise ValueError(f"unknown energy {name!r}; choose one of {', '.join(ENERGY_NAMES)}")
        self.name = name
        if name == "moebius":
            if alpha is not None or beta is not None:
                raise ValueError("alpha and beta are the tangent-point energy's exponents: "
                                 "pass energy='tangent_point' with them, or leave them out "
                                 "(the penalty methods' weight is penalty=)")
            self.alpha = self.beta = None
        else:
            a0, b0 = DEFAULT_EXPONENTS
            self.alpha, self.beta = tangent_point.check_exponents(a0 if alpha is None else alpha,
                                                    b0 if beta is None else beta)

    def __repr__(self) -> str:
        return f"EnergyChoice({self.label!r})"

    @property
    def label(self) -> str:
        """``"moebius"`` or ``"tangent_point(2, 4.5)"`` (the exponents as given, shortest
        form): what results and keyed properties call the energy."""
        if self.name == "moebius":
            return "moebius"
        return f"tangent_point({self.alpha:g}, {self.beta:g})"

    @property
    def scaling(self) -> float:
        """``k`` of ``E(λP) = λ^k E(P)``: 0 for the Möbius energy."""
        return 0.0 if self.name == "moebius" else tangent_point.scaling(self.alpha, self.beta)

    @property
    def metric_order(self) -> float:
        """Order ``s`` of the fractional Sobolev metric that fits the energy (``hs`` and
        ``hs_pure``): 3/2 for the Möbius energy (the paper's W^{3/2,2}), ``(β − 1)/α`` for the
        tangent-point energy (Repulsive Curves; 7/4 at the default (2, 4.5), 3/2 at (2, 4))."""
        return 1.5 if self.name == "moebius" else (self.beta - 1.0) / self.alpha

    @property
    def default_theta(self) -> float:
        """The tree's admissibility when none is given (each energy measured its own)."""
        return barnes_hut.THETA if self.name == "moebius" else tangent_point_tree.THETA

    # -- evaluations (X at the run's scale; layout of the run) ---------------------------------

    def exact(self, X: np.ndarray, layout: Layout) -> float:
        """The exact sum over all pairs of edges."""
        if self.name == "moebius":
            return energy_x(X, layout)  # open curves: O'Hara's regularized sum
        return tp_energy_x(X, layout, self.alpha, self.beta)

    def exact_gradient(self, X: np.ndarray, layout: Layout) -> tuple[float, np.ndarray]:
        """``(E, ∇E)`` by the exact sum; ``∇E`` is (N, 3)."""
        if self.name == "moebius":
            return energy_gradient_x(X, layout)
        return tp_energy_gradient_x(X, layout, self.alpha, self.beta)

    def frame(self, X: np.ndarray, layout: Layout, theta: float):
        """The tree's frame at ``X`` (open curves: Möbius only): ``.energy(X)`` and
        ``.energy_gradient(X)`` of the approximated sum."""
        if self.name == "moebius":
            return barnes_hut.Frame(X, layout, theta)
        return tangent_point_tree.TangentPointFrame(X, layout, self.alpha, self.beta, theta)


#: The Möbius energy (the default of every run).
MOEBIUS = EnergyChoice()


def check_energy(energy="moebius", alpha=None, beta=None) -> EnergyChoice:
    """The :class:`EnergyChoice` for the options ``energy``, ``alpha``, ``beta`` (an
    ``EnergyChoice`` passes as it is); ValueError naming the option that is wrong."""
    if isinstance(energy, EnergyChoice):
        if alpha is not None or beta is not None:
            return EnergyChoice(energy.name, alpha, beta)
        return energy
    if not isinstance(energy, str):
        raise ValueError(f"energy must be one of {', '.join(ENERGY_NAMES)}, not {energy!r}")
    return EnergyChoice(energy, alpha, beta)
