"""Live relax of a cable bundle, headless: the top end of one cable dragged across the scene the
way a user drags a pinned point (its coordinates written into the curve, then the operator's
``LiveSession.sync``), the bundle following with its tubes apart, recorded as keys. Renders
the start, the middle and the end of the drag with Workbench (``--out``, default
``out/live-cables``; ``--docs`` writes ``docs/img/live-cables-{1,2,3}.png``) and prints the
viewport updates per second, the least distance between two cables over the recorded keys
(tests/live_checks.py's certificate: no two consecutive keys let a strand pass through
another) and where the dragged end ended. Prints measurements; not a test::

    NUMBA_NUM_THREADS=2 .venv/bin/python bench/live_cables_film.py --docs
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

# first: demo_blender gives Blender a throw-away user directory before bpy is imported
from demo_blender import frame_camera, render, setup_render  # noqa: E402, I001

import bpy  # noqa: E402
import numpy as np  # noqa: E402
from cables_tree import plates_scene  # noqa: E402

import moebius_addon  # noqa: E402
from moebius_addon.blender import live  # noqa: E402
from tests.live_checks import certify_record  # noqa: E402


def bundle(cables: int, edges: int, spacing: float):
    """Open cables from z = 0 to z = 1 on a square grid, one curve object, every end selected
    (the pins of *Pin Selected Points*)."""
    parts = plates_scene(cables, edges, spacing=spacing, jitter=0.02)
    curve = bpy.data.curves.new("Cables", "CURVE")
    curve.dimensions = "3D"
    for P in parts:
        sp = curve.splines.new("POLY")
        sp.points.add(len(P) - 1)
        sp.points.foreach_set("co", np.column_stack([P, np.ones(len(P))]).ravel())
        for k, p in enumerate(sp.points):
            p.select = k in (0, len(P) - 1)
    obj = bpy.data.objects.new("Cables", curve)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    obj.select_set(True)
    curve.bevel_depth = 0.3 * spacing / 2
    curve.bevel_resolution = 4
    curve.use_fill_caps = True
    for name, rgb in (("Bundle", (0.15, 0.35, 0.75)), ("Dragged", (0.9, 0.35, 0.1))):
        mat = bpy.data.materials.new(name)
        mat.diffuse_color = (*rgb, 1.0)
        curve.materials.append(mat)
    curve.splines[0].material_index = 1  # the cable whose end is dragged
    return obj, parts


def between_cables(states) -> float:
    """Least distance between edges of two different cables over ``states``."""
    from tests.mesh_checks import segments_closest

    least = np.inf
    for parts in states:
        p = np.concatenate([P[:-1] for P in parts])
        q = np.concatenate([P[1:] for P in parts])
        comp = np.concatenate([np.full(len(P) - 1, c) for c, P in enumerate(parts)])
        for c in range(len(parts)):
            mine, other = comp == c, comp > c
            i, j = np.nonzero(mine[:, None] & other[None, :])
            if len(i):
                least = min(least, float(segments_closest(p[i], q[i], p[j], q[j]).min()))
    return least


def points(obj) -> list[np.ndarray]:
    out = []
    for sp in obj.data.splines:
        co = np.empty(4 * len(sp.points))
        sp.points.foreach_get("co", co)
        out.append(co.reshape(-1, 4)[:, :3])
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cables", type=int, default=10)
    ap.add_argument("--edges", type=int, default=100)
    ap.add_argument("--spacing", type=float, default=0.12)
    ap.add_argument("--steps", type=int, default=24, help="pin moves of the drag")
    ap.add_argument("--hold", type=float, default=0.15, help="seconds of syncing per move")
    ap.add_argument("--resolution", type=int, default=420)
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "live-cables")
    ap.add_argument("--docs", action="store_true", help="write docs/img/live-cables-*.png")
    args = ap.parse_args(argv)
    out = (ROOT / "docs" / "img") if args.docs else args.out.resolve()
    out.mkdir(parents=True, exist_ok=True)

    bpy.ops.wm.read_factory_settings(use_empty=True)
    moebius_addon.register()
    scene = bpy.context.scene
    obj, parts = bundle(args.cables, args.edges, args.spacing)
    # the dragged end: the top of the first cable, pulled down a quarter and across the
    # bundle between its first two rows, its cable pushing the others aside
    c = 0
    top = len(parts[c]) - 1
    start = points(obj)[c][top].copy()
    path = [start + [4.5 * args.spacing * t, 0.5 * args.spacing * min(1.0, 4 * t), -0.25 * t]
            for t in np.linspace(0.0, 1.0, args.steps + 1)[1:]]
    session = live.LiveSession([obj], record=True, pin_selected=True, thickness="bevel")
    end = time.perf_counter() + 600
    while session.frame.seq < 1 and time.perf_counter() < end:  # the first step compiles
        session.sync()
        time.sleep(0.01)
    setup_render(scene, args.resolution)
    scene.display.shading.color_type = "MATERIAL"
    everything = np.concatenate(points(obj) + [np.array(path)])
    frame_camera(scene, np.vstack([everything, everything.min(0) - 0.05,
                                   everything.max(0) + 0.05]), direction=(0.35, -1.0, 0.8))
    shots = {0: 1, args.steps // 2: 2, args.steps: 3}
    t0, u0 = time.perf_counter(), session.updates
    try:
        for k in range(args.steps + 1):
            if k > 0:
                obj.data.splines[c].points[top].co = (*path[k - 1], 1.0)
                t_end = time.perf_counter() + args.hold
                while time.perf_counter() < t_end:
                    session.sync()
                    time.sleep(1.0 / 60.0)
            if k in shots:
                session.sync()
                render(scene, out / f"live-cables-{shots[k]}.png")
                print(f"move {k}: {session.status()}", flush=True)
        rate = (session.updates - u0) / (time.perf_counter() - t0)
    except BaseException:
        session.cancel()
        raise
    done = session.finish()
    record = session.driver.record
    certify_record([f.parts for f in record], [False] * len(parts))  # raises on a crossing
    apart = between_cables([f.parts for f in record])
    reached = np.linalg.norm(record[-1].parts[c][top] - path[-1])
    print(f"{args.cables} cables x {args.edges} edges, tubes of radius {obj.data.bevel_depth:g}: "
          f"{rate:.1f} viewport updates/s while dragging (renders included), {done['states']} "
          f"states keyed (frames {done['frames'].start}-{done['frames'].stop - 1}), every move "
          f"between two keys certified crossing-free, least distance between two cables over "
          f"the keys {apart:.4g} (tube diameter {2 * obj.data.bevel_depth:.3g}), dragged end "
          f"{reached:.3g} from the mouse's last place; "
          f"{session.driver.clipped or 'no move clipped at the end'}; images in {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
