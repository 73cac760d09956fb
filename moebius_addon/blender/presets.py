"""The panel's presets (Möbius ▸ Presets): *Untangle Cables*, *Pack in Volume*, *Relax Knot*.

A preset sets a few settings of ``scene.moebius`` (the table is ``options.PRESETS``, bpy-free);
the user can change any of them afterwards. Where there is an active curve it also prepares the
curve for that use: a thickness (bevel depth) so that the result renders at once, the cable ends
selected (Pin Selected Points pins them), the length to grow to.
"""

from __future__ import annotations

import bpy
import numpy as np

from . import options


def spline_length(spline) -> float:
    """Length of a spline's control polygon in object units (closing edge included when it
    is cyclic)."""
    P = np.empty(4 * len(spline.points))
    spline.points.foreach_get("co", P)
    P = P.reshape(-1, 4)[:, :3]
    if spline.use_cyclic_u:
        P = np.vstack([P, P[:1]])
    return float(np.linalg.norm(np.diff(P, axis=0), axis=1).sum())


def curve_length(obj: bpy.types.Object) -> tuple[float, int]:
    """Total length of the splines of the curve object ``obj`` (object units) and its
    number of edges."""
    splines = list(obj.data.splines)
    edges = sum(len(s.points) - (0 if s.use_cyclic_u else 1) for s in splines)
    return sum(spline_length(s) for s in splines), edges


def _select_ends(obj: bpy.types.Object) -> int:
    """Select exactly the two end points of every open spline of ``obj`` (none of a closed
    one); the number selected."""
    count = 0
    for s in obj.data.splines:
        sel = np.zeros(len(s.points), dtype=bool)
        if not s.use_cyclic_u:
            sel[[0, -1]] = True
        s.points.foreach_set("select", sel)
        count += int(sel.sum())
    return count


def apply_preset(scene: bpy.types.Scene, name: str, obj=None) -> str:
    """Set the settings of preset ``name`` (a key of ``options.PRESETS``) on
    ``scene.moebius``, and prepare the curve object ``obj`` (None, or not a curve: settings
    only; a list: each curve object of it, as Relax relaxes a selection together). Returns
    what was done, in words.

    Raises
    ------
    ValueError
        An unknown preset; ``obj`` in Edit Mode (its selection is the Edit Mode's then);
        nothing is changed then.
    """
    if name not in options.PRESETS:
        raise ValueError(f"unknown preset '{name}'; choose one of {', '.join(options.PRESETS)}")
    label, _, values = options.PRESETS[name]
    objs = [o for o in ([obj] if isinstance(obj, bpy.types.Object) or obj is None else obj)
            if o is not None and o.type == "CURVE"]
    for o in objs:
        if o.mode == "EDIT":
            raise ValueError(f"'{o.name}' is in Edit Mode: leave it (Tab) to apply the preset "
                             "(it sets the curve's thickness and selection)")
    objs = [o for o in objs if o.data.splines]
    s = scene.moebius
    if name == "relax_knot":
        for key in options.PRESET_SETTINGS:
            s.property_unset(key)
    for key, value in values.items():
        setattr(s, key, value)
    notes = []
    if name == "untangle_cables":
        if s.obstacles is None and "Obstacles" in bpy.data.collections:
            s.obstacles = bpy.data.collections["Obstacles"]
        notes.append(f"obstacles '{s.obstacles.name}'" if s.obstacles is not None else
                     "no obstacles: choose their collection in Advanced")
    if objs:
        lengths = [curve_length(o) for o in objs]
        named = f"'{objs[0].name}'" + (f" and {len(objs) - 1} more" if len(objs) > 1 else "")
        if name == "untangle_cables":
            ends = sum(_select_ends(o) for o in objs)
            notes.append(f"{ends} cable ends of {named} selected to pin")
        if name == "pack_in_volume":
            length = sum(L for L, _ in lengths)
            s.length_target = options.PACK_LENGTH_FACTOR * length
            notes.append(f"length {length:.4g} → {s.length_target:.4g}")
        for o, (length, edges) in zip(objs, lengths, strict=True):
            data = o.data
            data.bevel_depth = options.BEVEL_EDGES * length / max(edges, 1)
            data.bevel_resolution = 4
            data.use_fill_caps = True
        notes.append(f"thickness {objs[0].data.bevel_depth:.3g}")
    if name == "pack_in_volume" and s.container is None:
        notes.append("no container: choose a closed mesh around the curve in Advanced")
    return f"{label}" + (": " + ", ".join(notes) if notes else "")
