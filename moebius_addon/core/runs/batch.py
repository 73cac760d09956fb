"""Batch runs: many relaxations, in this process or on a Dask cluster.

A :class:`Task` is one relaxation: a curve (a knot or link of the table by name, a typed
braid word or PD code, or the polylines of an OBJ file), its edge count, the energy, the
settings and, for a tangled start, a seed. :func:`tasks` builds them from what a user types
(names, patterns like ``10_*``, crossing ranges, files, folders of OBJ files) and refuses bad
input before any work, two inputs of one name among it (one would replace the other);
:func:`run` runs them, largest first, and writes to one folder (:mod:`.batch_folder`):

* ``results.csv`` — one row per task (its settings, per stage the edge count, energy,
  iterations, seconds and status, the identified type, the worker, the error if it failed);
* ``curves/<id>.npz`` — the relaxed polygon (``x0``, ``x1``, … one array per component);
* ``run.json`` — the settings and the versions of each run into the folder.

A task whose row is whole and has no error and whose polygon loads is skipped when the run
starts again, so a run can be stopped at any point (Ctrl-C says what finished); one that
finished with other settings is refused, not reported as done. A task that raises is recorded
with its message and the others go on (it is tried again on the next run).

Dask (``pip install moebius_addon[batch]``) is imported only by :func:`run` with workers: the
core, and the Blender extension that ships it without Dask, never need it. ``workers=0``
runs the tasks here, one after the other, through the same :func:`run_task`.
"""

from __future__ import annotations

import argparse
import fnmatch
import hashlib
import json
import os
import platform
import shlex
import signal
import socket
import sys
import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ..energies.choice import (
    DEFAULT_ENERGY,
    ENERGY_OPTIONS,
    RUN_ENERGY_NAMES,
    check_energy,
    check_run_energy,
)
from ..topology import knots, table
from .batch_folder import SETTINGS_FIELDS as _SETTINGS
from .batch_folder import (  # noqa: F401 - the folder's public names, read as batch.<name>
    STAGE_FIELDS,
    FolderError,
    Writer,
    column_type,
    done_ids,
    load_curve,
    read_results,
)
from .batch_folder import check as _check_folder
from .batch_folder import finished as _finished
from .batch_folder import log_run as _log_run
from .batch_folder import read_log as _read_log
from .methods import METHODS

#: the energy table's optimizer: it converges where the explicit method stalls
#: (docs/lab/knot-table.md, "The Möbius-energy table")
DEFAULT_METHOD = "projected_gradient_implicit"
MISSING_DASK = ("Dask is not installed; batch runs on workers need it: "
                "pip install moebius_addon[batch]  (or: pip install 'dask[distributed]')")


#: the longest task id: ``curves/<id>.npz`` and its temporary name stay far below the 255
#: bytes a file name may have on common file systems
MAX_ID = 120
_SAFE = frozenset("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-.")


def safe_name(text: str, limit: int = 80) -> str:
    """``text`` itself if it has at most ``limit`` characters, all ASCII letters, digits or
    ``_-.``; else those characters kept (any other ``-``), cut to ``limit`` and followed by
    ``-`` and 10 hex digits of the text's SHA-256. Distinct names stay distinct (``a b`` and
    ``a-b``, two long names with the same start), and every name fits in a file name."""
    if len(text) <= limit and set(text) <= _SAFE:
        return text
    digest = hashlib.sha256(text.encode("utf-8", "surrogatepass")).hexdigest()[:10]
    return "".join(c if c in _SAFE else "-" for c in text[:limit]) + "-" + digest


@dataclass(frozen=True)
class Task:
    """One relaxation. ``kind``: ``"knot"`` (``ref`` a table name), ``"notation"`` (``ref``
    a braid word or PD code) or ``"file"`` (``ref`` the OBJ path; its polygons in ``curve``,
    read by :func:`tasks` so that workers need no shared file system). ``edges``: the first
    stage's edge count; ``stages``: factors of ``edges``, each stage relaxed from the last
    one resampled (``(1, 2)``: the energy table's ``n1``, ``2 n1``). ``seed``: None for the
    plain start, else a tangled start (:func:`.tangle.tangled` for a table entry,
    :func:`.tangle.crumple` otherwise)."""

    name: str
    kind: str
    ref: str
    edges: int
    stages: tuple = (1,)
    energy: str = DEFAULT_ENERGY
    method: str = DEFAULT_METHOD
    tol: float = 1e-4
    max_iter: int = 1500
    max_seconds: float = 600.0
    seed: int | None = None
    how: str = "braid"
    identify: bool = True
    curve: tuple = field(default=(), compare=False, repr=False)
    #: the energy's options (its records' ``alpha``, ``beta``, ``stiffness``) as sorted
    #: ``(name, value)`` pairs; empty: the defaults
    energy_options: tuple = ()

    @property
    def id(self) -> str:
        """A key for the curve, energy, edges, stages and start, safe as a file name on any
        file system (:func:`safe_name`): it names the task's row and ``curves/<id>.npz``."""
        tag = "" if self.energy == DEFAULT_ENERGY else f"_{self.energy}"
        tag += "".join(f"_{k}{v:g}" for k, v in self.energy_options)
        stages = "" if self.stages == (1,) else "_x" + "-".join(f"{s:g}" for s in self.stages)
        seed = "" if self.seed is None else f"_{self.how}{self.seed}"
        key = f"{safe_name(self.name)}_{self.edges}{tag}{stages}{seed}"
        return key if len(key) <= MAX_ID else safe_name(key, MAX_ID - 11)

    @property
    def cost(self) -> float:
        """Relative work, for largest-first order: each stage's edges squared (the dense
        energy and metric are O(n²) per iteration; larger knots also take more iterations)."""
        return sum((self.edges * s) ** 2 for s in self.stages)

    def start(self):
        """The start polygon (a link: a list)."""
        if self.kind == "knot":
            if self.seed is not None:
                from ..topology.tangle import tangled

                return tangled(self.ref, self.edges, self.seed, self.how)
            return knots.named(self.ref, self.edges)
        if self.kind == "notation":
            P = knots.from_notation(self.ref, self.edges)
        else:
            from ..geometry.polygon import resample

            parts = [np.asarray(c, dtype=float) for c in self.curve]
            P = resample(parts[0] if len(parts) == 1 else parts, self.edges)
        if self.seed is not None:
            from ..topology.tangle import crumple

            P = crumple(P, self.seed)
        return P

    def settings(self) -> dict:
        """The row's description of the task (everything but the curve)."""
        d = asdict(self)
        d.update(id=self.id, stages=" ".join(f"{s:g}" for s in self.stages),
                 seed="" if self.seed is None else self.seed,
                 energy=self.energy + "".join(f" {k}={v:g}" for k, v in self.energy_options))
        return {k: d[k] for k in _SETTINGS}


# --------------------------------------------------------------------------------------------
# Input: what a user types, checked before any work


def parse_crossings(text: str) -> tuple[int, int]:
    """``"7"`` or ``"6-7"`` as an inclusive range."""
    lo, _, hi = str(text).partition("-")
    try:
        a, b = int(lo), int(hi or lo)
    except ValueError:
        raise ValueError(f"crossings must be a number or a range like 6-7, got {text!r}") from None
    if a < 0 or b < a:
        raise ValueError(f"crossings range {text!r} is empty")
    return a, b


def default_edges(name: str) -> int:
    """The table entry's default edge count (:func:`.knots.named`); the unknot 100 (the
    energy table's)."""
    P = knots.named(name)
    if table.entry(name).crossings == 0:
        return 100
    return sum(len(c) for c in P) if isinstance(P, list) else len(P)


def _expand(item: str, names: list[str]) -> list[tuple[str, str, str, tuple, str]]:
    """(name, kind, ref, curve, origin) for one input: a path, a pattern or a name;
    ``origin`` says where it came from, for messages."""
    path = Path(item)
    if path.is_dir():
        files = sorted(path.glob("*.obj"))
        if not files:
            raise ValueError(f"folder {item!r} holds no .obj files")
        return [x for f in files for x in _expand(str(f), names)]
    if path.suffix.lower() == ".obj" or path.is_file():
        if not os.access(path, os.R_OK) or not path.is_file():
            raise ValueError(f"cannot read {item!r}: no such file or not readable")
        if path.suffix.lower() == ".obj":
            from ..geometry.objio import read_obj

            try:
                parts = read_obj(path)
            except (OSError, ValueError) as e:
                raise ValueError(f"cannot read {item!r}: {e}") from None
            return [(path.stem, "file", str(path), tuple(np.asarray(p) for p in parts),
                     f"the file {str(path)!r}")]
        return _notation_file(path)
    if any(c in item for c in "*?["):
        found = [n for n in names if fnmatch.fnmatchcase(n, item)]
        if not found:
            raise ValueError(f"pattern {item!r} matches no knot or link of the table")
        return [(n, "knot", n, (), f"the table's {n}") for n in found]
    found = table.lookup(item)
    if found is None:
        near = table.close_matches(item)
        hint = f"; did you mean {', '.join(near)}?" if near else ""
        raise ValueError(f"unknown knot or link {item!r}{hint}")
    return [(found, "knot", found, (), f"the table's {found}")]


def _notation_file(path: Path) -> list[tuple[str, str, str, tuple, str]]:
    """One braid word or PD code per line (``name: notation``, or the notation alone, named
    by file and line); ``#`` comments and blank lines skipped."""
    from ..topology.notation import parse_notation

    try:
        lines = path.read_text().splitlines()
    except (OSError, UnicodeDecodeError) as e:
        raise ValueError(f"cannot read {str(path)!r}: {e}") from None
    out = []
    for k, line in enumerate(lines, 1):
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        name, sep, text = line.partition(":")
        if not sep or "[" in name or "{" in name:
            name, text = f"{path.stem}-{k}", line
        try:
            parse_notation(text.strip())
        except ValueError as e:
            raise ValueError(f"{path}:{k}: {e}") from None
        out.append((name.strip(), "notation", text.strip(), (), f"{path}:{k} ({line!r})"))
    if not out:
        raise ValueError(f"{str(path)!r} holds no braid word or PD code")
    return out


def tasks(inputs=(), *, crossings: str | None = None, edges=None, stages=(1,),
          energy: str = DEFAULT_ENERGY, seeds=(None,), how: str = "braid",
          method: str = DEFAULT_METHOD, tol: float = 1e-4, max_iter: int = 1500,
          max_seconds: float = 600.0, identify: bool = True,
          energy_options: dict | None = None) -> list[Task]:
    """The tasks for ``inputs`` (table names or aliases, patterns such as ``"10_*"``, notation
    files, OBJ files, folders of OBJ files) and the knots of ``crossings`` (``"11"``,
    ``"6-7"``), each at every edge count of ``edges`` (None: the entry's default, a file's own
    count) and every seed of ``seeds``. The same input twice is one task. Raises ValueError
    naming the first bad input before anything runs, and both inputs if two different ones
    have one name (one task would replace the other). ``energy_options``: the options of the
    energies' records (``{"stiffness": 0.1}``), None or 0-weight ones left out."""
    energy_options = {k: float(v) for k, v in (energy_options or {}).items() if v is not None}
    check_run_energy(energy, **energy_options)
    energy_options = tuple(sorted(energy_options.items()))
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    if not stages or any(not s > 0 for s in stages):
        raise ValueError(f"stages must be positive factors, got {stages!r}")
    if how not in ("braid", "crumple", "both"):
        raise ValueError(f"how must be 'braid', 'crumple' or 'both', got {how!r}")
    counts = [None] if edges is None else list(edges) if np.iterable(edges) else [edges]
    for n in counts:
        if n is not None and (int(n) != n or n < 4):
            raise ValueError(f"edge counts must be whole numbers of at least 4, got {n!r}")
    names = knots.names()
    found = [x for item in inputs for x in _expand(str(item), names)]
    if crossings is not None:
        lo, hi = parse_crossings(crossings)
        hit = [n for n in knots.names("knot") if lo <= table.entry(n).crossings <= hi]
        if not hit:
            raise ValueError(f"the table has no knot of {crossings} crossings")
        found += [(n, "knot", n, (), f"the table's {n}") for n in hit]
    if not found:
        raise ValueError("nothing to run: give knot names, patterns, files or --crossings")
    out, seen, named = [], {}, {}
    for k, (name, kind, ref, curve, origin) in enumerate(found):
        # the same input twice (a name and a pattern, a file and its folder) is one task;
        # two inputs of one name are refused: one task would replace the other, or two rows
        # of one name would hold different curves
        same = (kind, str(Path(ref).resolve()) if kind == "file" else ref)
        first = named.setdefault(name, (same, origin))
        if first[0] != same:
            raise ValueError(f"{first[1]} and {origin} are both named {name!r}; give one "
                             f"another name (a notation line: 'new name: notation'; a file: "
                             f"rename it)")
        for n in counts:
            if n is None:
                n = default_edges(ref) if kind == "knot" else (
                    sum(len(c) for c in curve) if kind == "file"
                    else _count(knots.from_notation(ref)))
            for seed in seeds:
                t = Task(name, kind, ref, int(n), tuple(float(s) for s in stages), energy,
                         method, tol, max_iter, max_seconds, seed, how, identify, curve,
                         energy_options)
                first = seen.setdefault(t.id, (same, origin, k))
                if first[0] != same:
                    raise ValueError(
                        f"{first[1]} and {origin} would both be task {t.id!r} (one row of "
                        f"results.csv, one curves/{t.id}.npz); give one another name (a "
                        f"notation line: 'new name: notation'; a file: rename it)")
                if first[2] == k:
                    out.append(t)
    return out


def _interrupted(e: BaseException) -> bool:
    """Whether ``e`` arose from a KeyboardInterrupt (numba may turn one into a SystemError)."""
    seen = set()
    while e is not None and id(e) not in seen:
        if isinstance(e, KeyboardInterrupt):
            return True
        seen.add(id(e))
        e = e.__cause__ or e.__context__
    return False


def _count(P) -> int:
    return sum(len(c) for c in P) if isinstance(P, list) else len(P)


# --------------------------------------------------------------------------------------------
# One task, wherever it runs


def run_task(task: Task, threads: int | None = None) -> dict:
    """Relax ``task`` stage by stage; never raises. Returns its row (``stages``: a list of
    dicts of :data:`STAGE_FIELDS`; ``error``: the message of what went wrong, else empty)
    and ``x``, the relaxed polygon (None on failure). ``threads``: numba's thread count for
    the task (capped by the process's ``NUMBA_NUM_THREADS``), restored afterwards."""
    import numba

    from ..geometry.polygon import resample
    from ..topology.identify import identify
    from .flow import relax

    row = {**task.settings(), "runs": [], "identified": "", "error": "",
           "worker": f"{socket.gethostname()}:{os.getpid()}", "x": None}
    before = numba.get_num_threads()
    try:
        if threads:
            numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
        P = task.start()
        previous = 1.0
        for factor in task.stages:
            if factor != previous:
                if isinstance(P, list):
                    P = resample(P, [round(len(c) * factor / previous) for c in P])
                else:
                    P = resample(P, round(len(P) * factor / previous))
                previous = factor
            t0, c0 = time.perf_counter(), time.process_time()
            r = relax(P, method=task.method, max_iter=task.max_iter, tol=task.tol,
                      max_seconds=task.max_seconds, energy=task.energy,
                      **dict(task.energy_options))
            P = r.x
            row["runs"].append({"n": _count(P), "energy": float(r.fun), "iterations": r.nit,
                                  "seconds": round(time.perf_counter() - t0, 3),
                                  "cpu": round(time.process_time() - c0, 3),
                                  "status": r.status.name})
        if task.identify:
            row["identified"] = " | ".join(identify(P).names)
        row["x"] = P
    except Exception as e:  # noqa: BLE001 - recorded in the row; the other tasks go on
        if _interrupted(e):  # Ctrl-C inside a compiled kernel: stop, do not record
            raise KeyboardInterrupt from e
        row["error"] = f"{type(e).__name__}: {e}"
    finally:
        numba.set_num_threads(before)
    return row


def versions() -> dict:
    """Python, numpy, numba, the package (and its git commit when run from a checkout), Dask."""
    import numba

    from ... import __file__ as package_file

    v = {"python": platform.python_version(), "numpy": np.__version__,
         "numba": numba.__version__, "host": socket.gethostname()}
    try:
        from importlib.metadata import version

        v["moebius_addon"] = version("moebius_addon")
    except Exception:  # noqa: BLE001 - not installed: run from a checkout
        pass
    head = Path(package_file).resolve().parents[1] / ".git"
    try:
        import subprocess

        v["commit"] = subprocess.run(["git", "-C", str(head.parent), "rev-parse", "--short",
                                      "HEAD"], capture_output=True, text=True,
                                     timeout=5).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        pass
    for mod in ("dask", "distributed"):
        try:
            v[mod] = __import__(mod).__version__
        except ImportError:
            pass
    return v


# --------------------------------------------------------------------------------------------
# Running


def _dask():
    try:
        import dask  # noqa: F401
        import distributed
    except ImportError:
        raise ImportError(MISSING_DASK) from None
    return distributed


def run(task_list: list[Task], out, *, workers: int | None = None, threads: int = 1,
        scheduler: str | None = None, resume: bool = True, limit: int | None = None,
        timeout: float = 10.0, dashboard: str | None = ":8787", say=print) -> dict:
    """Run ``task_list`` into the folder ``out``, largest task first.

    Parameters
    ----------
    workers : int, optional
        0: here, one task after another. n: a ``LocalCluster`` of n worker processes of one
        Dask thread each. None: as many as ``os.cpu_count() // threads``. Ignored with
        ``scheduler``. Workers × threads may not exceed the cores (they would only wait).
    threads : int
        numba threads per task.
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:8786``); its workers must have
        moebius_addon importable. Refused after ``timeout`` seconds without answer.
    resume : bool
        Skip the tasks finished in ``out`` before (``done_ids``); a task finished there with
        other settings is refused (a FolderError naming the difference), not reported as
        done. False: run them again.
    limit : int, optional
        Stop after this many tasks (the rest are cancelled): a slice of a long run.
    dashboard : str or None
        Address of the local cluster's dashboard (``":0"`` any free port, None none).

    Returns
    -------
    dict
        ``done`` (ids finished now), ``failed`` (id → message), ``skipped`` (finished
        before), ``seconds`` (wall time), ``dashboard`` (its address, if any).

    Raises
    ------
    FolderError
        A ValueError naming the file and the fix, before any work, if ``out`` cannot be
        used (a file, a table of something else, a damaged ``run.json``, no permission),
        and during the run if a result cannot be written.
    KeyboardInterrupt
        On Ctrl-C, after saying what finished; the same call again resumes.
    """
    out = Path(out)
    cores = os.cpu_count() or 1
    if threads < 1:
        raise ValueError(f"threads must be at least 1, got {threads}")
    if scheduler is None:
        workers = max(1, cores // threads) if workers is None else workers
        if workers < 0:
            raise ValueError(f"workers must be 0 (here) or more, got {workers}")
        if max(workers, 1) * threads > cores:
            raise ValueError(f"{workers} workers × {threads} threads exceed the {cores} cores "
                             f"of this machine; use fewer workers or threads")
    ids = [t.id for t in task_list]
    if len(set(ids)) != len(ids):
        first = {}
        for t in task_list:
            other = first.setdefault(t.id, t)
            if other is not t:
                raise ValueError(f"two tasks have the id {t.id!r} ({other.kind} {other.ref!r} "
                                 f"and {t.kind} {t.ref!r}); give one another name")
    # the folder is read before any work: a table, log or polygon it cannot use is refused
    _check_folder(out)
    rows = read_results(out)
    _read_log(out)
    skipped, changed = set(), {}
    for t in task_list if resume else ():
        row = rows.get(t.id)
        if row is not None and _finished(out, t.id, row):
            diff = _changed(t, row)
            if diff:
                changed[t.id] = diff
            else:
                skipped.add(t.id)
    if changed:
        i, diff = next(iter(changed.items()))
        more = f" and {len(changed) - 1} more" if len(changed) > 1 else ""
        what = "; ".join(f"{k} {a or '(none)'} there, {b if b != '' else '(none)'} now"
                         for k, (a, b) in diff.items())
        raise FolderError(f"{out / 'results.csv'}: task {i!r}{more} finished with other "
                          f"settings ({what}); choose another output folder (--out) to keep "
                          f"both, or run them again here with --no-resume (resume=False)")
    todo = sorted((t for t in task_list if t.id not in skipped), key=lambda t: -t.cost)
    if limit is not None:
        todo = todo[:limit] if limit >= 0 else todo
    report = {"done": [], "failed": {}, "skipped": sorted(skipped), "seconds": 0.0,
              "dashboard": None}
    say(f"{len(task_list)} tasks: {len(skipped)} done before, {len(todo)} to run -> {out}")
    if not todo:  # a finished folder is only read: it may be read-only
        return report
    client = cluster = None
    if scheduler is not None or workers > 0:
        distributed = _dask()
        if scheduler is not None:
            try:
                client = distributed.Client(scheduler, timeout=f"{timeout}s")
            except (OSError, TimeoutError) as e:
                raise ValueError(f"no Dask scheduler answers at {scheduler!r} within "
                                 f"{timeout:g} s ({type(e).__name__}); start one "
                                 f"('dask scheduler') or check the address") from None
    try:
        writer = Writer(out, max((len(t.stages) for t in task_list), default=1))
        _log_run(out, _run_record(task_list, todo, report, workers, threads, scheduler))
    except FolderError:
        if client is not None:
            client.close()
        raise
    t0 = time.perf_counter()
    bar = _Progress(len(todo), say)
    # a LocalCluster's nannies write their workers' settings (OMP_NUM_THREADS=1 and others)
    # into this process's os.environ and leave them: every process started from here later
    # ran its BLAS on one thread (the last bits of its products changed)
    environ = dict(os.environ)
    quiet = _Quiet()
    quiet.guard()
    try:
        if client is None and workers == 0:
            for t in todo:
                _record(run_task(t, threads), writer, report, bar)
        else:
            if client is None:
                # fill numba's cache here first: the workers then load the kernels from it
                # instead of each compiling them (the cache is numba's default, the package's
                # __pycache__, or NUMBA_CACHE_DIR, which the workers inherit)
                from ..compilation.warmup import warm

                warm(_warm_paths(todo), say=None)
                cluster = distributed.LocalCluster(
                    n_workers=workers, threads_per_worker=1, processes=True,
                    dashboard_address=dashboard, env=thread_env(threads))
                client = distributed.Client(cluster)
            # every worker loads its kernels before the first task, so that a task's seconds
            # are its relaxation's (on a cluster without a shared cache each compiles here)
            client.run(_warm_worker, _warm_paths(todo), threads)
            report["dashboard"] = _dashboard(client)
            say(f"Dask: {len(client.scheduler_info()['workers'])} workers at "
                f"{client.scheduler.address}; dashboard {report['dashboard'] or 'none'}")
            futures = {client.submit(run_task, t, threads, key=f"moebius-{t.id}", pure=False,
                                     priority=len(todo) - k): t
                       for k, t in enumerate(todo)}
            for fut in distributed.as_completed(list(futures)):
                try:
                    row = fut.result()
                except Exception as e:  # noqa: BLE001 - a worker died or the task was lost
                    t = futures[fut]
                    row = {**t.settings(), "runs": [], "identified": "", "worker": "",
                           "error": f"{type(e).__name__}: {e}"}
                _record(row, writer, report, bar)
    except (KeyboardInterrupt, FolderError) as e:
        quiet.start()  # the closing cluster's complaints about lost connections and tasks
        if client is not None:
            try:
                client.run(_quiet_worker)
            except Exception:  # noqa: BLE001 - a worker already gone says nothing either
                pass
        left = len(todo) - len(report["done"]) - len(report["failed"])
        how = "interrupted" if isinstance(e, KeyboardInterrupt) else "stopped"
        say(f"{how}: {len(report['done'])} done now, {len(report['failed'])} failed, "
            f"{left} not run, {len(skipped)} done before; the results are in {out}; run the "
            f"same command again to resume (finished tasks are skipped)")
        raise
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
        quiet.stop()
        if os.environ != environ:
            os.environ.clear()
            os.environ.update(environ)
    report["seconds"] = time.perf_counter() - t0
    say(f"{len(report['done'])} done, {len(report['failed'])} failed in "
        f"{report['seconds']:.1f} s")
    return report


def _run_record(task_list, todo, report, workers, threads, scheduler) -> dict:
    """The entry of ``run.json`` for this run."""
    return {"started": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "tasks": len(task_list), "to_run": len(todo), "skipped": len(report["skipped"]),
            "workers": workers if scheduler is None else None, "threads": threads,
            "scheduler": scheduler, "versions": versions(),
            "settings": sorted({json.dumps({k: v for k, v in t.settings().items()
                                            if k not in ("id", "name", "ref", "edges", "seed")},
                                           sort_keys=True) for t in task_list})}


def _changed(task: Task, row: dict) -> dict[str, tuple]:
    """The settings in which ``row`` (a finished task of the same id) differs from ``task``:
    column → (the row's text, the task's value). A file's path and an unseeded task's
    ``how`` are not compared: they do not change the result."""
    want = task.settings()
    diff = {}
    for k, b in want.items():
        if k in ("id", "name") or (k == "ref" and task.kind == "file") or (
                k == "how" and task.seed is None):
            continue
        a, kind = row.get(k, ""), column_type(k)
        try:
            same = kind(a) == kind(b) if kind is not None and a != "" and b != "" else (
                a == str(b))
        except ValueError:
            same = False
        if not same:
            diff[k] = (a, b)
    return diff


def _sync_cancel_race(record) -> bool:
    """False for the traceback distributed's ``sync`` has tornado log when Ctrl-C lands before
    its future exists: its ``cancel`` callback, run in the loop's thread, reads the unset
    ``future`` (a NameError in distributed/utils.py; distributed 2026.8.0). It can come before
    :meth:`_Quiet.start` (once in tests/core/test_batch.py's Ctrl-C test); other records pass."""
    import traceback

    exc = record.exc_info[1] if record.exc_info else None
    if not isinstance(exc, NameError) or exc.__traceback__ is None:
        return True
    last = traceback.extract_tb(exc.__traceback__)[-1]
    return not (last.name == "cancel"
                and Path(last.filename).parts[-2:] == ("distributed", "utils.py"))


class _Quiet:
    """Silences Dask's loggers (and tornado's, under them) while an interrupted run closes its
    cluster: lost connections and cancelled tasks are expected then. From :meth:`guard` on,
    tornado's log drops :func:`_sync_cancel_race`'s record, which can precede :meth:`start`."""

    names = ("distributed", "tornado")

    def __init__(self):
        self.levels = {}

    @staticmethod
    def guard() -> None:
        import logging

        logging.getLogger("tornado.application").addFilter(_sync_cancel_race)

    def start(self) -> None:
        import logging

        for name in self.names:
            logger = logging.getLogger(name)
            self.levels[name] = logger.level
            logger.setLevel(logging.CRITICAL + 1)

    def stop(self) -> None:
        import logging

        for name, level in self.levels.items():
            logging.getLogger(name).setLevel(level)
        self.levels = {}
        logging.getLogger("tornado.application").removeFilter(_sync_cancel_race)


def _quiet_worker() -> None:
    _Quiet().start()


def _warm_paths(todo: list[Task]) -> tuple[str, ...]:
    """The warm-up paths of the tasks: the exact engine's, and each energy's own."""
    paths = ["exact"]
    for t in todo:
        for record in check_energy(t.energy, **dict(t.energy_options)).records:
            if record.warmup and record.name not in paths:
                paths.append(record.name)
    return tuple(paths)


def _warm_worker(paths: tuple[str, ...], threads: int) -> None:
    import numba

    from ..compilation.warmup import warm

    numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
    warm(paths, say=None)
    # Ctrl-C in a terminal reaches the workers too: the client stops the run and closes them
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)


def thread_env(threads: int) -> dict[str, str]:
    """The environment of a local worker: ``threads`` for the BLAS under numpy (Dask's
    default gives it one). The BLAS thread count changes the last bits of its products, so a
    run here gives the same bits only with the same count. numba's count is set per task
    (``numba.set_num_threads``), not here: a worker that inherited another
    ``NUMBA_NUM_THREADS`` failed every task that compiled a kernel ("Cannot set
    NUMBA_NUM_THREADS to a different value once the threads have been launched")."""
    return {name: str(threads) for name in
            ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}


def _dashboard(client) -> str | None:
    try:
        import bokeh  # noqa: F401 - the dashboard needs it
    except ImportError:
        return None
    try:
        return client.dashboard_link
    except Exception:  # noqa: BLE001 - no dashboard on that scheduler
        return None


def _record(row: dict, writer: Writer, report: dict, bar) -> None:
    writer.write(row)
    if row["error"]:
        report["failed"][row["id"]] = row["error"]
    else:
        report["done"].append(row["id"])
    last = row["runs"][-1] if row["runs"] else None
    what = (f"E({last['n']}) = {last['energy']:.6f}, {last['status']}" if last and
            not row["error"] else row["error"])
    bar.step(f"{row['id']}: {what}")


class _Progress:
    """A text bar, one line per finished task: no dependency, readable in a log file."""

    def __init__(self, total: int, say):
        self.total, self.k, self.say, self.t0 = total, 0, say, time.perf_counter()

    def step(self, text: str) -> None:
        self.k += 1
        width = 20
        full = width * self.k // max(self.total, 1)
        el = time.perf_counter() - self.t0
        eta = el / self.k * (self.total - self.k)
        self.say(f"[{'#' * full}{'.' * (width - full)}] {self.k}/{self.total} "
                 f"{el:.0f} s, ~{eta:.0f} s left | {text}")


# --------------------------------------------------------------------------------------------
# Command line: ``moebius batch …`` and ``python -m moebius_addon.core.runs.batch …``


def _edges(text: str) -> list[int]:
    out = []
    for part in text.split(","):
        try:
            out.append(int(part))
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"edge counts like 200 or 100,200, not {text!r}") from None
    return out


def parser(prog: str = "moebius batch") -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog=prog, description="Relax many knots: "
                                 "one CSV row and one polygon per task, resumable.")
    ap.add_argument("inputs", nargs="*", help="table names or aliases, patterns ('10_*'), "
                    "notation files (one braid word or PD code a line), OBJ files or folders")
    ap.add_argument("--crossings", help="every knot of these crossings: 11 or 6-7")
    ap.add_argument("--edges", type=_edges, help="edge count(s), e.g. 200 or 100,200 "
                    "(default: the table's for the knot, a file's own)")
    ap.add_argument("--stages", type=float, nargs="+", default=[1.0],
                    help="factors of the edge count, each relaxed from the last (1 2: the "
                    "energy table's n1, 2 n1)")
    ap.add_argument("--energy", default=DEFAULT_ENERGY, choices=RUN_ENERGY_NAMES,
                    help=f"the energy (default {DEFAULT_ENERGY})")
    for option, (_, p) in ENERGY_OPTIONS.items():  # --alpha, --beta, --stiffness, ...
        ap.add_argument(f"--{option.replace('_', '-')}", dest=option, type=float, default=None,
                        help=f"{p.help} (default {p.default:g})")
    ap.add_argument("--method", default=DEFAULT_METHOD)
    ap.add_argument("--tol", type=float, default=1e-4)
    ap.add_argument("--max-iter", type=int, default=1500)
    ap.add_argument("--max-seconds", type=float, default=600.0)
    ap.add_argument("--seeds", type=int, nargs="+", default=None,
                    help="tangled starts with these seeds (core.tangle)")
    ap.add_argument("--how", default="braid", help="tangling: braid, crumple or both")
    ap.add_argument("--no-identify", action="store_true")
    ap.add_argument("--out", type=Path, default=Path("batch_out"))
    ap.add_argument("--workers", type=int, default=None,
                    help="local worker processes (0: here; default cores // threads)")
    ap.add_argument("--threads", type=int, default=1, help="numba threads per worker")
    ap.add_argument("--scheduler", help="address of a running Dask scheduler")
    ap.add_argument("--timeout", type=float, default=10.0, help="seconds to reach it")
    ap.add_argument("--limit", type=int, default=None, help="run at most this many tasks")
    ap.add_argument("--dashboard", default=":8787", help="local dashboard address ('' none)")
    ap.add_argument("--resume", action=argparse.BooleanOptionalAction, default=True,
                    help="skip finished tasks (default; --no-resume runs them again)")
    ap.add_argument("--dry-run", action="store_true", help="list the tasks and stop")
    return ap


def main(argv: list[str] | None = None, prog: str = "moebius batch") -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parser(prog).parse_args(argv)
    try:
        todo = tasks(args.inputs, crossings=args.crossings, edges=args.edges,
                     stages=tuple(args.stages), energy=args.energy,
                     seeds=tuple(args.seeds) if args.seeds else (None,), how=args.how,
                     method=args.method, tol=args.tol, max_iter=args.max_iter,
                     max_seconds=args.max_seconds, identify=not args.no_identify,
                     energy_options={k: getattr(args, k) for k in ENERGY_OPTIONS})
        if args.dry_run:
            for t in sorted(todo, key=lambda t: -t.cost):
                print(t.id)
            print(f"{len(todo)} tasks")
            return 0
        report = run(todo, args.out, workers=args.workers, threads=args.threads,
                     scheduler=args.scheduler, resume=args.resume, limit=args.limit,
                     timeout=args.timeout, dashboard=args.dashboard or None,
                     say=lambda s: print(s, flush=True))
    except (ValueError, ImportError) as e:
        print(f"{prog}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        again = " ".join(shlex.quote(a) for a in [*prog.split(), *argv] if a != "--no-resume")
        print(f"{prog}: interrupted; to resume: {again}", file=sys.stderr)
        return 130
    return 1 if report["failed"] else 0


def console(argv: list[str] | None = None) -> int:
    """The ``moebius`` command: ``moebius batch …`` (the only subcommand so far)."""
    argv = sys.argv[1:] if argv is None else argv
    if not argv or argv[0] in ("-h", "--help"):
        print("usage: moebius batch [options] inputs…   (moebius batch --help)")
        return 0 if argv else 2
    if argv[0] != "batch":
        print(f"moebius: unknown command {argv[0]!r}; the commands: batch", file=sys.stderr)
        return 2
    return main(argv[1:])


if __name__ == "__main__":
    sys.exit(main(prog="python -m moebius_addon.core.runs.batch"))

