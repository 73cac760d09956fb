"""A long session in one process, as in Blender: every knot of the table relaxed one after the
other (default edge counts, a fixed number of iterations each). Prints the time per iteration
of every run, the process's peak memory and numba's threading layer. Prints measurements;
not a test.

    python bench/session.py                  # 40 iterations per knot
    NUMBA_THREADING_LAYER=tbb python bench/session.py --iterations 40

The time per iteration should depend on the knot's edge count only, not on how many runs came
before it (with numba's TBB layer it did not: see moebius_addon/core/_threads.py).
"""

from __future__ import annotations

import argparse
import os
import resource
import time

import numba

if os.environ.get("SESSION_WITH_BPY"):  # inside the Blender module, with its own TBB
    import bpy  # noqa: F401
from paper import machine  # bench/ is on sys.path when run as a script

from moebius_addon import core
from moebius_addon.core.topology import knots


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--iterations", type=int, default=40)
    args = ap.parse_args()
    print("machine:", machine())
    start = time.perf_counter()
    for k, name in enumerate(n for n in knots.names() if n != "0_1"):
        P = knots.named(name)
        run = core.Relaxation(P, max_iter=args.iterations)
        t = time.perf_counter()
        while not run.done:
            run.step()
        dt = time.perf_counter() - t
        rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        if k == 0:
            print("threading layer:", numba.threading_layer())
        print(f"  run {k + 1:2d} {name:>5s} N={len(P):4d}: {run.nit:3d} iterations, "
              f"{1e3 * dt / max(run.nit, 1):7.1f} ms/it, peak memory {rss:5.0f} MB", flush=True)
    print(f"total {time.perf_counter() - start:.1f} s")


if __name__ == "__main__":
    main()
