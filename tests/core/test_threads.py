"""numba's threading layer (core/_threads.py): importing the core asks numba for OpenMP or its
workqueue before TBB, whose per-call cost grows with every parallel call, and keeps the
user's own choice. Each case runs in a fresh interpreter: numba settles on a layer once."""

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
print(json.dumps([numba.threading_layer(), os.environ.get("GOMP_SPINCOUNT")]))
"""


def _layer(**env):
    clean = {k: v for k, v in os.environ.items()
             if not k.startswith(("NUMBA_THREADING_LAYER", "OMP_WAIT_POLICY", "GOMP_SPINCOUNT"))}
    out = subprocess.run([sys.executable, "-c", CODE], env={**clean, **env}, cwd=ROOT,
                         capture_output=True, text=True, check=True, timeout=300)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_import_prefers_a_layer_whose_calls_stay_cheap():
    # on a machine with TBB installed (this one: Debian's libtbb12) numba would take TBB
    layer, spin = _layer()
    assert layer in ("omp", "workqueue")
    assert spin == "1000"  # OpenMP threads stop spinning soon (OpenBLAS needs the cores)


def test_the_users_choice_is_kept():
    assert _layer(NUMBA_THREADING_LAYER="workqueue", GOMP_SPINCOUNT="5") == ["workqueue", "5"]
    assert _layer(NUMBA_THREADING_LAYER_PRIORITY="workqueue omp tbb")[0] == "workqueue"
