"""Shared fixtures: test curves built from closed formulas (no catalogue needed)."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

DATA = Path(__file__).resolve().parents[1] / "moebius_addon" / "core" / "data"
# the project's shared folder (beside the checkout, as in CI): more curves for the OBJ tests
SHARED = Path(__file__).resolve().parents[1].parent / "shared"
ROOT = Path(__file__).resolve().parents[1]


def trefoil(n: int) -> np.ndarray:
    """docs/design.md's trefoil (sin t + 2 sin 2t, cos t − 2 cos 2t, −sin 3t), n equal parameter
    steps (not equilateral)."""
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    return np.c_[np.sin(t) + 2 * np.sin(2 * t), np.cos(t) - 2 * np.cos(2 * t), -np.sin(3 * t)]


def varied_curves(n: int, rng: np.random.Generator):
    """``(name, parts, closed)`` of about ``n`` edges each, for the tangent-point tree's error
    (tests/core/test_tangent_point.py, bench/tp_accuracy.py): knots of the table (two of ten
    crossings), the FHW unknot, a chain of three round rings, one round ring (nearly critical:
    every cluster curved alike), ten open cables and a trefoil with noise."""
    from moebius_addon import core

    out = [(k, core.resample(core.knots.named(k), n), True)
           for k in ("3_1", "7_2", "10_1", "10_132")]
    out.append(("fhw", core.knots.freedman_unknot(n), True))
    t = np.linspace(0, 2 * np.pi, 400, endpoint=False)
    ring = np.c_[np.cos(t), np.sin(t), 0 * t]
    out.append(("three rings", core.resample([ring, ring[:, [0, 2, 1]] + [1.2, 0, 0],
                                              ring + [2.4, 0, 0]], [n // 3] * 3), True))
    out.append(("round ring", core.resample(ring, n), True))
    s = np.linspace(0, 1, 4 * n // 10 + 1)
    cables = []
    for c in range(10):
        w = rng.uniform(-0.02, 0.02, 2)
        cables.append(np.c_[0.1 * (c % 4) + w[0] * np.sin(np.pi * s),
                            0.1 * (c // 4) + w[1] * np.sin(2 * np.pi * s), s])
    out.append(("ten cables", core.resample(cables, [n // 10 + 1] * 10, closed=False), False))
    P = core.resample(core.knots.named("3_1"), n)
    h = float(np.linalg.norm(P[1] - P[0]))
    out.append(("noisy trefoil", P + 0.1 * h * rng.standard_normal(P.shape), True))
    return out


def ngon(n: int) -> np.ndarray:
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    return np.c_[np.cos(t), np.sin(t), np.zeros(n)]


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] *= -1
    return q


def read_obj_vertices(path) -> np.ndarray:
    with open(path) as f:
        return np.array([[float(x) for x in line.split()[1:4]] for line in f
                         if line.startswith("v ")])


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


@pytest.fixture(scope="session")
def fhw_raw() -> np.ndarray:
    """The Freedman–He–Wang unknot as published (1184 vertices)."""
    return read_obj_vertices(DATA / "freedman_unknot_1184.obj")


def out_here_and_in_one_thread(code: str):
    """``OUT`` (JSON-able) of ``code`` run in this process, with all its threads and the kernels
    compiled or loaded here, and in a subprocess with one numba thread that loads them from the
    cache this process wrote: ``(here, there)``. Two fresh processes would compile every kernel
    twice (60-110 s in CI)."""
    here: dict = {}
    exec(code, here)
    env = {**os.environ, "NUMBA_NUM_THREADS": "1"}
    out = subprocess.run([sys.executable, "-c", code + "\nimport json\nprint(json.dumps(OUT))"],
                         env=env, cwd=ROOT, capture_output=True, text=True, check=True,
                         timeout=600)
    return here["OUT"], json.loads(out.stdout.strip().splitlines()[-1])


#: numba's compiles in this process (printed at the end of the session: where CI's minutes go);
#: None where numba cannot be imported (the Blender venvs: it comes with the extension)
_COMPILES = None


def pytest_configure(config):
    global _COMPILES
    try:
        from numba.core import event

        from moebius_addon.core.compilation.notice import CompileWatch
    except ImportError:
        return
    _COMPILES = CompileWatch()
    event.register("numba:compile", _COMPILES)


def pytest_terminal_summary(terminalreporter):
    if _COMPILES is None:
        return
    top = sorted(_COMPILES.by_kernel.items(), key=lambda kv: -kv[1])[:8]
    terminalreporter.write_line(
        f"numba compiled {_COMPILES.kernels} kernels in this process in "
        f"{_COMPILES.seconds:.0f} s" + "".join(f"; {k} {v:.1f} s" for k, v in top))
