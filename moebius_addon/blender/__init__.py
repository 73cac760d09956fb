"""Blender layer: properties, operators, panel, menus, keyframes and a scripting API.

Scripts use the same functions as the buttons::

    from bl_ext.user_default.moebius_addon import blender as moebius
    knot = moebius.add_knot("fhw", 150)
    result = moebius.relax_object(knot, max_iterations=100)
"""

from __future__ import annotations

from .api import (
    EDGE_LIMIT,
    KNOT_TYPE_PROP,
    ObjectRelaxation,
    add_knot,
    add_notation,
    apply_conversion,
    apply_frame,
    check_edge_count,
    clear_animation,
    convert_object,
    edge_limit,
    energy,
    export_flow,
    identify_object,
    knot_polygons,
    make_curve_object,
    prepare_conversion,
    relax_object,
    relax_settings,
    show_gradients,
)
from .geometry import curve_polygons, object_polylines, write_polygons
from .keyframes import (
    ENERGY_NAME_PROP,
    ENERGY_PROP,
    keyed_energies,
    keyed_frames,
    remove_flow_keyframes,
    write_flow_keyframes,
)

__all__ = [
    "EDGE_LIMIT", "ENERGY_NAME_PROP", "ENERGY_PROP", "KNOT_TYPE_PROP", "ObjectRelaxation",
    "add_knot",
    "add_notation", "apply_conversion", "identify_object",
    "apply_frame", "check_edge_count", "clear_animation", "convert_object", "curve_polygons",
    "edge_limit", "energy", "export_flow",
    "keyed_energies", "keyed_frames", "knot_polygons", "make_curve_object", "object_polylines",
    "prepare_conversion", "relax_object", "relax_settings", "remove_flow_keyframes",
    "show_gradients", "write_flow_keyframes", "write_polygons",
]


def register() -> None:
    from . import cli, operators, panel, properties

    properties.register()
    operators.register()
    panel.register()
    cli.register()


def unregister() -> None:
    from . import cli, operators, panel, properties

    cli.unregister()
    panel.unregister()
    operators.unregister()
    properties.unregister()
