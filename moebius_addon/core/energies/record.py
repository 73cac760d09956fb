"""The record an energy module fills in: what every other room reads about an energy.

The engine, the runs, the warm-up, batch and the Blender layer (its menu, sliders, command-line
options, keyed tooltips) learn an energy from its :class:`Energy` record in
:data:`.ENERGIES` and never compare its name; a default written once here cannot drift
(each energy's tree θ is its own). Adding an energy is a module here that defines
``RECORD`` and one line in :mod:`.energies`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass


@dataclass(frozen=True)
class Parameter:
    """One numeric option of an energy (``alpha=``), as the core checks it and a UI shows it.

    ``setting`` is the name of the panel's setting that holds it (``scene.moebius.<setting>``,
    also the command line's ``--<setting>`` with ``_`` as ``-`` where it differs from
    ``name``); ``minimum``, ``soft_max`` and ``precision`` are the slider's."""

    name: str
    label: str
    help: str
    default: float
    setting: str
    minimum: float = 0.0
    soft_max: float = 10.0
    precision: int = 2


def _no_params(values: dict) -> dict:
    return {}


@dataclass(frozen=True)
class Energy:
    """An energy: its names, options and evaluations.

    Evaluations take ``X`` (N, 3) at the run's scale, its ``Layout`` and the checked
    parameters (``**params``): ``exact(X, layout, **params) -> E``, ``exact_gradient(...) ->
    (E, ∇E)``, ``frame(X, layout, theta, **params)`` -> the tree's frame (``.energy(X)``,
    ``.energy_gradient(X)``) or None where the energy has no tree (a local sum is O(N)
    already)."""

    #: the ``energy=`` option's value
    name: str
    #: the UI's name and tooltip
    label: str
    help: str
    exact: Callable
    exact_gradient: Callable
    #: the parameters the energy takes (``alpha=``, ``beta=``), checked jointly by ``check``
    parameters: tuple[Parameter, ...] = ()
    #: ``{name: value or None}`` -> ``{name: float}``, defaults filled in; ValueError naming
    #: the one at fault
    check: Callable[[dict], dict] = _no_params
    #: ``k`` of ``E(λP) = λ^k E(P)`` for the checked parameters
    scaling: Callable[..., float] = lambda **params: 0.0
    #: the order of the ``hs`` metrics that fits the energy, or None where it cannot be a
    #: run's energy alone (:attr:`repulsive` False)
    metric_order: Callable[..., float] | None = None
    #: the tree's admissibility θ when none is given; None: no tree
    default_theta: float | None = None
    frame: Callable | None = None
    #: what results and keyed properties call the energy: ``"tangent_point(2, 4.5)"``
    tag: Callable[..., str] | None = None
    #: the keyed energy's tooltip for the checked parameters
    words: Callable[..., str] | None = None
    #: the row name of the panel's *Last Run* box ("TP"; the parameters follow)
    short: str = ""
    #: whether it keeps strands apart, so that a run may minimize it alone
    repulsive: bool = True
    #: an energy that adds to the repulsive one with a weight: that weight's option
    #: (``stiffness=``); None for the others
    weight: Parameter | None = None
    #: run options of the warm-up path that compiles this energy's kernels (empty: the
    #: energy is compiled by the warm-up's other paths), and the sizes it runs at
    warmup: tuple[dict, ...] = ()
    warmup_sizes: tuple[int, ...] = (100,)

    def describe(self, **params) -> str:
        """The :attr:`tag` for ``params`` (checked): the name alone without parameters."""
        return self.name if self.tag is None else self.tag(**params)

    @property
    def options(self) -> tuple[Parameter, ...]:
        """Every option the record brings to a run: its parameters and its weight."""
        return self.parameters + ((self.weight,) if self.weight is not None else ())
