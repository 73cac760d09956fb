"""numba's threading layer: OpenMP first, then TBB, numba's own workqueue last.

numba takes TBB whenever it finds the library (on the benchmark machine Debian's libtbb12
2021.8; inside Blender, Blender's own TBB). With numba 0.68.1 and that Debian TBB the cost of
every parallel call on the TBB layer grows with the number of parallel calls already made in
the process, and so does its memory (numba issues 10225 and 10556; a numba pull request gives
the calls a shared task arena). Measured here with a 220 × 220 product: 29 µs per call over
the first 2 000 calls, 678 µs after 16 000. The knot 7_3, relaxed 40 iterations at a time in
12 runs in one process, took 7.2 ms per iteration in the first run and 20.4 in the last
(memory 3 MB more per run); a sweep over the knot table (200 iterations per knot) reached
470–510 ms per iteration at 220–500 edges (8_2 at 220 edges: 471.5 ms, 8_1 at 500: 507.8;
bench/session.py with OpenMP: 6.9 and 18.0 ms, docs/benchmarks.md). With OpenMP the same
product costs 7 µs per call, constant; with the workqueue layer about 100 µs, constant.

The growth comes with that TBB: inside the Blender module (bpy 5.0.1, which brings its own
TBB 2021.13) TBB calls stayed at 22–24 µs (OpenMP 9) and the knot table took 7.4 s in one
session with TBB, 8.5 s with OpenMP — no harm there either way; but plain Python on a system
with the older TBB (Debian 12; also Debian's own Blender package) got slower with every run.

OpenMP threads that spin while they wait for work take the CPU from OpenBLAS's threads
between the parallel kernels: FHW 1648 to the circle took 51 s with libgomp's default spin
count against 25–32 s with ``GOMP_SPINCOUNT=1000`` (``OMP_WAIT_POLICY=PASSIVE``: 28–32 s, and
60 µs per call for small kernels). The price of this choice: a single large run in a fresh
process is about 11% slower than with TBB (FHW 1648, alternated: TBB 22.9–31.5 s, mean 25.7,
in 10 runs; OpenMP 25.3–32.2 s, mean 28.6, in 7; in the Blender module 23.6 and 28.1 s against
29.5 and 28.7 s).
"""

from __future__ import annotations

import os

# TBB stays before the workqueue: where OpenMP cannot be loaded (libgomp is part of every Linux
# GCC runtime; Windows and macOS builds may lack their OpenMP library) a recent TBB such as
# Blender's is still better than the workqueue's 100 µs per call.
PRIORITY = ("omp", "tbb", "workqueue")
SPINCOUNT = "1000"
_USER_LAYER = ("NUMBA_THREADING_LAYER", "NUMBA_THREADING_LAYER_PRIORITY")
_USER_WAIT = ("OMP_WAIT_POLICY", "GOMP_SPINCOUNT")


def prefer_stable_layer() -> None:
    """Ask numba for the layers in the order of ``PRIORITY`` and libgomp for short spinning,
    unless the user has chosen (any of the environment variables ``_USER_LAYER``,
    ``_USER_WAIT`` set). numba settles on a layer, and libgomp reads its settings, at the
    first parallel call of the process, so this must run before it; it is called when
    ``moebius_addon.core`` is imported."""
    if not any(name in os.environ for name in _USER_WAIT):
        os.environ["GOMP_SPINCOUNT"] = SPINCOUNT
    if any(name in os.environ for name in _USER_LAYER):
        return
    # the environment variable keeps the order when numba rereads its configuration (it does
    # so whenever a NUMBA_ variable changes); the attribute sets it for the current one
    os.environ["NUMBA_THREADING_LAYER_PRIORITY"] = " ".join(PRIORITY)
    import numba

    numba.config.THREADING_LAYER_PRIORITY = list(PRIORITY)
