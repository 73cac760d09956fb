"""Same-energy comparison with Henrik Schumacher's Repulsor. Prints measurements.

    python bench/repulsor_compare.py                        # 2 400 and 10 000 edges, 1 and 2
                                                            # threads, 5 alternated rounds
    python bench/repulsor_compare.py --sizes 100000 --reps 2
    python bench/repulsor_compare.py --million              # adds 10^6 edges (slow)
    python bench/repulsor_compare.py --moebius              # also our Möbius E+g and iteration
    python bench/repulsor_compare.py --moebius --later 2    # and 2 more Möbius iterations in its
                                                            # process (a step history, as in a run)
    python bench/repulsor_compare.py --parts                # also E+g in two parts: the trees
                                                            # built, the sums on built trees
    python bench/repulsor_compare.py --parts --again 4      # and 4 more trees and sums in the
                                                            # same process, both sides (warm
                                                            # allocator: as in a flow)
    python bench/repulsor_compare.py --core-from DIR        # our side imported from DIR (e.g. an
                                                            # export of another branch)
    python bench/repulsor_compare.py --driver PATH          # Repulsor's driver binary (default
                                                            # $REPULSOR_BUILD/driver/driver, else
                                                            # build/repulsor/driver/driver here)
    python bench/repulsor_compare.py --curve knot.obj       # another curve (one closed polyline)

The curve is the Freedman–He–Wang unknot shipped with the package
(``moebius_addon/core/data/freedman_unknot_1184.obj``; ``--curve`` for another OBJ polyline)
resampled with ``core.resample(P, n)``. Per size and thread count,
one round runs four processes in turn, k rounds: Repulsor E+g, our E+g, Repulsor iteration, our
iteration; each process times one measurement with its own clock (Repulsor: std::chrono::
steady_clock; ours: time.perf_counter, after a warm-up on a small curve so that no numba compile
is timed) and reports its peak resident memory (VmHWM of /proc/self/status: getrusage's
ru_maxrss would carry the Python parent's peak across the exec). Both sides run with the
same thread count T: Repulsor's ``thread_count`` and ``OPENBLAS_NUM_THREADS=T``; ours
``NUMBA_NUM_THREADS=T`` and ``OPENBLAS_NUM_THREADS=T``. After the rounds of a size and thread
count: a ``host`` line, the share of the VM's CPU time other guests of the host took while they
ran (``steal`` of /proc/stat; on a shared VM it moved Repulsor's E+g at 2 400 edges from 7.8 to
42 ms in one afternoon), and ``rounds`` lines, Repulsor's time ÷ ours round by round and their
median.

Energy. Repulsor's ``TangentPointEnergy0(q, p)`` for curves sums, over ordered pairs of distinct
edges, ``l_I l_J |P_I (m_J − m_I)|^q / |m_J − m_I|^p`` with ``P_I`` the projection onto the
normal plane of edge I (so ``|P_I d| = |T_I × d|``), far pairs by its cluster tree. Ours (branch
tangent-point) is ``Σ l_I l_J |T_I × (m_I − m_J)|^α / |m_I − m_J|^β`` over ordered pairs of
*disjoint* edges. So ``(q, p) = (α, β) = (2, 4)``, and the two differ by the adjacent pairs,
which Repulsor counts and we do not; the ``mapping`` line checks this with a numpy sum.

Iterations. Repulsor's, as its Example/ and Example2/ do it: a new mesh (cluster tree, block
cluster tree), energy and differential, the tangent-point metric solved for the gradient
(GMRES, at most 100 iterations, relative tolerance 1e-5, preconditioned by H^1-solve,
pseudo-Laplacian, H^1-solve), a collision-free step size in [0, 1] along minus the gradient
(``MaximumSafeStepSize``), the move (``SemiStaticUpdate``, the hierarchy kept) and the energy
of the moved curve. No constraints, no line search. Ours: ``core.relax(P, max_iter=1,
engine="tree")``, the seconds of its one iteration from the run's history (``history
["seconds"][1] − [0]``; ``[0]`` is the setup with the first energy, gradient and solve): the
projected Sobolev (hs) gradient under edge-length and barycenter constraints, Armijo line
search with a collision-free step bound, back-projection onto the constraints, and the next
energy, gradient and solve. With ``--moebius`` also our Möbius energy's E+g (``eg_moebius``)
and the same iteration of our Möbius-energy flow (``iter_moebius``, to compare with
Repulsor's tangent-point iteration); ``ratio`` lines give each side's iteration ÷ E+g of the
same energy (best of each). Our iteration lines give the Krylov iterations of each hs solve
(``krylov=``). ``--later K``: the Möbius run goes on for K more iterations
(``iter_moebius_later`` lines, each iteration's seconds from the history): the first iteration
has no step of its own to start from (its first trial is the run's ``initial_step``), the later
ones start from the step before, as every iteration of a run but the first.

Repulsor is never a dependency of the add-on and nothing of it is in this repository: the driver
binary (``--driver``) is a small C++ program of ours that calls Repulsor's API
(``bench/repulsor_driver/driver.cpp``). ``bench/repulsor_driver/build.sh [DIR]`` fetches
Repulsor into DIR and builds DIR/driver/driver; DIR defaults to ``$REPULSOR_BUILD``, else to
``build/repulsor`` in this checkout (git ignores it; ``make clean`` removes it), which is where
``--driver`` looks by default too. The driver is built against
Repulsor 5db79ff19cd8bbd17dafdd256017aa690d70b392 (submodules Tensors 6de11784d4d54403091410d9
b622281c28e5f211, Tools dfa339a6d599fb166d543329a6b718a328a0d384, with upstream's later fix of
``Tools::Accumulate``, Tools 0525a91, applied: without it the block cluster tree reads
uninitialised memory and the energy comes out NaN in most runs); docs/performance.md,
"Tangent-point energy against Repulsor", gives the figures, docs/lab/repulsor.md how the
driver was compiled and every run. Without the binary, only our side runs.
Results also go to ``out/repulsor_compare.json``.
"""

from __future__ import annotations

import argparse
import hashlib
import itertools
import json
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
# the curve shipped with the package (its data folder stays where it is)
FHW = ROOT / "moebius_addon" / "core" / "data" / "freedman_unknot_1184.obj"
# where bench/repulsor_driver/build.sh puts the driver: $REPULSOR_BUILD, else build/repulsor
DRIVER = Path(os.environ.get("REPULSOR_BUILD") or ROOT / "build" / "repulsor") / "driver" / "driver"
CACHE = ROOT / "out" / "repulsor_curves"
EXACT_UP_TO = 10000
ALPHA, BETA = 2.0, 4.0


# -- our side, in a process of its own -------------------------------------------------------------

def _core(core_from: str | None):
    # this checkout's core unless told otherwise: a venv may hold another (an editable install
    # of the main tree measured a worktree's bench against main's code)
    sys.path.insert(0, core_from or str(ROOT))
    from moebius_addon import core
    return core


def peak_rss_mb() -> float:
    """Peak resident memory of this process image: VmHWM. getrusage's ru_maxrss is kept across
    execve on Linux, so a process started from a large parent reports the parent's peak."""
    try:
        with open("/proc/self/status") as f:
            return next(float(line.split()[1]) / 1024 for line in f if line.startswith("VmHWM:"))
    except (OSError, StopIteration):
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _energy(energy: str) -> dict:
    """The energy options of our evaluators and runs: the tangent-point energy with the
    bench's exponents, or the Möbius energy."""
    return {"energy": energy} if energy == "moebius" else {
        "energy": "tangent_point", "alpha": ALPHA, "beta": BETA}


def _ours_eg(core, P: np.ndarray, engine: str, theta: float | None,
             energy: str = "tangent_point"):
    """(energy name, E, G) of one tangent-point (or Möbius) energy+gradient."""
    E, G = core.energy_gradient(P, engine=engine, theta=theta, **_energy(energy))
    return energy, E, np.asarray(G)


def _ours_relax(core, P: np.ndarray, theta: float | None, energy: str = "tangent_point",
                iterations: int = 1):
    """(energy name, result) of one iteration (or more) of the tangent-point (or Möbius) flow
    on the tree."""
    return energy, core.relax(P, max_iter=iterations, engine="tree", theta=theta,
                              **_energy(energy))


def forget_warm_up() -> float:
    """Give the warm-up's freed memory back (glibc's ``malloc_trim``) and restart the peak
    (``VmHWM``, by writing 5 to ``/proc/self/clear_refs``), so that the peak measured after it
    is the measurement's, not the warm-up's (a warm-up's peak can exceed a small measurement's).
    The resident set now (MB)."""
    try:
        import ctypes
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:
        pass
    try:
        with open("/proc/self/status") as f:
            return next(float(line.split()[1]) / 1024 for line in f if line.startswith("VmRSS:"))
    except (OSError, StopIteration):
        return peak_rss_mb()


def worker(args) -> None:
    """One measurement of ours; prints one ``ours ...`` line and one ``ours memory`` line."""
    core = _core(args.core_from)
    P = np.fromfile(args.raw_curve, dtype=np.float64).reshape(-1, 3)
    n = len(P)
    theta = args.theta
    # warm-up: load (or compile) every kernel used below. A 600-edge curve alone misses the
    # paths taken from a size on (the contact tree, the multilevel preconditioner, the single-
    # precision weights), whose loading from numba's cache was timed (40 ms at 10^4 edges):
    # core.warm runs those too, on small curves (no kernel loads in the timed call at 10^4,
    # 10^5 or 10^6 edges, cProfile)
    small = core.resample(P, 600)
    _ours_eg(core, small, "tree", theta)
    _ours_relax(core, small, theta)
    _ours_relax(core, small, theta, "moebius")
    core.warm(("exact", "tree", "tangent_point"), say=None)
    if args.worker == "error":
        _ours_eg(core, small, "exact", theta)
    before = forget_warm_up()
    head = f"ours {args.worker} edges={n} threads={args.threads}"
    if args.worker in ("eg", "eg_moebius"):
        t0 = time.perf_counter()
        name, E, G = _ours_eg(core, P, "tree", theta,
                              "moebius" if args.worker == "eg_moebius" else "tangent_point")
        s = time.perf_counter() - t0
        print(f"{head} energy_name={name} seconds={s:.6f} energy={E:.12e} "
              f"diff_norm={np.linalg.norm(G):.12e}", flush=True)
    elif args.worker == "eg_parts":
        # the same E+g in its two parts: the frame (hierarchy, split, cluster data) and the
        # sums on it, as the driver's "info eg" line splits Repulsor's (mesh; energy and
        # differential on the built trees)
        from moebius_addon.core.runs.engine import _frame, as_checked_layout
        choice = core.check_energy("tangent_point", ALPHA, BETA)
        for again in range(1 + args.again):  # --again: new frames in the same process
            t0 = time.perf_counter()
            X, layout, _ = as_checked_layout(P, True)
            frame = _frame(X, layout, "tree", theta, choice)  # the evaluators' own frame
            t1 = time.perf_counter()
            E, G = frame.energy_gradient(X)
            t2 = time.perf_counter()
            mode = "eg_parts_again" if again else "eg_parts"
            print(f"ours {mode} edges={n} threads={args.threads} energy_name=tangent_point "
                  f"seconds={t2 - t0:.6f} build_seconds={t1 - t0:.6f} "
                  f"kernel_seconds={t2 - t1:.6f}", flush=True)
    elif args.worker in ("iter", "iter_moebius"):
        later = args.later if args.worker == "iter_moebius" else 0
        t0 = time.perf_counter()
        name, r = _ours_relax(core, P, theta,
                              "moebius" if args.worker == "iter_moebius" else "tangent_point",
                              1 + later)
        wall = time.perf_counter() - t0
        sec = r.history["seconds"]
        its = r.stats.get("krylov_iterations")
        print(f"{head} energy_name={name} seconds={sec[1] - sec[0]:.6f} "
              f"setup_seconds={sec[0]:.6f} wall_seconds={wall:.6f} "
              f"krylov={','.join(map(str, its)) if its else '-'} "
              f"energy={r.history['energy'][0]:.12e} energy_new={r.history['energy'][1]:.12e} "
              f"step={r.history['step'][1]:.6e}", flush=True)
        for i in range(2, len(sec)):
            print(f"ours iter_moebius_later edges={n} threads={args.threads} index={i} "
                  f"seconds={sec[i] - sec[i - 1]:.6f} energy={r.history['energy'][i]:.12e} "
                  f"step={r.history['step'][i]:.6e}", flush=True)
    elif args.worker == "error":
        name, E0, G0 = _ours_eg(core, P, "exact", theta)
        t0 = time.perf_counter()
        _, E1, G1 = _ours_eg(core, P, "tree", theta)
        s = time.perf_counter() - t0
        print(f"{head} energy_name={name} energy_tree={E1:.12e} energy_exact={E0:.12e} "
              f"energy_rel_error={abs(E1 - E0) / abs(E0):.3e} "
              f"diff_rel_error={np.linalg.norm(G1 - G0) / np.linalg.norm(G0):.3e} "
              f"tree_seconds={s:.6f}", flush=True)
    peak = peak_rss_mb()
    print(f"ours memory mode={args.worker} edges={n} threads={args.threads} peak_rss_mb={peak:.1f} "
          f"after_warm_up_mb={before:.1f}", flush=True)


# -- the curves, the mapping check, the driver -----------------------------------------------------

def curve(core, obj: Path, n: int) -> Path:
    """The curve of the OBJ file (the FHW unknot by default) resampled to n edges, as raw
    float64 (N, 3) for both sides; cached under out/, keyed by the file's content."""
    CACHE.mkdir(parents=True, exist_ok=True)
    digest = hashlib.sha1(obj.read_bytes()).hexdigest()[:10]
    path = CACHE / f"{obj.stem}-{digest}_{n}.bin"
    if not path.exists():
        polygons = core.read_obj(obj)
        if len(polygons) != 1:
            sys.exit(f"{obj} holds {len(polygons)} polylines; --curve needs a file with one "
                     "closed polyline (Repulsor's driver takes one curve)")
        np.ascontiguousarray(core.resample(polygons[0], n), dtype=np.float64).tofile(path)
    return path


def tp_sums(P: np.ndarray, alpha: float = ALPHA, beta: float = BETA) -> tuple[float, float]:
    """(sum over ordered pairs of distinct edges, over ordered pairs of disjoint edges) of
    ``l_I l_J |T_I × (m_I − m_J)|^α / |m_I − m_J|^β``, in numpy (Repulsor's and our
    conventions)."""
    e = np.roll(P, -1, axis=0) - P
    m = P + 0.5 * e
    lengths = np.linalg.norm(e, axis=1)
    T = e / lengths[:, None]
    n = len(P)
    total = disjoint = 0.0
    for i0 in range(0, n, 256):
        i = np.arange(i0, min(n, i0 + 256))
        d = m[i, None, :] - m[None, :, :]
        r2 = np.einsum("ijk,ijk->ij", d, d)
        r2[np.arange(len(i)), i] = np.inf
        c = np.linalg.norm(np.cross(T[i, None, :], d), axis=2)
        f = lengths[i, None] * lengths[None, :] * c ** alpha / r2 ** (beta / 2)
        total += f.sum()
        f[np.arange(len(i)), (i + 1) % n] = 0.0
        f[np.arange(len(i)), (i - 1) % n] = 0.0
        disjoint += f.sum()
    return float(total), float(disjoint)


def run(cmd: list[str], env: dict) -> list[dict]:
    """Run one measuring process; its ``side mode key=value ...`` lines as dicts."""
    out = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if out.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({out.returncode}):\n{out.stderr[-2000:]}")
    rows = []
    for line in out.stdout.splitlines():
        words = line.split()
        if len(words) < 2 or words[0] not in ("repulsor", "ours"):
            continue
        if words[1] == "info":
            # the driver's split of its E+g: mesh (trees) and the sums on the built trees
            if words[0] == "repulsor" and len(words) > 2 and words[2] in ("eg", "eg_again"):
                kv = dict(w.split("=", 1) for w in words[3:])
                rows.append({"side": "repulsor",
                             "mode": "eg_parts" if words[2] == "eg" else "eg_parts_again",
                             "build_seconds": float(kv["mesh_seconds"]),
                             "kernel_seconds": float(kv["energy_differential_seconds"])})
            continue
        row = {"side": words[0], "mode": words[1]}
        for w in words[2:]:
            k, _, v = w.partition("=")
            k = "of" if k == "mode" else k  # a memory line names the mode it measured
            try:
                row[k] = float(v) if any(ch in v for ch in ".e") or not v.isdigit() else int(v)
            except ValueError:
                row[k] = v
        rows.append(row)
    for r in rows:  # the info line names no size: the eg line of the same process does
        if r["mode"] in ("eg_parts", "eg_parts_again") and "edges" not in r:
            eg = next((q for q in rows if q["mode"] == "eg"), {})
            r["edges"], r["threads"] = eg.get("edges"), eg.get("threads")
    return rows


def env_for(threads: int) -> dict:
    env = dict(os.environ)
    env["OPENBLAS_NUM_THREADS"] = str(threads)
    env["NUMBA_NUM_THREADS"] = str(threads)
    return env


def show(row: dict) -> None:
    print(" ".join([row["side"], row["mode"]] + [f"{k}={v}" for k, v in row.items()
                                                  if k not in ("side", "mode")]), flush=True)


def cpu_ticks() -> tuple[int, int] | None:
    """(steal, all) clock ticks of every CPU from /proc/stat's ``cpu`` line (None elsewhere):
    the share other guests of the host took from this VM, which moves the seconds of a run."""
    try:
        with open("/proc/stat") as f:
            ticks = [int(v) for v in f.readline().split()[1:9]]
    except (OSError, ValueError):
        return None
    return ticks[7], sum(ticks)


def host_line(before, after, n: int, threads: int) -> dict | None:
    """The stolen share of the VM's CPU time between two :func:`cpu_ticks`."""
    if before is None or after is None or after[1] <= before[1]:
        return None
    hz = os.sysconf("SC_CLK_TCK")
    return {"side": "host", "mode": "steal", "edges": n, "threads": threads,
            "steal_seconds": (after[0] - before[0]) / hz,
            "steal_share": (after[0] - before[0]) / (after[1] - before[1])}


def per_round(rows: list[dict], mode: str, n: int, threads: int) -> list[float]:
    """Repulsor's time ÷ ours round by round (the processes of a round ran one after another,
    so they saw much the same host)."""
    def times(side):
        return [r["seconds"] for r in rows if r["side"] == side and r["mode"] == mode
                and r["edges"] == n and r["threads"] == threads]
    return [a / b for a, b in zip(times("repulsor"), times("ours"), strict=False)]


def summary(rows: list[dict], side: str, mode: str, n: int, threads: int, key="seconds"):
    vals = [r[key] for r in rows if r["side"] == side and r["mode"] == mode
            and r["edges"] == n and r["threads"] == threads]
    mem = [r["peak_rss_mb"] for r in rows if r["side"] == side and r["mode"] == "memory"
           and r.get("edges") == n and r.get("threads") == threads
           and r.get("of") == mode]
    if not vals:
        return None
    return {"best": min(vals), "median": statistics.median(vals), "k": len(vals),
            "peak_rss_mb": max(mem) if mem else None}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", type=int, nargs="*", default=[2400, 10000])
    ap.add_argument("--million", action="store_true", help="add 10^6 edges (slow)")
    ap.add_argument("--threads", type=int, nargs="*", default=[1, 2])
    ap.add_argument("--reps", type=int, default=5, help="alternated rounds k per size")
    ap.add_argument("--driver", default=str(DRIVER),
                    help="Repulsor's driver, built by bench/repulsor_driver/build.sh (default "
                         "%(default)s: $REPULSOR_BUILD/driver/driver, else build/repulsor in "
                         "this checkout)")
    ap.add_argument("--curve", default=str(FHW),
                    help="OBJ file of one closed polyline, resampled to each size (default: the "
                         "FHW unknot shipped in moebius_addon/core/data)")
    ap.add_argument("--theta", type=float, default=None,
                    help="our tree's admissibility (default: the core's)")
    ap.add_argument("--repulsor-theta", type=float, default=0.5,
                    help="Repulsor's far_field_separation_parameter (its default 0.5)")
    ap.add_argument("--core-from", default=None)
    ap.add_argument("--json", default=str(ROOT / "out" / "repulsor_compare.json"))
    ap.add_argument("--moebius", action="store_true",
                    help="also time our Möbius E+g and one iteration of its flow")
    ap.add_argument("--later", type=int, default=0,
                    help="with --moebius: K more iterations of our Möbius run, each timed")
    ap.add_argument("--parts", action="store_true",
                    help="also time our E+g in two parts: frame built, sums on it")
    ap.add_argument("--again", type=int, default=0,
                    help="with --parts: K more trees and sums on them in the same process, on "
                         "both sides (warm allocator and caches; summary mode eg_parts_again)")
    ap.add_argument("--worker", choices=("eg", "eg_parts", "iter", "eg_moebius", "iter_moebius",
                                         "error"),
                    help=argparse.SUPPRESS)
    ap.add_argument("--raw-curve", help=argparse.SUPPRESS)
    ap.add_argument("--threads-of-worker", type=int, dest="worker_threads", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        args.threads = args.worker_threads
        worker(args)
        return

    core = _core(args.core_from)  # before bench/paper.py, which imports the core too
    sys.path.insert(0, str(HERE))
    from paper import machine

    sizes = args.sizes + ([1000000] if args.million else [])
    obj = Path(args.curve).resolve()
    if not obj.is_file():
        sys.exit(f"no curve at {obj}: give an OBJ file with --curve")
    driver = Path(args.driver)
    have_driver = driver.exists()
    out: dict = {"machine": machine(), "driver": str(driver) if have_driver else None,
                 "ours_energy": "tangent_point",
                 "repulsor_theta": args.repulsor_theta, "theta": args.theta, "rows": []}
    print(out["machine"], flush=True)
    print(f"ours: E+g of {out['ours_energy']}; iteration: core.relax(max_iter=1, engine='tree'): "
          "projected hs gradient, edge-length and barycenter constraints, Armijo line search, "
          "collision-free step bound, back-projection", flush=True)
    if have_driver:
        print("repulsor: E+g = mesh + TangentPointEnergy0(q=2, p=4) Value and Differential; "
              "iteration = mesh, E+g, TangentPointMetric0 GMRES solve (<= 100 its, rtol 1e-5), "
              "MaximumSafeStepSize along -gradient in [0, 1], SemiStaticUpdate, new energy; "
              "no constraints, no line search", flush=True)
    else:
        print(f"repulsor: no driver at {driver}; our side only", flush=True)
    rows = out["rows"]
    me = [sys.executable, str(Path(__file__).resolve())]
    extra = (["--theta", str(args.theta)] if args.theta is not None else []) + \
        (["--core-from", args.core_from] if args.core_from else [])
    later = ["--later", str(args.later)] if args.later else []

    def measure(cmd, env):
        for r in run(cmd, env):
            show(r)
            rows.append(r)

    for n in sizes:
        path = curve(core, obj, n)
        if n <= EXACT_UP_TO:
            total, disjoint = tp_sums(np.fromfile(path).reshape(-1, 3))
            row = {"side": "numpy", "mode": "mapping", "edges": n, "threads": 0,
                   "all_distinct_pairs": total, "disjoint_pairs": disjoint,
                   "adjacent_share": (total - disjoint) / total}
            show(row)
            rows.append(row)
        for t in args.threads:
            env = env_for(t)
            ticks = cpu_ticks()
            for _ in range(args.reps):
                for mode in ("eg", "iter"):
                    if have_driver:
                        again = (["--repeat", str(1 + args.again)]
                                 if mode == "eg" and args.parts and args.again else [])
                        measure([str(driver), str(path), mode, str(t), "--theta",
                                 str(args.repulsor_theta)] + again, env)
                    measure(me + ["--worker", mode, "--raw-curve", str(path), "--threads-of-worker",
                                  str(t)] + extra, env)
                if args.parts:
                    measure(me + ["--worker", "eg_parts", "--raw-curve", str(path),
                                  "--threads-of-worker", str(t), "--again", str(args.again)]
                            + extra, env)
                if args.moebius:
                    for mode in ("eg_moebius", "iter_moebius"):
                        measure(me + ["--worker", mode, "--raw-curve", str(path),
                                      "--threads-of-worker", str(t)] + extra
                                + (later if mode == "iter_moebius" else []), env)
            if n <= EXACT_UP_TO:  # both sides' all-pairs sums (Repulsor's: 300 s at 10^5)
                if have_driver:
                    measure([str(driver), str(path), "error", str(t), "--theta",
                             str(args.repulsor_theta)], env)
                measure(me + ["--worker", "error", "--raw-curve", str(path), "--threads-of-worker",
                              str(t)] + extra, env)
            host = host_line(ticks, cpu_ticks(), n, t)
            if host:
                rows.append(host)
                print(f"host edges={n} threads={t} steal_seconds={host['steal_seconds']:.1f} "
                      f"steal_share={host['steal_share']:.3f} (of all the VM's CPU time while "
                      "these rounds ran)", flush=True)
            best = {}
            for side in ("repulsor", "ours"):
                for mode in ("eg", "iter", "eg_moebius", "iter_moebius", "iter_moebius_later"):
                    s = summary(rows, side, mode, n, t)
                    if s:
                        best[side, mode] = s["best"]
                        print(f"summary side={side} mode={mode} edges={n} threads={t} "
                              f"best={s['best']:.4f} median={s['median']:.4f} k={s['k']} "
                              f"peak_rss_mb={s['peak_rss_mb']}", flush=True)
            for side, mode in itertools.product(("repulsor", "ours"),
                                                ("eg_parts", "eg_parts_again")):
                # E+g's parts: trees built, sums on them (first in a process, and again)
                parts = [summary(rows, side, mode, n, t, key) for key in
                         ("build_seconds", "kernel_seconds")]
                if all(parts):
                    print(f"summary side={side} mode={mode} edges={n} threads={t} "
                          f"build_best={parts[0]['best']:.4f} kernel_best={parts[1]['best']:.4f} "
                          f"k={parts[1]['k']}", flush=True)
            for mode in ("eg", "iter"):
                r = per_round(rows, mode, n, t)
                if r:
                    print(f"rounds mode={mode} edges={n} threads={t} repulsor/ours "
                          f"{' '.join(f'{x:.2f}' for x in r)} median={statistics.median(r):.2f}",
                          flush=True)
            # iteration ÷ E+g of the same energy, best of each ("iteration ≤ 6 E+g")
            for side, it, eg in (("repulsor", "iter", "eg"), ("ours", "iter", "eg"),
                                 ("ours", "iter_moebius", "eg_moebius"),
                                 ("ours", "iter_moebius_later", "eg_moebius")):
                if (side, it) in best and (side, eg) in best:
                    print(f"ratio side={side} {it}/{eg} edges={n} threads={t} "
                          f"{best[side, it] / best[side, eg]:.2f}", flush=True)
    Path(args.json).parent.mkdir(parents=True, exist_ok=True)
    Path(args.json).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
