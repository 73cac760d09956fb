"""Headless Blender demo: untangle the Freedman–He–Wang unknot and film it.

Writes an OBJ polyline of the FHW unknot, imports it (a mesh of edge loops, as a user would),
converts it to an equilateral polygon, relaxes it by the W^{3/2,2} flow with every iterate
keyframed, then saves ``OUT/demo.blend``, exports ``OUT/flow.abc`` and renders a contact sheet
of frames with Workbench (``OUT/contact_sheet.png``) and the energy curve (``OUT/energy.png``).

Run with the ``bpy`` module of the project's venv (``make demo``)::

    .venv/bin/python bench/demo_blender.py --out out
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
# a throw-away Blender user directory: the demo must not touch the user's preferences; it goes
# when the demo ends
if "BLENDER_USER_RESOURCES" not in os.environ:
    _USER = tempfile.mkdtemp(prefix="moebius-demo-user-")
    os.environ["BLENDER_USER_RESOURCES"] = _USER
    atexit.register(shutil.rmtree, _USER, ignore_errors=True)
sys.path.insert(0, str(ROOT))

import bpy  # noqa: E402
import numpy as np  # noqa: E402

import moebius_addon  # noqa: E402
from moebius_addon.core.geometry import objio  # noqa: E402
from moebius_addon.core.topology import knots  # noqa: E402


def world_points(obj) -> np.ndarray:
    M = np.array(obj.matrix_world)
    X = np.concatenate([np.array([p.co[:3] for p in s.points]) for s in obj.data.splines])
    return X @ M[:3, :3].T + M[:3, 3]


def setup_render(scene, resolution: int) -> None:
    scene.render.engine = "BLENDER_WORKBENCH"
    scene.display.shading.light = "STUDIO"
    scene.display.shading.color_type = "OBJECT"
    scene.display.shading.show_cavity = False
    scene.render.resolution_x = scene.render.resolution_y = resolution
    scene.render.image_settings.file_format = "PNG"
    scene.view_settings.view_transform = "Standard"
    world = bpy.data.worlds.new("White")
    world.color = (1.0, 1.0, 1.0)
    scene.world = world


def frame_camera(scene, points: np.ndarray, direction=(0.35, -0.55, 1.0)) -> None:
    """An orthographic camera looking at ``points`` from ``direction``, fitting all of them."""
    centre = 0.5 * (points.min(0) + points.max(0))
    d = np.asarray(direction, float)
    d /= np.linalg.norm(d)
    radius = float(np.linalg.norm(points - centre, axis=1).max())
    cam_data = bpy.data.cameras.new("Camera")
    cam_data.type = "ORTHO"
    cam_data.ortho_scale = 2.2 * radius
    cam = bpy.data.objects.new("Camera", cam_data)
    scene.collection.objects.link(cam)
    cam.location = centre + 4 * radius * d
    from mathutils import Vector

    cam.rotation_euler = (Vector(centre) - cam.location).to_track_quat("-Z", "Y").to_euler()
    cam_data.clip_end = 10 * radius
    scene.camera = cam


def render(scene, path: Path) -> None:
    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)


def contact_sheet(images: list[Path], labels: list[str], path: Path, columns: int) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = -(-len(images) // columns)
    fig, axes = plt.subplots(rows, columns, figsize=(3 * columns, 3.2 * rows))
    for ax in np.ravel(axes):
        ax.axis("off")
    for ax, img, label in zip(np.ravel(axes), images, labels, strict=False):
        ax.imshow(plt.imread(img))
        ax.set_title(label, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def energy_plot(energies: list[float], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 3.2))
    ax.semilogy(np.arange(len(energies)), np.asarray(energies) - 4.0)
    ax.set_xlabel("iteration (= frame − start frame)")
    ax.set_ylabel("Möbius energy − 4")
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "out")
    parser.add_argument("--edges", type=int, default=600,
                        help="edges of the polygon (the FHW unknot needs about 570)")
    parser.add_argument("--iterations", type=int, default=300)
    parser.add_argument("--tiles", type=int, default=8, help="frames in the contact sheet")
    parser.add_argument("--resolution", type=int, default=360)
    args = parser.parse_args(argv)
    out = args.out.resolve()
    out.mkdir(parents=True, exist_ok=True)

    bpy.ops.wm.read_factory_settings(use_empty=True)
    moebius_addon.register()
    scene = bpy.context.scene

    # 1. an OBJ polyline, imported the way a user would bring in a curve from elsewhere
    obj_path = out / "fhw.obj"
    objio.write_obj(obj_path, knots.freedman_unknot(2 * args.edges))
    bpy.ops.wm.obj_import(filepath=str(obj_path))
    source = bpy.context.selected_objects[0]

    # 2. convert: equal edges, one cyclic poly spline; the imported mesh is kept, hidden
    scene.moebius.edges = args.edges
    bpy.ops.moebius.convert()
    knot = bpy.context.active_object
    knot.data.bevel_depth = 0.006 * float(np.ptp(world_points(knot), axis=0).max())
    knot.color = (0.85, 0.25, 0.1, 1.0)
    print(f"converted '{source.name}' to '{knot.name}': {args.edges} edges, "
          f"energy {knot['moebius_energy']:.2f}", flush=True)

    # 3. relax, every iterate keyframed: the function behind the Relax button (in background
    #    mode the button runs blocking too), called directly to keep the float64 energy history
    #    (keyframes hold float32)
    moebius = moebius_addon.blender
    s = scene.moebius
    s.max_iterations = args.iterations
    s.tolerance = 1e-4
    t0 = time.perf_counter()
    result = moebius.relax_object(knot, **moebius.relax_settings(s))
    seconds = time.perf_counter() - t0
    keyed = moebius.keyed_frames(knot)  # the scene range may be longer (it only grows)
    print(f"relaxed: {s.last_iterations} iterations in {seconds:.1f} s "
          f"({seconds / max(s.last_iterations, 1):.3f} s/iteration), energy "
          f"{s.last_energy_start:.2f} -> {s.last_energy_end:.4f}, frames "
          f"{keyed[0]}-{keyed[-1]} ({s.last_message})", flush=True)

    # 4. save and export
    moebius.export_flow(knot, out / "flow.abc")
    bpy.ops.wm.save_as_mainfile(filepath=str(out / "demo.blend"))
    print(f"saved {out / 'demo.blend'} and {out / 'flow.abc'}", flush=True)

    # 5. contact sheet and energy curve
    frames = np.unique(np.linspace(keyed[0], keyed[-1], args.tiles).round()
                       ).astype(int)
    allpts = np.concatenate([world_points(knot) for f in frames if scene.frame_set(f) is None])
    setup_render(scene, args.resolution)
    frame_camera(scene, allpts)
    energies = {}
    images = []
    for f in frames:
        scene.frame_set(f)
        energies[f] = knot["moebius_energy"]
        path = out / f"frame_{f:04d}.png"
        render(scene, path)
        images.append(path)
    contact_sheet(images, [f"frame {f}: E = {energies[f]:.2f}" for f in frames],
                  out / "contact_sheet.png", columns=min(4, len(images)))
    energy_plot(result.history["energy"], out / "energy.png")
    print(f"rendered {len(images)} frames -> {out / 'contact_sheet.png'}, {out / 'energy.png'}")
    gradient_figure(out, args.resolution)
    return 0


def gradient_figure(out: Path, resolution: int) -> None:
    """The paper's Fig. 2 in Blender: L², pure and geometric W^{3/2,2} gradients of a trefoil."""
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    bpy.ops.moebius.add_knot(kind="3_1")
    knot = bpy.context.active_object
    knot.color = (0.2, 0.2, 0.2, 1.0)
    bpy.ops.moebius.show_gradient(length=0.25)
    arrows = [bpy.data.objects[f"{knot.name}.grad.{m}"] for m in ("l2", "hs_pure", "hs")]
    for a in arrows:  # mesh edges do not render: sweep them as thin tubes
        bpy.context.view_layer.objects.active = a
        for o in bpy.context.view_layer.objects:
            o.select_set(o == a)
        bpy.ops.object.convert(target="CURVE")
        a.data.bevel_depth = 0.004
    setup_render(scene, resolution)
    pts = np.concatenate([world_points(knot)] + [
        np.array([p.co[:3] for s in a.data.splines for p in s.points]) for a in arrows])
    frame_camera(scene, pts, direction=(0.0, 0.0, 1.0))
    images = []
    for shown in arrows:
        for a in arrows:
            a.hide_render = a is not shown
        path = out / f"gradient_{shown['moebius_gradient']}.png"
        render(scene, path)
        images.append(path)
    contact_sheet(images, ["L² gradient", r"$W^{3/2,2}$ pure", r"$W^{3/2,2}$ geometric"],
                  out / "gradients.png", columns=3)
    print(f"rendered {out / 'gradients.png'}")


if __name__ == "__main__":
    sys.exit(main())
