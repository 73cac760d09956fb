"""In-Blender side of the UI test: installs the add-on, then answers the driver from a timer.

Started by ``run_ui_test.py`` as ``blender knot.blend --python harness.py -- --out DIR --zip ZIP``
in a real (Xvfb) window. It never presses a button itself: the driver clicks and types with
xdotool. This script only

* installs the add-on the classic way (``preferences.addon_install`` of a zip of the package
  folder, as Preferences ▸ Add-ons ▸ Install… does) and enables it;
* counts redraws of the Möbius panel (a draw function appended to it), so the driver knows
  when the sidebar shows the Möbius tab and when a theme change has reached the screen;
* answers commands that the driver drops as ``DIR/cmd/NNNN.json`` (read every 0.2 s by a
  ``bpy.app.timers`` function, which also runs while the modal Relax operator is running) with
  ``DIR/resp/NNNN.json``: window/region rectangles, a one-frame colour marker on operator
  buttons, checks of the scene after Esc / Clear / a full run, and a Graph Editor view;
* writes ``DIR/state.json`` (the live state of the panel settings) on every tick.
"""

from __future__ import annotations

import json
import os
import sys
import time
import traceback
from itertools import pairwise
from pathlib import Path

import bpy

ARGS = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []


def _arg(name: str, default: str | None = None) -> str | None:
    return ARGS[ARGS.index(name) + 1] if name in ARGS else default


OUT = Path(_arg("--out", "out/ui")).resolve()
ZIP = _arg("--zip")
SOURCE = "Helix"
MARKER = (1.0, 0.0, 1.0, 1.0)  # magenta: no button of the default theme is drawn in it

_state: dict = {"ready": False, "panel_draws": 0, "sidebar_draws": 0, "errors": []}
_saved: dict = {}


def _write_json(path: Path, data) -> None:
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(data, indent=1, default=float))
    os.replace(tmp, path)


def _points(curve) -> list[list[float]]:
    out = []
    for spline in curve.splines:
        pts = spline.points if spline.type != "BEZIER" else spline.bezier_points
        out += [list(p.co)[:3] for p in pts]
    return out


def _maxdiff(a, b) -> float:
    if len(a) != len(b):
        return float("inf")
    return max((abs(x - y) for p, q in zip(a, b, strict=True)
                for x, y in zip(p, q, strict=True)), default=0.0)


# ---------------------------------------------------------------------------------------------
# Set-up: install and enable the add-on as a legacy add-on.

def _install() -> None:
    t0 = time.perf_counter()
    if ZIP:
        bpy.ops.preferences.addon_install(filepath=ZIP, overwrite=True)
    result = bpy.ops.preferences.addon_enable(module="moebius_addon")
    import moebius_addon  # the installed copy in BLENDER_USER_SCRIPTS/addons

    _state["install"] = {
        "result": sorted(result), "seconds": time.perf_counter() - t0,
        "module_file": moebius_addon.__file__, "bl_info": moebius_addon.bl_info,
        "blender": bpy.app.version_string, "python": sys.version.split()[0],
    }
    import numba
    import numpy

    _state["install"]["numpy"] = numpy.__version__
    _state["install"]["numba"] = numba.__version__
    _state["install"]["numba_file"] = numba.__file__
    bpy.types.VIEW3D_PT_moebius.append(_count_draw)
    _saved["ui_handler"] = bpy.types.SpaceView3D.draw_handler_add(
        _count_sidebar_draw, (), "UI", "POST_PIXEL")
    _saved["view_handler"] = bpy.types.SpaceView3D.draw_handler_add(
        _note_view_draw, (), "WINDOW", "POST_PIXEL")
    src = bpy.data.objects.get(SOURCE)
    _saved["source_points"] = _points(src.data) if src is not None else None


def _count_draw(self, context) -> None:
    _state["panel_draws"] += 1


def _count_sidebar_draw() -> None:
    _state["sidebar_draws"] += 1


def _note_view_draw() -> None:
    """Remember which iterate the 3D view showed when it was last drawn."""
    s = getattr(bpy.context.scene, "moebius", None)
    _state["view_iteration"] = s.live_iteration if s is not None and s.running else None


# ---------------------------------------------------------------------------------------------
# Commands from the driver.

def _window():
    return bpy.context.window_manager.windows[0]


def _rect(obj) -> dict:
    return {"x": obj.x, "y": obj.y, "width": obj.width, "height": obj.height}


def cmd_regions(_args) -> dict:
    win = _window()
    areas = []
    for area in win.screen.areas:
        areas.append({"type": area.type, **_rect(area),
                      "regions": {r.type: _rect(r) for r in area.regions if r.width > 1}})
    prefs = bpy.context.preferences.system
    return {"window": {"width": win.width, "height": win.height}, "areas": areas,
            "ui_scale": prefs.ui_scale, "pixel_size": prefs.pixel_size}


def _tag_redraw_all() -> None:
    for area in _window().screen.areas:
        area.tag_redraw()


def cmd_marker(args) -> dict:
    """Paint one theme colour in the marker colour (``on``) or restore it (``off``).

    ``path`` is the colour's path in the theme: ``user_interface.wcol_tool.inner`` (the inside
    of operator buttons) or ``view_3d.space.tab_inactive`` (the sidebar's category tabs other
    than the active one).
    """
    path = args.get("path", "user_interface.wcol_tool.inner")
    owner_path, attr = path.rsplit(".", 1)
    owner = bpy.context.preferences.themes[0]
    for part in owner_path.split("."):
        owner = getattr(owner, part)
    if args.get("on"):
        value = getattr(owner, attr)
        _saved.setdefault(path, tuple(value))
        setattr(owner, attr, MARKER[:len(value)])
    elif path in _saved:
        setattr(owner, attr, _saved.pop(path))
    _tag_redraw_all()
    return {"sidebar_draws": _state["sidebar_draws"]}


def cmd_clipboard(args) -> dict:
    """The window manager's clipboard (set to ``set`` first, if given): the driver presses
    Ctrl+C over a button, which copies an operator button's Python command."""
    wm = bpy.context.window_manager
    if "set" in args:
        wm.clipboard = args["set"]
    return {"clipboard": wm.clipboard}


def _flow_object():
    obj = bpy.context.view_layer.objects.active
    return obj if obj is not None and obj.type == "CURVE" else None


def cmd_record_start(_args) -> dict:
    """Remember the converted polygon (the start of the flow) to check it is recoverable."""
    obj = _flow_object()
    _saved["start_points"] = _points(obj.data)
    _saved["start_name"] = obj.name
    return {"object": obj.name, "points": len(_saved["start_points"])}


def _fcurves(idblock):
    adt = idblock.animation_data
    if adt is None or adt.action is None:
        return []
    action = adt.action
    if hasattr(action, "layers") and adt.action_slot is not None:  # 4.4+ slotted actions
        from bpy_extras import anim_utils

        bag = anim_utils.action_get_channelbag_for_slot(action, adt.action_slot)
        return list(bag.fcurves) if bag is not None else []
    return list(action.fcurves)


def _keys(fc) -> list[tuple[float, float]]:
    return [tuple(k.co) for k in fc.keyframe_points]


def _flow_keys(obj) -> dict:
    """Frames and values of the energy keys, and the point channels of the curve data."""
    energy = [fc for fc in _fcurves(obj) if fc.data_path == '["moebius_energy"]']
    points = [fc for fc in _fcurves(obj.data) if fc.data_path.startswith("splines[")]
    keys = _keys(energy[0]) if energy else []
    return {"energy_keys": keys, "point_channels": len(points),
            "keys_per_point_channel": sorted({len(fc.keyframe_points) for fc in points}),
            "point_fcurves": points}


def _polygon_at(point_fcurves, frame: float, template) -> list[list[float]]:
    """The curve's points at ``frame`` from its F-curves (``splines[s].points[i].co``)."""
    pts = [list(p) for p in template]
    offsets, k = [], 0
    for spline in _flow_object().data.splines:
        offsets.append(k)
        k += len(spline.points)
    for fc in point_fcurves:
        path = fc.data_path  # splines[S].points[I].co
        s = int(path.split("[")[1].split("]")[0])
        i = int(path.split("[")[2].split("]")[0])
        pts[offsets[s] + i][fc.array_index] = fc.evaluate(frame)
    return pts


def _common_checks(obj, s) -> dict:
    keys = _flow_keys(obj)
    frames = [f for f, _ in keys["energy_keys"]]
    energies = [e for _, e in keys["energy_keys"]]
    start = _saved.get("start_points")
    at_start = _polygon_at(keys["point_fcurves"], s.frame_start, start) if start else None
    src = bpy.data.objects.get(SOURCE)
    return {
        "object": obj.name,
        "running": bool(s.running),
        "iterations": s.last_iterations,
        "max_iterations": s.max_iterations,
        "message": s.last_message,
        "energy_start": s.last_energy_start,
        "energy_end": s.last_energy_end,
        "keyed_frames": len(frames),
        "first_frame": frames[0] if frames else None,
        "last_frame": frames[-1] if frames else None,
        "scene_frame_range": [bpy.context.scene.frame_start, bpy.context.scene.frame_end],
        "energies_non_increasing": all(b <= a * (1 + 1e-9) for a, b in pairwise(energies)),
        "energies": energies,
        "point_channels": keys["point_channels"],
        "keys_per_point_channel": keys["keys_per_point_channel"],
        "start_frame_vs_converted_maxdiff": _maxdiff(at_start, start) if at_start else None,
        "rest_shape_vs_converted_maxdiff": _maxdiff(
            [list(obj.data["moebius_rest"][3 * i:3 * i + 3])
             for i in range(len(obj.data["moebius_rest"]) // 3)], start)
        if "moebius_rest" in obj.data and start else None,
        "source_exists": src is not None,
        "source_hidden": bool(src.hide_get()) if src is not None else None,
        "source_unchanged_maxdiff": _maxdiff(_points(src.data), _saved["source_points"])
        if src is not None and _saved.get("source_points") else None,
    }


def cmd_check_run(args) -> dict:
    """The scene after a run (stopped by Esc when ``cancelled``, else finished)."""
    obj = _flow_object()
    s = bpy.context.scene.moebius
    out = _common_checks(obj, s)
    n = out["iterations"]
    ok = {
        "stopped": not out["running"],
        "message": ("cancel" in out["message"].lower()) == bool(args.get("cancelled")),
        "iterations_positive": n >= 1,
        "every_iterate_keyed": out["keyed_frames"] == n + 1
        and out["keys_per_point_channel"] == [n + 1],
        "all_points_keyed": out["point_channels"] == 3 * len(_saved["start_points"]),
        "energy_decreases": out["energies_non_increasing"]
        and out["energy_end"] < out["energy_start"],
        "start_frame_is_converted_curve": out["start_frame_vs_converted_maxdiff"] is not None
        and out["start_frame_vs_converted_maxdiff"] < 1e-5,
        "rest_shape_is_converted_curve": out["rest_shape_vs_converted_maxdiff"] is not None
        and out["rest_shape_vs_converted_maxdiff"] < 1e-5,
        "original_kept_hidden": out["source_exists"] and out["source_hidden"]
        and out["source_unchanged_maxdiff"] == 0.0,
    }
    if args.get("cancelled"):
        ok["stopped_early"] = n < out["max_iterations"]
    out["ok"] = ok
    return out


def cmd_check_cleared(_args) -> dict:
    """After Clear Flow Animation: no flow keys, the curve is the converted start again."""
    obj = _flow_object()
    keys = _flow_keys(obj)
    now = _points(obj.data)
    diff = _maxdiff(now, _saved["start_points"])
    out = {"object": obj.name, "energy_keys": len(keys["energy_keys"]),
           "point_channels": keys["point_channels"], "curve_vs_converted_maxdiff": diff}
    out["ok"] = {"keys_removed": not keys["energy_keys"] and keys["point_channels"] == 0,
                 "curve_is_converted_curve": diff < 1e-5}
    return out


def cmd_graph_editor(_args) -> dict:
    """Split the 3D view and show the energy F-curve in a Graph Editor below it."""
    win = _window()
    screen = win.screen
    view3d = max((a for a in screen.areas if a.type == "VIEW_3D"),
                  key=lambda a: a.width * a.height)
    before = set(a.as_pointer() for a in screen.areas)
    with bpy.context.temp_override(window=win, screen=screen, area=view3d):
        bpy.ops.screen.area_split(direction="HORIZONTAL", factor=0.45)
    new = [a for a in screen.areas if a.as_pointer() not in before]
    # The lower of the two halves becomes the Graph Editor.
    halves = new + [view3d]
    graph = min(halves, key=lambda a: a.y)
    graph.type = "GRAPH_EDITOR"
    space = graph.spaces.active
    space.dopesheet.filter_text = "energy"
    space.show_region_ui = False
    obj = _flow_object()
    for fc in _fcurves(obj):
        fc.select = True
    region = next(r for r in graph.regions if r.type == "WINDOW")
    with bpy.context.temp_override(window=win, screen=screen, area=graph, region=region):
        bpy.ops.graph.view_all()
    return {"graph": _rect(graph), "view3d": _rect(next(a for a in halves if a != graph))}


# -- Live (docs/ui-testing.md, "Live") -----------------------------------------------------------

def _snapshot(obj) -> dict:
    keys = _flow_keys(obj)
    return {"points": _points(obj.data),
            "energy_keys": keys["energy_keys"],
            "point_keys": {f"{fc.data_path}[{fc.array_index}]": _keys(fc)
                           for fc in keys["point_fcurves"]}}


def cmd_live_prepare(args) -> dict:
    """Select the points ``pins`` of the active curve (Pin Selected Points on, Record on) and
    remember the scene as it is (what Esc and one Ctrl+Z must bring back)."""
    obj = _flow_object()
    for i, p in enumerate(obj.data.splines[0].points):
        p.select = i in args["pins"]
    s = bpy.context.scene.moebius
    s.pin_selected = True
    s.live_record = True
    _saved["before_live"] = _snapshot(obj)
    return {"object": obj.name, "pins": args["pins"], "frame": bpy.context.scene.frame_current}


def cmd_pin_screen(args) -> dict:
    """Where point ``index`` of the active curve is drawn: window pixels (origin bottom left)
    of the largest 3D view, and its world position."""
    from bpy_extras.view3d_utils import location_3d_to_region_2d

    obj = _flow_object()
    co = obj.matrix_world @ obj.data.splines[0].points[args["index"]].co.xyz
    area = max((a for a in _window().screen.areas if a.type == "VIEW_3D"),
               key=lambda a: a.width * a.height)
    region = next(r for r in area.regions if r.type == "WINDOW")
    xy = location_3d_to_region_2d(region, area.spaces.active.region_3d, co)
    return {"x": region.x + xy.x, "y": region.y + xy.y, "world": list(co)}


def cmd_check_live(args) -> dict:
    """After Live: ``compare`` — the scene equals what ``live_prepare`` saw (points and flow
    keys to the bit); ``record`` — the recorded keys never cross (the tests' own certificate,
    tests/live_checks.py: every straight move between keyed frames)."""
    obj = _flow_object()
    out = {"mode": obj.mode}
    if args.get("compare"):
        now, before = _snapshot(obj), _saved["before_live"]
        out["points_equal"] = now["points"] == before["points"]
        out["points_maxdiff"] = _maxdiff(now["points"], before["points"])
        out["keys_equal"] = (now["energy_keys"] == before["energy_keys"]
                             and now["point_keys"] == before["point_keys"])
    if args.get("record"):
        sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
        import numpy as np

        from moebius_addon.blender import keyframes
        from tests.live_checks import certify_record

        frames, points, _ = keyframes.read_flow_keyframes(obj)
        M = np.array(obj.matrix_world)
        states = [[P @ M[:3, :3].T + M[:3, 3]] for P in points]
        out["recorded_frames"] = len(frames)
        try:
            out["least_distance"] = certify_record(states, [True])
            out["never_cross"] = len(states) > 1
        except AssertionError as err:
            out["never_cross"], out["certify_error"] = False, str(err)
        out["moved"] = float(np.abs(points[-1] - points[0]).max()) if len(states) > 1 else 0.0
    return out


def cmd_status(_args) -> dict:
    return dict(_state)


def cmd_quit(_args) -> dict:
    # Blender 3.4 with Debian's numba: multiprocessing (imported by numba's OpenMP pool) keeps
    # a reference to the temporary __main__ of the --python script in sys.modules, and the
    # module scan at exit then crashes; drop it so the quit is clean.
    sys.modules.pop("__mp_main__", None)
    bpy.app.timers.register(lambda: bpy.ops.wm.quit_blender() and None, first_interval=0.5)
    return {"quitting": True}


COMMANDS = {name[4:]: fn for name, fn in globals().items() if name.startswith("cmd_")}


# ---------------------------------------------------------------------------------------------
# The timer: state heartbeat and command dispatch.

def _live_state() -> None:
    s = getattr(bpy.context.scene, "moebius", None)
    obj = bpy.context.view_layer.objects.active
    _state.update({
        "t": time.time(),
        "active": obj.name if obj is not None else None,
        "objects": sorted(o.name for o in bpy.data.objects),
        "frame": bpy.context.scene.frame_current,
        "energy_keys": sum(len(fc.keyframe_points) for fc in _fcurves(obj)
                           if fc.data_path == '["moebius_energy"]') if obj is not None else 0,
    })
    if s is not None:
        _state.update({
            "running": bool(s.running), "progress": s.progress,
            "live": bool(getattr(s, "live", False)),
            "mode": obj.mode if obj is not None else None,
            "live_iteration": s.live_iteration, "live_energy": s.live_energy,
            "last_object": s.last_object, "last_iterations": s.last_iterations,
            "last_message": s.last_message, "last_keyframes": s.last_keyframes,
        })


def _tick():
    try:
        _live_state()
        for path in sorted((OUT / "cmd").glob("*.json")):
            request = json.loads(path.read_text())
            path.unlink()
            try:
                result = {"ok": True, "result": COMMANDS[request["cmd"]](request.get("args", {}))}
            except Exception:  # noqa: BLE001 - reported to the driver, which fails the test
                result = {"ok": False, "error": traceback.format_exc()}
            _write_json(OUT / "resp" / path.name, result)
        _write_json(OUT / "state.json", _state)
    except Exception:  # noqa: BLE001 - keep the timer alive; the driver sees the error
        _state["errors"].append(traceback.format_exc())
    return 0.2


def main() -> None:
    (OUT / "cmd").mkdir(parents=True, exist_ok=True)
    (OUT / "resp").mkdir(parents=True, exist_ok=True)
    try:
        _install()
        _state["ready"] = True
    except Exception:  # noqa: BLE001
        _state["errors"].append(traceback.format_exc())
    _write_json(OUT / "state.json", _state)
    bpy.app.timers.register(_tick, first_interval=0.5, persistent=True)


main()
