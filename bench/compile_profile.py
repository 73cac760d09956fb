"""Where a first session's compile time goes: runs warm-up paths
(``moebius_addon.core.compilation.warmup``) in a fresh numba cache and prints each path's
CPU seconds (as the warm-up prints them) and the kernels that took longest to compile: each
kernel's own seconds (the kernels it calls and compiles on the way are counted to them, not
to it) and how many signatures it compiled. A kernel listed with more compiles than it has
uses (a literal argument typed ``Literal[int]``, say) compiles twice for nothing.

    NUMBA_CPU_NAME=x86-64-v3 NUMBA_CPU_FEATURES="" \\
        python bench/compile_profile.py [PATH ...] [--top 30]

Without paths, every path of the warm-up (what the extension's kernel cache is built from).
"""

from __future__ import annotations

import argparse
import collections
import os
import tempfile
import time


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("paths", nargs="*")
    ap.add_argument("--top", type=int, default=30)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as cache:
        os.environ["NUMBA_CACHE_DIR"] = cache  # before numba is imported: nothing cached yet
        from numba.core import event

        from moebius_addon.core.compilation import warmup

        own, count, stack = collections.Counter(), collections.Counter(), []

        class Listener(event.Listener):
            def on_start(self, ev):
                stack.append([time.perf_counter(), 0.0])

            def on_end(self, ev):
                t0, inner = stack.pop()
                seconds = time.perf_counter() - t0
                f = ev.data["dispatcher"].py_func
                name = f"{f.__module__.removeprefix('moebius_addon.core.')}.{f.__qualname__}"
                own[name] += seconds - inner
                count[name] += 1
                if stack:
                    stack[-1][1] += seconds

        event.register("numba:compile", Listener())
        total = time.perf_counter()
        warmup.warm(args.paths or tuple(warmup.PATHS))  # prints each path's CPU seconds
        print(f"all: {time.perf_counter() - total:.1f} s, compiling {sum(own.values()):.1f} s "
              f"({len(own)} kernels)")
        print("\n  own s  compiles  kernel")
        for name, seconds in own.most_common(args.top):
            print(f"{seconds:7.1f}  {count[name]:8d}  {name}")


if __name__ == "__main__":
    main()
