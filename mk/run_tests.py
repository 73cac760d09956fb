"""`make test`: every part of the suite, in two streams side by side (CI has two cores).

Most parts run one process on one core (pytest, numba's compiler, Blender), so run one after
the other they left the second core idle for most of `make test`. Here two streams share the
machine, each running its parts in order:

* stream 1: the test repository (``make build/test-repo/index.json``: the zip with its kernel
  cache, two compiling processes), then the Blender tests on 5.0 (``tests/blender`` in .venv);
* stream 2: the core suite (everything outside ``tests/blender``), the UI test in a real
  Blender window (``make ui-test``), then the ``lines`` tests on 4.2, 4.5 and 5.2, which wait
  for stream 1's repository.

Every part runs even when one before it failed (a part that needs the repository is failed
when the repository could not be built); each part's output is printed whole when it ends,
with a ``[time]`` line, then a summary; the exit status is 1 when any part failed.

    python mk/run_tests.py --lines 4.2 4.5 5.2 --repo build/test-repo
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LOGS = ROOT / "build" / "test-logs"


class Runner:
    def __init__(self, repo: str) -> None:
        self.repo = repo
        self.repo_built = threading.Event()
        self.repo_ok = False
        self.lock = threading.Lock()
        self.results: list[tuple[str, str, float]] = []  # (part, PASS/FAIL, seconds)
        self.start = time.perf_counter()

    def part(self, name: str, argv: list[str], env: dict | None = None,
             needs_repo: bool = False) -> bool:
        """Run one part, its output into a log file; print the log whole when it ends."""
        if needs_repo:
            self.repo_built.wait()
            if not self.repo_ok:
                self._report(name, "FAIL", 0.0, "not run: the test repository was not built\n")
                return False
        LOGS.mkdir(parents=True, exist_ok=True)
        log = LOGS / (name.replace(" ", "-").replace("/", "-") + ".log")
        t0 = time.perf_counter()
        with open(log, "w") as out:
            rc = subprocess.call(argv, cwd=ROOT, stdout=out, stderr=subprocess.STDOUT,
                                 env={**os.environ, **(env or {})})
        seconds = time.perf_counter() - t0
        self._report(name, "PASS" if rc == 0 else "FAIL", seconds, log.read_text())
        return rc == 0

    def _report(self, name: str, verdict: str, seconds: float, text: str) -> None:
        with self.lock:
            self.results.append((name, verdict, seconds))
            bar = "=" * 20
            print(f"\n{bar} {name}: {verdict} {bar}\n{text.rstrip()}", flush=True)
            print(f"[time] {name}: {seconds:.0f} s (at {self._elapsed():.0f} s of make test)",
                  flush=True)

    def _elapsed(self) -> float:
        return time.perf_counter() - self.start


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--python", default=str(ROOT / ".venv" / "bin" / "python"))
    ap.add_argument("--repo", default="build/test-repo")
    ap.add_argument("--lines", nargs="*", default=["4.2", "4.5", "5.2"])
    ap.add_argument("--make", default=os.environ.get("MAKE", "make"))
    ap.add_argument("--no-ui", action="store_true", help="leave out the real-window UI test")
    args = ap.parse_args()

    run = Runner(args.repo)
    repo_env = {"MOEBIUS_TEST_REPO": args.repo}
    make = [args.make, "--no-print-directory"]
    # the slowest tests of each part are listed, to see where CI's minutes go
    pytest = [args.python, "-m", "pytest", "-q", "--durations=15"]

    def stream1() -> None:
        try:
            run.repo_ok = run.part("test repository", [*make, f"{args.repo}/index.json"])
        finally:
            run.repo_built.set()
        run.part("Blender 5.0 (tests/blender)", [*pytest, "-m", "not slow", "tests/blender"],
                 repo_env, needs_repo=True)

    def stream2() -> None:
        run.part("core suite (all but tests/blender)", [
            *pytest, "-m", "not slow", "tests",
            "--ignore=tests/blender"])
        if not args.no_ui:
            run.part("UI test, Blender 3.4 window", [*make, "ui-test"])
        for line in args.lines:
            run.part(f"Blender {line} (lines)", [
                f".venv-blender-{line}/bin/python", "-m", "pytest", "-q", "--durations=15", "-m",
                "lines and not slow", "tests/blender"], repo_env, needs_repo=True)

    threads = [threading.Thread(target=stream1), threading.Thread(target=stream2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    failed = [name for name, verdict, _ in run.results if verdict != "PASS"]
    print("\nmake test:")
    for name, verdict, seconds in run.results:
        print(f"  {verdict}  {seconds:6.0f} s  {name}")
    print(f"[time] make test, both streams: {run._elapsed():.0f} s; "
          f"{'failed: ' + ', '.join(failed) if failed else 'every part passed'}", flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
