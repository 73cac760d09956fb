"""numba's threading layer: OpenMP first, then TBB, numba's own workqueue last; libgomp spins
briefly.

Why: with the TBB of Debian 12 (and Debian's Blender) every parallel call grows slower with the
number already made in the process (numba issues 10225 and 10556), while OpenMP's cost per call
stays constant; long spinning OpenMP threads take the CPU from OpenBLAS's. The measurements are
in docs/lab/exact-engine.md ("Numba's threading layer, and long sessions").
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
