"""Keyframes of a relaxation: spline point positions on the curve data, energy on the object.

Blender 4.4+ stores F-curves in *channelbags* of slotted actions; 4.2-4.3 keep them on
``action.fcurves``. Keys are written in bulk (``keyframe_points.add`` + ``foreach_set``) with
LINEAR interpolation: the core's step-size control keeps the straight segment between two
successive iterates free of self-intersections, so linear in-betweens never pass the curve
through itself (with ``keyframe_stride`` > 1 that guarantee is for the skipped iterates only).
"""

from __future__ import annotations

from collections.abc import Sequence

import bpy
import numpy as np

#: Custom property on the object that holds (and is keyframed with) the Möbius energy.
ENERGY_PROP = "moebius_energy"
ENERGY_PATH = f'["{ENERGY_PROP}"]'
_POINT_PATH = "splines[{s}].points[{i}].co"
_GROUP = "Möbius flow"
_LINEAR = 1  # index of 'LINEAR' in Keyframe.interpolation (CONSTANT, LINEAR, BEZIER, ...)


def _action_name(idblock: bpy.types.ID) -> str:
    """``<name>Action`` for an object, ``<name>CurveAction`` for its curve data.

    A converted curve and its data share one name, so one pattern for both would give
    ``<name>Action`` and ``<name>Action.001``.
    """
    # the RNA class name, not ID.id_type: Blender 3.4 (the legacy install) has no id_type
    kind = "" if isinstance(idblock, bpy.types.Object) else type(idblock).bl_rna.identifier
    return f"{idblock.name}{kind}Action"


def _fcurves(idblock: bpy.types.ID, create: bool):
    """The F-curve collection of ``idblock``'s action (channelbag on 4.4+), or None."""
    adt = idblock.animation_data
    if adt is None or adt.action is None:
        if not create:
            return None
        adt = adt or idblock.animation_data_create()
        adt.action = bpy.data.actions.new(_action_name(idblock))
    action = adt.action
    if not hasattr(action, "layers"):  # Blender 4.2-4.3: legacy actions
        return action.fcurves
    from bpy_extras import anim_utils

    slot = adt.action_slot
    if slot is None:
        if not create:
            return None
        slot = action.slots.new(id_type=idblock.id_type, name=idblock.name)
        adt.action_slot = slot
    if create:
        return anim_utils.action_ensure_channelbag_for_slot(action, slot).fcurves
    channelbag = anim_utils.action_get_channelbag_for_slot(action, slot)
    return None if channelbag is None else channelbag.fcurves


def _drop_empty_action(idblock: bpy.types.ID) -> None:
    adt = idblock.animation_data
    if adt is None or adt.action is None:
        return
    fcurves = _fcurves(idblock, create=False)
    if fcurves is None or len(fcurves) == 0:
        action = adt.action
        adt.action = None
        if action.users == 0:
            bpy.data.actions.remove(action)


def remove_flow_keyframes(obj: bpy.types.Object) -> int:
    """Delete the point and energy F-curves written by :func:`write_flow_keyframes`.

    Other animation of the object or curve (e.g. a keyframed location) is left alone; an action
    left empty is removed.

    Returns
    -------
    int
        Number of F-curves removed.
    """
    removed = 0
    for idblock, is_ours in (
        (obj.data, lambda p: p.startswith("splines[")),
        (obj, lambda p: p == ENERGY_PATH),
    ):
        fcurves = _fcurves(idblock, create=False)
        if fcurves is None:
            continue
        for fc in [fc for fc in fcurves if is_ours(fc.data_path)]:
            fcurves.remove(fc)
            removed += 1
        _drop_empty_action(idblock)
    return removed


def _write_channel(fcurves, data_path: str, index: int, frames: np.ndarray,
                   values: np.ndarray) -> None:
    try:  # channelbag F-curves (4.4+)
        fc = fcurves.new(data_path, index=index, group_name=_GROUP)
    except TypeError:  # legacy action.fcurves (4.2-4.3)
        fc = fcurves.new(data_path, index=index, action_group=_GROUP)
    keys = fc.keyframe_points
    keys.add(len(frames))
    keys.foreach_set("co", np.column_stack([frames, values]).ravel())
    keys.foreach_set("interpolation", np.full(len(frames), _LINEAR, dtype=np.int32))
    fc.update()


def write_flow_keyframes(obj: bpy.types.Object, iterates: Sequence[Sequence[np.ndarray]],
                         energies: Sequence[float], frame_start: int = 1) -> range:
    """Keyframe a sequence of polygons on the curve's splines and the energy on the object.

    Replaces keys from an earlier call (to append, pass the earlier iterates too: see
    :func:`read_flow_keyframes`); other animation stays.

    Parameters
    ----------
    obj : bpy.types.Object
        Curve object with one cyclic poly spline per polygon.
    iterates : sequence of K links
        Each a sequence of ``(n_i, 3)`` arrays, one per spline, in object coordinates.
    energies : sequence of K floats
        Möbius energy of each iterate (keyed as ``obj["moebius_energy"]``).
    frame_start : int
        Frame of the first iterate; iterate ``k`` lands on ``frame_start + k``.

    Returns
    -------
    range
        The keyed frames.
    """
    if len(iterates) != len(energies) or len(iterates) == 0:
        raise ValueError("need one energy per iterate and at least one iterate")
    remove_flow_keyframes(obj)
    sizes = [len(s.points) for s in obj.data.splines]
    X = np.stack([np.concatenate([np.asarray(P, float) for P in link]) for link in iterates])
    if X.shape[1] != sum(sizes):
        raise ValueError(f"iterates have {X.shape[1]} points, curve '{obj.name}' has {sum(sizes)}")
    frames = frame_start + np.arange(len(iterates), dtype=np.float64)
    fcurves = _fcurves(obj.data, create=True)
    offset = 0
    for s, n in enumerate(sizes):
        for i in range(n):
            path = _POINT_PATH.format(s=s, i=i)
            for c in range(3):
                _write_channel(fcurves, path, c, frames, X[:, offset + i, c])
        offset += n
    obj[ENERGY_PROP] = float(energies[0])
    _write_channel(_fcurves(obj, create=True), ENERGY_PATH, 0, frames,
                   np.asarray(energies, dtype=np.float64))
    return range(frame_start, frame_start + len(iterates))


def keyed_energies(obj: bpy.types.Object) -> tuple[np.ndarray, np.ndarray]:
    """Frames and energies keyed on ``obj`` by the last relaxation.

    Returns
    -------
    frames : (K,) int array
        Whole frame numbers (``scene.frame_set`` takes them as they are).
    energies : (K,) float array
        Empty when the object has no flow keys.
    """
    fcurves = _fcurves(obj, create=False)
    fc = None if fcurves is None else fcurves.find(ENERGY_PATH, index=0)
    if fc is None:
        return np.empty(0, dtype=np.int64), np.empty(0)
    co = np.empty(2 * len(fc.keyframe_points))
    fc.keyframe_points.foreach_get("co", co)
    return np.rint(co[0::2]).astype(np.int64), co[1::2]


def keyed_frames(obj: bpy.types.Object) -> list[int]:
    """Frames at which the energy of ``obj`` is keyed (empty when it has no flow keys)."""
    return keyed_energies(obj)[0].tolist()


def read_flow_keyframes(obj: bpy.types.Object) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The flow keyed on ``obj``: what :func:`write_flow_keyframes` wrote, read back.

    Returns
    -------
    None when the object has no flow keys, else
    frames : (K,) int array
    points : (K, N, 3) float array
        The keyed positions of all N points of all splines (in spline order) on every frame.
    energies : (K,) float array

    Raises
    ------
    ValueError
        When the keys are not a whole flow (a point without keys, or keyed on other frames
        than the energy): they were edited by hand.
    """
    frames, energies = keyed_energies(obj)
    if frames.size == 0:
        return None
    if not np.array_equal(frames, frames[0] + np.arange(len(frames))):
        raise ValueError(
            f"the flow keys of '{obj.name}' were edited (the energy is not keyed on every frame "
            f"from {frames[0]} to {frames[-1]}): use Apply Frame, then Relax, to start a new "
            f"flow from the current shape")
    fcurves = _fcurves(obj.data, create=False)
    by_path = {} if fcurves is None else {(fc.data_path, fc.array_index): fc for fc in fcurves}
    sizes = [len(s.points) for s in obj.data.splines]
    points = np.empty((len(frames), sum(sizes), 3))
    co = np.empty(2 * len(frames))
    offset = 0
    for s, n in enumerate(sizes):
        for i in range(n):
            path = _POINT_PATH.format(s=s, i=i)
            for c in range(3):
                fc = by_path.get((path, c))
                if fc is None or len(fc.keyframe_points) != len(frames):
                    raise ValueError(
                        f"the flow keys of '{obj.name}' were edited ({path}[{c}] is not keyed "
                        f"on the {len(frames)} frames of the energy): use Apply Frame, then "
                        f"Relax, to start a new flow from the current shape")
                fc.keyframe_points.foreach_get("co", co)
                if not np.array_equal(np.rint(co[0::2]), frames):
                    raise ValueError(
                        f"the flow keys of '{obj.name}' were edited ({path}[{c}] is keyed on "
                        f"other frames than the energy): use Apply Frame, then Relax, to start "
                        f"a new flow from the current shape")
                points[:, offset + i, c] = co[1::2]
        offset += n
    return frames, points, energies
