"""Scripting API of the Blender layer: what the buttons do, as plain functions.

Every operator in ``bpy.ops.moebius`` validates its input and calls one of these, so a
``blender --background --python`` script, the ``blender -c moebius`` command and the tests run
exactly the code the panel runs. Numerics come from :mod:`moebius_addon.core`.

This module gathers the public names of the modules that do each job (and keeps the
``moebius_addon.blender.api`` path of scripts working):

* :mod:`.labels`: names, labels and defaults of the menus (metrics, methods, catalogue);
* :mod:`.options`: the settings that act on a method, the run's keyword arguments, the checks
  every door makes before any work;
* :mod:`.conversion`: curves and meshes made into equal-edge poly curves;
* :mod:`.relaxation`: the run on a curve object (the stepper and the blocking call);
* :mod:`.rest`: the rest shape, *Clear Flow* and *Apply Frame*;
* :mod:`.catalogue`: knots and links by name (searchable) or notation (braid word, PD code);
* :mod:`.identification`: which knot or link a curve is, stored on it; whether a run kept it;
* :mod:`.gradients`: the gradient fields drawn as vector fields;
* :mod:`.export`: the keyed flow as Alembic or USD;
* below them :mod:`.geometry` (curves ↔ polygons), :mod:`.keyframes` (the flow's keys),
  :mod:`.polygons` (the core's input, the energy) and :mod:`.objects` (linking, selecting).
"""

from __future__ import annotations

from .catalogue import (
    COMPONENT_COLOURS,
    add_knot,
    add_notation,
    check_knot,
    colour_components,
    knot_names,
    knot_polygons,
    notation_polygons,
    search_knots,
)
from .conversion import apply_conversion, convert_object, make_curve_object, prepare_conversion
from .export import export_flow, export_suffix
from .gradients import refresh_gradients, show_gradients
from .group import group_name
from .identification import KNOT_TYPE_PROP, identify_object, object_curves, type_kept
from .keyframes import ENERGY_NAME_PROP, ENERGY_PROP
from .labels import (
    AUTO_METHOD,
    DEFAULT_ENGINE,
    DEFAULT_METHOD,
    DEFAULT_PENALTY,
    DEFAULT_THETA,
    ENERGIES,
    ENGINES,
    EXPLICIT_METHOD,
    KNOT_METHOD,
    METHODS,
    METRICS,
    PENALTY_METHODS,
    SPECIAL_KNOTS,
)
from .options import (
    EDGE_LIMIT,
    acting_settings,
    check_edge_count,
    check_relax_options,
    edge_limit,
    relax_settings,
)
from .polygons import energy
from .relaxation import (
    ObjectRelaxation,
    Preparation,
    choose_method,
    method_hint,
    relax_object,
    solver_paths,
    solver_warm,
)
from .rest import apply_frame, clear_animation

__all__ = [
    "COMPONENT_COLOURS", "KNOT_TYPE_PROP", "add_notation", "colour_components",
    "identify_object", "notation_polygons", "object_curves", "search_knots", "type_kept",
    "AUTO_METHOD", "DEFAULT_ENGINE", "DEFAULT_METHOD", "DEFAULT_PENALTY", "DEFAULT_THETA",
    "EDGE_LIMIT", "ENERGIES", "ENERGY_NAME_PROP", "ENERGY_PROP", "ENGINES", "EXPLICIT_METHOD",
    "KNOT_METHOD", "METHODS", "METRICS",
    "PENALTY_METHODS", "SPECIAL_KNOTS", "ObjectRelaxation", "acting_settings", "add_knot",
    "apply_conversion", "apply_frame", "check_edge_count", "check_knot", "check_relax_options",
    "choose_method", "clear_animation", "convert_object", "edge_limit", "energy", "export_flow",
    "export_suffix", "knot_names", "knot_polygons", "make_curve_object", "method_hint",
    "prepare_conversion", "refresh_gradients", "relax_object", "relax_settings", "show_gradients",
    "solver_warm", "Preparation", "solver_paths", "group_name",
]
