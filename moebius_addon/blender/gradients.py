"""Gradient fields of a curve drawn as vector fields (the paper's Fig. 2), and their redraw when
the curve's shape changes."""

from __future__ import annotations

import json
from collections.abc import Sequence

import bpy
import numpy as np

from .. import core
from . import geometry
from .objects import link_like
from .polygons import as_input, as_link

_GRADIENT_COLOURS = {"l2": (0.9, 0.2, 0.15, 1.0), "hs_pure": (0.2, 0.7, 0.2, 1.0),
                     "hs": (0.15, 0.35, 0.9, 1.0), "h1": (0.8, 0.6, 0.1, 1.0),
                     "h2": (0.6, 0.2, 0.8, 1.0)}


def show_gradients(obj: bpy.types.Object, metrics: Sequence[str] = ("l2", "hs_pure", "hs"),
                   length: float = 0.15, projected: bool = True,
                   context: bpy.types.Context | None = None, *,
                   energy: str = core.energies.DEFAULT_ENERGY,
                   **energy_options) -> list[bpy.types.Object]:
    """Draw energy gradients of a curve as vector fields (the paper's Fig. 2).

    For each metric a mesh object ``"<curve>.grad.<metric>"`` is made with one edge per vertex,
    from the vertex along the gradient. Each field is scaled on its own so that its longest
    arrow is ``length`` times the curve's bounding-box diagonal (the fields differ by orders of
    magnitude); the factor is stored as ``["moebius_arrow_scale"]``. Earlier fields of the same
    curve and metric are replaced. The fields show the shape they were drawn at; a relaxation,
    *Clear Flow* and *Apply Frame* redraw them at the shape they leave (:func:`refresh_gradients`).

    Parameters
    ----------
    obj : bpy.types.Object
        Curve of cyclic poly splines.
    metrics : sequence of str
        Metric names of ``core.sobolev_gradient``.
    length : float
        Longest arrow as a fraction of the bounding-box diagonal.
    projected : bool
        Project onto the constraints' tangent space (what the flow uses).
    context : bpy.types.Context, optional
    energy, **energy_options
        The energy whose gradient is drawn and its options (``alpha``, ``beta``,
        ``stiffness``), as ``relax_object`` takes them (the Flow panel's *Energy*; ``hs`` and
        ``hs_pure`` of the order that fits it). Stored on the fields
        (``["moebius_gradient_energy"]``, its label, and ``["moebius_energy_options"]``) so
        that a redraw draws the same energy's.

    Returns
    -------
    list of bpy.types.Object
        The gradient objects, parented to ``obj``.
    """
    context = context or bpy.context
    choice = core.check_energy(energy, **energy_options)
    polygons = geometry.curve_polygons(obj)
    try:  # NaN or a self-intersection would give NaN arrows; coarseness is no obstacle here
        core.check_polygon(as_input(polygons), coarseness=False)
    except ValueError as err:
        raise ValueError(f"'{obj.name}': {err}") from None
    X = np.concatenate(polygons)
    diagonal = float(np.linalg.norm(np.ptp(X, axis=0)))
    out = []
    for metric in metrics:
        G = np.concatenate(as_link(core.sobolev_gradient(
            as_input(polygons), metric=metric, projected=projected, energy=choice)))
        longest = float(np.linalg.norm(G, axis=1).max())
        scale = length * diagonal / longest if longest > 0 else 0.0
        name = f"{obj.name}.grad.{metric}"
        old = bpy.data.objects.get(name)
        if old is not None:
            mesh_old = old.data
            bpy.data.objects.remove(old)
            if mesh_old.users == 0:
                bpy.data.meshes.remove(mesh_old)
        mesh = bpy.data.meshes.new(name)
        n = len(X)
        mesh.from_pydata(np.vstack([X, X + scale * G]).tolist(),
                         np.column_stack([np.arange(n), np.arange(n) + n]).tolist(), [])
        mesh.update()
        arrows = bpy.data.objects.new(name, mesh)
        link_like(arrows, obj, context)
        arrows.parent = obj
        arrows.matrix_parent_inverse.identity()
        arrows.color = _GRADIENT_COLOURS.get(metric, (1, 1, 1, 1))
        arrows["moebius_gradient"] = metric
        arrows["moebius_arrow_scale"] = scale
        arrows["moebius_arrow_length"] = length
        arrows["moebius_projected"] = bool(projected)
        arrows["moebius_gradient_energy"] = choice.label
        arrows["moebius_energy_options"] = json.dumps(choice.options)
        out.append(arrows)
    return out


def refresh_gradients(obj: bpy.types.Object,
                      context: bpy.types.Context | None = None) -> list[bpy.types.Object]:
    """Redraw the gradient fields of ``obj`` (:func:`show_gradients`) at its current shape,
    with the metrics, length and projection they were drawn with; a field that cannot be drawn
    there any more (the shape touches itself) is removed rather than left stale.

    Returns
    -------
    list of bpy.types.Object
        The redrawn fields (empty when ``obj`` has none).
    """
    fields = [c for c in obj.children if "moebius_gradient" in c]
    if not fields:
        return []
    metrics = [c["moebius_gradient"] for c in fields]
    length = float(fields[0].get("moebius_arrow_length", 0.15))
    projected = bool(fields[0].get("moebius_projected", True))
    energy = json.loads(fields[0].get("moebius_energy_options", "{}"))
    try:
        return show_gradients(obj, metrics, length=length, projected=projected, context=context,
                              **energy)
    except ValueError:
        for c in fields:
            mesh = c.data
            bpy.data.objects.remove(c)
            if mesh.users == 0:
                bpy.data.meshes.remove(mesh)
        return []

