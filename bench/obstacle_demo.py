"""Headless Blender demo of pins and obstacles: ``--scene trefoil``, a trefoil wound
around the tube of a torus, two of its points pinned; ``--scene cable``, an open cable
threaded through the torus' hole with both ends pinned and coils that untangle; each relaxed
with the torus as an obstacle.

The torus is a mesh in a collection set as the panel's *Obstacles*; the two pinned points are
selected in Edit Mode with *Pin Selected Points* on; Relax is the panel's button (blocking in
background mode). Prints the iterations, seconds and energies, checks every keyed frame
against the torus with an independent segment–triangle test and keeps the pinned points'
coordinates, and renders a Workbench contact sheet (``OUT/<scene>_demo.png``, OUT by default
``out/<scene>_demo``)::

    .venv/bin/python bench/obstacle_demo.py
    .venv/bin/python bench/obstacle_demo.py --scene cable --iterations 300
"""

from __future__ import annotations

import argparse
import atexit
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if "BLENDER_USER_RESOURCES" not in os.environ:  # never the user's own preferences
    _USER = tempfile.mkdtemp(prefix="moebius-obstacle-user-")
    os.environ["BLENDER_USER_RESOURCES"] = _USER
    atexit.register(shutil.rmtree, _USER, ignore_errors=True)
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

import bpy  # noqa: E402
import numpy as np  # noqa: E402
from demo_blender import contact_sheet, frame_camera, render, setup_render  # noqa: E402

import moebius_addon  # noqa: E402
from moebius_addon import core  # noqa: E402
from tests.mesh_checks import crossings  # noqa: E402 - the tests' independent edge-triangle check


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", choices=["trefoil", "cable"], default="trefoil")
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--edges", type=int, default=240)
    ap.add_argument("--iterations", type=int, default=150)
    ap.add_argument("--tiles", type=int, default=6)
    ap.add_argument("--resolution", type=int, default=320)
    args = ap.parse_args(argv)
    out = (args.out or ROOT / "out" / f"{args.scene}_demo").resolve()
    cable = args.scene == "cable"
    out.mkdir(parents=True, exist_ok=True)

    bpy.ops.wm.read_factory_settings(use_empty=True)
    moebius_addon.register()
    scene = bpy.context.scene

    # the obstacle: a torus in its own collection
    coll = bpy.data.collections.new("Obstacles")
    scene.collection.children.link(coll)
    bpy.ops.mesh.primitive_torus_add(major_radius=1.0, minor_radius=0.22, major_segments=48,
                                     minor_segments=16,
                                     rotation=(0.0, np.pi / 2, 0.0) if cable else (0, 0, 0))
    torus = bpy.context.active_object
    for c in list(torus.users_collection):
        c.objects.unlink(torus)
    coll.objects.link(torus)
    torus.color = (0.6, 0.62, 0.66, 1.0)
    me = torus.data
    me.calc_loop_triangles()
    Mt = np.array(torus.matrix_world)
    V = np.array([v.co[:] for v in me.vertices]) @ Mt[:3, :3].T + Mt[:3, 3]
    F = np.array([t.vertices[:] for t in me.loop_triangles])

    # the curve: the (2, 3) torus knot on a fatter torus about the same core circle, pulled
    # off-centre so that the flow has work to do
    if cable:
        # from (-2.5, 0, 0) to (2.5, 0, 0) through the hole (the torus' axis is x), with two
        # coils before the torus and one after it
        x = np.linspace(-2.5, 2.5, 4000)
        coil = (np.clip((x + 2.1) / 1.3, 0, 1) * (x < -0.8)) + (np.clip((x - 0.9) / 0.9, 0, 1)
                                                                * (x > 0.9))
        turns = np.where(x < 0, 2.0, 1.0) * coil
        w = 0.3 * np.sin(np.pi * coil)
        phase = 2 * np.pi * turns
        P = np.stack([x, w * np.cos(phase) - w, w * np.sin(phase)], -1)
        P = core.resample(P, args.edges, closed=False)
    else:
        t = np.linspace(0, 2 * np.pi, 4 * args.edges, endpoint=False)
        r = 0.55 + 0.2 * np.cos(t)
        P = np.stack([(1 + r * np.cos(3 * t)) * np.cos(2 * t),
                      (1 + r * np.cos(3 * t)) * np.sin(2 * t),
                      r * np.sin(3 * t) + 0.15 * np.sin(t)], -1)
        P = core.resample(P, args.edges)
    assert crossings(P, V, F, not cable) == 0
    curve = bpy.data.curves.new("Cable" if cable else "Trefoil", "CURVE")
    curve.dimensions = "3D"
    curve.bevel_depth = 0.02
    sp = curve.splines.new("POLY")
    sp.points.add(len(P) - 1)
    sp.points.foreach_set("co", np.c_[P, np.ones(len(P))].ravel())
    sp.use_cyclic_u = not cable
    pins = [0, args.edges - 1] if cable else [0, args.edges // 2]
    for i, p in enumerate(sp.points):
        p.select = i in pins
    knot = bpy.data.objects.new(curve.name, curve)
    knot.color = (0.85, 0.25, 0.1, 1.0)
    scene.collection.objects.link(knot)
    bpy.context.view_layer.objects.active = knot

    s = scene.moebius
    s.obstacles = coll
    s.pin_selected = True
    s.max_iterations = args.iterations
    s.tolerance = 1e-4
    t0 = time.perf_counter()
    assert bpy.ops.moebius.relax() == {"FINISHED"}
    seconds = time.perf_counter() - t0
    keyframes = moebius_addon.blender.keyframes
    frames, points, _ = keyframes.read_flow_keyframes(knot)
    crossed = sum(crossings(Q, V, F, not cable) for Q in points)
    P32 = P.astype(np.float32).astype(np.float64)  # what the curve's points hold
    pinned_moved = max(float(np.abs(Q[pins] - P32[pins]).max()) for Q in points)
    print(f"{args.scene}: {args.edges} points, torus of {len(F)} triangles: "
          f"{s.last_iterations} iterations "
          f"in {seconds:.1f} s ({s.last_message}); energy {s.last_energy_start:.2f} -> "
          f"{s.last_energy_end:.2f} (Möbius + obstacle); {len(frames)} keyed frames, "
          f"{crossed} edge-triangle crossings in them; pinned points moved by at most "
          f"{pinned_moved:g}", flush=True)

    tiles = np.unique(np.linspace(frames[0], frames[-1], args.tiles).round()).astype(int)
    setup_render(scene, args.resolution)
    frame_camera(scene, np.concatenate([V, *points]), direction=(0.3, -0.7, 0.9))
    images = []
    for f in tiles:
        scene.frame_set(int(f))
        path = out / f"frame_{f:04d}.png"
        render(scene, path)
        images.append(path)
    contact_sheet(images, [f"frame {f}" for f in tiles], out / f"{args.scene}_demo.png",
                  columns=min(3, len(images)))
    print(f"rendered {len(images)} frames -> {out / f'{args.scene}_demo.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
