"""numba's threading layer (core/_threads.py): importing the core asks numba for OpenMP before
TBB (whose per-call cost grew with every parallel call with an older TBB), and keeps the user's
own choice. Each case runs in a fresh interpreter: numba settles on a layer once."""

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
CODE = """
import json, os, numba
import moebius_addon.core as core
core.moebius_energy(core.knots.circle(64))  # a parallel kernel: numba picks its layer now
layer = numba.threading_layer()
try:
    from numba.np.ufunc import omppool  # noqa: F401
    omp = True
except ImportError:
    omp = False
print(json.dumps([layer, os.environ.get("GOMP_SPINCOUNT"), omp]))
"""


def _layer(**env):
    clean = {k: v for k, v in os.environ.items()
             if not k.startswith(("NUMBA_THREADING_LAYER", "OMP_WAIT_POLICY", "GOMP_SPINCOUNT"))}
    out = subprocess.run([sys.executable, "-c", CODE], env={**clean, **env}, cwd=ROOT,
                         capture_output=True, text=True, check=True, timeout=300)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_import_prefers_openmp():
    # on a machine with TBB installed (this one: Debian's libtbb12) numba would take TBB
    layer, spin, omp_loads = _layer()
    assert layer == "omp" if omp_loads else layer in ("tbb", "workqueue")
    assert spin == "1000"  # OpenMP threads stop spinning soon (OpenBLAS needs the cores)


def test_the_users_choice_is_kept():
    assert _layer(NUMBA_THREADING_LAYER="workqueue", GOMP_SPINCOUNT="5")[:2] == ["workqueue", "5"]
    assert _layer(NUMBA_THREADING_LAYER_PRIORITY="workqueue omp tbb")[0] == "workqueue"
