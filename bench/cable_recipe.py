"""The cable recipe of docs/blender.md, headless, with the add-on of this checkout: ten cables
as ten curve objects hanging between two plates through a torus; select them, *Presets ▸
Untangle Cables*, *Relax*. Prints the run (iterations, seconds, the report) and the least
distances over every keyed frame and the straight moves between frames, measured here
(tubes apart against the sum of their radii, tubes from the torus and the plates against a
radius), and renders the first and the last frame side by side with Workbench::

    .venv/bin/python bench/cable_recipe.py --iterations 40 --png docs/img/cable_recipe.png
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
if "BLENDER_USER_RESOURCES" not in os.environ:  # never the user's preferences
    _USER = tempfile.mkdtemp(prefix="moebius-bench-user-")
    os.environ["BLENDER_USER_RESOURCES"] = _USER
    atexit.register(shutil.rmtree, _USER, ignore_errors=True)
sys.path[:0] = [str(ROOT), str(ROOT / "tests" / "blender"), str(ROOT / "bench")]

import bpy  # noqa: E402
import numpy as np  # noqa: E402
from bpy_helpers import R_TORUS, Z_TORUS, cable_scene, r_TORUS  # noqa: E402
from demo_blender import frame_camera, render, setup_render  # noqa: E402

import moebius_addon  # noqa: E402
from moebius_addon import core  # noqa: E402
from moebius_addon.blender import keyframes  # noqa: E402
from tests.mesh_checks import segments_closest  # noqa: E402


def world(obj, X):
    M = np.array(obj.matrix_world)
    return X @ M[:3, :3].T + M[:3, 3]


def least_gaps(paths, samples=(0.0, 0.25, 0.5, 0.75)):
    """Least cable–cable, cable–torus and cable–plate distances over the keyed frames and
    the straight moves between them (the torus: its smooth surface, which holds its mesh;
    the free points only for the plates, the ends lying on them)."""
    cc = ct = cp = np.inf
    n = paths[0].shape[1]
    i, j = (g.ravel() for g in np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij"))
    s = np.linspace(0.0, 1.0, 9)[:, None, None]
    for f in range(len(paths[0]) - 1):
        for u in samples:
            X = [p[f] + u * (p[f + 1] - p[f]) for p in paths]
            for a, A in enumerate(X):
                Q = (A[:-1] + s * (A[1:] - A[:-1])).reshape(-1, 3)
                rho = np.hypot(Q[:, 0], Q[:, 1]) - R_TORUS
                ct = min(ct, float((np.hypot(rho, Q[:, 2] - Z_TORUS) - r_TORUS).min()))
                cp = min(cp, float(A[1:-1, 2].min()), float(1.0 - A[1:-1, 2].max()))
                for B in X[:a]:
                    cc = min(cc, float(segments_closest(A[i], A[i + 1], B[j], B[j + 1]).min()))
    return cc, ct, cp


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cables", type=int, default=10)
    ap.add_argument("--edges", type=int, default=40)
    ap.add_argument("--iterations", type=int, default=40)
    ap.add_argument("--png", type=Path, default=None, help="render first and last frame here")
    ap.add_argument("--resolution", type=int, default=480)
    a = ap.parse_args(argv)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    moebius_addon.register()
    scene = bpy.context.scene
    # wavier than the test's scene (seed 8: a start the check takes at 40 edges)
    cables = cable_scene(core.resample, a.cables, a.edges, seed=8, twist=0.5, spread=0.1)
    assert bpy.ops.moebius.apply_preset(preset="untangle_cables") == {"FINISHED"}
    s = scene.moebius
    s.max_iterations = a.iterations
    t0 = time.perf_counter()
    assert bpy.ops.moebius.relax() == {"FINISHED"}
    seconds = time.perf_counter() - t0
    r = max(o.data.bevel_depth for o in cables)
    print(f"{s.last_object}: {s.last_iterations} iterations in {seconds:.1f} s "
          f"({s.last_method}, {s.last_engine} engine), energy {s.last_energy_start:.6g} → "
          f"{s.last_energy_end:.6g}; {s.last_message}; tube radius {r:.4g}")
    keys = [keyframes.read_flow_keyframes(o) for o in cables]
    paths = [np.stack([world(o, X) for X in k[1]]) for o, k in zip(cables, keys, strict=True)]
    cc, ct, cp = least_gaps(paths)
    print(f"least distances over {len(keys[0][0])} frames and the moves between them: "
          f"cable–cable {cc:.4g} (twice the radius {2 * r:.4g}), cable–torus {ct:.4g}, "
          f"cable–plate {cp:.4g} (the radius {r:.4g})")
    if a.png is not None:
        setup_render(scene, a.resolution)
        for o in bpy.data.objects:
            o.color = (0.8, 0.8, 0.82, 1.0) if o.type == "MESH" else (0.85, 0.3, 0.15, 1.0)
        bpy.data.objects["Ceiling"].hide_render = True  # to see in
        frame_camera(scene, np.concatenate([p[0] for p in paths]), direction=(0.5, -1.0, 0.25))
        frames = keys[0][0]
        shots = []
        for f in (frames[0], frames[-1]):
            scene.frame_set(int(f))
            path = a.png.with_name(f"{a.png.stem}_{int(f)}.png")
            render(scene, path)
            shots.append(path)
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, axes = plt.subplots(1, 2, figsize=(8, 4.2))
        for ax, shot, title in zip(axes, shots, ("start", f"after {len(frames) - 1} "
                                                 "iterations"), strict=True):
            ax.imshow(plt.imread(shot))
            ax.set_title(title)
            ax.axis("off")
        fig.tight_layout()
        fig.savefig(a.png, dpi=100)
        for shot in shots:
            shot.unlink()
        print(f"rendered {a.png}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
