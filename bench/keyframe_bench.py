"""How fast the flow's keys are written and played in Blender. Prints; not a test.

    .venv/bin/python bench/keyframe_bench.py                       # 5 000 and 20 000 points
    .venv/bin/python bench/keyframe_bench.py --sizes 1000 --iterates 100 --repeats 3
    .venv/bin/python bench/keyframe_bench.py --flow 20000 20    # a whole run in Blender

For each size the two ways ``keyframes.write_flow_keyframes`` can key a flow are measured in
the same process, alternately (per point, shape keys, per point, ...): the seconds to write
``--iterates`` iterates of a curve (7_2 resampled to N points, each iterate displaced a little;
the values do not matter to the cost), and the milliseconds per frame change while it plays
(``scene.frame_set`` to each keyed frame in turn), with the curve bevelled as *Add Knot* makes
it (Blender rebuilds the tube on every frame, as in the viewport, whatever the keys) and without
a bevel (the keys alone). Medians over ``--repeats``; the load average is printed beside them.

``--flow N ITERATIONS`` instead times one run through the scripting API as a user would make
it: *Add Knot* 7_2 with N edges, *Relax* with H² on the tree engine (the explicit method) for
that many iterations, then the keys written by ``finish`` and the frame changes through the
keyed frames (median).
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
if "BLENDER_USER_RESOURCES" not in os.environ:  # never the user's own Blender directory
    _USER = tempfile.mkdtemp(prefix="moebius-bench-user-")
    os.environ["BLENDER_USER_RESOURCES"] = _USER
    atexit.register(shutil.rmtree, _USER, ignore_errors=True)
sys.path.insert(0, str(ROOT))

import bpy  # noqa: E402
import numpy as np  # noqa: E402

import moebius_addon  # noqa: E402
from moebius_addon.core import resample  # noqa: E402
from moebius_addon.core.topology import knots  # noqa: E402

WAYS = {"per point": False, "shape keys": True}


def one(n: int, iterates: int, shape_keys: bool, frames_played: int,
        bevel: float) -> tuple[float, float]:
    """Seconds to write, median milliseconds per frame change."""
    from moebius_addon.blender import geometry, keyframes

    bpy.ops.wm.read_homefile(use_empty=True)
    P = resample(knots.named("7_2"), n)
    P = 2.0 * (P - P.mean(0)) / np.ptp(P, axis=0).max()
    wave = np.sin(np.arange(n) / 50.0)[:, None]
    links = [[P + 1e-3 * k * wave] for k in range(iterates)]
    curve = geometry.new_curve("Knot", [P])
    curve.bevel_depth = bevel
    obj = bpy.data.objects.new("Knot", curve)
    bpy.context.scene.collection.objects.link(obj)
    scene = bpy.context.scene
    scene.frame_set(1)
    t = time.perf_counter()
    keyframes.write_flow_keyframes(obj, links, list(range(iterates)), 1, shape_keys=shape_keys)
    write = time.perf_counter() - t
    scene.frame_set(1)
    play = []
    for frame in range(2, 2 + min(frames_played, iterates - 1)):
        t = time.perf_counter()
        scene.frame_set(frame)
        play.append(time.perf_counter() - t)
    return write, 1e3 * float(np.median(play))


def flow(n: int, iterations: int) -> None:
    from moebius_addon import blender as moebius

    bpy.ops.wm.read_homefile(use_empty=True)
    t = time.perf_counter()
    knot = moebius.add_knot("7_2", n, metric="h2", engine="tree")
    added = time.perf_counter() - t
    t = time.perf_counter()
    run = moebius.ObjectRelaxation(knot, metric="h2", engine="tree", tolerance=0.0,
                                   method="projected_gradient", max_iterations=iterations)
    setup = time.perf_counter() - t
    steps = []
    more = True
    while more:
        t = time.perf_counter()
        more = run.step()
        steps.append(time.perf_counter() - t)
    t = time.perf_counter()
    result = run.finish()
    keyed = time.perf_counter() - t
    scene = bpy.context.scene
    scene.frame_set(1)
    changes = []
    for f in range(2, 2 + len(run.iterates) - 1):
        t = time.perf_counter()
        scene.frame_set(f)
        changes.append(time.perf_counter() - t)
    frame = float(np.median(changes))
    print(f"{n} edges: add knot {added:.2f} s, set-up {setup:.2f} s, {result.nit} iterations "
          f"({run.engine} engine) median {np.median(steps):.2f} s, total {sum(steps):.1f} s; "
          f"keys of {len(run.iterates)} iterates written in {keyed:.2f} s "
          f"({'shape keys' if knot.data.shape_keys else 'per point'}); frame change "
          f"{1e3 * frame:.0f} ms (median); energy {result.history['energy'][0]:.2f} -> "
          f"{float(result.fun):.2f}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[5000, 20000])
    p.add_argument("--iterates", type=int, default=100)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--frames", type=int, default=30, help="frame changes timed per run")
    p.add_argument("--flow", type=int, nargs=2, metavar=("N", "ITERATIONS"),
                   help="time one run in Blender instead")
    args = p.parse_args()
    moebius_addon.register()
    print(f"bpy {bpy.app.version_string}, {os.cpu_count()} cores, load average "
          f"{os.getloadavg()[0]:.2f} at the start")
    if args.flow:
        flow(*args.flow)
        print(f"load average {os.getloadavg()[0]:.2f} at the end")
        return
    print(f"{'points':>7} {'way':>11} {'write s':>8} {'play ms/frame':>14} {'(no bevel)':>11}"
          f"   (medians of {args.repeats}; {args.iterates} iterates)")
    for n in args.sizes:
        got = {way: [] for way in WAYS}
        for _ in range(args.repeats):
            for way, shape_keys in WAYS.items():  # alternately, in one process
                write, play = one(n, args.iterates, shape_keys, args.frames, 0.02)
                _, bare = one(n, args.iterates, shape_keys, args.frames, 0.0)
                got[way].append((write, play, bare))
        for way, runs in got.items():
            write, play, bare = np.median(np.array(runs), axis=0)
            print(f"{n:>7} {way:>11} {write:>8.2f} {play:>14.1f} {bare:>11.1f}", flush=True)
    print(f"load average {os.getloadavg()[0]:.2f} at the end")


if __name__ == "__main__":
    main()
