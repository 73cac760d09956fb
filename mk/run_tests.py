"""`make test`: every part of the suite, on two workers side by side (CI has two cores).

Most parts run one process on one core (pytest, numba's compiler, Blender), so run one after
the other they left the second core idle for most of `make test`. Here two workers take the
parts in this order, each the next one it can run:

1. the test repository (``make build/test-repo/index.json``: the zip with its kernel cache,
   two compiling processes), and ``make lint``'s ruff check (seconds);
2. the UI test in a real Blender window (``make ui-test``), beside the repository's build;
3. the core suite (everything outside ``tests/blender``) in two halves, once the repository is
   built: it loads the kernels the zip ships (``$MOEBIUS_KERNEL_CACHE``) rather than
   compiling them;
4. the Blender tests on 5.0 (``tests/blender`` in .venv-blender-5.0: bpy, numpy and pytest,
   no scipy, as in Blender), once the repository is built;
5. the ``lines`` tests on 4.2, 4.5 and 5.2, once the repository is built.

Every part runs even when one before it failed (a part that needs the repository is failed
when the repository could not be built); each part's output is printed whole when it ends,
with a ``[time]`` line (its wall and CPU seconds), then a summary; the exit status is 1 when
any part failed.

    python mk/run_tests.py --lines 4.2 4.5 5.2 --repo build/test-repo
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import threading
import time
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LOGS = ROOT / "build" / "test-logs"


class Runner:
    def __init__(self, repo: str) -> None:
        self.repo = repo
        self.repo_built = threading.Event()
        self.repo_ok = False
        self.lock = threading.Lock()
        # (part, PASS/FAIL, seconds, seconds of CPU)
        self.results: list[tuple[str, str, float, float]] = []
        self.start = time.perf_counter()

    def part(self, name: str, argv: list[str], env: dict | None = None,
             needs_repo: bool = False) -> bool:
        """Run one part, its output into a log file; print the log whole when it ends."""
        if needs_repo:  # handed out only once the repository's build has ended (take())
            if not self.repo_ok:
                self.fail(name, "not run: the test repository was not built")
                return False
        LOGS.mkdir(parents=True, exist_ok=True)
        log = LOGS / (name.replace(" ", "-").replace("/", "-") + ".log")
        t0 = time.perf_counter()
        with open(log, "w") as out:
            proc = subprocess.Popen(argv, cwd=ROOT, stdout=out, stderr=subprocess.STDOUT,
                                    env={**os.environ, **(env or {})})
            # wait4: the CPU seconds of this part's process tree (the wall time is shared)
            _, status, usage = os.wait4(proc.pid, 0)
            proc.returncode = rc = os.waitstatus_to_exitcode(status)
        seconds = time.perf_counter() - t0
        self._report(name, "PASS" if rc == 0 else "FAIL", seconds, log.read_text(),
                     usage.ru_utime + usage.ru_stime)
        return rc == 0

    def fail(self, name: str, why: str) -> None:
        self._report(name, "FAIL", 0.0, why + "\n", 0.0)

    def _report(self, name: str, verdict: str, seconds: float, text: str, cpu: float) -> None:
        with self.lock:
            self.results.append((name, verdict, seconds, cpu))
            bar = "=" * 20
            print(f"\n{bar} {name}: {verdict} {bar}\n{text.rstrip()}", flush=True)
            print(f"[time] {name}: {seconds:.0f} s, {cpu:.0f} s of CPU "
                  f"(at {self.elapsed():.0f} s of make test)", flush=True)

    def elapsed(self) -> float:
        return time.perf_counter() - self.start


def unpack_kernel_cache(repo: Path, dest: Path) -> None:
    """``core/kernel_cache`` of the repository's linux-x64 zip, unpacked into ``dest``."""
    shutil.rmtree(dest, ignore_errors=True)
    (zip_path,) = repo.glob("*-linux_x64.zip")
    prefix = "core/kernel_cache/"
    with zipfile.ZipFile(zip_path) as z:
        for name in z.namelist():
            if name.startswith(prefix) and not name.endswith("/"):
                target = dest / name[len(prefix):]
                target.parent.mkdir(parents=True, exist_ok=True)
                target.write_bytes(z.read(name))


def core_halves() -> tuple[list[str], list[str]]:
    """Every test file outside ``tests/blender``, alternately into two halves (sorted by path:
    the same halves on every machine, a new file lands in one)."""
    files = sorted(str(p.relative_to(ROOT)) for p in (ROOT / "tests").rglob("test_*.py")
                   if p.relative_to(ROOT / "tests").parts[0] != "blender")
    return files[0::2], files[1::2]


def plan(args) -> list[tuple[str, list[str], dict | None, bool]]:
    """The parts as (name, argv, environment, needs the repository), in the order the
    workers take them."""
    repo_env = {"MOEBIUS_TEST_REPO": args.repo}
    make = [args.make, "--no-print-directory"]
    # the slowest tests of each part are listed, to see where CI's minutes go
    pytest = ["-m", "pytest", "-q", "--durations=15"]
    # the core suite loads the kernels of the test zip (compiled for the generic CPU, as users
    # on linux-x64 run them) instead of compiling every one natively
    # (core/compilation/shipped_cache.py); the Blender tests install the zip, whose own cache
    # they test, so they are not pointed
    core_env = {"MOEBIUS_KERNEL_CACHE": str(ROOT / "build" / "test-kernel-cache")}
    parts = [("test repository", [*make, f"{args.repo}/index.json"], None, False),
             # make lint's check (seconds): outside CI, three findings had come in unseen
             ("lint (ruff)", [args.python, "-m", "ruff", "check", "moebius_addon", "tests",
                              "bench", "mk"], None, False)]
    if not args.no_ui:
        parts.append(("UI test, Blender 3.4 window", [*make, "ui-test"], None, False))
    # the core suite in two halves, one per worker once the repository is built: run whole,
    # it took as long as the Blender parts beside it together
    for k, half in enumerate(core_halves(), 1):
        parts.append((f"core suite, half {k} of 2",
                      [args.python, *pytest, "-m", "not slow", *half], core_env, True))
    parts += [("Blender 5.0 (tests/blender)",
               [".venv-blender-5.0/bin/python", *pytest, "-m", "not slow", "tests/blender"],
               repo_env, True)]
    for line in args.lines:
        parts.append((f"Blender {line} (lines)",
                      [f".venv-blender-{line}/bin/python", *pytest, "-m", "lines and not slow",
                       "tests/blender"], repo_env, True))
    return parts


def parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--python", default=str(ROOT / ".venv" / "bin" / "python"))
    ap.add_argument("--repo", default="build/test-repo")
    ap.add_argument("--lines", nargs="*", default=["4.2", "4.5", "5.2"])
    ap.add_argument("--make", default=os.environ.get("MAKE", "make"))
    ap.add_argument("--no-ui", action="store_true", help="leave out the real-window UI test")
    return ap


def main() -> int:
    args = parser().parse_args()

    run = Runner(args.repo)
    parts = plan(args)
    names = [p[0] for p in parts]
    queue = threading.Condition()

    def take():
        """The next part this worker can run (None when none is left); one that needs the
        repository waits for it unless a part that does not is left."""
        with queue:
            while parts:
                for i, p in enumerate(parts):
                    if not p[3] or run.repo_built.is_set():
                        return parts.pop(i)
                queue.wait()
            return None

    def worker() -> None:
        while (p := take()) is not None:
            name, argv, env, needs_repo = p
            ok = False
            try:
                ok = run.part(name, argv, env, needs_repo)
                if ok and name == "test repository":
                    try:
                        unpack_kernel_cache(ROOT / args.repo, ROOT / "build" / "test-kernel-cache")
                    except (OSError, ValueError, zipfile.BadZipFile) as err:
                        run.fail(name, f"its kernel cache could not be unpacked: {err}")
                        ok = False
            finally:
                if name == "test repository":
                    run.repo_ok = ok
                    run.repo_built.set()
                    with queue:
                        queue.notify_all()

    threads = [threading.Thread(target=worker) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for name in names:  # a part that never reported (its worker died) is a failure too
        if name not in {r[0] for r in run.results}:
            run.fail(name, "did not run")
    failed = [name for name, verdict, *_ in run.results if verdict != "PASS"]
    print("\nmake test:               wall     CPU")
    for name, verdict, seconds, cpu in run.results:
        print(f"  {verdict}  {seconds:6.0f} s  {cpu:6.0f} s  {name}")
    print(f"  total CPU {sum(r[3] for r in run.results):.0f} s")
    print(f"[time] make test, two workers: {run.elapsed():.0f} s; "
          f"{'failed: ' + ', '.join(failed) if failed else 'every part passed'}", flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
