"""The speed cost of the kernels compiled for a generic CPU (what the linux-x64 zip ships,
``core/_shipped_cache.py``: x86-64-v3) against those compiled for this CPU, and how far their
results differ. Prints measurements; not a test.

Each target runs in processes of its own (numba compiles for one CPU per process:
``NUMBA_CPU_NAME``/``NUMBA_CPU_FEATURES``), each with its own warm cache; the parent alternates
them, ``--rounds`` times, and every child times each case ``--repeat`` times (CPU seconds of
the process, so the other work on a shared machine matters less; the median). Cases: energy +
gradient (exact engine at 500 and 2 000 edges, tree at 20 000) and one iteration of the run
*Relax* makes (*Automatic* on a knot: the implicit method; exact at 500, tree at 5 000).

    .venv/bin/python bench/generic_cpu.py --rounds 3
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

TARGETS = {"native": None, "x86-64-v3": "x86-64-v3"}


def child(repeat: int) -> dict:
    import numpy as np

    from moebius_addon import core

    out = {}
    for name, n, eng in (("E+g exact", 500, "exact"), ("E+g exact", 2000, "exact"),
                         ("E+g tree", 20000, "tree")):
        P = core.knots.named("7_2", n)
        run = core.make_run("projected_gradient", P, engine=eng)
        e, X = run.engine, run.X  # the run's engine at its scaled start
        e.energy_gradient(X)  # warm
        seconds = []
        for _ in range(repeat):
            t = time.process_time()
            E, g = e.energy_gradient(X)
            seconds.append(time.process_time() - t)
        out[f"{name} {n}"] = (statistics.median(seconds), float(E),
                              float(np.linalg.norm(g)))
    for n, eng in ((500, "exact"), (5000, "tree")):
        seconds = []
        for _ in range(repeat):
            P = core.knots.named("7_2", n)
            run = core.make_run("projected_gradient_implicit", P, engine=eng, max_iter=2,
                                tol=0.0, target_lengths="keep")
            run.step()  # the first iterate (factorizations, frames) untimed
            t = time.process_time()
            run.step()
            seconds.append(time.process_time() - t)
        out[f"iteration {eng} {n}"] = (statistics.median(seconds), float(run.energy), 0.0)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--cache", help="keep each target's numba cache under this directory "
                                    "(default: a temporary one, compiled in a first round)")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        print(json.dumps(child(args.repeat)))
        return 0
    import llvmlite.binding as ll

    print(f"this CPU: {ll.get_host_cpu_name()}; {args.rounds} rounds alternated, median of "
          f"{args.repeat} per case, CPU seconds", flush=True)
    seen: dict[str, dict[str, list]] = {t: {} for t in TARGETS}
    with tempfile.TemporaryDirectory(prefix="moebius-generic-") as work:
        work = args.cache or work
        for r in range(args.rounds + 1):  # round 0 compiles into (or warms) each target's cache
            for target, cpu in TARGETS.items():
                env = dict(os.environ, NUMBA_CACHE_DIR=os.path.join(work, target))
                env.pop("NUMBA_CPU_NAME", None)
                env.pop("NUMBA_CPU_FEATURES", None)
                if cpu:
                    env.update(NUMBA_CPU_NAME=cpu, NUMBA_CPU_FEATURES="")
                proc = subprocess.run([sys.executable, __file__, "--child", "--repeat",
                                       str(args.repeat)], env=env, capture_output=True,
                                      text=True, check=True)
                if r == 0:
                    continue
                for case, value in json.loads(proc.stdout.strip().splitlines()[-1]).items():
                    seen[target].setdefault(case, []).append(value)
    print("| case | native | x86-64-v3 | ratio | results (native vs v3) |")
    print("|---|---|---|---|---|")
    for case in seen["native"]:
        a = [v[0] for v in seen["native"][case]]
        b = [v[0] for v in seen["x86-64-v3"][case]]
        ea, eb = seen["native"][case][0][1:], seen["x86-64-v3"][case][0][1:]
        diff = max(abs(x - y) / max(abs(x), 1e-300) for x, y in zip(ea, eb, strict=True))
        same = "same bits" if ea == eb else f"relative difference {diff:.1e}"
        print(f"| {case} | {statistics.median(a) * 1e3:.1f} ms | {statistics.median(b) * 1e3:.1f} "
              f"ms | {statistics.median(b) / statistics.median(a):.2f} | {same} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
