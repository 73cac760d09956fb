"""Curve objects relaxed together as one system: an artist's cables are separate objects, and a
run on a selection keeps every one of them apart from the others as from itself.

The run works in the object coordinates of the first (active) object; each :class:`Member`
maps its own splines there and back. Maps are similarities (rotation, translation, one
scale): edge lengths and distances keep their ratios, so what the core keeps (equal edges,
no contact) holds in every object's own coordinates.
"""

from __future__ import annotations

import re
from collections.abc import Sequence

import bpy
import numpy as np

from . import geometry


class Member:
    """One curve object of a run: its splines' place among the run's components (``span``)
    and the map of its object coordinates to the run's (``to_run``, ``to_local``).

    Raises
    ------
    ValueError
        Not a curve object, or scaled unevenly against the run's first object (the distances
        the run keeps would not be the object's own).
    """

    def __init__(self, obj: bpy.types.Object, first: bpy.types.Object, start: int) -> None:
        if obj.type != "CURVE":
            raise ValueError(f"'{obj.name}' is a {obj.type.lower()} object, not a curve; "
                             "convert it first (Möbius ▸ Polygon ▸ Convert) or leave it out "
                             "of the selection")
        self.obj = obj
        self.identity = obj == first
        M = np.array(first.matrix_world.inverted() @ obj.matrix_world, dtype=np.float64)
        self.A, self.t = M[:3, :3], M[:3, 3]
        G = self.A.T @ self.A
        s2 = float(np.trace(G)) / 3.0
        if not self.identity and (s2 <= 0.0 or np.abs(G - s2 * np.eye(3)).max() > 1e-6 * s2):
            raise ValueError(f"'{obj.name}' is scaled unevenly against '{first.name}' (or "
                             "sheared): the distances kept apart would differ between them; "
                             "apply the scale of both (Object ▸ Apply ▸ Scale)")
        self._inv = np.linalg.inv(self.A)
        #: lengths in the object's coordinates times this are lengths in the run's
        self.scale = 1.0 if self.identity else float(np.sqrt(s2))
        #: the splines at the current frame (object coordinates) and whether each is closed
        self.polygons = geometry.curve_polygons(obj, allow_open=True)
        self.closed = geometry.curve_closed(obj)
        self.span = slice(start, start + len(self.polygons))
        #: where each spline ends in the member's stacked points
        self.cuts = np.cumsum([len(p) for p in self.polygons])[:-1]
        #: the earlier flow keys (frames, points, energies), when continued or shown live
        self.prior = None

    def to_run(self, polygons: Sequence[np.ndarray]) -> list[np.ndarray]:
        """Object coordinates to the run's (the first member's: unchanged)."""
        if self.identity:
            return list(polygons)
        return [np.asarray(P, dtype=np.float64) @ self.A.T + self.t for P in polygons]

    def to_local(self, polygons: Sequence[np.ndarray]) -> list[np.ndarray]:
        """The run's coordinates to the object's."""
        if self.identity:
            return list(polygons)
        return [(np.asarray(P, dtype=np.float64) - self.t) @ self._inv.T for P in polygons]


def members(objects) -> list[Member]:
    """The :class:`Member` of each curve object of ``objects`` (one object or a sequence, the
    first the run's frame), each once."""
    objs = [objects] if isinstance(objects, bpy.types.Object) else list(objects)
    if not objs:
        raise ValueError("no curve object given: select the curves to relax")
    names = [o.name for o in objs]
    if len(set(names)) != len(names):
        twice = sorted({n for n in names if names.count(n) > 1})
        raise ValueError(f"{', '.join(repr(n) for n in twice)} given twice")
    out, start = [], 0
    for o in objs:
        out.append(Member(o, objs[0], start))
        start += len(out[-1].polygons)
    return out


#: A custom property of a curve object: its tube radius in world units, kept instead of its
#: bevel (a tube another modifier or a render setting draws).
THICKNESS_PROP = "moebius_thickness"


def bevel_thickness(members_: Sequence[Member]) -> float:
    """The tube radius of the run's curves in its coordinates: the largest of each curve's
    :data:`THICKNESS_PROP` (world units) or else its bevel (the rendered tube's radius, in
    the object's units) — every tube is kept at least that thick, so none meets another."""
    first = members_[0].obj.matrix_world.to_scale()
    world = float(abs(first[0] * first[1] * first[2])) ** (1.0 / 3.0) or 1.0
    radii = []
    for m in members_:
        own = m.obj.get(THICKNESS_PROP)
        if isinstance(own, (int, float)) and own > 0:
            radii.append(float(own) / world)
        else:
            radii.append(m.obj.data.bevel_depth * m.scale)
    return max(radii, default=0.0)


def name_components(message: str, members_: Sequence[Member]) -> str:
    """A core message with its "component k" named as the user knows it: the object (and its
    spline) holding that component."""
    if len(members_) == 1 and len(members_[0].polygons) == 1:
        return message
    return re.sub(r"\bcomponent (\d+)\b",
                  lambda m: component_owner(members_, int(m.group(1))), message)


def group_name(objects: Sequence[bpy.types.Object]) -> str:
    """How reports name a run's objects: ``'Knot'``, or ``'Cable' and 9 other curves``."""
    first = f"'{objects[0].name}'"
    rest = len(objects) - 1
    return first if not rest else f"{first} and {rest} other curve{'s' * (rest > 1)}"


def component_owner(members_: Sequence[Member], component: int) -> str:
    """The object (and its spline) holding the run's ``component``, in words."""
    for m in members_:
        if m.span.start <= component < m.span.stop:
            k = component - m.span.start
            return f"'{m.obj.name}'" + (f" (spline {k + 1})" if len(m.polygons) > 1 else "")
    raise IndexError(component)
