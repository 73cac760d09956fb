"""Numerical core of moebius_addon: numpy + numba, never bpy.

The discrete method of Reiter & Schumacher, *Sobolev Gradients for the Möbius Energy*: the
Möbius energy of polygons and links, the metrics of the paper, the constraints, and the
projected Sobolev-gradient flow with collision-bounded Armijo steps, and the further optimizers
of the paper's comparison (``METHODS``, ``make_run``). See ``docs/api.md``.
"""

from . import knots
from .collision import max_collision_free_step
from .constraints import Constraints
from .energy import moebius_energy, moebius_gradient
from .flow import IterationState, Relaxation, RelaxResult, relax, sobolev_gradient
from .methods import METHODS, make_run
from .metrics import METRICS, gram_matrix
from .objio import read_obj, write_obj
from .polygon import check_polygon, contact_ratio, resample, suggest_edge_count

__all__ = [
    "METHODS",
    "METRICS",
    "Constraints",
    "IterationState",
    "RelaxResult",
    "Relaxation",
    "check_polygon",
    "contact_ratio",
    "gram_matrix",
    "knots",
    "make_run",
    "max_collision_free_step",
    "moebius_energy",
    "moebius_gradient",
    "read_obj",
    "relax",
    "resample",
    "sobolev_gradient",
    "suggest_edge_count",
    "write_obj",
]
