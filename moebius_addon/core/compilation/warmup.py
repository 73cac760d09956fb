"""Run the paths of a first session on small curves, so that numba compiles (or loads) their
kernels: what ``make extension`` runs to build the cache it ships with the linux-x64 zip
(mk/build_extension.py, docs/blender.md "Install"), and what ``python -m
moebius_addon.core.compilation.warmup`` runs to fill numba's cache ahead of use.

Each path does what the Blender layer does on that first contact: *Add Knot* (resample, start
check, energy), the method *Automatic* chooses (the knot determinant), a few iterates, and the
invariants compared at the end of a run.
"""

from __future__ import annotations

import argparse
import hashlib
import sys
import time
from collections.abc import Callable

import numpy as np

from ..energies import ENERGIES
from ..geometry.layout import layout_from_sizes
from ..geometry.polygon import check_polygon, contact_ratio, resample
from ..geometry.push_apart import separate
from ..metrics import banded, hs_solve
from ..runs.engine import energy, energy_gradient, moebius_energy
from ..runs.methods import make_run
from ..topology import knots
from ..topology.identify import identify
from ..topology.invariants import knot_determinant
from ..tree import hs_metric as hs_tree


def _relax(P, method: str, steps: int = 2, **options) -> None:
    run = make_run(method, P, metric="hs", max_iter=steps, tol=0.0, target_lengths="keep",
                   **options)
    while run.step():
        pass
    run.result()


def _knot(name: str, n: int, method: str = "projected_gradient_implicit") -> None:
    """Add Knot + Relax of a knot: *Automatic* takes the implicit method (determinant > 1);
    the explicit one for unknots."""
    P = knots.named(name, n)
    check_polygon(P)
    moebius_energy(P)
    knot_determinant(P)
    _relax(P, method)
    identify(P)


def _exact() -> None:
    _knot("3_1", 100)
    _relax(knots.named("3_1", 100), "projected_gradient")  # unknots, and as chosen
    # a start whose strands nearly touch is pushed apart first (solvers.adaptive)
    separate(resample(knots.named("3_1", 30) * [1.0, 1.0, 0.3], 30))


def _tree() -> None:
    # from engine.AUTO_TREE_FROM edges on Automatic takes the tree; from engine.ENERGY_TREE_FROM
    # (3 000) the energy shown by Add Knot and Convert is the tree's too
    _knot("3_1", 3000)
    _relax(knots.named("3_1", 3000), "projected_gradient")
    # from hs_solve.MULTILEVEL_FROM (2·10⁴) vertices the hs solve's hierarchy: its transfers
    _, _, P = hs_solve._halve(layout_from_sizes([64], False))
    P.T @ (P @ np.zeros((P.shape[1], 3)))
    # and its levels' operators, in single precision as the fine one from
    # engine.SINGLE_WEIGHTS_FROM (2·10⁵) vertices on
    X = knots.named("3_1", 400)
    hs_tree.HsOperator(X, layout_from_sizes([400], False), single=True).product(X)
    # from banded.SPLIT_FROM (2·10⁴) vertices a component's band in two halves: its cut and
    # its separator's set-up (an identity band of 80 rows, cut at 32)
    ab = np.zeros((80, 23))
    ab[:, 11] = 1.0
    S, FA, EA, FB, EB = banded._split_band(ab, 11, 32, 44, 80, 22)
    piv, mult, _ = banded.band_lu_blocks(ab, 11, 11, np.array([0, 32, 44, 80], np.int64))
    banded._window(ab, mult, piv, 11, 10, 32, FA, EA)


def _energy_path(record) -> Callable[[], None]:
    """The warm-up path of an energy's record (``warmup``: run options, ``warmup_sizes``):
    its sums alone, then runs minimizing it (the metric of its order; from
    engine.AUTO_TREE_FROM edges on, the tree)."""
    def path() -> None:
        for n in record.warmup_sizes:
            P = knots.named("3_1", n)
            energy(P, energy=record.name)
            for options in record.warmup:
                _relax(P, "projected_gradient_implicit", **options)
    return path


def _convert() -> None:
    t = np.linspace(0.0, 2.0 * np.pi, 400, endpoint=False)
    drawn = np.c_[np.sin(t) + 2 * np.sin(2 * t), np.cos(t) - 2 * np.cos(2 * t), -np.sin(3 * t)]
    P = resample(drawn, 200)
    check_polygon(P, coarseness=False)
    contact_ratio(P)


def _identify() -> None:
    identify(knots.named("8_19", 200))


def _open() -> None:
    t = np.linspace(0.0, 1.0, 80)
    P = resample(np.c_[np.cos(6 * t), np.sin(6 * t), 3 * t], 80, closed=False)
    check_polygon(P, closed=False)
    moebius_energy(P, closed=False)
    _relax(P, "projected_gradient", closed=False)


def _cables() -> None:
    # Presets ▸ Untangle Cables: open cables with both ends pinned; from engine.AUTO_TREE_FROM
    # vertices on (6 × 171 here) the tree's open-curve kernels (the arc-length field, the open
    # band solver), which a first run compiled for about a minute
    t = np.linspace(0.0, 1.0, 171)
    P = [np.c_[0.1 * (c % 3) + 0.01 * np.sin(3 * t + c), 0.1 * (c // 3) + 0.01 * np.cos(2 * t + c),
               t] for c in range(6)]
    _relax(P, "projected_gradient", closed=False, pinned=[[0, 170]] * 6)


def _box(lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """A closed box mesh ``(V, F)`` from corner ``lo`` to corner ``hi``, faces outward."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    V = np.array([[(hi if (v >> d) & 1 else lo)[d] for d in range(3)] for v in range(8)])
    F = np.array([[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4],
                  [2, 6, 3], [3, 6, 7], [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]])
    return V, F


def _torus(R: float, r: float, nu: int, nv: int, z: float = 0.0):
    """A closed torus mesh ``(V, F)`` about the z axis at height ``z``."""
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, nu, endpoint=False),
                       np.linspace(0, 2 * np.pi, nv, endpoint=False), indexing="ij")
    V = np.c_[((R + r * np.cos(v)) * np.cos(u)).ravel(), ((R + r * np.cos(v)) * np.sin(u)).ravel(),
              (z + r * np.sin(v)).ravel()]
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    a, b = i * nv + j, ((i + 1) % nu) * nv + j
    c, d = ((i + 1) % nu) * nv + (j + 1) % nv, i * nv + (j + 1) % nv
    F = np.r_[np.c_[a.ravel(), b.ravel(), c.ravel()], np.c_[a.ravel(), c.ravel(), d.ravel()]]
    return V, F


def _sphere(radius: float, n: int = 12):
    """A closed UV sphere ``(V, F)`` about the origin: ``n`` rings of ``2 n`` vertices and
    the two poles, faces outward."""
    m = 2 * n
    lat = np.pi * (np.arange(1, n + 1) / (n + 1) - 0.5)
    lon = 2 * np.pi * np.arange(m) / m
    V = np.r_[[[0.0, 0.0, -radius]],
              radius * np.c_[(np.cos(lat)[:, None] * np.cos(lon)).ravel(),
                             (np.cos(lat)[:, None] * np.sin(lon)).ravel(),
                             np.repeat(np.sin(lat), m)],
              [[0.0, 0.0, radius]]]
    ring = lambda k, j: 1 + k * m + j % m  # noqa: E731
    F = [[0, ring(0, j + 1), ring(0, j)] for j in range(m)]
    for k in range(n - 1):
        for j in range(m):
            F += [[ring(k, j), ring(k, j + 1), ring(k + 1, j + 1)],
                  [ring(k, j), ring(k + 1, j + 1), ring(k + 1, j)]]
    F += [[len(V) - 1, ring(n - 1, j), ring(n - 1, j + 1)] for j in range(m)]
    return V, np.array(F)


def _obstacles() -> None:
    # Advanced ▸ Obstacles on a knot, both methods Automatic takes; the obstacle's hierarchy
    # from obstacles.OBSTACLE_TREE_FROM edge–triangle pairs on
    P = knots.named("3_1", 100)
    box = _box([1.3, -0.3, -0.3], [1.9, 0.3, 0.3])
    for method in ("projected_gradient_implicit", "projected_gradient"):
        _relax(P, method, obstacles=[box])
    _relax(knots.named("3_1", 1000), "projected_gradient", obstacles=[_torus(3.0, 0.5, 40, 25)])


def _untangle_cables() -> None:
    # Presets ▸ Untangle Cables: open cables hanging from two plates through a torus, the ends
    # on the plates pinned with their tangents (and, the plates apart, without), the tree from
    # engine.AUTO_TREE_FROM vertices on, θ 0.3
    t = np.linspace(0.0, 1.0, 171)
    parts = [np.c_[0.3 * np.cos(2 * np.pi * c / 6) + 0.02 * np.sin(3 * t + c),
                   0.3 * np.sin(2 * np.pi * c / 6) + 0.02 * np.cos(2 * t + c), t]
             for c in range(6)]
    ring = _torus(0.6, 0.08, 24, 12, z=0.5)
    bevel = 0.3 / 170  # the preset's tube: 0.3 mean edge lengths
    for tangents, gap, thickness in ((True, 0.0, bevel), (False, 0.02, 0.0)):
        plates = [_box([-1.0, -1.0, -0.04 - gap], [1.0, 1.0, -gap]),
                  _box([-1.0, -1.0, 1.0 + gap], [1.0, 1.0, 1.04 + gap])]
        _relax(parts, "projected_gradient", closed=False, pinned=[[0, 170]] * 6,
               pin_tangents=tangents, obstacles=[*plates, ring], theta=0.3,
               thickness=thickness)
    small = [resample(p, 30, closed=False) for p in parts[:2]]
    for thickness in (0.0, 0.3 / 29):
        _relax(small, "projected_gradient", closed=False, pinned=[[0, 29]] * 2,
               obstacles=plates, thickness=thickness)


def _pack_in_volume() -> None:
    # Presets ▸ Pack in Volume: a loop growing inside a container, exact and tree engines
    for n in (60, 1000):
        t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
        P = resample(np.c_[0.6 * np.cos(t), 0.6 * np.sin(t), 0.2 * np.sin(5 * t)], n)
        edge = float(np.linalg.norm(P[1] - P[0]))
        _relax(P, "projected_gradient", container=_sphere(0.9), length_target=3.0 * n * edge,
               length_growth=0.01, thickness=0.3 * edge)


#: The paths, in the order a first session meets them.
PATHS: dict[str, Callable[[], None]] = {
    "exact": _exact,
    "convert": _convert,
    "identify": _identify,
    "open": _open,
    "tree": _tree,
    # Energy ▸ Tangent-Point, Stiffness, ...: each energy's own path (energies.ENERGIES)
    **{name: _energy_path(r) for name, r in ENERGIES.items() if r.warmup},
    "cables": _cables,
    "obstacles": _obstacles,
    "untangle_cables": _untangle_cables,
    "pack_in_volume": _pack_in_volume,
}


def fingerprint() -> str:
    """One hash of the tree engine's energy and gradient, Möbius and tangent-point, on a fixed
    noisy trefoil of 300 edges: the build records it with the kernels it compiled
    (``--fingerprint``), and tests compare it with the same sums from the kernels the zip
    ships. Kernels with fast-math "contract" must give the same bits either way (the Möbius
    near field's did not)."""
    P = knots.named("3_1", 300) + 0.002 * np.random.default_rng(6).standard_normal((300, 3))
    h = hashlib.sha256()
    for name in ("moebius", "tangent_point"):
        e, g = energy_gradient(P, energy=name, engine="tree")
        h.update(np.float64(e).tobytes())
        h.update(np.ascontiguousarray(g, np.float64).tobytes())
    return h.hexdigest()


def warm(paths=tuple(PATHS), say: Callable[[str], None] | None = print) -> dict[str, float]:
    """Run ``paths`` (names of :data:`PATHS`); return the CPU seconds of each."""
    seconds = {}
    for name in paths:
        t = time.process_time()
        PATHS[name]()
        seconds[name] = time.process_time() - t
        if say is not None:
            say(f"{name}: {seconds[name]:.1f} s CPU")
    return seconds


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("paths", nargs="*", default=list(PATHS),
                    help=f"which paths (default: all of {', '.join(PATHS)})")
    ap.add_argument("--fingerprint", metavar="FILE",
                    help="then write fingerprint() of the kernels as compiled (or loaded) here")
    args = ap.parse_args(argv)
    unknown = [p for p in args.paths if p not in PATHS]
    if unknown:
        ap.error(f"unknown path(s) {', '.join(unknown)}; choose from {', '.join(PATHS)}")
    warm(args.paths, lambda line: print(line, flush=True))
    if args.fingerprint:
        with open(args.fingerprint, "w") as out:
            out.write(fingerprint() + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
