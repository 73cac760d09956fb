"""Numerical core of moebius_addon: numpy + numba, never bpy.

The discrete method of Reiter & Schumacher, *Sobolev Gradients for the Möbius Energy*: the
Möbius energy of polygons and links, the metrics of the paper, the constraints, and the
projected Sobolev-gradient flow with collision-bounded Armijo steps, and the further optimizers
of the paper's comparison (``METHODS``, ``make_run``). The rooms:

- :mod:`.energies` — the energies, their pair kernels and dense sums;
- :mod:`.tree` — the tree engine: the edge hierarchy, near and far fields, tree contact;
- :mod:`.metrics` — Gram matrices and the saddle-point solves of the projected gradient;
- :mod:`.geometry` — polygons, layouts, collision, pins, constraints, obstacles, containers;
- :mod:`.topology` — the catalogue, the knot table, notations, invariants, identification;
- :mod:`.runs` — the engine (the one door to the numerics), the optimizers, entry points, batch;
- :mod:`.compilation` — numba's threads, the shipped kernels, the warm-up.

A run goes ``runs.flow`` → ``runs.methods`` → ``runs.engine`` → ``energies``/``tree``/``metrics``
(docs/api.md, "Architecture").
"""

from .compilation.threads import prefer_stable_layer

prefer_stable_layer()  # before any parallel kernel runs: numba settles on a layer then

from .compilation.notice import compiling  # noqa: E402
from .compilation.shipped_cache import use_shipped_cache  # noqa: E402
from .compilation.warmup import warm  # noqa: E402
from .energies import moebius_open as open_energy  # noqa: E402, F401
from .energies.choice import EnergyChoice, check_energy  # noqa: E402
from .geometry.collision import max_collision_free_step  # noqa: E402
from .geometry.constraints import Constraints  # noqa: E402
from .geometry.objio import read_obj, write_obj  # noqa: E402
from .geometry.polygon import (  # noqa: E402
    check_polygon,
    contact_ratio,
    resample,
    subdivide,
    suggest_edge_count,
)
from .metrics.gram import METRICS, gram_matrix  # noqa: E402
from .runs.adaptive import default_max_edges  # noqa: E402
from .runs.base import IterationState, RelaxResult, Status, check_number  # noqa: E402
from .runs.engine import (  # noqa: E402
    ENERGY_NAMES,
    ENGINES,
    energy,
    energy_gradient,
    moebius_energy,
    moebius_gradient,
)
from .runs.flow import relax, sobolev_gradient  # noqa: E402
from .runs.methods import METHODS, Relaxation, check_size, make_run  # noqa: E402
from .runs.penalty import DEFAULT_PENALTY_WEIGHT  # noqa: E402
from .topology import invariants, knots, pd, table, tangle  # noqa: E402
from .topology.identify import Identification, Match, identify  # noqa: E402
from .topology.invariants import (  # noqa: E402
    alexander_polynomial,
    is_knotted,
    jones_polynomial,
    knot_determinant,
    linking_numbers,
    signature,
)

# every kernel module is imported (those not yet, by use_shipped_cache): their kernels look in
# the cache shipped with the package as well
use_shipped_cache(__name__)

__all__ = [
    "DEFAULT_PENALTY_WEIGHT",
    "ENERGY_NAMES",
    "ENGINES",
    "METHODS",
    "METRICS",
    "Constraints",
    "EnergyChoice",
    "Identification",
    "IterationState",
    "Match",
    "RelaxResult",
    "Relaxation",
    "Status",
    "alexander_polynomial",
    "check_energy",
    "check_number",
    "check_polygon",
    "check_size",
    "compiling",
    "contact_ratio",
    "default_max_edges",
    "energy",
    "energy_gradient",
    "gram_matrix",
    "identify",
    "invariants",
    "is_knotted",
    "jones_polynomial",
    "knot_determinant",
    "knots",
    "linking_numbers",
    "make_run",
    "max_collision_free_step",
    "moebius_energy",
    "moebius_gradient",
    "pd",
    "read_obj",
    "relax",
    "resample",
    "signature",
    "sobolev_gradient",
    "subdivide",
    "suggest_edge_count",
    "table",
    "tangle",
    "warm",
    "write_obj",
]
