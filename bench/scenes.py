"""Scenes artists make: Repulsive Curves' public scenes *CableUntangle* (earbuds),
*RingsPacking* and *BunnyCurvePacking* in our terms, and 100 cables between two plates with a
torus in the way. Prints sizes, iterations, seconds per iteration, energy and length, and
checks every accepted iterate and the straight move between consecutive iterates with an
independent numpy test (no curve meets itself, another curve or a mesh; the container is
never left; pinned vertices exact to the bit)::

    NUMBA_NUM_THREADS=2 .venv/bin/python bench/scenes.py --scene cables --iterations 20
    NUMBA_NUM_THREADS=2 .venv/bin/python bench/scenes.py --scene cables --thickness 0,0.3
    NUMBA_NUM_THREADS=2 .venv/bin/python bench/scenes.py --scene all --frames out/scenes
    .venv/bin/python bench/scenes.py --render out/scenes        # contact sheets, real bpy

Their files are in ``bench/data/repulsive_curves/`` (README there: where from, licence).
What differs from their runs is in docs/blender.md, "Scenes: cables, rings, packing".
"""

from __future__ import annotations

import argparse
import gzip
import json
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from cables_tree import plates_scene  # noqa: E402

from moebius_addon import core  # noqa: E402
from tests.core.test_obstacles import torus  # noqa: E402
from tests.mesh_checks import ray_parity_inside, segments_closest  # noqa: E402

RC = ROOT / "bench" / "data" / "repulsive_curves"


# -- Repulsive Curves' files ------------------------------------------------------------------


def _resolve(folder: Path, name: str) -> Path:
    """``name`` beside the scene file, else (the bunny, shipped once) gzipped in ``RC``."""
    for p in (folder / name, folder / (name + ".gz"), RC / (name + ".gz")):
        if p.exists():
            return p
    raise FileNotFoundError(f"{name} (looked beside {folder} and in {RC})")


def read_obj(path: Path):
    """Vertices (M, 3), line edges (E, 2) and triangles (K, 3, polygons fanned) of an OBJ
    (0-based; ``.gz`` read as well)."""
    opener = gzip.open if str(path).endswith(".gz") else open
    V, L, F = [], [], []
    with opener(path, "rt") as f:
        for line in f:
            s = line.split()
            if not s:
                continue
            if s[0] == "v":
                V.append([float(x) for x in s[1:4]])
            elif s[0] in ("l", "f"):
                idx = [int(x.split("/")[0]) - 1 for x in s[1:]]
                if s[0] == "l":
                    L += list(zip(idx[:-1], idx[1:], strict=True))
                else:
                    F += [(idx[0], idx[k], idx[k + 1]) for k in range(1, len(idx) - 1)]
    return (np.array(V, float), np.array(L, np.int64).reshape(-1, 2),
            np.array(F, np.int64).reshape(-1, 3))


def read_rc_scene(path: Path) -> dict:
    """The keywords of a Repulsive Curves ``scene.txt`` (their scenes/FORMATS.md) that the
    three scenes use: curve, surfaces, edge-length scale, pins, limits."""
    out = {"curve": None, "surfaces": [], "edge_scale": None, "fix_vertex": [],
           "iteration_limit": 0, "subdivide_limit": 0, "repel_curve": None, "other": []}
    for line in Path(path).read_text().splitlines():
        s = line.split()
        if not s or s[0].startswith("#"):
            continue
        k, args = s[0], s[1:]
        if k == "curve":
            out["curve"] = _resolve(Path(path).parent, args[0])
        elif k == "repel_surface":
            out["surfaces"].append(_resolve(Path(path).parent, args[0]))
        elif k == "fix_edgelengths":
            out["edge_scale"] = float(args[0]) if args else 1.0
        elif k == "fix_vertex":
            out["fix_vertex"].append(int(args[0]))
        elif k in ("iteration_limit", "subdivide_limit"):
            out[k] = int(args[0])
        elif k == "repel_curve":
            out["repel_curve"] = [float(a) for a in args]
        else:
            out["other"].append(line.strip())
    return out


def polylines(V: np.ndarray, L: np.ndarray, gap: int = 1):
    """A curve network as our polylines: chains between vertices of degree ≠ 2 and closed
    loops. At a junction (degree ≥ 3) the two longest chains become one polyline through it;
    every other chain there is cut back by ``gap`` vertices and its new end and the junction
    are pinned (we have no graph vertices: the Y is held by two pins, ``gap`` edges apart).
    Returns parts, closed flags and pins (one list per part)."""
    adj: list[list[int]] = [[] for _ in range(len(V))]
    for a, b in L:
        adj[a].append(b)
        adj[b].append(a)
    deg = np.array([len(a) for a in adj])
    seen: set[tuple[int, int]] = set()

    def walk(a: int, b: int) -> list[int]:
        chain = [a]
        while True:
            seen.add((min(a, b), max(a, b)))
            chain.append(b)
            if deg[b] != 2 or b == chain[0]:
                return chain
            a, b = b, next(c for c in adj[b] if (min(b, c), max(b, c)) not in seen)

    chains = [walk(v, w) for v in np.flatnonzero(deg != 2) for w in adj[v]
              if (min(v, w), max(v, w)) not in seen]
    loops = []
    for a, b in L:
        if (min(a, b), max(a, b)) not in seen:
            loops.append(walk(a, b)[:-1])
    parts, closed, pins = [], [], []
    junctions = [int(v) for v in np.flatnonzero(deg >= 3)]
    used = set()
    for j in junctions:
        at = [c if c[-1] == j else c[::-1] for c in chains if j in (c[0], c[-1])]
        if any(deg[c[0]] >= 3 for c in at):
            raise ValueError("a chain between two junctions: not one of the three scenes")
        at.sort(key=len, reverse=True)
        main = at[0] + at[1][::-1][1:]
        parts.append(main)
        pins.append([len(at[0]) - 1])
        for c in at[2:]:
            parts.append(c[:-gap])
            pins.append([len(c) - 1 - gap])
        used |= {id(c) for c in chains if j in (c[0], c[-1])}
        closed += [False] * (len(at) - 1)
    for c in chains:
        if id(c) not in used:
            parts.append(c)
            pins.append([])
            closed.append(False)
    for c in loops:
        parts.append(c)
        pins.append([])
        closed.append(True)
    return [V[np.array(p)] for p in parts], closed, pins


# -- the scenes --------------------------------------------------------------------------------


@dataclass
class Scene:
    name: str
    parts: list
    closed: list
    pinned: list | None = None
    obstacles: list = field(default_factory=list)
    container: tuple | None = None
    options: dict = field(default_factory=dict)
    note: str = ""


def mean_edge(parts, closed) -> float:
    e = [np.linalg.norm(np.diff(np.vstack([P, P[:1]]) if c else P, axis=0), axis=1)
         for P, c in zip(parts, closed, strict=True)]
    return float(np.concatenate(e).mean())


def total_length(parts, closed) -> float:
    return sum(float(np.linalg.norm(np.diff(np.vstack([P, P[:1]]) if c else P, axis=0),
                                    axis=1).sum()) for P, c in zip(parts, closed, strict=True))


def earbuds(gap: int = 2) -> Scene:
    """*CableUntangle*: their earbuds (one Y of three cables) as two open polylines; the
    third cable's end is cut back ``gap`` edges from the junction, and the junction and that
    end pinned (their network has a vertex of degree 3; ours are polylines)."""
    sc = read_rc_scene(RC / "CableUntangle" / "scene.txt")
    V, L, _ = read_obj(sc["curve"])
    parts, closed, pins = polylines(V, L, gap)
    # our runs hold edges at their start's lengths; theirs (fix_edgelengths) too
    return Scene("earbuds", parts, closed, pins, options={"target_lengths": "keep"},
                 note=f"RC scene: {' / '.join(sc['other'])}; fix_edgelengths")


def packing(which: str, factor: float | None, rate: float) -> Scene:
    """*RingsPacking* (three rings) or *BunnyCurvePacking* (one circle) inside their bunny,
    the bunny as our container, their edge-length scale as our length target (``factor``
    overrides it: a subset of their run)."""
    folder = {"rings": "RingsPacking", "bunny": "BunnyCurvePacking"}[which]
    sc = read_rc_scene(RC / folder / "scene.txt")
    V, L, _ = read_obj(sc["curve"])
    parts, closed, _ = polylines(V, L)
    Vb, _, Fb = read_obj(sc["surfaces"][0])
    f = sc["edge_scale"] if factor is None else factor
    n = sum(len(p) for p in parts)
    opts = {"length_target": f * total_length(parts, closed), "length_growth": rate,
            "target_lengths": "keep", "obstacle_tol": 0.1,
            "max_edges": n * 2 ** max(sc["subdivide_limit"], 1)}
    return Scene(which, parts, closed, None, container=(Vb, Fb), options=opts,
                 note=f"RC: edge lengths x{sc['edge_scale']:g}, subdivide_limit "
                      f"{sc['subdivide_limit']}, iteration_limit {sc['iteration_limit']}; "
                      f"here x{f:g} at {100 * rate:g} % per iteration")


#: The Untangle Cables preset's θ (moebius_addon.blender.options.PRESETS; not imported here:
#: that package is the add-on's).
CABLES_THETA = 0.3


def cables_torus(cables: int = 100, edges: int = 200, R: float = 0.25, r: float = 0.04,
                 clear: float = 0.07) -> Scene:
    """``cables`` open cables of ``edges`` edges between the plates z = 0 and z = 1
    (bench/cables_tree.py's ``plates_scene``, ends pinned) and a flat torus (major radius
    ``R``, tube ``r``) at z = 1/2 about the bundle's axis: at the start the cables near its
    core circle are bent away from it to ``clear`` > ``r`` (inwards through the hole, or
    outwards), horizontally, over a smooth bump in z."""
    k = int(np.ceil(np.sqrt(cables)))
    c = 0.05 * (k - 1)
    parts = plates_scene(cables, 4 * edges)
    out = []
    for P in parts:
        d = P[:, :2] - c
        rho = np.maximum(np.linalg.norm(d, axis=1), 1e-12)
        dz = np.abs(P[:, 2] - 0.5)
        w = np.clip((3 * clear - dz) / (2 * clear), 0.0, 1.0)
        w = w * w * (3 - 2 * w)  # 1 within clear of the torus' plane, 0 from 3 clear on
        side = np.where(rho >= R, 1.0, -1.0)
        rho2 = R + side * np.maximum(np.abs(rho - R), clear * w)
        Q = P.copy()
        Q[:, :2] = c + d * (rho2 / rho)[:, None]
        out.append(Q)
    parts = core.resample(out, [edges + 1] * cables, closed=False)
    V, F = torus(R, r, 64, 16)
    V = V + np.array([c, c, 0.5])
    return Scene("cables", parts, [False] * cables, [[0, edges] for _ in range(cables)],
                 obstacles=[(V, F)], options={"obstacle_tol": 0.1, "theta": CABLES_THETA},
                 note=f"torus R {R}, r {r}, start bent to {clear} from its core circle")


# -- the independent check -------------------------------------------------------------------


def _edges(parts, closed):
    """Segments (p, q) of every component and the global ids of their two vertices."""
    p, q, a, b, off = [], [], [], [], 0
    for P, c in zip(parts, closed, strict=True):
        n = len(P)
        i = np.arange(n if c else n - 1)
        j = (i + 1) % n
        p.append(P[i])
        q.append(P[j])
        a.append(off + i)
        b.append(off + j)
        off += n
    return np.concatenate(p), np.concatenate(q), np.concatenate(a), np.concatenate(b)


def point_triangle(x, a, b, c):
    """Distance of points to triangles, row by row: the plane's where the projection falls
    inside, else the nearest of the three sides."""
    e1, e2, v = b - a, c - a, x - a
    d00, d01, d11 = (np.einsum("ij,ij->i", e1, e1), np.einsum("ij,ij->i", e1, e2),
                     np.einsum("ij,ij->i", e2, e2))
    d20, d21 = np.einsum("ij,ij->i", v, e1), np.einsum("ij,ij->i", v, e2)
    den = d00 * d11 - d01 * d01
    s = (d11 * d20 - d01 * d21) / den
    t = (d00 * d21 - d01 * d20) / den
    n = np.cross(e1, e2)
    plane = np.abs(np.einsum("ij,ij->i", v, n)) / np.linalg.norm(n, axis=1)

    def side(p, q):
        d = q - p
        u = np.clip(np.einsum("ij,ij->i", x - p, d) / np.einsum("ij,ij->i", d, d), 0, 1)
        return np.linalg.norm(x - p - u[:, None] * d, axis=1)

    sides = np.minimum(np.minimum(side(a, b), side(b, c)), side(c, a))
    return np.where((s >= 0) & (t >= 0) & (s + t <= 1), plane, sides)


def segment_crosses(p, q, a, b, c):
    """Whether segment ``p q`` meets triangle ``a b c``, row by row (the 3 × 3 system of
    tests/mesh_checks.py's ``crossings`` per pair)."""
    M = np.stack([p - q, b - a, c - a], -1)
    ok = np.abs(np.linalg.det(M)) > 1e-300
    sol = np.zeros((len(p), 3))
    sol[ok] = np.linalg.solve(M[ok], (p - a)[ok][..., None])[..., 0]
    t, v, w = sol.T
    return ok & (t >= 0) & (t <= 1) & (v >= 0) & (w >= 0) & (v + w <= 1)


def segment_triangle(p, q, a, b, c):
    """Distance between segments and triangles, row by row: 0 where they meet, else the
    least of the segment's ends to the triangle and the segment to the triangle's sides."""
    d = np.minimum(point_triangle(p, a, b, c), point_triangle(q, a, b, c))
    for u, v in ((a, b), (b, c), (c, a)):
        d = np.minimum(d, segments_closest(p, q, u, v))
    return np.where(segment_crosses(p, q, a, b, c), 0.0, d)


class Mesh:
    """A triangle mesh with a k-d tree of its triangles' centroids (to find near pairs)."""

    def __init__(self, V, F):
        self.V, self.F = np.asarray(V, float), np.asarray(F)
        self.a, self.b, self.c = (self.V[self.F[:, k]] for k in range(3))
        cen = (self.a + self.b + self.c) / 3
        self.radius = float(max(np.linalg.norm(x - cen, axis=1).max()
                                for x in (self.a, self.b, self.c)))
        self.tree = cKDTree(cen)


def curve_pairs(p, q, a, b, r: float) -> tuple[np.ndarray, np.ndarray]:
    """Pairs of edges that share no vertex and whose midpoints are closer than ``r`` (two
    edges closer than ``g`` have midpoints closer than their half-lengths plus ``g``)."""
    ij = cKDTree(0.5 * (p + q)).query_pairs(r, output_type="ndarray")
    i, j = ij[:, 0], ij[:, 1]
    keep = (a[i] != a[j]) & (a[i] != b[j]) & (b[i] != a[j]) & (b[i] != b[j])
    return i[keep], j[keep]


def mesh_pairs(p, q, mesh: Mesh, r: float) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (edge, triangle) whose midpoint and centroid are closer than ``r``."""
    near = cKDTree(0.5 * (p + q)).sparse_distance_matrix(mesh.tree, r, output_type="ndarray")
    return near["i"].astype(np.int64), near["j"].astype(np.int64)


def _half(p, q) -> float:
    return 0.5 * float(np.linalg.norm(q - p, axis=1).max())


def curve_gap(p, q, a, b, cap: float) -> float:
    """Least distance between two edges of the curves that share no vertex, or ``cap`` if
    all are at least that far."""
    i, j = curve_pairs(p, q, a, b, 2 * _half(p, q) + cap)
    if len(i) == 0:
        return cap
    return min(cap, float(segments_closest(p[i], q[i], p[j], q[j]).min()))


def mesh_gap(p, q, mesh: Mesh, cap: float) -> float:
    """Least distance between an edge and a triangle of ``mesh``, or ``cap``."""
    i, j = mesh_pairs(p, q, mesh, _half(p, q) + mesh.radius + cap)
    if len(i) == 0:
        return cap
    d = segment_triangle(p[i], q[i], mesh.a[j], mesh.b[j], mesh.c[j])
    return min(cap, float(d.min()))


def certify(distance, lipschitz: np.ndarray, floor: float = 2.0 ** -24):
    """Certify ``distance(k, t) > 0`` for every pair ``k`` and every ``t`` in [0, 1], where
    pair ``k``'s distance changes at most ``lipschitz[k] |t − s|`` between times ``s`` and
    ``t``: on ``[s, u]`` it stays above ``(d(s) + d(u))/2 − lipschitz (u − s)/2``; intervals
    where that bound is not positive are bisected, down to ``floor``. Returns (certified,
    least distance sampled, samples, time of the first failure or None)."""
    k = np.arange(len(lipschitz))
    s, u = np.zeros(len(k)), np.ones(len(k))
    ds, du = distance(k, s), distance(k, u)
    least = float(min(ds.min(), du.min())) if len(k) else np.inf
    samples = 2 * len(k)
    while len(k):
        bad = 0.5 * (ds + du) <= 0.5 * lipschitz[k] * (u - s)
        k, s, u, ds, du = k[bad], s[bad], u[bad], ds[bad], du[bad]
        if not len(k):
            break
        stuck = (ds <= 0) | (du <= 0) | (u - s < floor)
        if stuck.any():
            return False, min(least, float(ds.min()), float(du.min())), samples, float(
                s[stuck][0])
        m = 0.5 * (s + u)
        dm = distance(k, m)
        samples += len(k)
        least = min(least, float(dm.min()))
        k, s, u = np.r_[k, k], np.r_[s, m], np.r_[m, u]
        ds, du = np.r_[ds, dm], np.r_[dm, du]
    return True, least, samples, None


def split_like(P, n_new: int, closed: bool) -> np.ndarray:
    """``P`` with every edge split into equal parts so that it has ``n_new`` vertices (what
    a refinement does; the point set is the same)."""
    n = len(P)
    f = n_new // n if closed else (n_new - 1) // (n - 1)
    if (n * f if closed else (n - 1) * f + 1) != n_new:
        raise ValueError(f"{n} vertices cannot be split into {n_new}")
    Q = np.roll(P, -1, axis=0) if closed else P[1:]
    A = P if closed else P[:-1]
    s = np.arange(f) / f
    X = (A[:, None] + s[None, :, None] * (Q - A)[:, None]).reshape(-1, 3)
    return X if closed else np.vstack([X, P[-1:]])


class PathChecker:
    """The independent check of a run's path (numpy and scipy's k-d tree only).

    Between consecutive iterates the curve moves on the straight path ``X(t) = (1 − t) X0 +
    t X1`` (what Blender's keyframes interpolate). A point of an edge moves by the same mix of
    its two vertices' moves, so the distance between edges ``I`` and ``J`` changes at most
    ``L_IJ |t − s|``, ``L_IJ`` the largest difference of a move of ``I``'s vertices and one of
    ``J``'s (an edge and a fixed triangle: the larger move of the edge's vertices). Only pairs
    whose midpoints start within reach (half-lengths, twice the largest move ``V``, and the
    reported gap ``g``, one mean edge) can come that close; each is certified by
    :func:`certify`. The container is left only through its wall, so a start inside (ray
    parity) plus certified moves keep every iterate inside; ray parity is tested again at the
    end.
    """

    def __init__(self, scene: Scene):
        self.closed = list(scene.closed)
        self.meshes = [Mesh(V, F) for V, F in scene.obstacles]
        if scene.container is not None:
            self.meshes.append(Mesh(*scene.container))
        self.container = scene.container
        self.pins = [list(p) for p in (scene.pinned or [[] for _ in scene.parts])]
        self.pin_values = [P[p].copy() for P, p in zip(scene.parts, self.pins, strict=True)]
        self.sizes = [len(P) for P in scene.parts]
        self.steps = self.samples = 0
        self.failures: list[str] = []
        self.curve_min = self.mesh_min = np.inf
        self.pins_exact = True
        self.seconds = 0.0

    def gaps(self, parts, cap: float) -> tuple[float, float]:
        """Least curve–curve and curve–mesh distances of ``parts``, capped at ``cap``."""
        p, q, a, b = _edges(parts, self.closed)
        dm = min((mesh_gap(p, q, m, cap) for m in self.meshes), default=cap)
        return curve_gap(p, q, a, b, cap), dm

    def start(self, parts, rng) -> None:
        h = mean_edge(parts, self.closed)
        dc, dm = self.gaps(parts, h)
        self.curve_min, self.mesh_min = dc / h, dm / h
        if dc <= 0 or dm <= 0:
            self.failures.append(f"start: curve gap {dc:.3g}, mesh gap {dm:.3g}")
        self.outside(parts, rng, "start")

    def outside(self, parts, rng, label: str) -> int:
        if self.container is None:
            return 0
        V, F = self.container
        X = np.concatenate(parts)
        out = sum(int((~ray_parity_inside(X[k:k + 64], V, F, rng)).sum())
                  for k in range(0, len(X), 64))
        if out:
            self.failures.append(f"{label}: {out} vertices outside the container")
        return out

    def step(self, before, after, label: str = "") -> bool:
        """Certify the straight move ``before`` → ``after`` (lists of arrays); a refinement
        in between (more vertices) is undone on ``before`` by splitting its edges."""
        t0 = time.perf_counter()
        before = [P if len(P) == len(Q) else split_like(P, len(Q), c)
                  for P, Q, c in zip(before, after, self.closed, strict=True)]
        for k, Q in enumerate(after):
            if len(Q) != self.sizes[k]:  # a refinement: vertex i became vertex f i
                n = self.sizes[k]
                f = len(Q) // n if self.closed[k] else (len(Q) - 1) // (n - 1)
                self.pins[k] = [f * i for i in self.pins[k]]
                self.sizes[k] = len(Q)
            if self.pins[k] and not np.array_equal(Q[self.pins[k]], self.pin_values[k]):
                self.pins_exact = False
                self.failures.append(f"{label}: pinned vertices of component {k} moved")
        p0, q0, a, b = _edges(before, self.closed)
        p1, q1 = _edges(after, self.closed)[:2]
        dp, dq = p1 - p0, q1 - q0
        mp, mq = np.linalg.norm(dp, axis=1), np.linalg.norm(dq, axis=1)
        V = float(max(mp.max(), mq.max()))
        g = mean_edge(after, self.closed)
        h = max(_half(p0, q0), _half(p1, q1))
        ok = True

        def report(kind, good, least, samples, when):
            nonlocal ok
            self.samples += samples
            if kind == "curve":
                self.curve_min = min(self.curve_min, least / g)
            else:
                self.mesh_min = min(self.mesh_min, least / g)
            if not good:
                ok = False
                self.failures.append(f"{label}: {kind} contact not excluded near t = "
                                     f"{when:.6f} (largest move {V:.3g})")

        i, j = curve_pairs(p0, q0, a, b, 2 * h + 2 * V + g)
        lip = np.max([np.linalg.norm(x[i] - y[j], axis=1) for x in (dp, dq)
                      for y in (dp, dq)], axis=0)

        def dcurve(k, t):
            t = t[:, None]
            return segments_closest(p0[i[k]] + t * dp[i[k]], q0[i[k]] + t * dq[i[k]],
                                    p0[j[k]] + t * dp[j[k]], q0[j[k]] + t * dq[j[k]])

        good, least, n, when = certify(dcurve, lip)
        report("curve", good, min(least, g), n, when)
        for mesh in self.meshes:
            e, f = mesh_pairs(p0, q0, mesh, h + mesh.radius + V + g)

            def dmesh(k, t, e=e, f=f, mesh=mesh):
                t = t[:, None]
                return segment_triangle(p0[e[k]] + t * dp[e[k]], q0[e[k]] + t * dq[e[k]],
                                        mesh.a[f[k]], mesh.b[f[k]], mesh.c[f[k]])

            good, least, n, when = certify(dmesh, np.maximum(mp[e], mq[e]))
            report("mesh", good, min(least, g), n, when)
        self.steps += 1
        self.seconds += time.perf_counter() - t0
        return ok


# -- running a scene -----------------------------------------------------------------------


def run(scene: Scene, iterations: int, max_seconds: float | None = None,
        frames: Path | None = None, metric: str = "hs", check: bool = True,
        energy: str = "moebius", engine: str = "auto", say=print, **energy_options) -> dict:
    """Relax ``scene``, check its path and return (and print) the measurements."""
    rng = np.random.default_rng(0)
    checker = PathChecker(scene)
    start = [P.copy() for P in scene.parts]
    if check:
        checker.start(start, rng)
    kept = [start]
    stamps = {"exit": 0.0, "iter": []}
    if frames is not None:
        frames.mkdir(parents=True, exist_ok=True)
        meshes = list(scene.obstacles) + ([scene.container] if scene.container else [])
        np.savez_compressed(frames / "meshes.npz",
                            **{f"V{k}": m[0] for k, m in enumerate(meshes)},
                            **{f"F{k}": m[1] for k, m in enumerate(meshes)})
        _save(frames, 0, start, scene.closed, np.nan)

    def callback(state):
        t_in = time.perf_counter()
        stamps["iter"].append(t_in - stamps["exit"])
        X = state.x if isinstance(state.x, list) else [state.x]
        del kept[state.nit:]
        if check:
            checker.step(kept[-1], X, f"iterate {state.nit}")
        kept.append([P.copy() for P in X])
        if frames is not None:
            _save(frames, state.nit, X, scene.closed, state.energy)
        stamps["exit"] = time.perf_counter()

    n0 = sum(len(P) for P in start)
    e0 = sum(len(P) - (0 if c else 1) for P, c in zip(start, scene.closed, strict=True))
    tris = sum(len(F) for _, F in scene.obstacles) + (
        len(scene.container[1]) if scene.container else 0)
    npins = sum(len(p) for p in scene.pinned) if scene.pinned else 0
    say(f"[{scene.name}] {len(start)} curves ({scene.closed.count(False)} open), {e0} edges, "
        f"{n0} vertices, {npins} pins, {tris} triangles "
        f"({'container' if scene.container else 'obstacles'}); {scene.note}; metric {metric}, "
        f"energy {energy} {energy_options or ''}, "
        f"NUMBA_NUM_THREADS={os.environ.get('NUMBA_NUM_THREADS', 'all')}, "
        f"load {os.getloadavg()[0]:.2f}")
    P0 = start if len(start) > 1 else start[0]
    closed = scene.closed if len(start) > 1 else scene.closed[0]
    pinned = scene.pinned if len(start) > 1 or not scene.pinned else scene.pinned[0]
    t0 = time.perf_counter()
    stamps["exit"] = t0
    res = core.relax(P0, metric=metric, max_iter=iterations, callback=callback, closed=closed,
                     pinned=pinned or None, obstacles=scene.obstacles or None,
                     container=scene.container, max_seconds=max_seconds, energy=energy,
                     engine=engine, **energy_options, **scene.options)
    wall = time.perf_counter() - t0
    end = kept[-1]
    if check:
        checker.outside(end, rng, "end")
    it = stamps["iter"]
    L = res.history.get("length", [np.nan])
    out = {"scene": scene.name, "curves": len(start), "edges_start": e0,
           "edges_end": sum(len(P) - (0 if c else 1)
                            for P, c in zip(end, scene.closed, strict=True)),
           "pins": npins, "triangles": tris, "iterations": res.nit,
           "first_s": it[0] if it else np.nan,
           "median_s": float(np.median(it[1:])) if len(it) > 1 else np.nan,
           "wall_s": wall - checker.seconds, "energy_start": res.history["energy"][0],
           "energy_end": res.fun, "length_start": L[0], "length_end": L[-1],
           "length_target": scene.options.get("length_target", np.nan),
           "message": res.message, "engine": res.stats.get("engine"),
           "checked_steps": checker.steps, "samples": checker.samples,
           "curve_gap_min": checker.curve_min, "mesh_gap_min": checker.mesh_min,
           "pins_exact": checker.pins_exact, "failures": checker.failures,
           "check_s": checker.seconds, "load": os.getloadavg()[0]}
    say(f"  {res.nit} iterations ({out['engine']} engine, {res.message}); first "
        f"{out['first_s']:.2f} s, then median {out['median_s']:.3f} s/iteration; run "
        f"{out['wall_s']:.1f} s without the check")
    say(f"  edges {e0} -> {out['edges_end']}; energy {out['energy_start']:.6g} -> "
        f"{out['energy_end']:.6g}; length {L[0]:.4g} -> {L[-1]:.4g}"
        + (f" (target {out['length_target']:.4g})" if scene.options.get("length_target")
           else ""))
    if check:
        say(f"  check: {checker.steps} moves certified in {checker.samples} samples "
            f"({checker.seconds:.1f} s); least gap curve-curve {checker.curve_min:.3g}, "
            f"curve-mesh {checker.mesh_min:.3g} mean edges; pins exact: "
            f"{checker.pins_exact}; failures: {checker.failures or 'none'}; load "
            f"{out['load']:.2f}")
    if frames is not None:
        (frames / "run.json").write_text(json.dumps(
            {k: v for k, v in out.items() if k != "failures"} | {"closed": scene.closed,
                                                                  "note": scene.note},
            default=float, indent=1))
    return out


def _save(folder: Path, k: int, parts, closed, energy) -> None:
    np.savez_compressed(folder / f"iterate_{k:05d}.npz", energy=energy,
                        **{f"c{i}": P.astype(np.float32) for i, P in enumerate(parts)})


def make(name: str, args) -> Scene:
    if name == "earbuds":
        return earbuds(args.gap)
    if name in ("rings", "bunny"):
        return packing(name, args.factor, args.rate)
    if name == "cables":
        return cables_torus(args.cables, args.edges)
    raise ValueError(f"unknown scene {name!r}: earbuds, rings, bunny, cables or all")


# -- contact sheets (real bpy, Workbench) ----------------------------------------------------


VIEW = {"earbuds": (0.3, -1.0, 0.5), "rings": (0.2, -0.35, 1.0), "bunny": (0.2, -0.35, 1.0),
        "cables": (0.5, -0.9, 0.9)}
BEVEL = {"earbuds": 0.005, "cables": 0.0025}  # tube radius, fraction of the scene's size
TITLE = {"earbuds": "CableUntangle (earbuds)", "rings": "RingsPacking",
         "bunny": "BunnyCurvePacking", "cables": "100 cables and a torus"}


def render_sheets(folder: Path, out: Path, resolution: int) -> None:
    """``out/scene_<name>.png``: start, middle and end of each run saved under ``folder``."""
    import tempfile

    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="moebius-sc-"))
    import bpy
    from demo_blender import frame_camera, render, setup_render

    for sub in sorted(p for p in folder.iterdir() if (p / "run.json").exists()):
        meta = json.loads((sub / "run.json").read_text())
        name, nit = meta["scene"], int(meta["iterations"])
        picks = sorted({0, nit // 2, nit})
        with np.load(sub / "meshes.npz") as z:
            meshes = [(z[f"V{k}"], z[f"F{k}"]) for k in range(len(z.files) // 2)]
        iterates = []
        for k in picks:
            with np.load(sub / f"iterate_{k:05d}.npz") as z:
                iterates.append(([z[f"c{i}"].astype(float) for i in range(len(z.files) - 1)],
                                 float(z["energy"])))
        pts = np.concatenate([np.concatenate(p) for p, _ in iterates] + [V for V, _ in meshes])
        size = float(np.ptp(pts, axis=0).max())
        tiles = []
        for k, (parts, _) in zip(picks, iterates, strict=True):
            bpy.ops.wm.read_homefile(use_empty=True)
            scene = bpy.context.scene
            setup_render(scene, resolution)
            _curves(parts, meta["closed"], max(0.3 * mean_edge(parts, meta["closed"]),
                                               BEVEL.get(name, 0.003) * size))
            for V, F in meshes:
                me = bpy.data.meshes.new("mesh")
                me.from_pydata(V.tolist(), [], F.tolist())
                ob = bpy.data.objects.new("mesh", me)
                ob.color = (0.6, 0.6, 0.65, 0.25)  # alpha < 1: Workbench draws it see-through
                scene.collection.objects.link(ob)
            frame_camera(scene, pts, direction=VIEW.get(name, (0.3, -0.5, 1.0)))
            path = sub / f"tile_{k:05d}.png"
            render(scene, path)
            tiles.append(path)
        labels = [("start" if k == 0 else f"iteration {k}") + f": E = {e:.5g}"
                  for k, (_, e) in zip(picks, iterates, strict=True)]
        if np.isnan(iterates[0][1]):
            labels[0] = f"start: E = {meta['energy_start']:.5g}"
        _sheet(tiles, labels, TITLE.get(name, name), out / f"scene_{name}.png")
        print(f"{out / f'scene_{name}.png'}: {(out / f'scene_{name}.png').stat().st_size} "
              "bytes")


def _curves(parts, closed, bevel: float) -> None:
    """The curves as bevelled poly splines, one object (one colour) per fifth of them."""
    import bpy

    palette = [(0.10, 0.30, 0.70), (0.85, 0.30, 0.05), (0.10, 0.55, 0.20),
               (0.55, 0.15, 0.60), (0.75, 0.55, 0.00)]
    for g, col in enumerate(palette[:len(parts)]):
        curve = bpy.data.curves.new(f"curves{g}", "CURVE")
        curve.dimensions = "3D"
        curve.bevel_depth = bevel
        curve.bevel_resolution = 2
        for P, c in list(zip(parts, closed, strict=True))[g::len(palette)]:
            sp = curve.splines.new("POLY")
            sp.points.add(len(P) - 1)
            sp.points.foreach_set("co", np.column_stack([P, np.ones(len(P))]).ravel())
            sp.use_cyclic_u = bool(c)
        obj = bpy.data.objects.new(f"curves{g}", curve)
        obj.color = (*col, 1.0)
        bpy.context.scene.collection.objects.link(obj)


def _sheet(images, labels, title: str, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(images), figsize=(3.2 * len(images), 3.5))
    for ax, img, label in zip(np.ravel(axes), images, labels, strict=True):
        ax.imshow(plt.imread(img))
        ax.set_title(label, fontsize=9)
        ax.axis("off")
    fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="all", help="earbuds, rings, bunny, cables or all")
    ap.add_argument("--iterations", type=int, default=60)
    ap.add_argument("--max-seconds", type=float, default=None)
    ap.add_argument("--frames", type=Path, default=None, help="save every iterate here")
    ap.add_argument("--metric", default="hs")
    ap.add_argument("--energy", default="moebius")
    ap.add_argument("--alpha", type=float, default=None, help="tangent-point exponent")
    ap.add_argument("--beta", type=float, default=None, help="tangent-point exponent")
    ap.add_argument("--factor", type=float, default=None,
                    help="packing: grow to this many times the start's length (default: "
                         "Repulsive Curves' edge-length scale)")
    ap.add_argument("--rate", type=float, default=0.02, help="packing: growth per iteration")
    ap.add_argument("--gap", type=int, default=2, help="earbuds: edges cut at the junction")
    ap.add_argument("--cables", type=int, default=100)
    ap.add_argument("--edges", type=int, default=200)
    ap.add_argument("--thickness", default="0",
                    help="tube radii in mean edge lengths, comma-separated: each scene runs "
                         "once per radius, in turn, in this process (the Untangle Cables "
                         "preset's bevel is 0.3)")
    ap.add_argument("--theta", type=float, default=None,
                    help="the tree's θ for every scene (default: the scene's own, the cables' "
                         "the Untangle Cables preset's 0.3, else the energy's default); 0: "
                         "the energy's default everywhere")
    ap.add_argument("--no-check", action="store_true")
    ap.add_argument("--render", type=Path, default=None,
                    help="render the runs saved under this folder into docs/img/scene_*.png")
    ap.add_argument("--resolution", type=int, default=300)
    a = ap.parse_args(argv)
    if a.render is not None:
        render_sheets(a.render, ROOT / "docs" / "img", a.resolution)
        return 0
    names = ["earbuds", "rings", "bunny", "cables"] if a.scene == "all" else [a.scene]
    bad = 0
    tp = {k: v for k, v in (("alpha", a.alpha), ("beta", a.beta)) if v is not None}
    radii = [float(x) for x in a.thickness.split(",")]
    rows = []
    for name in names:
        for radius in radii:
            scene = make(name, a)
            if a.theta is not None:
                scene.options.pop("theta", None)
                if a.theta:
                    scene.options["theta"] = a.theta
            theta = scene.options.get("theta")
            scene.note += ("; the energy's default theta" if theta is None else f"; theta {theta:g}"
                           + (" (the Untangle Cables preset's)" if theta == CABLES_THETA else ""))
            if radius:
                scene.options["thickness"] = radius * mean_edge(scene.parts, scene.closed)
                scene.note += f"; thickness {radius:g} mean edges"
            folder = a.frames / (name + (f"_r{radius:g}" if radius else "")) if a.frames else None
            out = run(scene, a.iterations, a.max_seconds, folder, a.metric, not a.no_check,
                      a.energy, **tp)
            rows.append((name, radius, out))
            bad += bool(out["failures"])
    if len(radii) > 1:  # side by side, measured in this one run
        print("\nscene, thickness (mean edges): median s/iteration, least curve gap (mean edges)")
        for name, radius, out in rows:
            print(f"  {name:8s} {radius:5g}: {out['median_s']:.3f} s, gap "
                  f"{out['curve_gap_min']:.3g} (twice the radius {2 * radius:g})")
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
