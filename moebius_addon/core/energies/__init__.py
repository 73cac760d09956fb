"""The energies the flow can minimize, one module each.

A module here is one energy: its record (:class:`.record.Energy`: name, UI label and help,
parameters with their checks and defaults, scaling, metric order, default θ, sums, tree frame,
warm-up path) and its kernels, the only place its integrand is written; every other room reads
the record from :data:`ENERGIES` and never compares an energy's name. Every sum of the core
(the dense sums of :mod:`..moebius_dense` and :mod:`..open_energy`, the tree engine's near and far
fields) reaches the integrand through these kernels (``@nb.njit(inline="always")``: inlined
into each sum, compiled with that sum's own options), so a second energy is a second module
here, not a sixth copy of the formula. The sums, their order and their parallel split stay
where they are; the kernels hold no loops.
"""

from __future__ import annotations

from . import bending, moebius, tangent_point
from .record import Energy, Parameter

#: Energy records by name, the default first.
ENERGIES: dict[str, Energy] = {r.name: r for r in (moebius.RECORD, tangent_point.RECORD,
                                                    bending.RECORD)}
#: The energy of a run when none is named.
DEFAULT_ENERGY = moebius.NAME

__all__ = ["DEFAULT_ENERGY", "ENERGIES", "Energy", "Parameter"]
