"""The energies the flow can minimize, one module each (private).

A module here is one energy: its name, which inputs it supports (open curves, links), how it
scales, and its pair kernels, the only place its integrand is written. Every sum of the core
(the dense sums of :mod:`..moebius_dense` and :mod:`..open_energy`, the tree engine's near and far
fields) reaches the integrand through these kernels (``@nb.njit(inline="always")``: inlined
into each sum, compiled with that sum's own options), so a second energy is a second module
here, not a sixth copy of the formula. The sums, their order and their parallel split stay
where they are; the kernels hold no loops.
"""

from __future__ import annotations

from . import moebius, tangent_point

#: Energies by name.
ENERGIES = {moebius.NAME: moebius, tangent_point.NAME: tangent_point}
