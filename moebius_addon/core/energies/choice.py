"""Which energy a run minimizes (the ``energy=`` option of ``relax`` and the options its record
brings: ``alpha=``, ``beta=``, ``stiffness=``).

An :class:`EnergyChoice` is one energy of :data:`.ENERGIES` with its parameters, checked once,
plus the weighted energies added to it (bending with ``stiffness=``), with the three
evaluations an engine needs: the exact sum (:meth:`~EnergyChoice.exact`), the exact sum with
its gradient (:meth:`~EnergyChoice.exact_gradient`) and the tree's frame at a polygon
(:meth:`~EnergyChoice.frame`). The engines (:mod:`..runs.engine`) hold one and never name an
energy themselves; everything here comes from the records (:mod:`.record`).

An added energy (a record with a ``weight``) counts only at a weight above 0: at 0 the choice
is the repulsive energy alone, its sums and bits unchanged. A run works at total length 1
(``runs.base.Run``), so the energies of its history are those of the curve scaled to total
length 1 (the user's curve's for a scale-invariant energy without an added one).
"""

from __future__ import annotations

import numpy as np

from ..geometry.layout import Layout
from ..runs.checks import check_number
from . import DEFAULT_ENERGY, ENERGIES
from .record import Energy

#: The names of the ``energy=`` option, the default first (an energy evaluates alone by any
#: of them; a run minimizes one of :data:`RUN_ENERGY_NAMES`).
ENERGY_NAMES = tuple(ENERGIES)
#: The energies a run may minimize alone: those that keep strands apart.
RUN_ENERGY_NAMES = tuple(name for name, r in ENERGIES.items() if r.repulsive)
#: The energies added with a weight, and their weights' option names.
WEIGHTED = {r.weight.name: r for r in ENERGIES.values() if r.weight is not None}
#: Every option an energy brings to a run, as ``{option name: (record, Parameter)}``.
ENERGY_OPTIONS = {p.name: (r, p) for r in ENERGIES.values() for p in r.options}


def take_energy_options(options: dict) -> dict:
    """Remove the energies' options (:data:`ENERGY_OPTIONS`) from ``options``; return them."""
    return {k: options.pop(k) for k in list(options) if k in ENERGY_OPTIONS}


class EnergyChoice:
    """The energy ``name`` with its parameters (``**params``: its own, e.g. ``alpha``,
    ``beta``, and the weights of the added energies, e.g. ``stiffness``), checked; see the
    module docstring."""

    def __init__(self, name: str = DEFAULT_ENERGY, alpha=None, beta=None, **params):
        if name not in ENERGIES:
            raise ValueError(f"unknown energy {name!r}; choose one of {', '.join(ENERGY_NAMES)}")
        params = {k: v for k, v in dict(params, alpha=alpha, beta=beta).items()
                  if v is not None}
        unknown = sorted(set(params) - set(ENERGY_OPTIONS))
        if unknown:
            raise ValueError(f"unknown energy option(s) {', '.join(unknown)}; the energies "
                             f"take {', '.join(ENERGY_OPTIONS)}")
        #: the energy's record (:mod:`.record`)
        self.record: Energy = ENERGIES[name]
        self.name = name
        own = {p.name for p in self.record.parameters}
        foreign = sorted(k for k in params if k not in own and k not in WEIGHTED)
        if foreign:
            owner = ENERGY_OPTIONS[foreign[0]][0]
            one = len(foreign) == 1
            raise ValueError(
                f"{' and '.join(foreign)} {'is an option' if one else 'are options'} of the "
                f"{owner.label.lower()} energy: pass energy={owner.name!r} with "
                f"{'it' if one else 'them'}, or leave {'it' if one else 'them'} out (the "
                "penalty methods' weight is penalty=)")
        #: the energy's own parameters, checked, defaults filled in
        self.params: dict = self.record.check({k: params[k] for k in own if k in params})
        #: the added energies with their weights above 0, as ``(record, weight)``
        self.addends: tuple = ()
        for option, rec in WEIGHTED.items():
            if option in params:
                w = check_number(option, params[option], 0)
                if w > 0.0:
                    if rec is self.record:
                        raise ValueError(f"{option} adds the {rec.label.lower()} energy to a "
                                         f"repulsive one; energy={name!r} has it already")
                    self.addends += ((rec, w),)

    @property
    def alpha(self):
        """The tangent-point exponent α (None for another energy)."""
        return self.params.get("alpha")

    @property
    def beta(self):
        """The tangent-point exponent β (None for another energy)."""
        return self.params.get("beta")

    @property
    def options(self) -> dict:
        """The options that make this choice again: ``energy=`` and its parameters."""
        out = {"energy": self.name, **self.params}
        out.update((rec.weight.name, w) for rec, w in self.addends)
        return out

    @property
    def records(self) -> tuple[Energy, ...]:
        """The records of every energy the choice sums: its own, then the added ones."""
        return (self.record, *(rec for rec, _ in self.addends))

    def __repr__(self) -> str:
        return f"EnergyChoice({self.label!r})"

    @property
    def label(self) -> str:
        """What results and keyed properties call the energy: ``"moebius"``,
        ``"tangent_point(2, 4.5)"`` (the parameters as given, shortest form), an added energy
        after a ``+`` with its weight: ``"moebius + bending(0.1)"``."""
        out = self.record.describe(**self.params)
        return out + "".join(f" + {rec.name}({w:g})" for rec, w in self.addends)

    @property
    def short_label(self) -> str:
        """The energy's row name in the panel's *Last Run* box: "Energy" for the default
        energy alone, else its short name with its parameters and the added weights: "TP (2,
        4.5)", "Energy + 0.1 bend"."""
        rec = self.record
        out = rec.short or rec.label
        if self.params:
            out += " (" + ", ".join(f"{v:g}" for v in self.params.values()) + ")"
        return out + "".join(f" + {w:g} {r.short or r.label}" for r, w in self.addends)

    @property
    def words(self) -> str:
        """A sentence for the keyed energy's tooltip."""
        out = self.record.words(**self.params)
        return out + "".join(f"; plus {w:g} × the {rec.label.lower()} energy at total "
                             "length 1" for rec, w in self.addends)

    @property
    def scaling(self) -> float:
        """``k`` of ``E(λP) = λ^k E(P)`` of the repulsive energy (0 for the Möbius energy);
        an added energy scales as its own record says (:meth:`exact`)."""
        return self.record.scaling(**self.params)

    @property
    def scale_invariant(self) -> bool:
        """Whether the whole energy is scale-invariant (no added energy either)."""
        return self.scaling == 0.0 and not self.addends

    @property
    def metric_order(self) -> float:
        """Order ``s`` of the fractional Sobolev metric that fits the energy (``hs`` and
        ``hs_pure``): 3/2 for the Möbius energy (the paper's W^{3/2,2}), ``(β − 1)/α`` for the
        tangent-point energy (Repulsive Curves; 7/4 at the default (2, 4.5), 3/2 at (2, 4))."""
        if self.record.metric_order is None:
            raise ValueError(self._not_alone())
        return self.record.metric_order(**self.params)

    @property
    def default_theta(self) -> float | None:
        """The tree's admissibility when none is given (each energy measured its own)."""
        return self.record.default_theta

    def check_run(self) -> EnergyChoice:
        """This choice, or ValueError where a run cannot minimize the energy alone."""
        if not self.record.repulsive:
            raise ValueError(self._not_alone())
        return self

    def _not_alone(self) -> str:
        rec = self.record
        how = (f"; add it to one with {rec.weight.name}=" if rec.weight is not None else "")
        return (f"the {rec.label.lower()} energy does not keep strands apart, so a run cannot "
                f"minimize it alone: choose one of {', '.join(RUN_ENERGY_NAMES)}{how}")

    # -- evaluations (X at the run's scale; layout of the run) ---------------------------------
    # ``k``: X is the caller's curve scaled by 2^-k; the results are the energy's at X in the
    # repulsive energy's scaling (the caller multiplies by 2^(k s)), the added terms rescaled
    # to it. k = 0 for a run (its weights are at total length 1).

    def _addend_factor(self, rec: Energy, w: float, k: int) -> float:
        return w * 2.0 ** (k * (rec.scaling() - self.scaling)) if k else w

    def exact(self, X: np.ndarray, layout: Layout, k: int = 0) -> float:
        """The exact sum over all pairs of edges (plus the added energies)."""
        E = self.record.exact(X, layout, **self.params)
        for rec, w in self.addends:
            E = E + self._addend_factor(rec, w, k) * rec.exact(X, layout)
        return E

    def exact_gradient(self, X: np.ndarray, layout: Layout,
                       k: int = 0) -> tuple[float, np.ndarray]:
        """``(E, ∇E)`` by the exact sum; ``∇E`` is (N, 3)."""
        E, g = self.record.exact_gradient(X, layout, **self.params)
        return self._plus_addends(E, g, X, layout, k)

    def _plus_addends(self, E, g, X, layout, k=0):
        for rec, w in self.addends:
            c = self._addend_factor(rec, w, k)
            Eb, gb = rec.exact_gradient(X, layout)
            E, g = E + c * Eb, g + c * gb
        return E, g

    def frame(self, X: np.ndarray, layout: Layout, theta: float, k: int = 0):
        """The tree's frame at ``X``: ``.energy(X)`` and ``.energy_gradient(X)`` of the
        approximated sum (plus the added energies, exact: they are local)."""
        frame = self.record.frame(X, layout, theta, **self.params)
        if not self.addends:
            return frame
        return _PlusAddends(frame, self, layout, k)


class _PlusAddends:
    """A tree frame whose energy and gradient carry the choice's added energies (local, so
    summed exactly), once per evaluation."""

    def __init__(self, frame, choice: EnergyChoice, layout: Layout, k: int):
        self._frame, self._choice, self._layout, self._k = frame, choice, layout, k

    def energy(self, X):
        E = self._frame.energy(X)
        for rec, w in self._choice.addends:
            E = E + self._choice._addend_factor(rec, w, self._k) * rec.exact(X, self._layout)
        return E

    def energy_gradient(self, X):
        E, g = self._frame.energy_gradient(X)
        return self._choice._plus_addends(E, g, X, self._layout, self._k)

    def __getattr__(self, name):
        return getattr(self._frame, name)


#: The Möbius energy (the default of every run).
MOEBIUS = EnergyChoice()


def check_energy(energy=DEFAULT_ENERGY, alpha=None, beta=None, **params) -> EnergyChoice:
    """The :class:`EnergyChoice` for the options ``energy``, ``alpha``, ``beta`` and the other
    energy options (``stiffness``) (an ``EnergyChoice`` passes as it is, or with the options
    given replacing its own); ValueError naming the option that is wrong."""
    params = {k: v for k, v in dict(params, alpha=alpha, beta=beta).items() if v is not None}
    if isinstance(energy, EnergyChoice):
        return EnergyChoice(energy.name, **_merged(energy, params)) if params else energy
    if not isinstance(energy, str):
        raise ValueError(f"energy must be one of {', '.join(ENERGY_NAMES)}, not {energy!r}")
    return EnergyChoice(energy, **params)


def _merged(choice: EnergyChoice, params: dict) -> dict:
    out = {k: v for k, v in choice.options.items() if k != "energy"}
    out.update(params)
    return out


def check_run_energy(energy=DEFAULT_ENERGY, **params) -> EnergyChoice:
    """:func:`check_energy` for a run: also refuses an energy a run cannot minimize alone."""
    return check_energy(energy, **params).check_run()
