"""Keyframes of a relaxation: the point positions of every iterate on the curve data, the energy
on the object.

The positions are stored one of two ways, by the curve's size (measured in docs/blender.md,
"How the keys are stored"):

* up to :data:`PER_POINT_MAX` points, one F-curve per coordinate of every spline point
  (``splines[s].points[i].co``): the animated values are the curve's own points, which
  Blender's exporters and any script read directly;
* above it, one absolute shape key per iterate on the curve data and one F-curve for the key's
  evaluation time (``eval_time``, keyed on each key's position): writing and playing cost about
  N per iterate instead of one F-curve per coordinate. Blender shows the mix of the keys;
  :func:`flow_shape_at` computes that mix (``geometry.curve_polygons`` reads it), and
  ``export.export_flow`` writes it into the points while it exports (the exporters read the
  points, not the keys).

Blender 4.4+ stores F-curves in *channelbags* of slotted actions; 4.2-4.3 keep them on
``action.fcurves`` (``make test`` runs both: Blender 4.2, 4.5, 5.0 and 5.2). Keys are written in
bulk (``keyframe_points.add`` + ``foreach_set``) with LINEAR interpolation, and the shape keys
with KEY_LINEAR: the core's step-size control keeps the straight segment between two successive
iterates free of self-intersections, so linear in-betweens never pass the curve through itself
(with ``keyframe_stride`` > 1 that guarantee is for the skipped iterates only).
"""

from __future__ import annotations

from collections.abc import Sequence

import bpy
import numpy as np

#: Custom property on the object that holds (and is keyframed with) the energy of the flow:
#: the Möbius energy unless :data:`ENERGY_NAME_PROP` says otherwise.
ENERGY_PROP = "moebius_energy"
ENERGY_PATH = f'["{ENERGY_PROP}"]'
#: Custom property naming the energy keyed in :data:`ENERGY_PROP` (``core.EnergyChoice.label``:
#: "moebius" or "tangent_point(2, 4.5)"); also the property's tooltip.
ENERGY_NAME_PROP = "moebius_energy_name"
#: Curves of at most this many points are keyed per point, larger ones as shape keys (every
#: size the add-on took before shape keys keeps its per-point keys).
PER_POINT_MAX = 5000
_POINT_PATH = "splines[{s}].points[{i}].co"
_GROUP = "Möbius flow"
_LINEAR = 1  # index of 'LINEAR' in Keyframe.interpolation (CONSTANT, LINEAR, BEZIER, ...)
_EVAL_TIME = "eval_time"
_FLOW_KEY = "moebius_flow"  # custom property that marks the shape keys (Key) of a flow
_KEY_NAME = "Möbius {k}"  # shape key of iterate k


def _action_name(idblock: bpy.types.ID) -> str:
    """``<name>Action`` for an object, ``<name>CurveAction`` for its curve data,
    ``<curve>KeyAction`` for the curve's shape keys.

    A converted curve and its data share one name, so one pattern for both would give
    ``<name>Action`` and ``<name>Action.001``.
    """
    if isinstance(idblock, bpy.types.Key):  # named "Key", "Key.001", ...: by its curve
        return f"{idblock.user.name}KeyAction"
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
        return _ensure_channelbag(action, slot).fcurves
    channelbag = anim_utils.action_get_channelbag_for_slot(action, slot)
    return None if channelbag is None else channelbag.fcurves


def _ensure_channelbag(action: bpy.types.Action, slot: bpy.types.ActionSlot):
    """The channelbag of ``slot`` in the first keyframe strip of ``action``, made if missing.

    What ``bpy_extras.anim_utils.action_ensure_channelbag_for_slot`` does from Blender 5.0 on;
    4.4 and 4.5 have slotted actions but not that function.
    """
    layer = action.layers[0] if len(action.layers) else action.layers.new("Layer")
    strip = layer.strips[0] if len(layer.strips) else layer.strips.new(type="KEYFRAME")
    return strip.channelbag(slot, ensure=True)


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


def _flow_key(curve: bpy.types.Curve) -> bpy.types.Key | None:
    """The shape keys of ``curve`` if :func:`write_flow_keyframes` wrote them, else None."""
    key = curve.shape_keys
    return key if key is not None and key.get(_FLOW_KEY) else None


def is_flow_key(curve: bpy.types.Curve) -> bool:
    """Whether the shape keys of ``curve`` are a flow's (:func:`write_flow_keyframes`)."""
    return _flow_key(curve) is not None


def check_flow_target(obj: bpy.types.Object) -> None:
    """ValueError, before a run, when the flow of ``obj`` could not be keyed: a curve above
    :data:`PER_POINT_MAX` points keys its flow as shape keys, so it must have none of its own
    (the flow's own, from an earlier run, are replaced)."""
    key = obj.data.shape_keys
    n = sum(len(s.points) for s in obj.data.splines)
    if n > PER_POINT_MAX and key is not None and not key.get(_FLOW_KEY):
        raise ValueError(
            f"curve '{obj.name}' has shape keys of its own ({key.key_blocks[0].name}, …); the "
            f"flow of a curve above {PER_POINT_MAX} points is keyed as shape keys, so remove "
            f"them first (Properties ▸ Object Data ▸ Shape Keys)")


def _remove_flow_key(obj: bpy.types.Object) -> int:
    key = _flow_key(obj.data)
    if key is None:
        return 0
    adt = key.animation_data
    action = adt.action if adt is not None else None
    obj.shape_key_clear()
    if action is not None and action.users == 0:
        bpy.data.actions.remove(action)
    return 1


def remove_flow_keyframes(obj: bpy.types.Object) -> int:
    """Delete the keys written by :func:`write_flow_keyframes`: the point F-curves or the flow's
    shape keys, and the energy F-curve.

    Other animation of the object or curve (e.g. a keyframed location) is left alone; an action
    left empty is removed.

    Returns
    -------
    int
        Number of F-curves removed (the shape keys with their F-curve count as one).
    """
    removed = _remove_flow_key(obj)
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
    owner = fcurves.data  # the channelbag (4.4+) or the legacy action (4.2-4.3)
    if isinstance(owner, bpy.types.Action):
        fc = fcurves.new(data_path, index=index, action_group=_GROUP)
    else:  # 4.4 and 4.5 have no group_name argument here (5.0 added it)
        fc = fcurves.new(data_path, index=index)
        fc.group = owner.groups.get(_GROUP) or owner.groups.new(_GROUP)
    keys = fc.keyframe_points
    keys.add(len(frames))
    keys.foreach_set("co", np.column_stack([frames, values]).ravel())
    keys.foreach_set("interpolation", np.full(len(frames), _LINEAR, dtype=np.int32))
    fc.update()


def write_flow_keyframes(obj: bpy.types.Object, iterates: Sequence[Sequence[np.ndarray]],
                         energies: Sequence[float], frame_start: int = 1,
                         shape_keys: bool | None = None, energy_name: str | None = None,
                         energy_words: str | None = None) -> range:
    """Keyframe a sequence of polygons on the curve's splines and the energy on the object.

    Replaces keys from an earlier call (to append, pass the earlier iterates too: see
    :func:`read_flow_keyframes`); other animation stays. The curve's own points are left as
    they are (per-point keys overwrite them on every frame change; under shape keys they are
    not shown).

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
    shape_keys : bool, optional
        Key the positions as shape keys (True) or per point (False); None (default) chooses
        by the size (shape keys above :data:`PER_POINT_MAX` points).
    energy_name : str, optional
        Which energy ``energies`` are (``core.EnergyChoice.label``), stored as
        ``obj["moebius_energy_name"]``; None leaves the stored name as it is.
    energy_words : str, optional
        The energy property's tooltip (``core.EnergyChoice.words``; None: ``energy_name``).

    Returns
    -------
    range
        The keyed frames.
    """
    if len(iterates) != len(energies) or len(iterates) == 0:
        raise ValueError("need one energy per iterate and at least one iterate")
    sizes = [len(s.points) for s in obj.data.splines]
    for link in iterates:
        if sum(len(P) for P in link) != sum(sizes):
            raise ValueError(f"iterates have {sum(len(P) for P in link)} points, curve "
                             f"'{obj.name}' has {sum(sizes)}")
    if shape_keys is None:
        shape_keys = sum(sizes) > PER_POINT_MAX
    key = obj.data.shape_keys
    if shape_keys and key is not None and not key.get(_FLOW_KEY):
        raise ValueError(f"curve '{obj.name}' has shape keys of its own; remove them first")
    remove_flow_keyframes(obj)
    frames = frame_start + np.arange(len(iterates), dtype=np.float64)
    if shape_keys:
        _write_shape_keys(obj, iterates, frames)
    else:
        _write_points(obj, sizes, iterates, frames)
    obj[ENERGY_PROP] = float(energies[0])
    if energy_name is not None:
        obj[ENERGY_NAME_PROP] = energy_name
        obj.id_properties_ui(ENERGY_PROP).update(
            description=energy_name if energy_words is None else energy_words)
    _write_channel(_fcurves(obj, create=True), ENERGY_PATH, 0, frames,
                   np.asarray(energies, dtype=np.float64))
    return range(frame_start, frame_start + len(iterates))


def _write_points(obj, sizes, iterates, frames) -> None:
    """One F-curve per coordinate of every point."""
    X = np.stack([np.concatenate([np.asarray(P, float) for P in link]) for link in iterates])
    fcurves = _fcurves(obj.data, create=True)
    offset = 0
    for s, n in enumerate(sizes):
        for i in range(n):
            path = _POINT_PATH.format(s=s, i=i)
            for c in range(3):
                _write_channel(fcurves, path, c, frames, X[:, offset + i, c])
        offset += n


def _write_shape_keys(obj, iterates, frames) -> None:
    """One absolute shape key per iterate, and the key's evaluation time keyed on the frames
    (a run refuses a curve with shape keys of its own before it starts: ``check_flow_target``)."""
    # every block is added while the key is relative (Blender places each 0.1 after the one
    # before: frames 0, 10, 20, ...), then the key is made absolute
    for k in range(len(iterates)):
        obj.shape_key_add(name=_KEY_NAME.format(k=k), from_mix=False)
    key = obj.data.shape_keys
    key[_FLOW_KEY] = True
    key.use_relative = False
    for block, link in zip(key.key_blocks, iterates, strict=True):
        block.data.foreach_set(
            "co", np.concatenate([np.asarray(P, np.float32) for P in link]).ravel())
        block.interpolation = "KEY_LINEAR"
    # the evaluation time on each key's own position at its frame: every frame shows its
    # iterate exactly (the positions are float32 sums of 0.1, not exact multiples of 10)
    positions = np.array([block.frame for block in key.key_blocks])
    _write_channel(_fcurves(key, create=True), _EVAL_TIME, 0, frames, positions)


def flow_shape_at(obj: bpy.types.Object, frame: float) -> np.ndarray | None:
    """All points of a flow keyed as shape keys, as Blender shows them at ``frame`` (float:
    subframes too), one ``(N, 3)`` float64 array in spline order; None for a curve without them
    (a per-point flow animates the points themselves).

    The keys' evaluation time at ``frame`` comes from its F-curve (the property itself is
    updated only when Blender next evaluates the animation); the keys are mixed as Blender
    mixes absolute KEY_LINEAR keys: linearly between the two whose positions enclose the time,
    the first or last one outside."""
    key = _flow_key(obj.data)
    fcurves = None if key is None else _fcurves(key, create=False)
    fc = None if fcurves is None else fcurves.find(_EVAL_TIME)
    if fc is None:
        return None
    t = fc.evaluate(frame)
    blocks = key.key_blocks
    positions = np.array([b.frame for b in blocks])
    j = min(max(int(np.searchsorted(positions, t, side="right")) - 1, 0), len(blocks) - 1)
    a = _block_points(blocks[j])
    if j + 1 == len(blocks) or t <= positions[j]:
        return a
    d = (t - positions[j]) / (positions[j + 1] - positions[j])
    return (1.0 - d) * a + d * _block_points(blocks[j + 1])


def _block_points(block: bpy.types.ShapeKey) -> np.ndarray:
    co = np.empty(3 * len(block.data), dtype=np.float32)
    block.data.foreach_get("co", co)
    return co.reshape(-1, 3).astype(np.float64)


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
    if _flow_key(obj.data) is not None:
        return frames, _read_shape_keys(obj, frames), energies
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


def _read_shape_keys(obj: bpy.types.Object, frames: np.ndarray) -> np.ndarray:
    """The iterates of a flow keyed as shape keys, ``(K, N, 3)``; ValueError when the keys
    were edited (not one key per keyed frame, or the evaluation time not on their positions)."""
    key = _flow_key(obj.data)
    blocks = key.key_blocks
    fcurves = _fcurves(key, create=False)
    fc = None if fcurves is None else fcurves.find(_EVAL_TIME)
    co = np.empty(2 * len(frames))
    if fc is not None and len(fc.keyframe_points) == len(frames):
        fc.keyframe_points.foreach_get("co", co)
    positions = np.array([block.frame for block in blocks])
    if (fc is None or len(blocks) != len(frames) or len(fc.keyframe_points) != len(frames)
            or not np.array_equal(np.rint(co[0::2]), frames)
            or not np.allclose(co[1::2], positions, rtol=0, atol=1e-3)):
        raise ValueError(
            f"the flow keys of '{obj.name}' were edited (its shape keys are not one per frame "
            f"from {frames[0]} to {frames[-1]} of the energy): use Apply Frame, then Relax, to "
            f"start a new flow from the current shape")
    points = np.empty((len(blocks), len(blocks[0].data), 3))
    for k, block in enumerate(blocks):
        points[k] = _block_points(block)
    return points
